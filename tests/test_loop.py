"""The tick loop: virtual time, overrun detection, skipped deadlines, statistics and the timing log."""

from __future__ import annotations

import dataclasses
import io
import json
import sys
import threading

import pytest
from _clocks import MS, WorkClock
from hypothesis import given
from hypothesis import strategies as st

from pyrt.errors import PyrtError
from pyrt.scheduler import Loop, ReadyQueue, SimClock, TimingLog, WallClock, read_timing_log
from pyrt.scheduler.loop import overrun_line
from pyrt.scheduler.report import format_statistics
from pyrt.scheduler.stats import Accumulator, bin_edges, bin_index


def work_loop(slow_every: int = 0, slow_ns: int = 0, **kw) -> tuple[Loop, WorkClock, ReadyQueue]:
    clock = WorkClock()
    loop = Loop(clock, period_ns=MS, **kw)
    queue = ReadyQueue(divisor=1, name="r")
    calls = [0]

    def task():
        calls[0] += 1
        clock.work(slow_ns if slow_every and calls[0] % slow_every == 0 else 10_000)

    queue.add_periodic(0x10, "TASK", task, 1)
    queue.schedule(0x10, 1)
    loop.attach(queue)
    return loop, clock, queue


def test_simclock_advances_exactly_one_period_per_tick():
    """On a SimClock, n ticks move virtual time by exactly n periods and handlers see each tick's time."""
    loop = Loop(SimClock(), period_ns=250_000)
    seen = []
    loop.attach(seen.append)
    loop.run(4)
    assert seen == [250_000, 500_000, 750_000, 1_000_000]
    assert loop.now_ns == 1_000_000 and loop.tick_index == 4


def test_handlers_run_in_attach_order():
    """Handlers run every tick in the order they were attached (plant, queue, mailbox)."""
    loop = Loop(SimClock())
    order = []
    loop.attach(lambda now: order.append("plant"))
    loop.attach(lambda now: order.append("control"))
    loop.run(2)
    assert order == ["plant", "control", "plant", "control"]


def test_run_stops_on_duration_and_predicate():
    """run(duration_ns=...) and run_until stop where asked, on virtual time."""
    loop = Loop(SimClock())
    assert loop.run(duration_ns=10 * MS) == 10
    assert loop.run_until(lambda: loop.tick_index >= 25, max_ticks=100)
    assert loop.tick_index == 25
    assert not loop.run_until(lambda: False, max_ticks=5)
    assert loop.tick_index == 30


def test_overrun_is_detected_and_missed_deadlines_are_skipped():
    """A tick whose work ends 3 periods late is one overrun; the passed deadlines are skipped, not burst."""
    loop, _, _ = work_loop(slow_every=5, slow_ns=3 * MS)
    loop.run(20)
    stats = loop.statistics()
    assert stats.overruns == 4
    # Work ends exactly on the third deadline after its own: the two passed
    # deadlines in between are missed and skipped; the third is kept.
    assert stats.missed == 4 * 2
    assert stats.tasks["TASK"].overruns == 4
    loop.run(1)
    assert loop.now_ns == (21 + 8) * MS


def test_no_overrun_when_work_fits_in_the_tick():
    """Work that ends before the next deadline is not an overrun."""
    loop, _, _ = work_loop(slow_every=2, slow_ns=MS - 1)
    loop.run(10)
    assert loop.statistics().overruns == 0


def test_consecutive_overrun_limit_faults_every_robot():
    """max_consecutive_overruns: that many overruns in a row trip every robot (OROCOS maxOverRun): each station's trip, and a queue no station owns halts."""
    loop, _, queue = work_loop(slow_every=1, slow_ns=2 * MS, max_consecutive_overruns=3)
    trips = []
    loop.trip_handlers.append(lambda cause, source: trips.append((loop.tick_index, cause)))
    loop.run(10)
    assert len(trips) == 1 and "3 consecutive overruns" in trips[0][1]
    fault = loop.take_fault()
    assert fault is not None and "3 consecutive overruns" in fault.cause
    assert queue.halted


def test_overrun_warnings_are_rate_limited_to_one_line_per_second():
    """Many overruns within a second produce one warning line, then a summary per second."""
    lines: list[str] = []
    loop, _, _ = work_loop(slow_every=2, slow_ns=2 * MS, warn=lines.append)
    loop.run(600)  # about 1.8 s of loop time, 300 overruns
    assert loop.statistics().overruns == 300
    assert 1 <= len(lines) <= 3
    assert all(line.startswith("overrun:") for line in lines)
    assert "TASK" in lines[0]


def test_statistics_are_frozen_and_resettable():
    """statistics() returns a frozen snapshot; reset_statistics() starts counting afresh."""
    loop, _, _ = work_loop()
    loop.run(50)
    stats = loop.statistics()
    assert stats.tasks["TASK"].calls == 50
    assert stats.tasks["TASK"].mean_ns > 0
    with pytest.raises(dataclasses.FrozenInstanceError):
        stats.ticks = 0  # type: ignore[misc]
    loop.reset_statistics()
    assert loop.statistics().tasks["TASK"].calls == 0
    assert stats.tasks["TASK"].calls == 50


def test_timing_off_records_nothing():
    """With timing off, no task statistics are kept at all."""
    loop = Loop(SimClock(), timing=False)
    queue = ReadyQueue(divisor=1)
    queue.add_periodic(0x10, "T", lambda: None, 1)
    queue.schedule(0x10, 1)
    loop.attach(queue)
    loop.run(10)
    assert loop.statistics().tasks == {}
    assert queue.accumulators() == [] and queue.tasks_in_tick(loop.now_ns) == []


def test_timing_log_records_overruns_and_reads_back():
    """The loop's timing log holds a header, one record per overrun and summaries; it reads back."""
    buf = io.StringIO()
    loop, _, _ = work_loop(slow_every=10, slow_ns=3 * MS, timing_log=TimingLog(buf, version="t"))
    loop.run(2500)
    loop.close()
    records = [json.loads(line) for line in buf.getvalue().splitlines()]
    assert records[0]["type"] == "header" and records[0]["period_ns"] == MS
    assert records[0]["tasks"] == ["WAIT", "TASK"]
    overruns = [r for r in records if r["type"] == "overrun"]
    assert len(overruns) == 250
    first = overruns[0]
    assert first["tick"] == 9 and first["missed"] == 2
    assert first["tasks"] == [["TASK", 3 * MS]]
    assert first["task_groups"] == ["queue:r"]  # the queue is a group of its own
    assert first["group"] == "queue:r" and first["missed_releases"] == {"queue:r": 2}
    assert first["end_ns"] - first["start_ns"] == 3 * MS
    summaries = [r for r in records if r["type"] == "summary"]
    assert len(summaries) >= 2 and summaries[-1]["tasks"]["TASK"]["calls"] == 2500


def test_timing_log_file_read_back_counts(tmp_path):
    """read_timing_log attributes overruns to the task that ran longest."""
    path = tmp_path / "t.jsonl"
    loop, _, _ = work_loop(slow_every=4, slow_ns=2 * MS, timing_log=TimingLog(str(path)))
    loop.run(100)
    loop.close()
    rep = read_timing_log(str(path))
    assert len(rep.overruns) == 25
    assert rep.tasks["TASK"].overruns == 25 and rep.tasks["TASK"].calls == 100
    assert rep.worst(3)[0]["overrun_ns"] >= rep.worst(3)[-1]["overrun_ns"]


@pytest.mark.wallclock
def test_slow_task_on_wallclock_produces_an_overrun_record_naming_it():
    """A task that busy-waits three periods on the wall clock is logged as an overrun naming it
    (other ticks may overrun too on a loaded machine: the slow one's record is the one read)."""
    buf = io.StringIO()
    loop = Loop(WallClock(), period_ns=MS, timing_log=TimingLog(buf))
    queue = ReadyQueue(divisor=1)
    import time

    calls = [0]
    slow_tick = []

    def slow():
        calls[0] += 1
        if calls[0] == 5:
            slow_tick.append(loop.tick_index)
            end = time.perf_counter_ns() + 3 * MS
            while time.perf_counter_ns() < end:
                pass

    queue.add_periodic(0x10, "SLOWPOKE", slow, 1)
    queue.schedule(0x10, 1)
    loop.attach(queue)
    loop.run(20)
    loop.close()
    overruns = [json.loads(x) for x in buf.getvalue().splitlines() if '"overrun"' in x]
    (record,) = [r for r in overruns if r["tick"] == slow_tick[0]]
    assert any(n == "SLOWPOKE" and d >= 3 * MS for n, d in record["tasks"])
    assert record["missed"] >= 2
    assert loop.statistics().missed >= 2


def test_wallclock_rejects_bad_speed():
    """A non-positive speed is refused."""
    with pytest.raises(ValueError, match="speed"):
        WallClock(speed=0)


def test_loop_refuses_reentry_and_bad_arguments():
    """The loop refuses a non-positive period, negative ticks and attaching while running."""
    with pytest.raises(ValueError):
        Loop(SimClock(), period_ns=0)
    loop = Loop(SimClock())
    with pytest.raises(ValueError):
        loop.run(-1)

    def attach_inside(now):
        loop.attach(lambda n: None)

    loop.attach(attach_inside)
    loop.attach(lambda now: None)
    with pytest.raises(PyrtError):
        loop.run(1)


@given(st.integers(min_value=0, max_value=2**40))
def test_histogram_bins_hold_their_values(d):
    """Every duration falls in the bin whose edges enclose it."""
    low, high = bin_edges(bin_index(d))
    assert low <= d < high


@given(st.lists(st.integers(min_value=0, max_value=10**9), min_size=1, max_size=200))
def test_percentiles_bound_the_data(values):
    """p50/p99 from the histogram are upper bounds within one bin (25%) of the exact quantiles."""
    acc = Accumulator()
    for v in values:
        acc.add(v)
    dist = acc.distribution()
    ordered = sorted(values)
    exact99 = ordered[max(0, -(-len(ordered) * 99 // 100) - 1)]
    assert dist.max_ns == ordered[-1] and dist.count == len(values)
    assert exact99 <= dist.p99_ns <= max(exact99 * 1.25 + 1, exact99 + 1)


@given(st.integers(min_value=1, max_value=2**40))
def test_quantile_is_printed_as_a_two_figure_upper_bound(ns):
    """A histogram quantile prints as ≤ two significant figures, never below the bin's edge."""
    from pyrt.scheduler.stats import format_bound_us

    text = format_bound_us(ns)
    assert text.startswith("≤")
    digits = text[1:].replace(".", "").lstrip("0")
    assert len(digits.rstrip("0")) <= 2
    assert ns / 1e3 <= float(text[1:]) <= ns / 1e3 * 1.1 + 1e-9
    assert format_bound_us(ns, ns) == f"{ns / 1e3:.2f}"  # the exact maximum stays exact


def test_time_before_the_loop_runs_is_not_an_overrun():
    """Building a station takes time after the loop is made: the first tick is not late for it."""
    lines: list[str] = []
    clock = WorkClock()
    loop = Loop(clock, period_ns=1 * MS, warn=lines.append)
    loop.attach(lambda now: None)
    clock.work(250 * MS)  # the station's set-up, before run()
    loop.run(100)
    stats = loop.statistics()
    assert stats.overruns == 0 and stats.missed == 0 and lines == []
    assert stats.lateness.max_ns == 0


class _FakeTime:
    """time.monotonic_ns and time.sleep for WallClock: each sleep wakes ``error_ns`` late."""

    def __init__(self, error_ns: int):
        self.now = 10**9
        self.error_ns = error_ns
        self.spun = 0

    def monotonic_ns(self) -> int:
        self.spun += 1
        self.now += 1_000  # every look at the clock costs a microsecond
        return self.now

    def sleep(self, s: float) -> None:
        self.now += round(s * 1e9) + self.error_ns


def test_adaptive_spin_window_follows_the_measured_wake_up_error(monkeypatch):
    """Accurate sleeps shrink the spin window to error + margin; a preemption does not widen it."""
    import pyrt.scheduler.clock as clock_mod

    fake = _FakeTime(error_ns=5_000)
    monkeypatch.setattr(clock_mod, "time", fake)
    clock = WallClock(spin="always")
    for k in range(1, 1001):
        clock.wait_until(k * MS)
    assert 5_000 <= clock.spin_window_ns <= 5_000 + WallClock.SPIN_MARGIN_NS + 2_000
    fake.error_ns = 5 * MS  # a preemption: late past the whole window
    clock.wait_until(1001 * MS)
    assert clock.spin_window_ns <= 5_000 + WallClock.SPIN_MARGIN_NS + 2_000
    fixed = WallClock(adaptive=False, spin="always")
    fake.error_ns = 5_000
    for k in range(1002, 1100):
        fixed.wait_until(k * MS)
    assert fixed.spin_window_ns == 200_000


def test_the_spin_policy_spins_only_while_a_robot_moves(monkeypatch):
    """spin='moving' (the default): at rest the wait sleeps to the deadline (no spin, a
    wake-up error is lateness); while a robot moves it spins the window; always/never fixed."""
    import pyrt.scheduler.clock as clock_mod

    fake = _FakeTime(error_ns=30_000)
    monkeypatch.setattr(clock_mod, "time", fake)
    clock = WallClock()
    assert clock.spin == "moving" and not clock.spinning and clock.spin_window_ns == 0
    fake.spun = 0
    clock.wait_until(1 * MS)
    late = fake.now - clock.wall_deadline(1 * MS)
    assert late >= 30_000 and fake.spun <= 3  # slept to it, late by the wake-up error
    clock.moving(True)
    assert clock.spinning and clock.spin_window_ns > 30_000
    for k in range(2, 200):
        clock.wait_until(k * MS)
    late = fake.now - clock.wall_deadline(199 * MS)
    assert 0 <= late <= 1_000  # the spin took the wake-up error out
    clock.moving(False)
    assert clock.spin_window_ns == 0
    for policy, spins in (("always", True), ("never", False)):
        fixed = WallClock(spin=policy)
        fixed.moving(not spins)
        assert fixed.spinning is spins and (fixed.spin_window_ns > 0) is spins
    with pytest.raises(ValueError, match="spin must be one of moving, always, never"):
        WallClock(spin="sometimes")


def test_at_rest_a_tick_starts_after_one_sleep_between_two_clock_reads(monkeypatch):
    """At rest start_tick sleeps once to the deadline between two reads of the clock, the
    second the tick's start (its lateness the wake-up error, which the spin window still
    learns); while a robot moves it sleeps and spins the window out, on a scaled clock too."""
    import pyrt.scheduler.clock as clock_mod

    class Counted(_FakeTime):
        sleeps = 0

        def sleep(self, s: float) -> None:
            self.sleeps += 1
            super().sleep(s)

    fake = Counted(error_ns=30_000)
    monkeypatch.setattr(clock_mod, "time", fake)
    clock = WallClock()
    fake.spun = 0
    start = clock.start_tick(1 * MS)
    assert (fake.sleeps, fake.spun) == (1, 2)
    assert start == fake.now - clock.wall_deadline(0) and start - 1 * MS >= 30_000
    for k in range(2, 1000):
        clock.start_tick(k * MS)
    clock.moving(True)
    assert 30_000 < clock.spin_window_ns <= 30_000 + WallClock.SPIN_MARGIN_NS + 3_000
    for k in range(1000, 1010):
        start = clock.start_tick(k * MS)
        assert 0 <= start - k * MS <= 2_000  # the spin took the wake-up error out
    fast = WallClock(speed=4.0)
    for k in (1, 2, 3):
        assert fast.start_tick(k * MS) >= k * MS


def test_a_real_time_loop_keeps_every_tick_s_lateness_and_work():
    """On real time each tick's lateness and work are counted, whether the statistics are
    built in the loop thread or handed over to another (a runner's statistics)."""
    loop = Loop(WallClock(spin="never"), period_ns=MS)
    loop.attach(lambda now: None, name="nothing")
    loop.run(5)
    assert loop.statistics().lateness.count == 5
    loop.run(3)
    taken = loop.take_samples()
    loop.fold_samples(taken)
    stats = loop.statistics(fold=False)
    assert stats.lateness.count == 8 and stats.work.count == 8
    loop.reset_statistics()
    assert loop.statistics().lateness.count == 0


def test_a_station_tells_its_clock_when_a_robot_starts_and_stops_moving():
    """The gripper station on a clock that records it: moving(True) when a move starts,
    moving(False) when it has ended, once each."""
    from pyrt.commands import RobotShell
    from pyrt.station.gripper import build_gripper

    class Told(SimClock):
        def __init__(self) -> None:
            super().__init__()
            self.told: list[bool] = []

        def moving(self, busy: bool) -> None:
            self.told.append(busy)

    clock = Told()
    station = build_gripper(Loop(clock))
    try:
        runner = station.start()
        shell = RobotShell(station, io.StringIO())
        shell.onecmd("wait")
        start = len(clock.told)
        shell.onecmd("P-0800")
        shell.onecmd("wait")
        assert clock.told[start:] == [True, False], clock.told
        assert runner is not None
    finally:
        station.close()


def test_start_up_overruns_are_counted_apart_and_not_warned():
    """A slow first tick (code running for the first time) is a start-up overrun: no warning, not in overruns."""
    lines: list[str] = []
    loop, clock, _ = work_loop(warn=lines.append)
    first = [True]

    def cold_start(now):
        if first[0]:
            first[0] = False
            clock.work(8 * MS)

    loop.attach(cold_start, name="cold")
    loop.run(2000)
    stats = loop.statistics()
    assert stats.overruns == 0 and stats.missed == 0 and lines == []
    assert stats.startup_overruns == 1 and stats.startup_worst_ns == 7 * MS + 10_000  # the task ran 10 µs too
    assert "start-up (not counted above): 1 tick(s) overran, worst 7.01 ms" in format_statistics(stats)


def test_start_up_ends_at_the_first_tick_on_time():
    """An overrun after the first on-time tick is a real overrun, even among the first ticks."""
    loop, _, _ = work_loop(slow_every=2, slow_ns=2 * MS)
    loop.run(4)
    stats = loop.statistics()
    assert stats.startup_overruns == 0 and stats.overruns == 2


def test_a_loop_that_always_overruns_still_faults_after_start_up():
    """Start-up is at most STARTUP_TICKS ticks: a loop overrunning from its first tick is still faulted by the limit."""
    loop, _, queue = work_loop(slow_every=1, slow_ns=2 * MS, max_consecutive_overruns=2)
    loop.run(Loop.STARTUP_TICKS + 2)
    assert loop.statistics().startup_overruns == Loop.STARTUP_TICKS
    assert queue.halted and loop.take_fault() is not None


@given(count=st.integers(1, 10**9), worst=st.integers(0, 10**13), tick=st.integers(0, 10**12),
       culprit=st.text(min_size=0, max_size=200))
def test_overrun_line_fits_80_columns_and_keeps_the_count(count, worst, tick, culprit):
    """The overrun warning is one line of at most 80 characters that starts with the count."""
    line = overrun_line(count, worst, tick, culprit.replace("\n", " "))
    assert len(line) <= 80 and "\n" not in line
    assert line.startswith(f"overrun: {count} tick")


def test_real_overrun_warnings_fit_80_columns():
    """Warnings from a loop with a long task name are one line each, within 80 columns."""
    lines: list[str] = []
    clock = WorkClock()
    loop = Loop(clock, period_ns=MS, warn=lines.append)
    queue = ReadyQueue(divisor=1, name="r")
    queue.add_periodic(0x10, "A_TASK_WITH_A_VERY_LONG_NAME" * 3, lambda: clock.work(3 * MS), 3)
    queue.schedule(0x10, 1)
    loop.attach(queue)
    loop.run(3000)
    assert lines and all(len(x) <= 80 for x in lines)
    assert all(x.startswith("overrun: ") and "see stats" in x for x in lines)


def _slack_of_this_thread() -> int:
    import ctypes

    return ctypes.CDLL(None).prctl(30, 0, 0, 0, 0)  # PR_GET_TIMERSLACK


@pytest.mark.parametrize(("argv", "slack"), [([], None), (["--timer-slack"], 1),
                                             (["--timer-slack", "5000"], 5000)])
def test_timer_slack_option_reaches_the_wall_clock(argv, slack):
    """--timer-slack NS (alone: 1 ns) is handed to the loop's WallClock; without it the kernel default stays."""
    from pyrt.cli import build_parser
    from pyrt.cli._loopopts import make_loop

    args = build_parser().parse_args(["gripper", *argv])
    assert args.timer_slack == slack
    loop = make_loop(args)
    assert isinstance(loop.clock, WallClock) and loop.clock.timer_slack_ns == slack


@pytest.mark.parametrize("bad", ["0", "-5", "fast", "2000000000"])
def test_timer_slack_option_refuses_bad_values(bad, capsys):
    """A timer slack that is not 1..1e9 ns is refused with one line naming the option."""
    from pyrt.cli import build_parser

    with pytest.raises(SystemExit):
        build_parser().parse_args(["manipulator", "--timer-slack", bad])
    err = capsys.readouterr().err.strip().splitlines()
    assert "--timer-slack" in err[-1] and "timer slack must be" in err[-1]


@pytest.mark.wallclock
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="timer slack is Linux's")
def test_wall_clock_sets_the_timer_slack_in_the_loop_thread():
    """The loop thread itself runs with the asked timer slack (it is per thread), read back with PR_GET_TIMERSLACK."""
    seen: list[int] = []
    loop = Loop(WallClock(timer_slack_ns=7_000), period_ns=MS)
    loop.attach(lambda now: seen.append(_slack_of_this_thread()))
    thread = threading.Thread(target=loop.run, args=(3,))
    thread.start()
    thread.join(10)
    assert seen == [7_000] * 3


def test_timer_slack_elsewhere_than_linux_is_a_clear_warning(monkeypatch):
    """Off Linux, --timer-slack says in one line that it is Linux only, and the loop still runs."""
    import pyrt.scheduler.rt as rt
    from pyrt.cli import build_parser
    from pyrt.cli._loopopts import apply_rt_options, make_loop

    monkeypatch.setattr(rt.sys, "platform", "darwin")
    said: list[str] = []
    args = build_parser().parse_args(["gripper", "--timer-slack", "--speed", "50"])
    apply_rt_options(args, said.append)
    assert said == ["warning: timer slack is Linux only (prctl PR_SET_TIMERSLACK); not set on darwin"]
    loop = make_loop(args)
    loop.attach(lambda now: None)
    assert loop.run(2) == 2


# -- loop handlers as entries of their own ----------------------------------------------------


def handler_loop(slow_every: int = 5, slow_ns: int = 3 * MS, **kw) -> tuple[Loop, WorkClock]:
    """A queue with TASK (10 µs) and a board poll that takes ``slow_ns`` every ``slow_every``-th tick."""
    loop, clock, _ = work_loop(**kw)
    n = [0]

    def poll(now: int) -> None:
        n[0] += 1
        clock.work(slow_ns if n[0] % slow_every == 0 else 2_000)

    loop.attach(poll, name="boards")
    loop.attach(lambda now: clock.work(500), name="scope")
    return loop, clock


def test_a_slow_board_poll_is_an_entry_of_its_own_with_the_overruns():
    """Handlers are timed as entries (kind handler): calls, exact durations, and the overruns they caused."""
    loop, _ = handler_loop()
    loop.run(20)
    stats = loop.statistics()
    boards, scope, task = stats.tasks["boards"], stats.tasks["scope"], stats.tasks["TASK"]
    assert (boards.kind, scope.kind, task.kind) == ("handler", "handler", "task")
    assert boards.calls == 20 and scope.calls == 20
    assert boards.max_ns == 3 * MS and scope.max_ns == 500 and scope.mean_ns == 500
    assert stats.overruns == 4
    assert boards.overruns == 4 and task.overruns == 0 and scope.overruns == 0


def test_a_slow_handler_is_named_in_the_timing_log():
    """Overrun records list the handlers with their durations; summaries carry them with their kind; read back, the overruns are the handler's."""
    buf = io.StringIO()
    loop, _ = handler_loop(timing_log=TimingLog(buf, version="t"))
    loop.run(2500)
    loop.close()
    records = [json.loads(line) for line in buf.getvalue().splitlines()]
    assert records[0]["tasks"] == ["WAIT", "TASK", "boards", "scope"]
    overruns = [r for r in records if r["type"] == "overrun"]
    assert len(overruns) == 500
    assert overruns[0]["tasks"] == [["TASK", 10_000], ["boards", 3 * MS], ["scope", 500]]
    summary = [r for r in records if r["type"] == "summary"][-1]
    assert summary["tasks"]["boards"]["kind"] == "handler"
    assert summary["tasks"]["boards"]["overruns"] == 500 and summary["tasks"]["boards"]["calls"] == 2500
    assert summary["tasks"]["TASK"]["kind"] == "task" and summary["tasks"]["TASK"]["overruns"] == 0


def test_read_back_timing_log_attributes_the_overruns_to_the_handler(tmp_path):
    """read_timing_log finds the board poll as the culprit and knows it is a handler."""
    path = tmp_path / "t.jsonl"
    loop, _ = handler_loop(slow_every=4, timing_log=TimingLog(str(path)))
    loop.run(100)
    loop.close()
    rep = read_timing_log(str(path))
    assert rep.tasks["boards"].overruns == 25 and rep.tasks["boards"].kind == "handler"
    assert rep.tasks["TASK"].overruns == 0 and rep.tasks["TASK"].kind == "task"


def test_handler_entries_are_in_the_stats_table():
    """format_statistics prints the routines under 'task' and the handlers under 'handler'."""
    loop, _ = handler_loop()
    loop.run(20)
    lines = format_statistics(loop.statistics()).splitlines()
    heads = [i for i, line in enumerate(lines) if line.split()[:2] in (["task", "calls"],
                                                                      ["handler", "calls"])]
    assert len(heads) == 2
    task_rows = [line.split()[0] for line in lines[heads[0] + 1 : heads[1]]]
    handler_rows = [line.split() for line in lines[heads[1] + 1 : -1]]
    assert task_rows == ["TASK", "WAIT"]
    assert [r[0] for r in handler_rows] == ["boards", "scope"]
    assert handler_rows[0][1] == "20" and handler_rows[0][-1] == "4"


def test_timing_off_times_no_handler():
    """With timing off, handlers are not entries and nothing is recorded for them."""
    loop = Loop(SimClock(), timing=False)
    loop.attach(lambda now: None, name="boards")
    loop.run(10)
    assert loop.statistics().tasks == {}


def test_handler_entry_names_are_unique():
    """A second handler of one name gets '#2'; one named like a routine is shown as 'NAME (handler)'."""
    loop, _, _ = work_loop()
    loop.attach(lambda now: None, name="boards")
    loop.attach(lambda now: None, name="boards")
    loop.attach(lambda now: None, name="TASK")

    def physics(now: int) -> None:
        pass

    loop.attach(physics)
    loop.run(3)
    stats = loop.statistics()
    assert {"boards", "boards #2", "TASK (handler)", "physics"} <= set(stats.tasks)
    assert stats.tasks["TASK"].kind == "task" and stats.tasks["TASK (handler)"].kind == "handler"


def test_samples_taken_inside_a_tick_still_attribute_its_overrun():
    """A handler that takes the samples (as the mailbox does for 'stats') does not hide an earlier slow handler's overrun."""
    loop, _ = handler_loop(slow_every=2)
    taken = []
    loop.attach(lambda now: taken.append(loop.take_samples()), name="mailbox")
    loop.run(20)
    for t in taken:
        loop.fold_samples(t)
    stats = loop.statistics()  # the loop is stopped: fold what is left
    assert stats.overruns == 10 and stats.tasks["boards"].overruns == 10
    assert stats.tasks["boards"].calls == 20 and stats.tasks["mailbox"].calls == 20
    assert stats.tasks["TASK"].calls == 20


def test_jobs_and_the_loop_s_own_handlers_are_timed_on_simclock():
    """On a SimClock handlers are timed too (CPU time), and foreground jobs appear as 'jobs'."""
    loop = Loop(SimClock())
    loop.attach(lambda now: None, name="boards")

    def job():
        for _ in range(3):
            yield

    loop.spawn("j", job())
    loop.run(10)
    stats = loop.statistics()
    assert stats.tasks["boards"].calls == 10 and stats.tasks["jobs"].calls == 10
    loop.reset_statistics()
    assert loop.statistics().tasks["boards"].calls == 0


def _tick_trace(clock, **run) -> list[tuple[str, int, int]]:
    """What the handlers of a loop on ``clock`` saw: (handler, tick index, time), three ticks."""
    loop = Loop(clock, period_ns=MS)
    seen: list[tuple[str, int, int]] = []
    loop.attach(lambda now: seen.append(("plant", loop.tick_index, now)), name="plant")
    loop.attach(lambda now: seen.append(("control", loop.tick_index, now)), name="control")
    if run:
        loop.run(**run)
    else:
        loop.run(3)
    return seen


def test_one_tick_on_every_clock_and_every_way_of_running():
    """A tick is the same on virtual time and on a real-time clock, counted or
    run until a predicate or a duration: the handlers in order, each tick at its deadline."""
    expected = [(name, i, (i + 1) * MS) for i in range(3) for name in ("plant", "control")]
    assert _tick_trace(SimClock()) == expected
    assert _tick_trace(WorkClock()) == expected
    n = [0]

    def third() -> bool:
        n[0] += 1
        return n[0] == 3

    assert _tick_trace(SimClock(), until=third) == expected
    assert _tick_trace(SimClock(), duration_ns=3 * MS) == expected


def test_the_loop_moves_virtual_time_only_through_the_clock():
    """A SimClock subclass that counts its waits sees one per tick, and the
    loop never moves virtual time backward (a clock already ahead stays ahead)."""

    class Counting(SimClock):
        def __init__(self) -> None:
            super().__init__()
            self.waits = 0

        def start_tick(self, deadline_ns: int) -> int:
            self.waits += 1
            return super().start_tick(deadline_ns)

    clock = Counting()
    loop = Loop(clock, period_ns=MS)
    loop.run(5)
    assert clock.waits == 5 and clock.now_ns() == 5 * MS
    ahead = SimClock()
    behind = Loop(ahead, period_ns=MS)
    ahead.advance(10 * MS)  # moved by someone else after the loop was made
    behind.run(2)
    assert ahead.now_ns() == 10 * MS and behind.now_ns == 2 * MS


def test_a_stop_from_a_handler_ends_the_run_after_that_tick():
    """stop() inside a tick ends a counted run after that tick, and the next run starts afresh."""
    loop = Loop(SimClock(), period_ns=MS)
    seen: list[int] = []

    def handler(now: int) -> None:
        seen.append(now)
        if len(seen) == 2:
            loop.stop()

    loop.attach(handler)
    assert loop.run(10) == 2
    assert loop.run(3) == 3 and seen[-1] == 5 * MS


@pytest.mark.parametrize("timing", [False, True])
def test_writer_names_the_running_routine_handler_or_job(timing):
    """writer() is the routine a queue dispatches, else the handler or foreground job running,
    "loop" between handlers, "outside a task" with no run or from another thread."""
    loop = Loop(SimClock(), timing=timing)
    q = ReadyQueue.general("robot")
    seen: list[str] = []
    q.add_periodic(None, "SERVO", lambda: seen.append(loop.writer()), 1)
    q.schedule("SERVO", 1)
    loop.attach(lambda now: seen.append(loop.writer()), name="io:read")
    loop.attach(q)
    loop.attach(lambda now: seen.append(loop.writer()), name="mailbox")
    other: list[str] = []

    def job():
        seen.append(loop.writer())
        t = threading.Thread(target=lambda: other.append(loop.writer()))
        t.start()
        t.join()
        yield

    loop.spawn("init", job())
    assert loop.writer() == "outside a task"
    loop.run(1)
    assert seen == ["io:read", "SERVO", "mailbox", "init"]
    assert other == ["outside a task"] and loop.writer() == "outside a task"
    assert loop.writer_names() == ["SERVO", "WAIT", "io:read", "jobs", "mailbox"]


def test_writer_names_a_rate_group_member_and_its_routines():
    """In a rate group, writer() is the member handler running, or the routine of its queue."""
    from pyrt.scheduler import RateGroup

    loop = Loop(SimClock(), timing=True)
    group = RateGroup("servo", period_ns=2 * MS)
    seen: list[str] = []
    group.attach(lambda now: seen.append(loop.writer()), name="trajectory")
    q = group.new_queue("arm")
    q.add_periodic(None, "PID", lambda: seen.append(loop.writer()), 1)
    q.schedule("PID", 1)
    loop.attach(group)
    loop.run(4)
    assert seen == ["trajectory", "PID", "trajectory", "PID"]
