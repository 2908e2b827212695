"""The timing of a loop's handlers that are not ready queues.

Board polls, the physics, the motion executor, the scope, the mailbox and
the foreground jobs are each timed as an entry of their own, beside the
ready queues' routines: the loop reads the clock once between handlers (the
end of one is the start of the next) and appends each duration to the
handler's sample list; the lists are handed over (:meth:`HandlerTimes.take`)
and folded into histograms in bulk, off the tick.  The loop's own two
streams on real time, each tick's lateness and work, are kept the same way
(:attr:`HandlerTimes.lateness`, :attr:`HandlerTimes.work`): a tick appends
two integers and bins nothing.
"""

from __future__ import annotations

import threading
from typing import TYPE_CHECKING

from pyrt.scheduler._routinetiming import fold_many
from pyrt.scheduler.stats import Accumulator

if TYPE_CHECKING:
    from pyrt.scheduler.rategroup import GroupTiming
    from pyrt.scheduler.readyqueue import ReadyQueue

__all__ = ["HandlerTimes", "HandlerTiming", "TakenSamples"]


class HandlerTiming:
    """The timing of one loop handler that is not a ready queue."""

    __slots__ = ("acc", "last", "name", "samples")

    def __init__(self, name: str):
        self.name = name
        #: Durations (ns) not yet folded; the loop appends one per tick.
        self.samples: list[int] = []
        self.acc = Accumulator(name)
        #: The last duration handed over by a take (for an overrun in that tick).
        self.last = 0


class TakenSamples:
    """Timing samples handed over by :meth:`~pyrt.scheduler.loop.Loop.take_samples`,
    to fold elsewhere."""

    __slots__ = ("groups", "handlers", "queues")

    def __init__(self, queues: list[tuple[ReadyQueue, dict[int, list[int]]]],
                 handlers: list[tuple[HandlerTiming, list[int]]],
                 groups: list[tuple[GroupTiming, list[int]]] | None = None):
        self.queues = queues
        self.handlers = handlers
        #: Each rate group's work time per release.
        self.groups = groups or []


class HandlerTimes:
    """The entries of one loop's timed handlers (see the module text)."""

    def __init__(self) -> None:
        self.entries: list[HandlerTiming] = []
        #: How late each tick started and how long its work took (ns; the loop
        #: appends one of each per tick on real time): taken and folded with
        #: the entries, never listed among them.
        self.lateness = HandlerTiming("lateness")
        self.work = HandlerTiming("work")
        #: Where a queue's own stretch of a timed tick goes (its routines are
        #: timed by the queue); emptied at every take.
        self.sink: list[int] = []
        self.lock = threading.Lock()
        self._taken_tick = -1

    def add(self, name: str) -> HandlerTiming:
        """A new entry called ``name`` (a second of that name gets ``#2``)."""
        taken = {e.name for e in self.entries}
        key, n = name, 1
        while key in taken:
            n += 1
            key = f"{name} #{n}"
        entry = HandlerTiming(key)
        self.entries.append(entry)
        return entry

    def keys(self, routines: set[str]) -> dict[str, str]:
        """Each entry's name in the statistics: its own, or ``NAME (handler)``
        where a ready-queue routine (of ``routines``) has that name."""
        return {e.name: f"{e.name} (handler)" if e.name in routines else e.name
                for e in self.entries}

    def last_duration(self, entry: HandlerTiming, tick: int) -> int | None:
        """``entry``'s duration in ``tick``, the last one run (None: not known)."""
        if entry.samples:
            return entry.samples[-1]
        if self._taken_tick == tick:
            return entry.last  # the samples were taken during that tick
        return None

    def take(self, tick: int) -> list[tuple[HandlerTiming, list[int]]]:
        """Hand over the samples recorded so far (in ``tick``, loop thread)."""
        taken = []
        for e in (*self.entries, self.lateness, self.work):
            s = e.samples
            if s:
                e.last = s[-1]
                taken.append((e, s[:]))
                s.clear()  # the same list: the tick plan appends to it
        self.sink.clear()
        self._taken_tick = tick
        return taken

    def fold(self, taken: list[tuple[HandlerTiming, list[int]]],
             groups: list[tuple[GroupTiming, list[int]]] | None = None) -> None:
        """Fold samples handed over by :meth:`take` (any thread), and the rate
        groups' release times with them (one numpy pass for all)."""
        if taken or groups:
            with self.lock:
                fold_many([(e.acc, durs) for e, durs in taken]
                          + [(g.acc, durs) for g, durs in groups or ()])

    def reset(self) -> None:
        """Forget every sample and accumulated figure."""
        with self.lock:
            for e in (*self.entries, self.lateness, self.work):
                e.samples.clear()
                e.acc.reset()
        self.sink.clear()
