"""pyrt urdf on 004's two kinds of hardware: speed at --speed max while moving.

Run: ``python -m pytest bench/bench_urdf_hardware.py --benchmark-only -s``.  The same
script of joint and pose moves (bench_urdf's) on a SimClock, on hardware (b) (the
passive board, the host's servo at 1 kHz, 1 ms tick), on hardware (a) (the
motion-control board, its servo at 1 kHz in the world's step, the host writing
setpoints at 100 Hz) at a 1 ms tick and at a 10 ms tick: simulated seconds per wall
second, and per second of the process's CPU time (the same figure on a machine that
other work shares).
"""

from __future__ import annotations

import argparse
import io
import time

import pytest

from pyrt.commands import RobotShell
from pyrt.scheduler import Loop, SimClock
from pyrt.station.urdf import URDF

MOVES = ("puma560 movej 10 30 -150 20 -30 40", "puma560 movej -20 60 -170 -30 -50 -40",
         "puma560 moveto 500 100 400 180 0 90", "puma560 moveto 450 -150 500 170 10 45",
         "puma560 movej 0 45 -180 0 -45 0")


def _station(hardware: str, tick_ns: int):
    station = URDF.build(Loop(SimClock(), period_ns=tick_ns),
                         argparse.Namespace(boards=None, urdf=None, start=None,
                                            hardware=hardware))
    runner = station.start()
    runner.wait_until(lambda: station.arm.powered and not station.busy(), 5.0)
    return station, runner, RobotShell(station, io.StringIO())


def _moves(station, shell) -> float:
    t0 = station.loop.now_ns
    for move in MOVES:
        shell.onecmd(move)
        shell.onecmd("wait")
    return (station.loop.now_ns - t0) / 1e9


@pytest.mark.parametrize(("hardware", "tick_ns"),
                         [("b", 1_000_000), ("a", 1_000_000), ("a", 10_000_000)],
                         ids=["b-1ms", "a-1ms", "a-10ms"])
def test_urdf_hardware_speed_max(benchmark, hardware, tick_ns):
    """The moves on virtual time: simulated seconds per wall second and per CPU second."""
    sims: list[float] = []
    cpus: list[float] = []
    built: list = []

    def setup():
        built.append(_station(hardware, tick_ns))
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
    print(f"\npyrt urdf (PUMA 560) hardware ({hardware}), tick {tick_ns / 1e6:g} ms, "
          f"--speed max, moving: {ratio:.0f}x real time by the wall clock, {cpu_ratio:.0f}x "
          f"by the process's CPU time ({sims[-1]:.2f} s simulated)")
