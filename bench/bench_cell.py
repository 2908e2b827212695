"""pyrt cell (the PUMA 560 with 002's gripper, two robots in one loop): pick cycles at
--speed max and at real time.

Run: ``python -m pytest bench/bench_cell.py --benchmark-only -s``.  A cycle is ``pick``
of the object on the table, then the jaws opened (the object falls back onto the
table), each waited for.

* At ``--speed max`` (SimClock): simulated seconds per wall second over pick cycles
  (the target: 20x), and per second of the process's CPU time (the same figure on a
  machine that other work shares).
* At real time (WallClock, 1 kHz) for ``PYRT_BENCH_CELL_S`` seconds (default 60) of pick
  cycles: the arm's servo and trajectory tasks (mean, p99, max, the overruns charged
  to each), its ready queue's group and the gripper's SYSCLK group (p99, overruns,
  releases missed), the loop's overruns and lateness p99; beside them, the same
  figures of ``pyrt urdf`` alone (the arm's station without the gripper) holding
  and moving for the same time in the same run, as the anchor.
"""

from __future__ import annotations

import argparse
import io
import os
import time

from pyrt.commands import RobotShell
from pyrt.scheduler import Loop, SimClock, WallClock
from pyrt.station.cell import build_cell
from pyrt.station.urdf import URDF

OBJECT = "600 -150 400"
#: Real-time span of each station, s.
SPAN_S = float(os.environ.get("PYRT_BENCH_CELL_S", "60"))
#: The anchor's moves (pyrt urdf alone): the pick's three poses, as joint moves.
ANCHOR_MOVES = ("puma560 moveto 600 -150 500 180 0 180", "puma560 moveto 600 -150 400 180 0 180",
                "puma560 moveto 600 -150 550 180 0 180")


def _cell(clock):
    station = build_cell(Loop(clock, timing=True))
    runner = station.start()
    shell = RobotShell(station, io.StringIO())
    shell.onecmd("gripper I")
    runner.wait_until(lambda: station.arm.powered and not station.busy(), 30.0)
    shell.onecmd(f"sim object {OBJECT}")
    return station, runner, shell


def _cycle(station, shell) -> bool:
    """One pick and the release; whether the pick ended picked (at real time on a loaded
    machine a late tick may trip the arm's following error: acknowledged, counted)."""
    shell.onecmd(f"pick {OBJECT}")
    shell.onecmd("wait")
    picked = station.pick.last.startswith("picked")
    if station.fault is not None:
        shell.onecmd("ack")
        shell.onecmd("sim object " + OBJECT)  # what a fault dropped goes back in place
    shell.onecmd("gripper P 0")
    shell.onecmd("wait")
    return picked


def test_cell_pick_speed_max(benchmark):
    """Pick cycles on virtual time: simulated seconds per wall second (target 20x)."""
    sims, cpus, built = [], [], []

    def setup():
        built.append(_cell(SimClock()))
        return (), {}

    def run():
        station, _runner, shell = built[-1]
        t0, c0 = station.loop.now_ns, time.process_time()
        for _ in range(3):
            assert _cycle(station, shell), station.pick.last
        sims.append((station.loop.now_ns - t0) / 1e9)
        cpus.append(time.process_time() - c0)

    benchmark.pedantic(run, setup=setup, rounds=3, iterations=1)
    for station, _r, _s in built:
        station.close()
    ratio = sims[-1] / benchmark.stats.stats.min
    cpu_ratio = sims[-1] / min(cpus)
    benchmark.extra_info.update(sim_s=sims[-1], sim_s_per_wall_s=round(ratio, 1),
                                sim_s_per_cpu_s=round(cpu_ratio, 1))
    print(f"\npyrt cell, 3 pick cycles at --speed max: {ratio:.0f}x real time by the wall "
          f"clock, {cpu_ratio:.0f}x by the process's CPU time ({sims[-1]:.2f} s simulated; "
          "target 20x)")


def _task(stats, word: str):
    return next(t for name, t in stats.tasks.items() if word in name.lower())


def _us(ns: float) -> str:
    return f"{ns / 1e3:.0f} µs"


def _describe(stats, groups: tuple[str, ...]) -> str:
    servo, traj = _task(stats, "servo"), _task(stats, "trajectory")
    parts = [f"{stats.ticks} ticks, {stats.overruns} overruns, {stats.missed} missed, "
             f"lateness p99 {_us(stats.lateness.p99_ns)}",
             f"servo mean {_us(servo.mean_ns)} p99 {_us(servo.p99_ns)} max {_us(servo.max_ns)} "
             f"overruns {servo.overruns}",
             f"trajectory mean {_us(traj.mean_ns)} p99 {_us(traj.p99_ns)} max "
             f"{_us(traj.max_ns)} overruns {traj.overruns}"]
    for name, g in stats.groups.items():
        if any(w in name.lower() for w in groups):
            parts.append(f"group {name}: p99 {_us(g.p99_ns)} max {_us(g.max_ns)} "
                         f"overruns {g.overruns} missed {g.missed}")
    return "; ".join(parts)


def test_cell_pick_at_real_time(benchmark):
    """Real time: pick cycles for SPAN_S seconds; the servo's and trajectory's p99 and overruns, each group's; pyrt urdf alone over the same span as the anchor."""
    out: dict[str, object] = {}

    def run():
        station, runner, shell = _cell(WallClock())
        try:
            runner.statistics()  # the start-up's figures are not the cycles'
            cycles = picked = 0
            end = time.monotonic() + SPAN_S
            while time.monotonic() < end:
                picked += _cycle(station, shell)
                cycles += 1
            out["cell"] = runner.statistics()
            out["cycles"] = f"{cycles} pick cycles, {picked} picked"
        finally:
            station.close()
        anchor = URDF.build(Loop(WallClock(), timing=True),
                            argparse.Namespace(boards=None, urdf=None, start=None))
        try:
            runner = anchor.start()
            runner.wait_until(lambda: anchor.arm.powered and not anchor.busy(), 30.0)
            shell = RobotShell(anchor, io.StringIO())
            end = time.monotonic() + SPAN_S
            while time.monotonic() < end:
                for move in ANCHOR_MOVES:
                    shell.onecmd(move)
                    shell.onecmd("wait")
            out["urdf"] = runner.statistics()
        finally:
            anchor.close()

    benchmark.pedantic(run, rounds=1, iterations=1)
    cell = _describe(out["cell"], ("puma", "sysclk"))
    urdf = _describe(out["urdf"], ("puma",))
    benchmark.extra_info.update(cell=cell, urdf=urdf, cycles=out["cycles"])
    print(f"\npyrt cell at real time, {SPAN_S:g} s, {out['cycles']}: {cell}"
          f"\npyrt urdf alone (anchor), {SPAN_S:g} s of the same poses: {urdf}")
