"""Rate groups: periods in time units whatever the tick, per-group deadlines and timing,
overruns charged to the group and task that caused them, rate-monotonic order."""

from __future__ import annotations

import itertools
import json

import pytest
from _clocks import MS, WorkClock

from pyrt.cli import main
from pyrt.errors import ConfigError, PyrtError
from pyrt.scheduler import (
    Loop,
    RateGroup,
    ReadyQueue,
    SimClock,
    Task,
    TimingLog,
    read_timing_log,
)
from pyrt.scheduler.report import format_statistics


def servo_and_trajectory(work_ns: int = 3 * MS, **kw) -> tuple[Loop, WorkClock]:
    """A 1 ms loop on the work clock: a 1 kHz servo (50 µs) and a 100 Hz trajectory (``work_ns``)."""
    clock = WorkClock()
    loop = Loop(clock, period_ns=MS, **kw)
    servo = RateGroup("servo", hz=1000)
    trajectory = RateGroup("trajectory", period_ns=10 * MS)
    servo.new_queue("arm", [Task(lambda: clock.work(50_000), period=1, name="servo")])
    trajectory.new_queue("arm", [Task(lambda: clock.work(work_ns), period=1, name="plan")])
    loop.attach(lambda now: None, name="boards")
    loop.attach(servo)
    loop.attach(trajectory)
    return loop, clock


@pytest.mark.parametrize("tick_ns", [MS, MS // 2, MS // 4])
def test_a_100_hz_group_stays_at_100_hz_whatever_the_tick(tick_ns):
    """--tick-us 500 (a 0.5 ms loop period) or 250 leaves a 100 Hz group at 100 Hz on the simulated clock; a period-10 task on a queue of the tick doubles its rate."""
    loop = Loop(SimClock(), period_ns=tick_ns)
    seen: list[int] = []
    group = RateGroup("trajectory", hz=100)
    group.new_queue("arm", [Task(seen.append, period=1, name="plan", timed=True)])
    loop.attach(group)
    old: list[int] = []
    queue = ReadyQueue.general(name="old")
    queue.add_periodic(None, "tenth", lambda: old.append(loop.now_ns), 10)
    queue.schedule("tenth", 10)
    loop.attach(queue)
    loop.run(duration_ns=1_000 * MS)
    assert len(seen) == 100
    assert {b - a for a, b in itertools.pairwise(seen)} == {10 * MS}
    assert loop.statistics().groups["trajectory"].releases == 100
    assert len(old) == 1_000 * MS // (10 * tick_ns)  # the old way follows the tick


@pytest.mark.parametrize(("period_ns", "tick_ns", "says"), [
    (10 * MS, 3 * MS, "is not a whole number of ticks of 3 ms (3.33 ticks)"),
    (MS // 2, MS, "is shorter than the loop's tick"),
])
def test_a_period_that_is_not_a_whole_number_of_ticks_is_refused(period_ns, tick_ns, says):
    """A group whose period is not a whole number of ticks is refused with the reason (never rounded) and the loop is unchanged."""
    loop = Loop(SimClock(), period_ns=tick_ns)
    group = RateGroup("trajectory", period_ns=period_ns)
    with pytest.raises(ConfigError, match="rate group trajectory") as err:
        loop.attach(group)
    assert says in str(err.value)
    assert loop.statistics().groups == {} and loop.rate_groups == []
    loop.run(3)


def test_a_group_is_declared_with_a_period_or_a_rate():
    """RateGroup takes period_ns or hz (one of them, positive); a group holds no group and is attached once."""
    assert RateGroup("t", hz=100).period_ns == RateGroup("t", period_ns=10 * MS).period_ns
    for bad in ({}, {"hz": 100, "period_ns": MS}, {"hz": 0}, {"period_ns": -1}, {"period_ns": 1.5}):
        with pytest.raises(ValueError, match="rate group t"):
            RateGroup("t", **bad)
    with pytest.raises(ValueError, match="needs a name"):
        RateGroup("", hz=1)
    group = RateGroup("g", hz=100)
    with pytest.raises(PyrtError, match="cannot hold a group"):
        group.attach(RateGroup("h", hz=10))
    loop = Loop(SimClock())
    loop.attach(group)
    with pytest.raises(ConfigError, match="already attached"):
        Loop(SimClock()).attach(group)
    with pytest.raises(ConfigError, match="already on this loop"):
        loop.attach(RateGroup("g", hz=10))


def test_groups_released_in_one_tick_run_fastest_first():
    """Rate-monotonic order: groups released in one tick run fastest first, in the places where groups were attached; handlers keep theirs."""
    loop = Loop(SimClock(), period_ns=MS)
    ran: list[tuple[int, str]] = []

    def mark(name: str):
        return lambda now: ran.append((loop.tick_index, name))

    slow, mid, fast = RateGroup("slow", hz=50), RateGroup("mid", hz=100), RateGroup("fast", hz=500)
    for g in (slow, mid, fast):
        g.attach(mark(g.name), name=g.name)
    loop.attach(mark("read"), name="read")
    loop.attach(slow)
    loop.attach(mark("between"), name="between")
    loop.attach(mid)
    loop.attach(fast)
    loop.attach(mark("write"), name="write")
    loop.run(20)
    assert [n for t, n in ran if t == 19] == ["read", "fast", "between", "mid", "slow", "write"]
    assert [n for t, n in ran if t == 9] == ["read", "fast", "between", "mid", "write"]
    assert [t for t, n in ran if n == "fast"] == [1, 3, 5, 7, 9, 11, 13, 15, 17, 19]


def test_the_slow_groups_work_is_charged_to_it_not_to_the_servo():
    """1 kHz servo + 100 Hz trajectory doing 3 ms (injected work, no wall time): every overrun is charged to the trajectory group and its task; the servo group shows the releases it missed."""
    loop, _ = servo_and_trajectory()
    loop.run(duration_ns=1_000 * MS)
    st = loop.statistics()
    servo, trajectory = st.groups["servo"], st.groups["trajectory"]
    assert st.overruns == 100 and trajectory.overruns == 100 and servo.overruns == 0
    assert servo.missed == 300 and trajectory.missed == 0
    assert st.tasks["plan"].overruns == 100 and st.tasks["plan"].group == "trajectory"
    assert st.tasks["servo"].overruns == 0 and st.tasks["servo"].group == "servo"
    assert trajectory.releases == 100 and servo.releases == st.ticks  # a release every tick run


def test_each_group_has_its_own_max_and_average():
    """Per group: time per release, mean and max (004's max and avg per loop), and its tasks."""
    loop, _ = servo_and_trajectory(work_ns=400_000)
    loop.run(100)
    st = loop.statistics()
    servo, trajectory = st.groups["servo"], st.groups["trajectory"]
    assert (servo.mean_ns, servo.max_ns) == (50_000, 50_000)
    assert (trajectory.mean_ns, trajectory.max_ns) == (400_000, 400_000)
    assert st.overruns == 0 and "plan" in trajectory.tasks and "servo" in servo.tasks
    assert [g.name for g in st.groups.values()] == ["servo", "trajectory"]
    loop.reset_statistics()
    assert loop.statistics().groups["trajectory"].max_ns == 0


def test_a_group_that_overruns_its_own_period_misses_its_own_release():
    """A 100 Hz group doing 12 ms passes its own next release: it misses it and is charged; its grid stays on 10 ms."""
    loop = Loop(clock := WorkClock(), period_ns=MS)
    seen: list[int] = []

    def plan(now: int) -> None:
        seen.append(now)
        if len(seen) == 2:
            clock.work(12 * MS)

    group = RateGroup("trajectory", hz=100)
    group.new_queue("arm", [Task(plan, period=1, timed=True)])
    loop.attach(group)
    loop.run(duration_ns=60 * MS)
    st = loop.statistics().groups["trajectory"]
    assert st.missed == 1 and st.overruns == 1
    assert seen == [10 * MS, 20 * MS, 40 * MS, 50 * MS, 60 * MS]  # 30 ms missed, never run late


def test_an_overrun_is_named_in_stats_and_in_the_timing_log_under_its_group(tmp_path, capsys):
    """The task that overran its group is named in stats under that group, in the log's overrun records with the group, and read back by pyrt overruns."""
    path = tmp_path / "timing.jsonl"
    loop, _ = servo_and_trajectory(timing_log=TimingLog(str(path), version="test"))
    loop.run(duration_ns=200 * MS)
    loop.close()
    lines = format_statistics(loop.statistics()).splitlines()
    under = lines[lines.index("trajectory:") + 1:]
    plan = next(ln for ln in under if ln.split()[0] == "plan")
    assert plan.split()[1] == "20" and plan.split()[-1] == "20"
    group_row = next(ln for ln in lines if ln.startswith("trajectory "))
    assert group_row.split()[1:3] == ["10000", "20"] and group_row.split()[-2:] == ["20", "0"]

    records = [json.loads(ln) for ln in path.read_text().splitlines()]
    assert records[0]["format"] == "pyrt-timing/2"
    assert [g["name"] for g in records[0]["groups"]] == ["servo", "trajectory"]
    over = [r for r in records if r["type"] == "overrun"]
    assert len(over) == 20 and all(r["group"] == "trajectory" for r in over)
    assert over[0]["missed_releases"] == {"servo": 3}
    assert dict(zip([n for n, _ in over[0]["tasks"]], over[0]["task_groups"], strict=True))[
        "plan"] == "trajectory"

    rep = read_timing_log(str(path))
    assert rep.groups["trajectory"].overruns == 20 and rep.groups["servo"].missed == 60
    assert rep.tasks["plan"].group == "trajectory" and rep.tasks["plan"].overruns == 20
    assert main(["overruns", str(path), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["groups"]["trajectory"]["overruns"] == 20 and data["groups"]["servo"]["overruns"] == 0
    assert data["groups"]["trajectory"]["max_us"] == 3000.0
    assert data["tasks"]["plan"]["group"] == "trajectory" and data["worst"][0]["group"] == "trajectory"
    assert main(["overruns", str(path)]) == 0
    out = capsys.readouterr().out.splitlines()
    rows = out[out.index("trajectory:") + 1:]
    assert next(ln for ln in rows if ln.split()[0] == "plan").split()[-1] == "20"
    assert any(ln.split()[5:6] == ["trajectory"] for ln in out if ln[:10].strip().isdigit())


def test_a_queue_attached_alone_is_one_group_at_the_tick_rate():
    """A ready queue attached to the loop as before rate groups is a group of its own, named as attached, at the tick's period."""
    loop = Loop(WorkClock(), period_ns=MS)
    queue = ReadyQueue(divisor=1, name="gripper")
    queue.add_periodic(0x10, "TASK", lambda: None, 1)
    queue.schedule(0x10, 1)
    loop.attach(queue, name="SYSCLK")
    other = ReadyQueue(divisor=1, name="gripper")
    loop.attach(other, name="SYSCLK")
    loop.run(10)
    st = loop.statistics()
    assert list(st.groups) == ["SYSCLK", "SYSCLK #2"]
    assert st.groups["SYSCLK"].period_ns == MS and st.groups["SYSCLK"].releases == 10
    assert st.tasks["TASK"].group == "SYSCLK"


def test_groups_release_with_timing_off():
    """With timing off a group still releases at its rate and counts its releases; nothing is timed."""
    loop = Loop(SimClock(), period_ns=MS, timing=False)
    runs: list[int] = []
    group = RateGroup("g", hz=250)
    group.attach(runs.append, name="h")
    loop.attach(group)
    loop.run(20)
    assert len(runs) == 5 and loop.statistics().groups["g"].releases == 5
    assert loop.statistics().groups["g"].max_ns == 0


def test_a_member_cannot_join_while_the_loop_runs():
    """Attaching to a group whose loop runs is refused."""
    loop = Loop(SimClock())
    group = RateGroup("g", hz=100)
    loop.attach(group)
    errors: list[Exception] = []

    def late(now: int) -> None:
        try:
            group.attach(lambda now: None)
        except PyrtError as exc:
            errors.append(exc)

    loop.attach(late)
    loop.run(1)
    assert errors and "before its loop runs" in str(errors[0])


V1_LOG = [
    {"type": "header", "format": "pyrt-timing/1", "version": "0.9", "period_ns": MS,
     "clock": "WallClock", "tasks": ["WAIT", "TASK"], "handlers": ["queue:r"]},
    {"type": "overrun", "tick": 9, "deadline_ns": 9 * MS, "start_ns": 9 * MS, "end_ns": 12 * MS,
     "lateness_ns": 0, "overrun_ns": 2 * MS, "missed": 2, "tasks": [["TASK", 3 * MS]]},
    {"type": "summary", "time_ns": 20 * MS, "ticks": 20, "overruns": 1, "missed": 2,
     "tasks": {"TASK": {"calls": 20, "mean_ns": 1000.0, "max_ns": 3 * MS, "p99_ns": 3 * MS,
                        "overruns": 1, "kind": "task", "hist": []}}},
]


def test_a_log_from_before_rate_groups_is_still_read(tmp_path, capsys):
    """A pyrt-timing/1 log reads back (its tasks in no group); a format this pyrt does not know is refused by name."""
    path = tmp_path / "old.jsonl"
    path.write_text("".join(json.dumps(r) + "\n" for r in V1_LOG))
    rep = read_timing_log(str(path))
    assert rep.format == "pyrt-timing/1" and rep.groups == {}
    assert rep.tasks["TASK"].overruns == 1 and rep.tasks["TASK"].group == ""
    assert main(["overruns", str(path)]) == 0
    out = capsys.readouterr().out
    assert "1 overruns" in out and "group" not in out.split("worst")[0]
    future = dict(V1_LOG[0], format="pyrt-timing/9")
    path.write_text(json.dumps(future) + "\n")
    with pytest.raises(ConfigError, match="pyrt-timing/9 is not one this pyrt reads"):
        read_timing_log(str(path))


def test_release_times_are_folded_every_summary_without_a_log():
    """Without a timing log the groups' release times are folded once a second (memory stays bounded) and all of them are counted."""
    loop = Loop(SimClock(), period_ns=MS)
    queue = ReadyQueue(divisor=1, name="r")
    loop.attach(queue)
    loop.attach(lambda now: None, name="boards")
    group = RateGroup("g", hz=1000)
    group.attach(lambda now: None, name="h")
    loop.attach(group)
    loop.run(3_500)
    assert all(len(g.samples) <= 1_000 for g in loop._groups)  # what is not yet folded
    st = loop.statistics()
    assert st.groups["queue:r"].distribution.count == 3_500
    assert st.groups["g"].distribution.count == st.groups["g"].releases == 3_500


def test_tick_us_500_from_the_command_line_leaves_a_100_hz_group_at_100_hz():
    """The loop the command line makes with '--tick-us 500 --speed max' releases a 100 Hz group 100 times a second of loop time."""
    import argparse

    from pyrt.cli._loopopts import add_loop_options, make_loop

    parser = argparse.ArgumentParser()
    add_loop_options(parser)
    loop = make_loop(parser.parse_args(["--tick-us", "500", "--speed", "max"]), warn=print)
    group = RateGroup("trajectory", hz=100)
    runs: list[int] = []
    group.attach(runs.append, name="plan")
    loop.attach(group)
    loop.run(duration_ns=1_000 * MS)
    assert loop.period_ns == 500_000 and loop.tick_index == 2_000 and len(runs) == 100
