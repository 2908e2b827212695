"""Garbage collection under the loop's control: collections inside ticks counted and blamed."""

from __future__ import annotations

import gc
import json

import pytest
from _clocks import MS, WorkClock

from pyrt.scheduler import Loop, ReadyQueue, SimClock, WallClock
from pyrt.scheduler.gcwatch import GC_ENTRY, GC_IDLE_ENTRY, attribute
from pyrt.scheduler.report import format_statistics
from pyrt.scheduler.timinglog import TimingLog


def _cycles(n: int) -> None:
    """Allocate ``n`` reference cycles (garbage only the collector frees)."""
    for _ in range(n):
        a: list = []
        a.append(a)


def _queue_with(fn, name: str = "ALLOC") -> ReadyQueue:
    q = ReadyQueue(capacity=4)
    q.add_periodic(0x100, name, fn, 1)
    q.schedule(0x100, 1)
    return q


def test_a_forced_collection_in_a_task_is_counted_in_stats():
    """SimClock: a task that allocates and collects shows its collections as the entry gc."""
    loop = Loop(SimClock())
    runs = []

    def heavy() -> None:
        _cycles(200)
        runs.append(1)
        if len(runs) % 5 == 0:
            gc.collect(0)

    loop.attach(_queue_with(heavy))
    loop.run(20)
    st = loop.statistics()
    assert st.tasks[GC_ENTRY].calls >= 4
    assert st.tasks[GC_ENTRY].kind == "gc"
    assert st.tasks[GC_ENTRY].max_ns > 0
    assert any(line.startswith("gc ") for line in format_statistics(st).splitlines())


def test_no_collection_no_gc_entry():
    """A loop whose ticks collect nothing has no gc entry (nothing invented)."""
    was = gc.isenabled()
    gc.disable()
    try:
        loop = Loop(SimClock())
        loop.attach(_queue_with(lambda: None))
        loop.run(10)
    finally:
        if was:
            gc.enable()
    assert GC_ENTRY not in loop.statistics().tasks


def test_attribute_moves_the_pause_out_of_the_task_that_held_it():
    """A 4.9 ms pause inside a 5 ms task: the task keeps 0.1 ms, the collector takes the rest."""
    tasks = [("A", 5_000_000), ("B", 200_000)]
    out = attribute(tasks, [4_900_000])
    assert out == [("A", 100_000), ("B", 200_000), (GC_ENTRY, 4_900_000)]
    assert attribute(tasks, []) == tasks


def test_an_overrun_caused_by_a_collection_is_blamed_on_it(tmp_path):
    """WorkClock: a collection that makes the tick overrun is the culprit, in stats and the log."""
    clock = WorkClock()
    path = tmp_path / "t.jsonl"
    log = TimingLog(str(path))
    loop = Loop(clock, period_ns=MS, timing_log=log)
    pauses = iter([0, 0, 3 * MS, 0, 0])

    def task() -> None:
        clock.work(10_000)
        p = next(pauses, 0)
        if p:
            # a collection that the timer sees as taking 3 ms
            gc.callbacks.insert(0, lambda phase, info: clock.work(p) if phase == "stop" else None)
            try:
                gc.collect(0)
            finally:
                del gc.callbacks[0]

    loop.attach(_queue_with(task, "VICTIM"))
    loop.run(10)
    loop.close()
    st = loop.statistics()
    assert st.overruns == 1
    assert st.tasks[GC_ENTRY].overruns == 1
    assert st.tasks["VICTIM"].overruns == 0
    records = [json.loads(line) for line in path.read_text().splitlines()]
    over = [r for r in records if r["type"] == "overrun"]
    assert len(over) == 1
    names = dict(over[0]["tasks"])
    assert names[GC_ENTRY] >= 3 * MS > names["VICTIM"]


class _QuietTime:
    """time.monotonic_ns and time.sleep for WallClock: a sleep wakes on time, a task takes
    no time, so every tick leaves the whole period idle (however busy the machine is)."""

    def __init__(self):
        self.now = 10**9

    def monotonic_ns(self) -> int:
        self.now += 1_000  # every look at the clock costs a microsecond
        return self.now

    def sleep(self, s: float) -> None:
        self.now += round(s * 1e9)


def test_an_allocation_heavy_task_at_real_time_collects_in_idle_time(monkeypatch):
    """Real time (a WallClock on a quiet time source): automatic collection off while running, collections idle and in stats; back after."""
    import pyrt.scheduler.clock as clock_mod

    monkeypatch.setattr(clock_mod, "time", _QuietTime())
    was = gc.isenabled()
    seen = []

    def heavy() -> None:
        _cycles(3000)
        seen.append(gc.isenabled())

    loop = Loop(WallClock(), period_ns=2 * MS)
    loop.attach(_queue_with(heavy))
    loop.run(duration_ns=150 * MS)
    st = loop.statistics()
    assert len(seen) >= 70 and not any(seen)  # automatic collection was off in every tick
    assert gc.isenabled() == was
    assert st.tasks[GC_IDLE_ENTRY].calls >= 5  # 3000 cycles a tick: one collection a tick or so
    assert st.tasks[GC_IDLE_ENTRY].kind == "gc"
    assert GC_ENTRY not in st.tasks  # none inside a tick: every one waited for idle time
    assert "gc idle" in format_statistics(st)


@pytest.mark.wallclock
def test_gc_control_off_leaves_the_collector_alone():
    """gc_control=False on a wall clock: automatic collection stays as it was."""
    seen = []
    loop = Loop(WallClock(speed=1000.0), gc_control=False)
    loop.attach(_queue_with(lambda: seen.append(gc.isenabled())))
    loop.run(ticks=3)
    assert seen == [gc.isenabled()] * 3
