"""Garbage-collector pauses in a real-time manipulator run, without and with the loop's control.

Run: ``python bench/bench_gc.py [SECONDS]`` (default 60 s a run; or
``python -m pytest bench/bench_gc.py -s`` for 10 s runs).

The sno station runs at real time (WallClock, its 5 ms tick, the
write-back thread) with a move under way, a scope of 8 channels sampling
every tick, and the application asking for ``statistics`` every 200 ms
(what a console's ``top`` does).  Every collection is recorded from
``gc.callbacks`` (generation, pause, thread).  Two runs, one after the
other in the same process:

``before``  ``Loop(gc_control=False)``: the collector as CPython runs it
            (automatic, thresholds 700/10/10), which is what the loop did
            before it took control;
``after``   the default: start-up heap frozen, automatic collection off
            while running, collections in the idle part of ticks, any
            collection inside a tick counted (entry ``gc``).

It prints, per run: collections per generation, the largest generation-2
pause, the largest pause of any generation in the loop thread, the
overruns and the loop's ``gc`` / ``gc idle`` entries.  Then what a full
(generation-2) collection costs over the process heap of a built sno
station, as the heap is, and once it is frozen (``gc.freeze()``, what the
loop does after start-up): the pause a gen-2 collection inside a tick would
have been, before and after.
"""

from __future__ import annotations

import gc
import sys
import tempfile
import threading
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))

MOVE = (80.0, 60.0, 100.0)


def one_run(seconds: float, control: bool) -> dict:
    """A real-time sno run of ``seconds`` with the loop's gc control on or off."""
    from pyrt.db import copy_station
    from pyrt.scheduler import Loop, WallClock
    from pyrt.scope.scope import Scope
    from pyrt.scope.sources import Source
    from pyrt.station.manipulator import TICK_NS, ManipulatorStation

    pauses: list[tuple[int, float, str]] = []
    t0 = [0.0]

    def watch(phase: str, info: dict) -> None:
        if phase == "start":
            t0[0] = time.perf_counter()
        elif t0[0]:  # a collection under way when the watch was installed is not timed
            pauses.append((info["generation"], time.perf_counter() - t0[0],
                           threading.current_thread().name))

    with tempfile.TemporaryDirectory() as tmp:
        directory = copy_station("sno", Path(tmp) / "sno")
        loop = Loop(WallClock(), period_ns=TICK_NS, gc_control=control)
        station = ManipulatorStation(directory, loop=loop)
        pa = station.polyaxis
        values = pa.tensions
        scope = Scope(capacity=16_000, max_channels=16)
        for i in range(min(8, len(values))):
            scope.add(f"t{i}", Source.item(values, i))
        scope.run("roll")
        loop.attach(scope.sample, "bench scope")
        runner = station.start()
        gc.callbacks.append(watch)
        try:
            runner.call(pa.to, MOVE)
            end = time.perf_counter() + seconds
            while time.perf_counter() < end:
                time.sleep(0.2)
                stats = runner.statistics()
        finally:
            gc.callbacks.remove(watch)
            station.close()
    loop_thread = "pyrt-loop"
    by_gen = [sum(1 for g, _, _ in pauses if g == k) for k in range(3)]
    gen2 = [p for g, p, _ in pauses if g == 2]
    return {
        "control": control,
        "collections": by_gen,
        "max_gen2_ms": max(gen2) * 1e3 if gen2 else 0.0,
        "max_loop_thread_ms": max((p for _, p, th in pauses if th == loop_thread),
                                  default=0.0) * 1e3,
        "overruns": stats.overruns,
        "ticks": stats.ticks,
        "gc_entry": {n: (t.calls, round(t.max_ns / 1e3, 1), t.overruns)
                     for n, t in stats.tasks.items() if t.kind == "gc"},
    }


def full_collection_cost() -> dict:
    """ms of ``gc.collect(2)`` over the heap of a built sno station: unfrozen, frozen."""
    from pyrt.db import copy_station
    from pyrt.station.manipulator import ManipulatorStation

    def timed() -> float:
        best = float("inf")
        for _ in range(5):
            t0 = time.perf_counter()
            gc.collect(2)
            best = min(best, time.perf_counter() - t0)
        return best * 1e3

    with tempfile.TemporaryDirectory() as tmp:
        station = ManipulatorStation(copy_station("sno", Path(tmp) / "sno"))
        try:
            gc.collect()
            objects = len(gc.get_objects())
            unfrozen = timed()
            gc.freeze()
            try:
                frozen = timed()
            finally:
                gc.unfreeze()
        finally:
            station.close()
    return {"objects": objects, "unfrozen_ms": unfrozen, "frozen_ms": frozen}


def report(rows: list[dict]) -> str:
    """The two runs as text."""
    lines = [f"{'':8}{'gen0/1/2':>16}{'max gen2 ms':>13}{'max in loop ms':>16}"
             f"{'overruns':>10}{'ticks':>8}  gc entries (calls, max µs, overruns)"]
    for r in rows:
        gens = "/".join(str(c) for c in r["collections"])
        lines.append(f"{'after' if r['control'] else 'before':8}{gens:>16}"
                     f"{r['max_gen2_ms']:>13.2f}{r['max_loop_thread_ms']:>16.2f}"
                     f"{r['overruns']:>10}{r['ticks']:>8}  {r['gc_entry']}")
    return "\n".join(lines)


def test_gc_pauses_before_and_after():
    """10 s runs: the figures printed (-s); with control, no automatic collection in the loop."""
    rows = [one_run(10.0, False), one_run(10.0, True)]
    print("\n" + report(rows))
    print(full_collection_cost())


def main(argv: list[str]) -> int:
    seconds = float(argv[0]) if argv else 60.0
    rows = [one_run(seconds, False), one_run(seconds, True)]
    sys.stdout.write(report(rows) + "\n")
    c = full_collection_cost()
    sys.stdout.write(f"a full collection over a built sno station's heap ({c['objects']} objects"
                     f" tracked): {c['unfrozen_ms']:.2f} ms; frozen: {c['frozen_ms']:.3f} ms\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
