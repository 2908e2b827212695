"""Execution times of the routines a ready queue dispatches.

Off, it costs nothing.  On, each dispatch appends its duration to its
routine's sample list (one timer read, one append; in C when the queue's
dispatch is native); every few thousand samples they are folded into the
routines' accumulators with numpy, in bulk.  With tick tracking, the
routines run in the last check are kept too (address, duration), so that
the loop can name what ran in a tick that overran.

The state the C dispatch keeps itself (the samples pending, the time of the
last tracked check, its tick log) is read from it while it is attached.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from itertools import chain
from time import perf_counter_ns
from typing import Any

import numpy as np

from pyrt.scheduler.stats import NBINS, Accumulator

__all__ = ["RoutineTiming", "fold_into", "fold_many", "fold_samples"]


class RoutineTiming:
    """The timing of one ready queue's routines (see the module text)."""

    def __init__(self) -> None:
        #: Per routine address: its accumulator (None: timing off).
        self.stats: dict[int, Accumulator] | None = None
        #: Per routine address: durations (ns) not yet folded (None: timing off).
        self.samples: dict[int, list[int]] | None = None
        #: True when the routines of each check are kept for overrun records.
        self.track = False
        #: ``(address, duration)`` of the last tracked check (the Python dispatch).
        self.tick_log: list[tuple[int, int]] = []
        self._timer: Callable[[], int] = perf_counter_ns
        self._core: Any = None
        self._pending_py = 0
        self._checked_at_py = -1
        self._fold_lock = threading.Lock()

    # -- the C dispatch ------------------------------------------------------

    def attach(self, core: Any) -> None:
        """Time through ``core`` (a native dispatcher; None: the Python dispatch)."""
        self._core = core
        self.sync()

    def sync(self) -> None:
        """Tell the C dispatch the timer, the tracking and the sample lists."""
        core = self._core
        if core is None:
            return
        timer = self._timer if self.samples is not None else None
        core.set_timing(timer, timer is perf_counter_ns, self.track, self.samples)

    # -- configuration -------------------------------------------------------

    def enable(self, on: bool, track_ticks: bool, routines: dict[int, str]) -> None:
        """Timing on or off for ``routines`` (address -> name); see
        :meth:`~pyrt.scheduler.readyqueue.ReadyQueue.enable_timing`."""
        if on:
            self.stats = {a: Accumulator(name) for a, name in routines.items()}
            self.samples = {a: [] for a in routines}
        else:
            self.stats = None
            self.samples = None
        self.track = on and track_ticks
        self.pending = 0
        self.tick_log = []
        self.checked_at = -1
        self.sync()

    def add(self, address: int, name: str) -> None:
        """Time the routine registered at ``address`` too (when timing is on)."""
        if self.stats is not None and self.samples is not None:
            self.stats[address] = Accumulator(name)
            self.samples[address] = []
            if self._core is not None:
                self._core.set_samples(self.samples)

    @property
    def timer(self) -> Callable[[], int]:
        """Measures routine execution times (the loop sets its clock's timer)."""
        return self._timer

    @timer.setter
    def timer(self, timer: Callable[[], int]) -> None:
        if not callable(timer):
            raise TypeError(f"a timer must be callable, got {timer!r}")
        self._timer = timer
        self.sync()

    @property
    def pending(self) -> int:
        """Samples recorded since the last take."""
        core = self._core
        return core.pending if core is not None else self._pending_py

    @pending.setter
    def pending(self, n: int) -> None:
        if self._core is not None:
            self._core.pending = n
        self._pending_py = n

    @property
    def checked_at(self) -> int:
        """Loop time of the last check that ran routines, tracked (-1: none)."""
        core = self._core
        return core.checked_at if core is not None else self._checked_at_py

    @checked_at.setter
    def checked_at(self, t: int) -> None:
        if self._core is not None:
            self._core.checked_at = t
        self._checked_at_py = t

    # -- samples -------------------------------------------------------------

    def take(self) -> dict[int, list[int]]:
        """Hand over the samples recorded so far and start new lists (loop
        thread, O(routines))."""
        taken = self.samples
        if not taken or not self.pending:
            return {}
        self.samples = {a: [] for a in taken}
        self.pending = 0
        if self._core is not None:
            self._core.set_samples(self.samples)
        return taken

    def fold(self, samples: dict[int, list[int]]) -> None:
        """Fold samples handed over by :meth:`take` (any thread)."""
        if samples and self.stats is not None:
            with self._fold_lock:
                fold_samples(self.stats, samples)

    def fold_all(self) -> None:
        """Fold every recorded sample into the accumulators (the loop thread)."""
        if self.stats is not None and self.pending:
            self.fold(self.take())

    def accumulators(self, fold: bool) -> list[Accumulator]:
        """The accumulators (empty when timing is off); ``fold`` first."""
        if self.stats is None:
            return []
        if fold:
            self.fold_all()
        return list(self.stats.values())

    def in_tick(self, now_ns: int) -> list[tuple[int, int]]:
        """``(address, duration_ns)`` of the routines run in the tick at ``now_ns``."""
        if not self.track or self.checked_at != now_ns:
            return []
        return self._core.tick_log if self._core is not None else self.tick_log


def fold_samples(stats: dict[int, Accumulator], samples: dict[int, list[int]]) -> None:
    """Add each routine's duration samples (ns) to its accumulator, in bulk."""
    fold_many([(stats[a], durs) for a, durs in samples.items() if a in stats])


def fold_into(acc: Accumulator, durs: list[int]) -> None:
    """Add duration samples (ns) to ``acc``, in bulk (negative ones count as 0)."""
    fold_many([(acc, durs)])


def fold_many(pairs: list[tuple[Accumulator, list[int]]]) -> None:
    """Add each list of duration samples (ns) to its accumulator: one numpy
    pass over all of them (negative durations count as 0)."""
    pairs = [(acc, durs) for acc, durs in pairs if durs]
    if not pairs:
        return
    lengths = [len(durs) for _, durs in pairs]
    total = sum(lengths)
    d = np.fromiter(chain.from_iterable(durs for _, durs in pairs), dtype=np.int64, count=total)
    np.maximum(d, 0, out=d)
    k = len(pairs)
    idx = _bin_indices(d)
    if k > 1:
        idx += np.repeat(np.arange(0, k * NBINS, NBINS, dtype=np.int64), lengths)
    counts = np.bincount(idx, minlength=k * NBINS)
    starts = np.zeros(k, dtype=np.int64)
    np.cumsum(lengths[:-1], out=starts[1:])
    sums = np.add.reduceat(d, starts).tolist()
    maxs = np.maximum.reduceat(d, starts).tolist()
    for j, (acc, _) in enumerate(pairs):
        acc.calls += lengths[j]
        acc.total += sums[j]
        if maxs[j] > acc.max:
            acc.max = maxs[j]
    # the bins that took samples, all lists at once, as plain ints
    nz = np.flatnonzero(counts)
    for flat, c in zip(nz.tolist(), counts[nz].tolist(), strict=True):
        j, i = divmod(flat, NBINS)
        pairs[j][0].hist[i] += c


def _bin_indices(d: np.ndarray) -> np.ndarray:
    """Vectorised :func:`pyrt.scheduler.stats.bin_index` for non-negative int64 durations."""
    _, bl = np.frexp(d.astype(np.float64))  # bit length, exact below 2**53
    bl = bl.astype(np.int64)
    shift = np.maximum(bl - 3, 0)
    idx = (bl << 2) - 8 + ((d >> shift) & 3)
    idx = np.where(d < 8, d, idx)
    return np.minimum(idx, NBINS - 1)
