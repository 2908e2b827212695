"""pyrt urdf with the PUMA 560: speed at --speed max while moving, and where a tick's time goes.

Run: ``python -m pytest bench/bench_urdf.py --benchmark-only -s``.  Two rows
of moves on a SimClock, each reported as simulated seconds per wall second
while the arm moves (the target: 50x) and per second of the process's CPU
time (the same figure on a machine that other work shares):

* ``moves``: joint and pose moves (``movej``, ``moveto``), each waited for;
* ``lines``: straight lines (``movel``) queued together, blending into each
  other where they can, from a pose reached before the timing starts.

The breakdown gives each handler's and task's mean per tick from the loop's
own statistics over the same moves (the simulated arm's step, the servo, the
trajectory, the rest).

As a script it compares source trees side by side, interleaved (every row of
every tree in each round, each in a child process whose ``PYTHONPATH`` is the
tree, its compiled modules built in place), and prints the median of the
rounds with the load average before and after::

    python bench/bench_urdf.py --tree /tmp/before --tree . --rounds 3
"""

from __future__ import annotations

import argparse
import io
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

MOVES = ("puma560 movej 10 30 -150 20 -30 40", "puma560 movej -20 60 -170 -30 -50 -40",
         "puma560 moveto 500 100 400 180 0 90", "puma560 moveto 450 -150 500 170 10 45",
         "puma560 movej 0 45 -180 0 -45 0")
#: Where the lines start (reached before the timing starts) and the lines, queued at once.
LINES_FROM = "puma560 moveto 450 -150 450 160 20 45"
LINES = ("puma560 movel 450 150 450 160 20 45", "puma560 movel 350 150 300 150 20 60",
         "puma560 movel 350 -150 300 160 30 45", "puma560 movel 450 -150 450 160 20 45")
ROWS = ("moves", "lines")


def _station():
    from pyrt.commands import RobotShell
    from pyrt.scheduler import Loop, SimClock
    from pyrt.station.urdf import URDF

    station = URDF.build(Loop(SimClock(), timing=True),
                         argparse.Namespace(boards=None, urdf=None, start=None))
    runner = station.start()
    runner.wait_until(lambda: station.arm.powered and not station.busy(), 5.0)
    return station, runner, RobotShell(station, io.StringIO())


def _setup(row: str, shell) -> None:
    """What a row does before its timing starts."""
    if row == "lines":
        shell.onecmd(LINES_FROM)
        shell.onecmd("wait")


def _run(row: str, station, shell) -> tuple[float, float, float]:
    """The row's moves (``moves``: each waited for; ``lines``: queued together,
    then waited for): the simulated seconds they took, and the simulated and CPU
    seconds of the waits alone (the loop running the moves, no command planned)."""
    t0 = station.loop.now_ns
    waits = [0, 0.0]

    def wait() -> None:
        n0, c0 = station.loop.now_ns, time.process_time()
        shell.onecmd("wait")
        waits[0] += station.loop.now_ns - n0
        waits[1] += time.process_time() - c0

    if row == "lines":
        for line in LINES:
            shell.onecmd(line)
        wait()
    else:
        for move in MOVES:
            shell.onecmd(move)
            wait()
    return (station.loop.now_ns - t0) / 1e9, waits[0] / 1e9, waits[1]


def measure(row: str) -> dict:
    """One run of ``row`` on a new station: simulated, CPU and wall seconds (and
    those of the waits alone: the loop running the moves, without planning them),
    and each task's and handler's mean (µs per call) and calls from the loop's
    statistics."""
    station, runner, shell = _station()
    try:
        _setup(row, shell)
        base = runner.statistics()
        c0, w0 = time.process_time(), time.perf_counter()
        sim, wait_sim, wait_cpu = _run(row, station, shell)
        cpu, wall = time.process_time() - c0, time.perf_counter() - w0
        stats = runner.statistics()
    finally:
        station.close()
    parts = {}
    before = {**base.tasks, **getattr(base, "handlers", {})}
    for name, t in {**stats.tasks, **getattr(stats, "handlers", {})}.items():
        b = before.get(name)
        calls = t.calls - (b.calls if b else 0)
        total = t.mean_ns * t.calls - (b.mean_ns * b.calls if b else 0.0)
        if calls > 0:
            parts[name] = (total / calls / 1e3, calls)
    return {"sim_s": sim, "cpu_s": cpu, "wall_s": wall, "wait_sim_s": wait_sim,
            "wait_cpu_s": wait_cpu, "parts": parts}


def _line(parts: dict) -> str:
    return ", ".join(f"{name} {mean:.1f} µs x {calls}" for name, (mean, calls) in parts.items())


def test_urdf_puma_speed_max(benchmark):
    """Joint and pose moves on virtual time: simulated seconds per wall second while moving."""
    _speed(benchmark, "moves")


def test_urdf_puma_lines_speed_max(benchmark):
    """Straight lines (movel, blended) on virtual time: simulated seconds per wall second."""
    _speed(benchmark, "lines")


def _speed(benchmark, row: str) -> None:
    runs = []
    benchmark.pedantic(lambda: runs.append(measure(row)), rounds=3, iterations=1)
    sim = statistics.median(r["sim_s"] for r in runs)
    wall = sim / statistics.median(r["wall_s"] for r in runs)
    cpu = sim / statistics.median(r["cpu_s"] for r in runs)
    loop = statistics.median(r["wait_sim_s"] / r["wait_cpu_s"] for r in runs)
    benchmark.extra_info.update(sim_s=sim, sim_s_per_wall_s=round(wall, 1),
                                sim_s_per_cpu_s=round(cpu, 1), waits_sim_s_per_cpu_s=round(loop, 1))
    print(f"\npyrt urdf (PUMA 560) at --speed max, {row}: {wall:.0f}x real time by the "
          f"wall clock, {cpu:.0f}x by the process's CPU time ({loop:.0f}x in the waits alone, "
          f"the loop without planning) ({sim:.2f} s simulated, median of 3; target 50x)")


def test_urdf_puma_tick_breakdown(benchmark):
    """Where a tick goes while moving: each handler's and task's mean (µs per call)."""
    out = {}

    def run():
        out.update({row: measure(row) for row in ROWS})

    benchmark.pedantic(run, rounds=1, iterations=1)
    for row in ROWS:
        line = _line(out[row]["parts"])
        benchmark.extra_info[row] = line
        print(f"\npyrt urdf (PUMA 560), {row}, per call: {line}")


# -- trees side by side (a script) ------------------------------------------------------------


def _child(tree: str, row: str) -> dict:
    env = dict(os.environ, PYTHONPATH=str(Path(tree).resolve()))
    done = subprocess.run([sys.executable, __file__, "--child", row], env=env, check=True,
                          capture_output=True, text=True)
    return json.loads(done.stdout.splitlines()[-1])  # type: ignore[no-any-return]


def _med(ratios: list[float]) -> str:
    return f"{statistics.median(ratios):.1f}x ({' '.join(f'{v:.1f}' for v in ratios)})"


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--tree", action="append", help="a source tree (repeat; default: this one)")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--rows", default=",".join(ROWS))
    ap.add_argument("--child", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        print(json.dumps(measure(args.child)))
        return
    trees = args.tree or [str(Path(__file__).resolve().parent.parent)]
    rows = args.rows.split(",")
    load0 = os.getloadavg()
    runs: dict[tuple[str, str], list[dict]] = {(t, r): [] for t in trees for r in rows}
    for _ in range(args.rounds):
        for row in rows:
            for tree in trees:
                runs[(tree, row)].append(_child(tree, row))
    load1 = os.getloadavg()
    print(f"load average before {load0[0]:.2f} {load0[1]:.2f} {load0[2]:.2f}, "
          f"after {load1[0]:.2f} {load1[1]:.2f} {load1[2]:.2f}; median of {args.rounds} "
          "interleaved rounds")
    for row in rows:
        for tree in trees:
            rs = runs[(tree, row)]
            sim = statistics.median(r["sim_s"] for r in rs)
            cpu = [r["sim_s"] / r["cpu_s"] for r in rs]
            loop = [r["wait_sim_s"] / r["wait_cpu_s"] for r in rs]
            wall = [r["sim_s"] / r["wall_s"] for r in rs]
            names = list(rs[0]["parts"])
            parts = {n: (statistics.median(r["parts"].get(n, (0.0, 0))[0] for r in rs),
                         rs[0]["parts"][n][1]) for n in names}
            print(f"{row:5s} {tree}: {_med(cpu)} by the process's CPU time (the waits "
                  f"alone {_med(loop)}), {_med(wall)} by the wall; {sim:.2f} s simulated")
            print(f"      per call: {_line(parts)}")


if __name__ == "__main__":
    main()
