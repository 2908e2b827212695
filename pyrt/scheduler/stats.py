"""Timing statistics: log-spaced histograms and frozen snapshots.

Durations are integers in nanoseconds.  The histogram has four bins per
octave (bins 0-7 hold 0-7 ns exactly), so recording costs a ``bit_length``
and a shift; percentiles are read from the histogram as the upper edge of the
bin where the cumulative count crosses the fraction, clamped to the exact
maximum.  Snapshots are plain frozen values (:class:`Distribution`,
:class:`TaskStatistics`, :class:`LoopStatistics`), as trio's
``current_statistics()`` is.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

__all__ = [
    "NBINS",
    "Accumulator",
    "Distribution",
    "GroupStatistics",
    "LoopStatistics",
    "TaskStatistics",
    "bin_edges",
    "bin_index",
    "format_bound_us",
]

#: How ``stats`` and ``pyrt overruns`` print a quantile read from the
#: histogram: its bins are a quarter octave (up to 25 % wide), so a quantile
#: is an upper bound good to two significant figures, printed as ``≤2.6k``.
QUANTILE_NOTE = "quantiles are bin upper bounds (≤, 2 significant figures); max is exact"

#: Number of histogram bins: up to 2**41 ns (about 36 minutes) per sample.
NBINS = 160


def bin_index(d: int) -> int:
    """Histogram bin of a duration ``d`` (ns); negative values count as 0."""
    if d < 8:
        return d if d > 0 else 0
    bl = d.bit_length()
    i = (bl << 2) - 8 + ((d >> (bl - 3)) & 3)
    return i if i < NBINS else NBINS - 1


def bin_edges(i: int) -> tuple[int, int]:
    """``(low, high)`` of bin ``i``: it holds durations ``low <= d < high``."""
    if i < 8:
        return i, i + 1
    k, s = divmod(i - 8, 4)
    shift = k + 1
    return (4 + s) << shift, (5 + s) << shift


class Accumulator:
    """Mutable running statistics of one stream of durations.

    The hot loop updates the slots directly (``calls``, ``total``, ``max``,
    ``hist``) rather than through a method call; :meth:`add` is for code off
    the hot path.
    """

    __slots__ = ("calls", "hist", "max", "name", "overruns", "total")

    def __init__(self, name: str = ""):
        self.name = name
        self.calls = 0
        self.total = 0
        self.max = 0
        self.overruns = 0
        self.hist = [0] * NBINS

    def add(self, d: int) -> None:
        """Record one duration ``d`` in ns."""
        self.calls += 1
        self.total += d
        if d > self.max:
            self.max = d
        self.hist[bin_index(d)] += 1

    def reset(self) -> None:
        """Forget everything recorded so far."""
        self.calls = self.total = self.max = self.overruns = 0
        self.hist = [0] * NBINS

    def distribution(self) -> Distribution:
        """A frozen snapshot of what has been recorded."""
        return Distribution.from_hist(self.calls, self.total, self.max, self.hist)


def format_bound_us(ns: int, exact_ns: int | None = None) -> str:
    """A histogram quantile ``ns`` in µs with the precision its bin supports:
    two significant figures after ``≤`` (it is the bin's upper edge), or the
    exact value when it equals ``exact_ns`` (the clamp to the true maximum)."""
    us = ns / 1e3
    if exact_ns is not None and ns == exact_ns:
        return f"{us:.2f}"
    if us == 0:
        return "0"
    # rounded up at the second significant digit, in integer ns (no float
    # rounding can take it below the bound)
    step = 10 ** max(0, len(str(int(ns))) - 2)
    up = -(-int(ns) // step) * step / 1e3
    return "≤" + (f"{up:.0f}" if up >= 10 else f"{up:.2g}")


@dataclass(frozen=True)
class Distribution:
    """A frozen summary of a stream of durations (all times in ns)."""

    count: int = 0
    total_ns: int = 0
    max_ns: int = 0
    mean_ns: float = 0.0
    p50_ns: int = 0
    p99_ns: int = 0
    p999_ns: int = 0
    #: Sparse histogram: ``(bin, count)`` pairs with a non-zero count.
    hist: tuple[tuple[int, int], ...] = ()

    @classmethod
    def from_hist(cls, count: int, total: int, max_ns: int,
                  hist: Sequence[Any]) -> Distribution:
        """Build from raw counters; ``hist`` is dense (list) or sparse (pairs)."""
        if hist and isinstance(hist[0], (tuple, list)):
            sparse = tuple((int(b), int(c)) for b, c in hist if c)
        else:
            sparse = tuple((b, c) for b, c in enumerate(hist) if c)
        mean = total / count if count else 0.0
        return cls(
            count=count,
            total_ns=total,
            max_ns=max_ns,
            mean_ns=mean,
            p50_ns=_percentile(sparse, count, max_ns, 0.50),
            p99_ns=_percentile(sparse, count, max_ns, 0.99),
            p999_ns=_percentile(sparse, count, max_ns, 0.999),
            hist=sparse,
        )

    def percentile(self, q: float) -> int:
        """Upper-bound estimate of the ``q`` quantile (0 < q <= 1), in ns."""
        return _percentile(self.hist, self.count, self.max_ns, q)


def _percentile(sparse: Iterable[tuple[int, int]], count: int, max_ns: int, q: float) -> int:
    if count == 0:
        return 0
    need = q * count
    seen = 0
    for b, c in sparse:
        seen += c
        if seen >= need:
            return min(bin_edges(b)[1] - 1, max_ns)
    return max_ns


@dataclass(frozen=True)
class TaskStatistics:
    """Execution times of one task (a ready-queue routine or loop handler)."""

    name: str
    calls: int
    mean_ns: float
    max_ns: int
    p99_ns: int
    #: Overruns in which this task took the longest time of the tick.
    overruns: int
    distribution: Distribution = field(repr=False)
    #: ``"task"``: a ready-queue routine; ``"handler"``: a loop handler that is
    #: not a ready queue (board poll, physics, motion executor, scope, mailbox);
    #: ``"gc"``: garbage collections (``gc`` inside ticks, ``gc idle`` between).
    kind: str = "task"
    #: The rate group the task ran in ("" for a loop handler outside groups).
    group: str = ""


@dataclass(frozen=True)
class GroupStatistics:
    """One rate group: its period, its releases and the work time of each
    (004's max and average per loop), the overruns charged to it (its tasks
    ran longest in a tick that passed a deadline) and its releases missed
    (the loop was still busy at its next release)."""

    name: str
    period_ns: int
    releases: int
    mean_ns: float
    max_ns: int
    p99_ns: int
    overruns: int
    missed: int
    distribution: Distribution = field(repr=False)
    #: The keys in :attr:`LoopStatistics.tasks` of the group's tasks.
    tasks: tuple[str, ...] = ()


@dataclass(frozen=True)
class LoopStatistics:
    """A frozen snapshot of the tick loop's timing."""

    period_ns: int
    ticks: int
    overruns: int
    missed: int
    consecutive_overruns: int
    lateness: Distribution
    work: Distribution
    tasks: dict[str, TaskStatistics]
    #: Start-up ticks that overran (not in ``overruns``; see ``Loop``), and
    #: the worst of them in ns past the next deadline.
    startup_overruns: int = 0
    startup_worst_ns: int = 0
    #: Per rate group, in the order they run (a queue attached to the loop
    #: directly is a group of the tick's rate, named as attached).
    groups: dict[str, GroupStatistics] = field(default_factory=dict)
