"""The example arm (examples/arm): speed at --speed max, and its servo task at real time.

Run: ``python -m pytest bench/bench_arm.py --benchmark-only -s`` (needs
``pip install -e ./examples/arm``).  The first benchmark runs blended moves
on a SimClock and reports simulated seconds per wall second (the issue's
target: 100x); the second runs the arm at real time (1 kHz servo, 100 Hz
trajectory) for a few seconds of moves and reports the servo task's mean,
p99 and max and the overruns, from the loop's own statistics.
"""

from __future__ import annotations

import io

import pytest

from pyrt.commands import RobotShell
from pyrt.scheduler import Loop, SimClock, WallClock

arm = pytest.importorskip("pyrt_arm.station")

MOVES = ("arm to 90 45", "arm to -60 -30", "arm to 30 100", "arm to 0 0")


def _station(clock):
    from pyrt.cli._station import station_parser

    args = station_parser(arm.ARM, "bench").parse_args(["--speed", "max"])
    station = arm.ARM.build(Loop(clock, timing=True), args)
    return station, station.start(), RobotShell(station, io.StringIO())


def test_arm_speed_max(benchmark):
    """Blended moves on virtual time: simulated seconds per wall second."""
    sims = []

    def run():
        station, _runner, shell = _station(SimClock())
        t0 = station.loop.now_ns
        for move in MOVES:
            shell.onecmd(move)
            shell.onecmd("wait")
        sims.append((station.loop.now_ns - t0) / 1e9)
        station.close()

    benchmark.pedantic(run, rounds=3, iterations=1)
    ratio = sims[-1] / benchmark.stats.stats.min
    benchmark.extra_info.update(sim_s=sims[-1], sim_s_per_wall_s=round(ratio, 1))
    print(f"\narm at --speed max, moving: {ratio:.0f}x real time (target 100x)")


def test_arm_servo_at_real_time(benchmark):
    """Real time: the servo task's mean, p99, max and overruns over blended moves."""
    out = {}

    def run():
        station, runner, shell = _station(WallClock())
        try:
            for move in MOVES:
                shell.onecmd(move)
            shell.onecmd("wait")
            out["stats"] = runner.statistics()
        finally:
            station.close()

    benchmark.pedantic(run, rounds=1, iterations=1)
    stats = out["stats"]
    servo = next(t for name, t in stats.tasks.items() if "servo" in name.lower())
    line = (f"arm servo at 1 kHz real time: {servo.calls} calls, mean "
            f"{servo.mean_ns / 1e3:.1f} µs, p99 {servo.p99_ns / 1e3:.1f} µs, max "
            f"{servo.max_ns / 1e3:.1f} µs; {stats.overruns} overruns in {stats.ticks} ticks "
            f"({servo.overruns} attributed to the servo)")
    benchmark.extra_info.update(line=line)
    print("\n" + line)
