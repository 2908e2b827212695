"""The garbage collector under the loop's control.

CPython's cyclic collector runs whenever allocations pass a threshold, in
whatever code happens to allocate: inside a tick it is a pause of
microseconds (generation 0) to milliseconds (generation 2 over a large heap)
that shows as an overrun of whichever task was running.  A loop on real time
therefore (as real-time Python users do):

* freezes the heap built at start-up (``gc.freeze()``: the station's
  records, tables and code objects are never traversed again);
* turns automatic collection off while it runs, and collects itself in the
  idle part of a tick, after the work and before the wait, when the
  allocations since the last collection reach the generation-0 threshold and
  at least half a period is left (the generations escalate as CPython's do);
  a loop that never has that slack still collects once the allocations reach
  :attr:`GcWatch.FORCE_FACTOR` times the threshold;
* counts every collection it did not run itself (an explicit
  ``gc.collect()`` in a task, in a command or in another thread while a
  tick runs): its pause is an entry ``gc`` of the statistics (calls, mean,
  p99, max, overruns), and an overrun whose tick holds one is attributed to
  it, not to the task that happened to run (the task's share of the tick is
  taken without the pause).  The idle collections are the entry
  ``gc idle``.

Control applies to a loop on a :class:`~pyrt.scheduler.clock.WallClock`;
on any other clock nothing is frozen or switched off, but collections inside
ticks are still counted.  The heap stays frozen while any controlling loop
runs and is unfrozen when the last one stops.
"""

from __future__ import annotations

import contextlib
import gc
import threading
from collections.abc import Callable
from time import perf_counter_ns
from typing import Any

from pyrt.scheduler.stats import Accumulator

__all__ = ["GC_ENTRY", "GC_IDLE_ENTRY", "GcWatch"]

#: The statistics entry of collections inside ticks, and of the idle ones.
GC_ENTRY = "gc"
GC_IDLE_ENTRY = "gc idle"

# The collector is process-wide: the heap is frozen and automatic collection
# switched off while any controlling loop runs; when the last one stops, the
# heap is unfrozen and collection is as it was.
_lock = threading.Lock()
_holders = 0
_was_enabled = True


def _take_control() -> None:
    global _holders, _was_enabled
    with _lock:
        if _holders == 0:
            _was_enabled = gc.isenabled()
            gc.disable()
            gc.collect()  # start-up's garbage, before the rest is frozen
            gc.freeze()
        _holders += 1


def _give_back() -> None:
    global _holders
    with _lock:
        _holders -= 1
        if _holders == 0:
            gc.unfreeze()
            if _was_enabled:
                gc.enable()


class GcWatch:
    """Counts the collections of one loop's runs and runs its idle ones.

    ``tick()`` is a callable returning the loop's current tick index (a
    collection is remembered with the tick it happened in, for the overrun
    attribution); ``timer`` measures the pauses (the loop's clock's timer).
    """

    #: Without slack, collect anyway once allocations reach this many thresholds.
    FORCE_FACTOR = 20
    #: Pauses remembered for overrun attribution.
    RECENT = 64

    def __init__(self, tick: Callable[[], int], timer: Callable[[], int] = perf_counter_ns):
        self._tick = tick
        self._timer = timer
        #: Collections the loop did not run itself, while it ran.
        self.acc = Accumulator(GC_ENTRY)
        #: Collections run by the loop in the idle part of a tick.
        self.idle_acc = Accumulator(GC_IDLE_ENTRY)
        # (tick, pause) of the latest collections: the callback appends to
        # _new (no lock: a collection can start inside any allocation, this
        # object's own included); the loop thread moves them to _recent
        self._new: list[tuple[int, int]] = []
        self._recent: list[tuple[int, int]] = []
        self._idle = False
        self._t0 = 0
        #: True during a run that switched automatic collection off (an
        #: attribute: the loop reads it every tick).
        self.controlling = False
        self._installed = False
        #: Allocations (gc.get_count()[0]) at which an idle collection is due.
        self.threshold = max(1, gc.get_threshold()[0])

    # -- the collector's callback ------------------------------------------

    def _callback(self, phase: str, info: dict[str, Any]) -> None:
        if phase == "start":
            self._t0 = self._timer()
            return
        d = self._timer() - self._t0
        if self._idle:
            self.idle_acc.add(d)
        else:
            self.acc.add(d)
            new = self._new
            new.append((self._tick(), d))
            if len(new) > 2 * self.RECENT:
                del new[: self.RECENT]

    # -- a run -----------------------------------------------------------------

    def begin(self, control: bool) -> None:
        """A run starts: count collections; with ``control`` (real time), freeze
        the start-up heap and turn automatic collection off."""
        if control and not self.controlling:
            _take_control()  # its collection of start-up's garbage is not counted
            self.controlling = True
        if not self._installed:
            gc.callbacks.append(self._callback)
            self._installed = True

    def end(self) -> None:
        """The run ends: automatic collection as it was, no more counting."""
        if self.controlling:
            self.controlling = False
            _give_back()
        if self._installed:
            with contextlib.suppress(ValueError):  # someone cleared gc.callbacks
                gc.callbacks.remove(self._callback)
            self._installed = False

    def due(self) -> bool:
        """True when an idle collection is due (allocations past the threshold)."""
        return self.controlling and gc.get_count()[0] >= self.threshold

    def forced(self) -> bool:
        """True when allocations are so far past the threshold that the loop
        collects without slack."""
        return gc.get_count()[0] >= self.FORCE_FACTOR * self.threshold

    def collect_idle(self) -> None:
        """One collection now, counted as idle: generation 0, or an older one
        when its own count is due (as CPython's thresholds escalate)."""
        _, t1, t2 = gc.get_threshold()
        _, c1, c2 = gc.get_count()
        generation = 2 if c2 >= t2 and c1 >= t1 else 1 if c1 >= t1 else 0
        self._idle = True
        try:
            gc.collect(generation)
        finally:
            self._idle = False

    # -- attribution -----------------------------------------------------------

    def pauses_in(self, tick: int) -> list[int]:
        """The pauses (ns) of the collections counted in tick ``tick`` (the loop thread)."""
        new, self._new = self._new, []
        if new:
            self._recent = (self._recent + new)[-self.RECENT:]
        return [d for t, d in self._recent if t == tick]

    def count_overrun(self) -> None:
        """Attribute one overrun to the collector."""
        self.acc.overruns += 1

    def reset(self) -> None:
        """Forget what was counted."""
        self.acc.reset()
        self.idle_acc.reset()
        self._new = []
        self._recent = []


def attribute(tasks: list[tuple[str, int]], pauses: list[int]) -> list[tuple[str, int]]:
    """The tick's entries with each collection's pause taken out of the entry
    that held it (the longest one at least as long as the pause) and a
    ``gc`` entry of their sum added: the overrun's culprit is then the
    collector when it took the larger share."""
    if not pauses:
        return tasks
    out = list(tasks)
    for p in sorted(pauses, reverse=True):
        holders = [i for i, (_, d) in enumerate(out) if d >= p]
        if holders:
            i = max(holders, key=lambda k: out[k][1])
            out[i] = (out[i][0], out[i][1] - p)
    out.append((GC_ENTRY, sum(pauses)))
    return out
