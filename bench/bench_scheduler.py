"""Scheduler benchmarks: tick and dispatch cost on SimClock, side by side with
simpy and asyncio; WallClock lateness at 1 kHz and 100 Hz.

Run: ``python -m pytest bench/bench_scheduler.py --benchmark-only``.

``test_side_by_side`` (``-s`` shows its table) runs, interleaved in one
process and the same minutes, the 6-task dispatch of pyrt with timing on,
with timing off, the Python dispatch (``native=False``, the path before the
dispatch moved to C) and simpy, best of ``PYRT_SBS_ROUNDS`` rounds each
(default 7); target: pyrt with timing on at least 2x simpy.
The lateness benchmarks take 5 s each and report their figures in
``extra_info`` (shown with ``--benchmark-columns`` or ``--benchmark-json``)
and on stdout (``-s``).
"""

from __future__ import annotations

import asyncio
import os
import time

import pytest

from pyrt.scheduler import Loop, RateGroup, ReadyQueue, SimClock, Task, WallClock

TICKS = 20_000


def make_loop(ntasks: int, *, timing: bool = True, divisor: int = 1, period: int = 1,
              native: bool = True) -> Loop:
    """A SimClock loop with one queue of ``ntasks`` period-``period`` tasks
    (``native``: the dispatch in C; False: the Python dispatch it replaced)."""
    loop = Loop(SimClock(), timing=timing)
    queue = ReadyQueue(capacity=max(6, ntasks), divisor=divisor, native=native)
    for i in range(ntasks):
        queue.add_periodic(0x100 + i, f"T{i}", lambda: None, period)
        queue.schedule(0x100 + i, period)
    loop.attach(queue)
    return loop


@pytest.mark.benchmark(group="idle tick")
@pytest.mark.parametrize("timing", [True, False], ids=["timing-on", "timing-off"])
def test_idle_tick(benchmark, timing):
    """Cost of one tick when the queue is not checked (divisor FF), per tick."""
    loop = make_loop(6, timing=timing, divisor=0xFF)
    benchmark.extra_info["unit"] = f"per {TICKS} ticks"
    benchmark(loop.run, TICKS)


@pytest.mark.benchmark(group="idle tick")
@pytest.mark.parametrize("timing", [True, False], ids=["timing-on", "timing-off"])
def test_idle_tick_with_a_rate_group(benchmark, timing):
    """The idle tick above plus a 100 Hz rate group (one task) on the 1 ms tick:
    nine ticks in ten only count down, the tenth releases the group."""
    loop = make_loop(6, timing=timing, divisor=0xFF)
    group = RateGroup("trajectory", hz=100)
    group.new_queue("arm", [Task(lambda: None, period=1, name="plan")])
    loop.attach(group)
    benchmark.extra_info["unit"] = f"per {TICKS} ticks"
    benchmark(loop.run, TICKS)


@pytest.mark.benchmark(group="dispatch")
@pytest.mark.parametrize("ntasks", [4, 6])
@pytest.mark.parametrize("timing", [True, False], ids=["timing-on", "timing-off"])
def test_pyrt_dispatch(benchmark, ntasks, timing):
    """Every tick checks the queue and dispatches each period-1 task: cost per TICKS*ntasks dispatches."""
    loop = make_loop(ntasks, timing=timing)
    benchmark.extra_info["dispatches"] = TICKS * ntasks
    benchmark(loop.run, TICKS)


def simpy_run(nprocs: int, ticks: int) -> None:
    """simpy: ``nprocs`` processes each waking every time unit, until ``ticks``."""
    import simpy

    env = simpy.Environment()

    def proc(env):
        while True:
            yield env.timeout(1)

    for _ in range(nprocs):
        env.process(proc(env))
    env.run(until=ticks)


def best_of(fn, rounds: int) -> float:
    """The fastest of ``rounds`` calls of ``fn``, in seconds."""
    times = []
    for _ in range(rounds):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def side_by_side(ticks: int = TICKS, rounds: int = 7, ntasks: int = 6) -> dict[str, float]:
    """ms for ``ticks`` ticks of ``ntasks`` period-1 tasks, each variant
    interleaved with the others round by round (best of ``rounds``)."""
    variants = {
        "pyrt timing on": lambda: make_loop(ntasks).run(ticks),
        "pyrt timing off": lambda: make_loop(ntasks, timing=False).run(ticks),
        "pyrt Python dispatch, timing on": lambda: make_loop(ntasks, native=False).run(ticks),
        "simpy": lambda: simpy_run(ntasks, ticks),
    }
    best = {k: float("inf") for k in variants}
    for _ in range(rounds):
        for k, fn in variants.items():
            best[k] = min(best[k], best_of(fn, 1))
    return {k: v * 1e3 for k, v in best.items()}


@pytest.mark.benchmark(group="dispatch side by side")
def test_side_by_side(benchmark):
    """pyrt (timing on, off, Python dispatch) and simpy in one run: ms and ratios."""
    pytest.importorskip("simpy")
    rounds = int(os.environ.get("PYRT_SBS_ROUNDS", "7"))
    ms = benchmark.pedantic(side_by_side, kwargs={"rounds": rounds}, rounds=1, iterations=1)
    benchmark.extra_info.update({k: round(v, 2) for k, v in ms.items()})
    ratio = ms["simpy"] / ms["pyrt timing on"]
    benchmark.extra_info["simpy_over_pyrt"] = round(ratio, 2)
    print(f"\n{TICKS} ticks of 6 period-1 tasks (best of {rounds}, interleaved):")
    for k, v in ms.items():
        print(f"  {k:34s} {v:8.1f} ms  {v * 1e3 / (TICKS * 6):6.3f} µs/dispatch"
              f"  simpy/this {ms['simpy'] / v:5.2f}x")
    print(f"  target: pyrt timing on >= 2x simpy: {'met' if ratio >= 2 else 'NOT met'}"
          f" ({ratio:.2f}x)")


@pytest.mark.benchmark(group="dispatch")
def test_bare_counter_loop(benchmark):
    """Reference: a bare Python counter loop over 6 tasks, TICKS ticks."""
    counters = [1] * 6
    fns = [lambda: None] * 6

    def run():
        for _ in range(TICKS):
            for i in range(6):
                c = counters[i] - 1
                if c == 0:
                    fns[i]()
                    counters[i] = 1
                else:
                    counters[i] = c

    benchmark.extra_info["dispatches"] = TICKS * 6
    benchmark(run)


@pytest.mark.benchmark(group="dispatch")
def test_simpy_dispatch(benchmark):
    """Reference: simpy with 6 processes each waking every time unit (TICKS*6 dispatches)."""
    simpy = pytest.importorskip("simpy")

    def run():
        env = simpy.Environment()

        def proc(env):
            while True:
                yield env.timeout(1)

        for _ in range(6):
            env.process(proc(env))
        env.run(until=TICKS)

    benchmark.extra_info["dispatches"] = TICKS * 6
    benchmark(run)


@pytest.mark.benchmark(group="dispatch")
def test_asyncio_dispatch(benchmark):
    """Reference: asyncio with 6 tasks each yielding TICKS times (TICKS*6 dispatches)."""

    async def main():
        async def proc():
            for _ in range(TICKS):
                await asyncio.sleep(0)

        await asyncio.gather(*[proc() for _ in range(6)])

    benchmark.extra_info["dispatches"] = TICKS * 6
    benchmark(lambda: asyncio.run(main()))


def _lateness(period_ns: int, seconds: float) -> dict[str, float]:
    loop = Loop(WallClock(), period_ns=period_ns)
    queue = ReadyQueue(divisor=4)
    for i, p in enumerate((0x0C, 0x0A, 0x01)):
        queue.add_periodic(0x100 + i, f"T{i}", lambda: None, p)
        queue.schedule(0x100 + i, p)
    loop.attach(queue)
    loop.run(duration_ns=int(seconds * 1e9))
    st = loop.statistics()
    late = st.lateness
    return {
        "ticks": st.ticks,
        "overruns": st.overruns,
        "missed": st.missed,
        "median_us": late.p50_ns / 1e3,
        "p99_us": late.p99_ns / 1e3,
        "p999_us": late.p999_ns / 1e3,
        "max_us": late.max_ns / 1e3,
    }


@pytest.mark.benchmark(group="wallclock lateness")
@pytest.mark.parametrize("hz", [1000, 100])
def test_wallclock_lateness(benchmark, hz):
    """Lateness of WallClock ticks (sleep to absolute deadline, spin the last 200 µs), 5 s."""
    import resource

    r0 = resource.getrusage(resource.RUSAGE_SELF)
    result = benchmark.pedantic(_lateness, args=(1_000_000_000 // hz, 5.0), rounds=1, iterations=1)
    r1 = resource.getrusage(resource.RUSAGE_SELF)
    cpu = (r1.ru_utime + r1.ru_stime) - (r0.ru_utime + r0.ru_stime)
    result["cpu_fraction"] = round(cpu / 5.0, 3)
    benchmark.extra_info.update(result)
    print(f"\n{hz} Hz: {result}")


# -- the loop's own machinery, shaped as pyrt urdf's tick -------------------------------------


def machinery_loop(timing: bool = True) -> Loop:
    """A SimClock loop shaped as the ``pyrt urdf`` station's tick, every body
    empty: the read phase, a 1 kHz servo group and a 100 Hz trajectory group
    (one task each, in a ready queue of the arm), the move watch, the scope
    (at rest), the mailbox (a runner's) and the write phase.  What a tick of
    it costs is the loop's own share of every station's tick."""
    from pyrt.scheduler.runner import Runner
    from pyrt.scope import Scope

    loop = Loop(SimClock(), timing=timing)
    loop.attach(lambda now: None, name="io:read")
    for name, hz in (("servo", 1000), ("trajectory", 100)):
        group = RateGroup(name, hz=hz)
        group.new_queue("arm", [Task(lambda now: None, period=1, name=name, timed=True)])
        loop.attach(group)
    loop.attach(lambda now: None, name="moves")
    scope = Scope()
    if hasattr(scope, "attach_to"):
        scope.attach_to(loop)
    else:  # a tree from before the scope switched its own sampling on and off
        loop.attach(scope.sample, name="scope")
    Runner(loop).start()
    loop.attach(lambda now: None, name="io:write")
    return loop


def machinery_us(timing: bool = True, ticks: int = 50_000, rounds: int = 7) -> float:
    """The best of ``rounds`` runs of ``ticks`` ticks of :func:`machinery_loop`:
    process CPU µs per tick (summaries and their folds included)."""
    loop = machinery_loop(timing)
    loop.run(2_000)
    best = float("inf")
    for _ in range(rounds):
        c0 = time.process_time()
        loop.run(ticks)
        best = min(best, (time.process_time() - c0) / ticks * 1e6)
    return best


@pytest.mark.benchmark(group="loop machinery")
@pytest.mark.parametrize("timing", [True, False], ids=["timing-on", "timing-off"])
def test_loop_machinery_per_tick(benchmark, timing):
    """The urdf-shaped tick with empty bodies: the loop's own cost per tick (µs of CPU)."""
    us = benchmark.pedantic(machinery_us, kwargs={"timing": timing}, rounds=1, iterations=1)
    benchmark.extra_info["us_per_tick"] = round(us, 3)
    print(f"\nloop machinery, urdf-shaped tick, timing {'on' if timing else 'off'}: {us:.2f} µs")


def main(argv: list[str] | None = None) -> None:
    """Source trees side by side: the machinery row of each, interleaved, in
    child processes whose ``PYTHONPATH`` is the tree (run from any directory)."""
    import argparse
    import json
    import statistics
    import subprocess
    import sys
    from pathlib import Path

    ap = argparse.ArgumentParser(description="the loop's machinery per tick, trees side by side")
    ap.add_argument("--tree", action="append", help="a source tree (repeat; default: this one)")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        print(json.dumps({"on": machinery_us(True), "off": machinery_us(False)}))
        return
    trees = args.tree or [str(Path(__file__).resolve().parent.parent)]
    load0 = os.getloadavg()
    runs: dict[str, list[dict]] = {t: [] for t in trees}
    for _ in range(args.rounds):
        for tree in trees:
            env = dict(os.environ, PYTHONPATH=str(Path(tree).resolve()))
            done = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--child"],
                                  env=env, check=True, capture_output=True, text=True,
                                  cwd=Path(__file__).resolve().parent)
            runs[tree].append(json.loads(done.stdout.splitlines()[-1]))
    load1 = os.getloadavg()
    print(f"load average before {load0[0]:.2f}, after {load1[0]:.2f}; median of {args.rounds} "
          "interleaved rounds (each the best of 7 runs of 50,000 ticks)")
    for tree in trees:
        on = statistics.median(r["on"] for r in runs[tree])
        off = statistics.median(r["off"] for r in runs[tree])
        print(f"{tree}: {on:.2f} µs a tick with timing on, {off:.2f} µs with it off")


if __name__ == "__main__":
    main()
