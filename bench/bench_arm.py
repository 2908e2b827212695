"""The example arm (examples/arm): speed at --speed max, and its servo task at real time.

Run: ``python -m pytest bench/bench_arm.py --benchmark-only -s`` (needs
``pip install -e ./examples/arm``).  The first benchmark runs four moves (two
of them blended by the arm's queue) on a SimClock and reports simulated
seconds per second, of wall time and of the process's CPU time (the target:
100x; CPU time is the steadier figure on a shared machine), the CPU time per
tick and how much of it the moves' planning took (in the console's thread,
when each move is queued), and the share of the loop's timed work each of the
servo task, the trajectory task, the simulated arm's step and the station's
handlers took; the second times the parts of a tick on their own while the
arm moves (the world's step, the trajectory task, the servo task; the best
of 15 runs of 400 ticks, so a loaded machine's preemption drops out); the
third runs the arm at real time (1 kHz servo, 100 Hz trajectory) for a few
seconds of moves and reports the servo task's mean, p99 and max and the
overruns, from the loop's own statistics.

Figures (best of 9, the same runs, a shared two-core machine at load 5-7): the
arm with its own servo, interpolation and trajectory code (before pyrt's arm
layer) 63-70x in CPU time (31-32x wall); on pyrt.kinematics, pyrt.motion and
pyrt.native.Servo 53-65x (24-29x wall).  Of the timed work after: the simulated
arm's step (pure Python, about 5 µs per 1 ms tick) 34-48 %, the servo task
(about 3 µs) 21-22 %, the mailbox 15-28 % (each move is planned there when it
is queued, a few ms), the trajectory task 10-14 % (one knot of the evaluator
every 10th tick).  With moves planned in the console's thread (the loop only
takes the planned record), alternating runs of both on the same machine: before
54-57x in CPU time, the mailbox 20-24 % of the loop's timed work; after 51-57x
(the planning is the same work, done outside the ticks), the mailbox 3 %; of
the loop's work then: the simulated arm 40-47 %, the servo task 27-29 %, the
trajectory task 16-20 %.  The 100x target is not reached by moving the
planning: the simulated arm's step and the servo task are most of the time.

The simulated arm as pyrt's rigid-body world of the arm's URDF (one C call a
step) and the servo task as one C call (ServoBoard: encoders, law, bounds, DAC
counts), two sets of three interleaved rounds of this benchmark against the tree
before, at load 4.7-5.3: before 49-55x CPU (medians 53x and 50x), 18-42x wall
(26x, 31x); after 59-64x CPU (medians 61x and 62x), 24-38x wall (30x, 26x).
The parts of a tick on their own (the second benchmark, the same code run on
both trees, load 5.2-5.9): the world's step 5.9-7.6 µs before, 3.9-5.1 after
(its C step about 1 µs, the rest the registers around it in Python); the servo
task 4.4-5.7 before, 2.6-2.8 after; the trajectory task 1.9-2.5 on both
(pyrt's evaluator 7.5-11 µs a knot).  A tick then costs about 16 µs of CPU:
those three about 8.5 µs, the moves' planning 3.4-3.8 µs (pyrt's planner
samples each move three times: its first two plans are refused by its own
acceleration check at the segment's ends and made slower), the loop, the
station's handlers (moves, scope, mailbox) and the console about 4 µs.  100x
(10 µs a tick) is not within the example's reach: what is pyrt's (loop,
handlers, evaluator, planner, the world's Python around its C step) is about
10 µs of a tick.

Planned once, and the example's own tick cheaper (the world's wiring in the
board's own storage, the drives written through bound writes, the evaluator's
central differences on floats), five interleaved rounds of the script below
against the tree before, at load 10.3-10.4: before 56.9x CPU (43-60x), 19.1x
wall, 17.6 µs of CPU a tick; after 69.4x CPU (57-72x), 23.6x wall, 14.4 µs a
tick.  The parts of a tick (the second benchmark's loop through the image's
read and write phases, best of 57 runs of 100 ticks, load 10): the world with
the image's phases 5.3 -> 4.5 µs, the servo task 2.9 -> 2.55, the trajectory
task 1.95 -> 1.65; the four moves' planning (each planned once, its samples
taken at once) 3.0-3.8 ms -> 1.4 ms.  Of a tick's CPU time after (cProfile's
own times, grouped): pyrt's loop 21 %, the image and registers 12 %, the
simulated arm's Python around its C step 12 %, the cffi wrappers 11 %, the
example's own code 16 %, pyrt.motion (the evaluator and the planning) 7 %:
100x needs about 4 µs a tick more from pyrt's side.

The world's direct path serving the example's wired board (its drives, enables
and counters in place on the board while no fault is applied), the servo task
through ``Servo.board_ticker``, the trajectory glue on floats and the servo's
segments loaded without formatting a message: instructions per tick
(callgrind, ``PYTHONHASHSEED=0``, the four moves' run less a run of none, over
6931 ticks) 100,687 -> 79,080 (-21 %).  Five interleaved rounds of the script
below against the tree before, load 3.2-3.4: before 67.1x CPU (40-77x), 40-61x
wall, 14.9 µs of CPU a tick; after 84-87x CPU (54-91x), 68-78x wall, 11.5-11.9
µs a tick (1.3 µs of it the moves' planning).  The parts (best of 15 runs of
200 ticks, the same machine): the world with the image's read phase 4.0 ->
2.55 µs, the servo task 2.7 -> 2.1, the trajectory task 1.8 -> 1.45 (17.3 ->
12.6 µs a knot, 8.3-9.1 of it pyrt's evaluator), the write phase 0.6, the
move watch 0.34 -> 0.30.  Where the rest of a tick goes: the world's C step
about 0.9 µs (8.3k instructions), the servo's 0.15 (1.3k), the two drives'
writes into the image 0.56, the loop (its handlers' and tasks' timing, the
mailbox) about 3 µs, the planning 1.3: 100x (10 µs) needs about 1.5 µs a tick
more, from the loop's idle cost and pyrt.motion's evaluator (one knot in 3
µs instead of 8-9 would be 0.5 µs a tick) and planner.

As a script it compares source trees side by side (each run a child process
whose ``PYTHONPATH`` is the tree and its ``examples/arm``)::

    python bench/bench_arm.py --tree /tmp/before --tree . --rounds 5
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


def measure() -> dict:
    """One run of the four moves on a new station at --speed max: simulated, CPU
    and wall seconds, the CPU seconds of the moves' planning (in the console's
    thread, when each is queued), the ticks, each task's share of the loop's timed
    work."""
    station, runner, shell = _station(SimClock())
    try:
        t0, c0, w0 = station.loop.now_ns, time.process_time(), time.perf_counter()
        tick0 = station.loop.tick_index
        plan = 0.0
        for move in MOVES:
            c = time.process_time()
            shell.onecmd(move)  # planned here, in the console's thread
            plan += time.process_time() - c
            shell.onecmd("wait")
        cpu, wall = time.process_time() - c0, time.perf_counter() - w0
        sim = (station.loop.now_ns - t0) / 1e9
        ticks = station.loop.tick_index - tick0
        stats = runner.statistics()
    finally:
        station.close()
    total = sum(t.mean_ns * t.calls for t in stats.tasks.values())
    shares = {name: t.mean_ns * t.calls / total for name, t in stats.tasks.items()
              if t.calls} if total else {}
    return {"sim_s": sim, "cpu_s": cpu, "wall_s": wall, "plan_s": plan, "ticks": ticks,
            "shares": shares}


def test_arm_speed_max(benchmark):
    """Blended moves on virtual time: simulated seconds per wall second and per CPU second."""
    runs: list[dict] = []
    benchmark.pedantic(lambda: runs.append(measure()), rounds=9, iterations=1)
    sim = runs[-1]["sim_s"]
    ratio = sim / min(r["wall_s"] for r in runs)
    best = min(runs, key=lambda r: r["cpu_s"])
    cpu_ratio = sim / best["cpu_s"]
    parts = ", ".join(f"{name} {share:.0%}" for name, share in
                      sorted(runs[-1]["shares"].items(), key=lambda kv: -kv[1]))
    benchmark.extra_info.update(sim_s=sim, sim_s_per_wall_s=round(ratio, 1),
                                sim_s_per_cpu_s=round(cpu_ratio, 1))
    print(f"\narm at --speed max, moving: {ratio:.0f}x real time (wall), {cpu_ratio:.0f}x "
          f"(CPU time); target 100x; per tick {best['cpu_s'] / best['ticks'] * 1e6:.1f} µs of "
          f"CPU, {best['plan_s'] / best['ticks'] * 1e6:.1f} µs of it the moves' planning (in "
          f"the console's thread); of the loop's timed work: {parts}")


def test_arm_tick_parts(benchmark):
    """Where a tick's time goes while the arm moves: the world's step, the trajectory task
    (every 10th tick) and the servo task, each timed on its own (best of the rounds)."""
    from pyrt_arm.controller import TRAJECTORY_PERIOD

    best: dict[str, float] = {}

    def run():
        station, runner, shell = _station(SimClock())
        shell.onecmd("arm to 150 -100")  # about 3 s of motion
        runner.sleep(0.2)
        ctl, image = station.controller, station.board.client
        now, clock, n = station.loop.now_ns, time.perf_counter_ns, 400
        for _round in range(5):
            spent = {"physics": 0, "trajectory": 0, "servo": 0}
            for _ in range(n):
                now += station.loop.period_ns
                a = clock()
                image.read_phase(now)  # the world's step, then the inputs into the image
                b = clock()
                if now // station.loop.period_ns % TRAJECTORY_PERIOD == 0:
                    ctl.trajectory_tick(now)
                c = clock()
                ctl.servo_tick(now)
                d = clock()
                image.write_phase(now)  # the changed drives into the board
                spent["physics"] += b - a + clock() - d
                spent["trajectory"] += c - b
                spent["servo"] += d - c
            for name, ns in spent.items():
                best[name] = min(best.get(name, 1e9), ns / n / 1e3)
        assert ctl.state == "moving"
        station.close()

    benchmark.pedantic(run, rounds=3, iterations=1)
    benchmark.extra_info.update({f"{k}_us": round(v, 2) for k, v in best.items()})
    print("\nper 1 ms tick, moving (best of 15 runs of 400 ticks): " + ", ".join(
        f"{name} {us:.2f} µs" for name, us in best.items()))


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


# -- trees side by side (a script) ------------------------------------------------------------


def _child(tree: str) -> dict:
    root = Path(tree).resolve()
    path = os.pathsep.join([str(root), str(root / "examples" / "arm")])
    env = dict(os.environ, PYTHONPATH=path)
    done = subprocess.run([sys.executable, __file__, "--child"], env=env, check=True,
                          capture_output=True, text=True)
    return json.loads(done.stdout.splitlines()[-1])  # type: ignore[no-any-return]


def main(argv: list[str] | None = None) -> None:
    """Compare source trees side by side: every tree once in each round (interleaved),
    each run a child process whose ``PYTHONPATH`` is the tree and its
    ``examples/arm`` (the compiled modules built in place); the median of the rounds,
    with the load average before and after."""
    ap = argparse.ArgumentParser(description="the example arm at --speed max, trees side "
                                             "by side")
    ap.add_argument("--tree", action="append", help="a source tree (repeat; default: this one)")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        print(json.dumps(measure()))
        return
    trees = args.tree or [str(Path(__file__).resolve().parent.parent)]
    load0 = os.getloadavg()
    runs: dict[str, list[dict]] = {t: [] for t in trees}
    for _ in range(args.rounds):
        for tree in trees:
            runs[tree].append(_child(tree))
    load1 = os.getloadavg()
    print(f"load average before {load0[0]:.2f} {load0[1]:.2f} {load0[2]:.2f}, "
          f"after {load1[0]:.2f} {load1[1]:.2f} {load1[2]:.2f}; median of {args.rounds} "
          "interleaved rounds")
    for tree in trees:
        rs = runs[tree]
        cpu = [r["sim_s"] / r["cpu_s"] for r in rs]
        wall = [r["sim_s"] / r["wall_s"] for r in rs]
        tick = statistics.median(r["cpu_s"] / r["ticks"] * 1e6 for r in rs)
        plan = statistics.median(r["plan_s"] / r["ticks"] * 1e6 for r in rs)
        shares = rs[len(rs) // 2]["shares"]
        parts = ", ".join(f"{name} {share:.0%}" for name, share in
                          sorted(shares.items(), key=lambda kv: -kv[1]))
        print(f"{tree}: {statistics.median(cpu):.1f}x by the process's CPU time "
              f"({' '.join(f'{v:.1f}' for v in cpu)}), {statistics.median(wall):.1f}x by the "
              f"wall ({' '.join(f'{v:.1f}' for v in wall)}); per tick {tick:.1f} µs of CPU, "
              f"{plan:.1f} µs of it planning; of the loop's timed work: {parts}")


if __name__ == "__main__":
    main()
