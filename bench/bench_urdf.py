"""pyrt urdf with the PUMA 560: speed at --speed max while moving, and where a tick's time goes.

Run: ``python -m pytest bench/bench_urdf.py --benchmark-only -s``.  The first
benchmark runs a script of joint and pose moves (blended) on a SimClock and
reports simulated seconds per wall second while the arm moves (the target:
50x), and per second of the process's CPU time (the same figure on a machine
that other work shares); the second gives each handler's and task's mean per tick from the
loop's own statistics over the same moves (the simulated arm's step, the
servo, the trajectory, the rest).
"""

from __future__ import annotations

import argparse
import io
import time

from pyrt.commands import RobotShell
from pyrt.scheduler import Loop, SimClock
from pyrt.station.urdf import URDF

MOVES = ("puma560 movej 10 30 -150 20 -30 40", "puma560 movej -20 60 -170 -30 -50 -40",
         "puma560 moveto 500 100 400 180 0 90", "puma560 moveto 450 -150 500 170 10 45",
         "puma560 movej 0 45 -180 0 -45 0")


def _station():
    station = URDF.build(Loop(SimClock(), timing=True),
                         argparse.Namespace(boards=None, urdf=None, start=None))
    runner = station.start()
    runner.wait_until(lambda: station.arm.powered and not station.busy(), 5.0)
    return station, runner, RobotShell(station, io.StringIO())


def _moves(station, shell) -> float:
    """Every move, each waited for; the simulated seconds they took."""
    t0 = station.loop.now_ns
    for move in MOVES:
        shell.onecmd(move)
        shell.onecmd("wait")
    return (station.loop.now_ns - t0) / 1e9


def test_urdf_puma_speed_max(benchmark):
    """Joint and pose moves on virtual time: simulated seconds per wall second while moving."""
    sims = []
    cpus = []
    built = []

    def setup():
        built.append(_station())
        return (), {}

    def run():
        station, _runner, shell = built[-1]
        c0 = time.process_time()
        sims.append(_moves(station, shell))
        cpus.append(time.process_time() - c0)

    benchmark.pedantic(run, setup=setup, rounds=3, iterations=1)
    for station, _r, _s in built:
        station.close()
    ratio = sims[-1] / benchmark.stats.stats.min
    cpu_ratio = sims[-1] / min(cpus)
    benchmark.extra_info.update(sim_s=sims[-1], sim_s_per_wall_s=round(ratio, 1),
                                sim_s_per_cpu_s=round(cpu_ratio, 1))
    print(f"\npyrt urdf (PUMA 560) at --speed max, moving: {ratio:.0f}x real time by the "
          f"wall clock, {cpu_ratio:.0f}x by the process's CPU time ({sims[-1]:.2f} s "
          f"simulated; target 50x)")


def test_urdf_puma_tick_breakdown(benchmark):
    """Where a tick goes while moving: each handler's and task's mean (µs per call)."""
    out = {}

    def run():
        station, runner, shell = _station()
        try:
            _moves(station, shell)
            out["stats"] = runner.statistics()
        finally:
            station.close()

    benchmark.pedantic(run, rounds=1, iterations=1)
    stats = out["stats"]
    parts = {**stats.tasks, **getattr(stats, "handlers", {})}
    line = ", ".join(f"{name} {t.mean_ns / 1e3:.1f} µs x {t.calls}" for name, t in parts.items()
                     if t.calls)
    benchmark.extra_info.update(line=line)
    print(f"\npyrt urdf (PUMA 560) per call over {stats.ticks} ticks: {line}")
