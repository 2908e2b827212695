"""The gripper *station* at 1 kHz through the tcp:// back end (``--boards tcp://``).

Run: ``python -m pytest bench/bench_boards_station.py --benchmark-only -s``.

``pyrt board-sim gripper`` runs in a process of its own on 127.0.0.1; this
process builds the station exactly as ``pyrt gripper --boards URL`` does
(:func:`pyrt.station.gripper.build_gripper` on a 1 ms wall-clock loop, the
loop in its own thread, commands through RobotShell and the mailbox), runs
``I`` and ``P-1B86`` with ``wait``, and reports per tick: the time the
cage's encoder poll takes (after the read phase: the two pulse counters
read from the image, the interrupts raised), the read phase's mean (the
loop's ``io:read``), the whole tick's work and lateness (p50/p99/max, and
the mean), and the overruns, against the 1 ms tick.  The same run on the
in-process ``sim:`` boards (the jaws' physics in the read phase) is the
baseline, run first: what the machine does to a 1 ms loop without a second
process; the tcp:// row then says its tick work as a multiple of it (p50,
of histogram bin bounds as the loop keeps them, and mean).  The machine is
shared: read the tails as approximate, and run the file twice.
``bench_boards.py`` times single register round trips.
"""

from __future__ import annotations

import io
import time

import pytest

from pyrt.commands import RobotShell
from pyrt.scheduler import Loop, WallClock
from pyrt.station.gripper import build_gripper

TICK_NS = 1_000_000
#: The in-process row's tick work of this run (p50, mean; ns), for the tcp:// row's ratio.
_BASELINE: dict[str, float] = {}


def _quantile(samples: list[int], q: float) -> int:
    s = sorted(samples) or [0]
    return s[min(len(s) - 1, int(q * len(s)))]


@pytest.mark.benchmark(group="boards-station")
@pytest.mark.parametrize("backend", ["sim", "tcp"])
def test_gripper_station_tick_budget(benchmark, gripper_url, backend):
    """I, P-1B86 and wait on the gripper station at 1 kHz, through tcp:// (or in process, the
    baseline): poll p50/p99 and the tick's work, lateness and overruns."""
    result: dict[str, object] = {}
    url = gripper_url if backend == "tcp" else "sim:"

    def run() -> None:
        station = build_gripper(Loop(WallClock(), period_ns=TICK_NS), boards=url)
        polls: list[int] = []
        clock = time.perf_counter_ns
        after = station.boards.backend.after_read  # the cage's poll, after the read phase

        def timed(poll):
            def timed_poll(now_ns: int) -> None:
                t = clock()
                try:
                    poll(now_ns)
                finally:
                    polls.append(clock() - t)
            return timed_poll

        after[:] = [timed(poll) for poll in after]
        out = io.StringIO()
        shell = RobotShell(station, out)
        station.start()
        try:
            station.loop.reset_statistics()  # not the start-up tick
            for line in ("I", "P-1B86", "wait"):
                shell.onecmd(line)
            stats = station.runner.statistics()
        finally:
            station.close()
        assert "target E47A" in out.getvalue(), out.getvalue()
        assert station.fault is None, station.fault
        result.update(polls=polls, stats=stats)

    benchmark.pedantic(run, rounds=1, iterations=1)
    polls, stats = result["polls"], result["stats"]
    p50, p99, pmax = _quantile(polls, 0.5), _quantile(polls, 0.99), max(polls, default=0)
    work, late = stats.work, stats.lateness
    read = stats.tasks.get("io:read")
    read_mean = read.mean_ns if read is not None else 0.0
    benchmark.extra_info.update(
        read_phase_mean_us=round(read_mean / 1e3, 1),
        ticks=stats.ticks, poll_p50_us=round(p50 / 1e3, 1), poll_p99_us=round(p99 / 1e3, 1),
        poll_max_us=round(pmax / 1e3, 1), work_p50_us=round(work.p50_ns / 1e3, 1),
        work_p99_us=round(work.p99_ns / 1e3, 1), work_max_us=round(work.max_ns / 1e3, 1),
        work_mean_us=round(work.mean_ns / 1e3, 1),
        late_p99_us=round(late.p99_ns / 1e3, 1), overruns=stats.overruns, missed=stats.missed,
    )
    ratio = ""
    if backend == "sim":
        _BASELINE.update(p50=work.p50_ns, mean=work.mean_ns)
    elif _BASELINE.get("p50") and _BASELINE.get("mean"):
        p50_x, mean_x = work.p50_ns / _BASELINE["p50"], work.mean_ns / _BASELINE["mean"]
        benchmark.extra_info.update(work_p50_x_sim=round(p50_x, 2), work_mean_x_sim=round(mean_x, 2))
        ratio = f"; tick work {p50_x:.2f}x the in-process p50, {mean_x:.2f}x its mean"
    print(f"\ngripper station on {url} ({len(polls)} polls, {stats.ticks} ticks of 1 ms): "
          f"encoder poll p50 {p50 / 1e3:.1f} µs, p99 {p99 / 1e3:.1f} µs, max {pmax / 1e3:.0f} µs "
          f"({p50 / TICK_NS:.1%} / {p99 / TICK_NS:.1%} of the tick); read phase mean "
          f"{read_mean / 1e3:.1f} µs; tick work p50 <= "
          f"{work.p50_ns / 1e3:.0f} µs, p99 <= {work.p99_ns / 1e3:.0f} µs, max "
          f"{work.max_ns / 1e3:.0f} µs, mean {work.mean_ns / 1e3:.1f} µs; lateness p99 <= "
          f"{late.p99_ns / 1e3:.0f} µs; overruns {stats.overruns} (missed deadlines "
          f"{stats.missed}){ratio}")
