"""The loop's schedule: what each tick of its cycle runs, worked out before it runs.

A loop's rate groups release at whole numbers of ticks, so which of them a
tick releases repeats with the least common multiple of their periods (the
**cycle**: 10 ticks for a 1 kHz and a 100 Hz group on a 1 ms tick).  The
schedule holds, for each phase of the cycle, the tick's **plan**: the loop's
entries in the order they run, ``(fn, record, name)`` each, with the members
of the groups released in that tick in their group's place, and the groups it
releases.  A tick then takes its plan by its phase and runs it: no group
counts down, no member is called through its group, and ticks that release
the same groups share one plan (the cycle is a plan index per phase, so that
switching a handler on or off remakes a few plans, never the whole cycle).

A group whose period would stretch the cycle beyond :data:`MAX_CYCLE` ticks
stays an entry of every plan and counts down itself
(:meth:`~pyrt.scheduler.rategroup.RateGroup.tick`), as every group did
before schedules.  Handlers switched off (:meth:`Loop.enable
<pyrt.scheduler.loop.Loop.enable>`: the scope while it does not acquire) are
left out of the plans until switched on.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from math import lcm
from typing import Any

from pyrt.scheduler.rategroup import GroupTiming, RateGroup, rate_monotonic

__all__ = ["MAX_CYCLE", "Plan", "Schedule"]

#: The longest cycle a schedule lays out, in ticks (a plan reference each).
MAX_CYCLE = 1 << 16

#: One entry of a plan: the handler, what takes its duration (None when the
#: loop does not time), and the name the loop's ``current`` says while it runs.
Entry = tuple[Callable[[int], None], Callable[[int], None] | None, str]
#: A tick's plan: its entries, and the groups it releases (each with its timing).
Plan = tuple[list[Entry], tuple[tuple[RateGroup, GroupTiming], ...]]


class Schedule:
    """The plans of one loop's cycle (see the module text)."""

    def __init__(self) -> None:
        #: The distinct plans: phases that release the same groups share one.
        self.plans: list[Plan] = [([], ())]
        #: Each phase's plan, as its index in :attr:`plans`.
        self.keys: list[int] = [0]
        #: The groups the schedule releases (the others count down themselves).
        self.flat: list[RateGroup] = []
        # the groups each plan releases (indices into flat), in the plans' order
        self._released: list[tuple[int, ...]] = [()]

    @property
    def length(self) -> int:
        """Ticks in the cycle."""
        return len(self.keys)

    @property
    def lists(self) -> list[list[Entry]]:
        """The plans' entry lists (a handler attached while the loop runs is
        appended to each, in place: it runs in that tick already)."""
        return [p[0] for p in self.plans]

    def lay_out(self, groups: Sequence[RateGroup]) -> None:
        """Choose the groups the schedule releases and the cycle's length: the
        fastest first, each as long as the cycle stays within :data:`MAX_CYCLE`;
        the groups are told (their next releases kept: the phase is 0 now), and
        each phase's released groups are found (call :meth:`plan` next)."""
        for g in groups:
            g.scheduled(None)
        length, flat = 1, []
        for g in sorted(groups, key=lambda g: g.ticks):
            n = lcm(length, g.ticks)
            if n <= MAX_CYCLE:
                length = n
                flat.append(g)
        for g in flat:
            g.scheduled(0)
        self.flat = flat
        index: dict[tuple[int, ...], int] = {}
        keys = []
        for phase in range(length):
            released = tuple(i for i, g in enumerate(flat) if g.releases_at(phase))
            keys.append(index.setdefault(released, len(index)))
        self.keys = keys
        self._released = list(index)

    def plan(self, attached: list[tuple[int | None, Any]], timed: bool,
             off: set[int]) -> None:
        """Make the plans from the loop's ``attached`` entries ``(period or None,
        (fn, record, item, name))``; ``timed``: the loop reads its clock between
        entries (else no record is kept); ``off``: the ids of the items of the
        handlers switched off.  One assignment: a loop running takes the old
        plans or these."""
        run = rate_monotonic(attached)
        flat = {id(g) for g in self.flat}
        self.plans = [_plan(run, flat, {id(self.flat[i]) for i in released}, timed, off)
                      for released in self._released]


def _plan(run: list[tuple[Callable[[int], None], Callable[[int], None], Any, str]],
          flat: set[int], released: set[int], timed: bool, off: set[int]) -> Plan:
    entries: list[Entry] = []
    groups: list[tuple[RateGroup, GroupTiming]] = []
    for fn, record, item, name in run:
        if isinstance(item, RateGroup) and id(item) in flat:
            if id(item) in released:
                entries.extend(item.release_entries(timed))
                groups.append((item, item.timing))
        elif id(item) not in off:
            entries.append((fn, record if timed else None, name))
    return entries, tuple(groups)
