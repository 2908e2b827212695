"""The loop's schedule: what each tick of its cycle runs, worked out before it runs.

A loop's rate groups release at whole numbers of ticks, so which of them a
tick releases repeats with the least common multiple of their periods (the
**cycle**: 10 ticks for a 1 kHz and a 100 Hz group on a 1 ms tick).  The
schedule holds, for each phase of the cycle, the tick's **plan**: the loop's
entries in the order they run, ``(fn, record, name)`` each, with the members
of the groups released in that tick in their group's place, and the groups it
releases.  A tick then takes its plan by its phase and runs it: no group
counts down, no member is called through its group, and ticks that release
the same groups share one plan.

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
        #: The plan of each phase (phases that release the same groups share one).
        self.cycle: list[Plan] = [([], ())]
        #: The distinct plans' entry lists (a handler attached while the loop
        #: runs is appended to each, in place: it runs in that tick already).
        self.lists: list[list[Entry]] = [self.cycle[0][0]]
        #: The groups the schedule releases (the others count down themselves).
        self.flat: list[RateGroup] = []

    @property
    def length(self) -> int:
        """Ticks in the cycle."""
        return len(self.cycle)

    def lay_out(self, groups: Sequence[RateGroup]) -> None:
        """Choose the groups the schedule releases and the cycle's length: the
        fastest first, each as long as the cycle stays within :data:`MAX_CYCLE`.
        The groups are told (their next releases kept); the phase is 0 now."""
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
        self.cycle = [([], ())] * length

    def plan(self, attached: list[tuple[int | None, Any]], timed: bool,
             off: set[int]) -> None:
        """Make every phase's plan from the loop's ``attached`` entries ``(period
        or None, (fn, record, item, name))``; ``timed``: the loop reads its clock
        between entries (else no record is kept); ``off``: the ids of the items
        of handlers switched off."""
        run = rate_monotonic(attached)
        flat = {id(g) for g in self.flat}
        shared: dict[tuple[int, ...], Plan] = {}
        cycle: list[Plan] = []
        for phase in range(len(self.cycle)):
            key = tuple(i for i, g in enumerate(self.flat) if g.releases_at(phase))
            p = shared.get(key)
            if p is None:
                p = shared[key] = _plan(run, flat, phase, timed, off)
            cycle.append(p)
        self.lists = [p[0] for p in shared.values()]
        self.cycle = cycle  # one assignment: a loop running sees the old cycle or this one


def _plan(run: list[tuple[Callable[[int], None], Callable[[int], None], Any, str]],
          flat: set[int], phase: int, timed: bool, off: set[int]) -> Plan:
    entries: list[Entry] = []
    released: list[tuple[RateGroup, GroupTiming]] = []
    for fn, record, item, name in run:
        if isinstance(item, RateGroup) and id(item) in flat:
            if item.releases_at(phase):
                entries.extend(item.release_entries(timed))
                released.append((item, item.timing))
        elif id(item) not in off:
            entries.append((fn, record if timed else None, name))
    return entries, tuple(released)
