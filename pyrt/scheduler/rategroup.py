"""Rate groups: tasks released together at one rate, each group with its own
deadline, overrun detection and timing (004: "all real-time periodic loops
shall detect overrun conditions ... and measure the max. and avg. time use
for each loop").

A :class:`RateGroup` has a name and a period in time units (``period_ns``
or ``hz``), never in ticks: a 100 Hz group stays at 100 Hz whatever tick the
loop runs at.  Its members are ready queues (their tasks run at the group's
rate: a task of period 1 runs at every release) and plain handlers, run in
the order attached.  Attached to a loop, the group is released every
``period_ns / tick`` ticks; a period that is not a whole number of ticks is
refused with the reason.

The loop is cooperative (002's ready queue): a release runs to completion.
Each group's **deadline is its own next release**: when a tick's work ends
after the next release of a group, that release is missed (skipped, never
run late back to back) and counted against the group (``missed``); the
overrun is **charged** to the task that ran longest in that tick and to the
group it belongs to (``overruns``).  So a 100 Hz task whose 3 ms of work
makes the 1 kHz servo miss its releases is charged to the 100 Hz group, and
the servo group shows the releases it missed.

Groups released in the same tick run in **rate-monotonic** order, fastest
first (equal periods in the order attached), in the places of the loop's
handler order where groups were attached; handlers that are not groups keep
their places.  A ready queue attached to the loop directly is a group of its
own at the tick rate (named as attached), so every station built before
rate groups runs and replays as it did.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from typing import TYPE_CHECKING, Any

from pyrt.errors import ConfigError, PyrtError
from pyrt.scheduler.stats import Accumulator

if TYPE_CHECKING:
    from pyrt.scheduler.readyqueue import ReadyQueue
    from pyrt.scheduler.task import Task

__all__ = ["GroupTiming", "RateGroup", "rate_monotonic"]

Handler = Callable[[int], None]


def _ms(ns: int) -> str:
    return f"{ns / 1e6:g} ms"


class GroupTiming:
    """What a group's releases cost and how its deadlines went."""

    __slots__ = ("acc", "missed", "name", "period_ns", "releases", "samples")

    def __init__(self, name: str, period_ns: int):
        self.name = name
        self.period_ns = period_ns
        #: Work time (ns) of each release not yet folded into ``acc``.
        self.samples: list[int] = []
        #: Time per release; ``acc.overruns``: overruns charged to the group.
        self.acc = Accumulator(name)
        #: Releases of this group that the loop was too busy to run (skipped).
        self.missed = 0
        #: Releases run (a group of the loop's tick: its ticks).
        self.releases = 0

    def reset(self) -> None:
        """Forget every sample and count."""
        self.samples.clear()
        self.acc.reset()
        self.missed = self.releases = 0


class RateGroup:
    """Tasks and handlers released together every ``period_ns`` (or at ``hz``).

    ``attach`` ready queues (or plain handlers) to it, then attach it to a
    :class:`~pyrt.scheduler.loop.Loop`; :meth:`new_queue` makes a queue for
    a robot's tasks in one step.  See the module text for deadlines, overrun
    charging and the rate-monotonic order.
    """

    def __init__(self, name: str, period_ns: int | None = None, *, hz: float | None = None):
        if not isinstance(name, str) or not name.strip():
            raise ValueError(f"a rate group needs a name, got {name!r}")
        if (period_ns is None) == (hz is None):
            raise ValueError(f"rate group {name}: give its period_ns or its hz (one of them)")
        if hz is not None:
            if isinstance(hz, bool) or not hz > 0 or hz == float("inf"):
                raise ValueError(f"rate group {name}: hz must be a number > 0, got {hz!r}")
            period_ns = round(1e9 / hz)
        assert period_ns is not None
        if isinstance(period_ns, bool) or int(period_ns) != period_ns or period_ns <= 0:
            raise ValueError(f"rate group {name}: period must be a whole number of ns > 0, "
                             f"got {period_ns!r}")
        self.name = name
        self.period_ns = int(period_ns)
        #: The members, in the order attached: ``(name, queue or handler)``.
        self.members: list[tuple[str, Any]] = []
        self.queues: list[ReadyQueue] = []
        self.timing = GroupTiming(name, self.period_ns)
        #: The period in ticks of the loop it is attached to (set by the loop).
        self.ticks = 1
        # Ticks to the next release while no loop's schedule releases the group;
        # with one (_offset set), the loop's phase says it (:attr:`left`).
        self._left = 1
        self._offset: int | None = None
        #: Loop time of the last release (-1: none yet).
        self.released_at = -1
        #: What runs at a release, as the loop knows it (queues, handler entries).
        self.order: list[Any] = []
        self._handlers: list[Handler] = []
        self._names: list[str] = []
        self._plan: list[tuple[Handler, Callable[[int], None]]] = []
        # whether each member's duration is its own entry's (a handler) or only
        # part of the release (a queue: its routines are timed by the queue)
        self._own: list[bool] = []
        self._timer: Callable[[], int] | None = None
        self._loop: Any = None

    def __repr__(self) -> str:
        return f"RateGroup({self.name!r}, period_ns={self.period_ns})"

    # -- composition ---------------------------------------------------------

    def attach(self, member: ReadyQueue | Handler, name: str | None = None) -> None:
        """Run ``member`` at each release, after those attached before it: a
        ready queue (checked at each release: its tasks' periods count
        releases) or a handler ``fn(now_ns)`` (timed as an entry ``name``)."""
        from pyrt.scheduler.readyqueue import ReadyQueue

        if isinstance(member, RateGroup):
            raise PyrtError(f"rate group {self.name}: a group cannot hold a group "
                            f"({member.name}); attach both to the loop")
        if self._loop is not None and self._loop.running:
            raise PyrtError("attach to a rate group before its loop runs")
        if isinstance(member, ReadyQueue):
            label = name or f"queue:{member.name}"
            self.queues.append(member)
        else:
            label = name or str(getattr(member, "__name__", "handler"))
        self.members.append((label, member))
        if self._loop is not None:
            self._loop._join_group_member(self, label, member)

    def new_queue(self, robot: str, tasks: Iterable[Task] = ()) -> ReadyQueue:
        """A general ready queue of ``robot`` (faults name it) holding
        ``tasks``, attached to this group; returns it (its owner halts it)."""
        from pyrt.scheduler.readyqueue import ReadyQueue
        from pyrt.scheduler.task import install

        queue = ReadyQueue.general(name=robot)
        install(queue, tasks)
        self.attach(queue, name=f"{self.name}:{robot}")
        return queue

    def bind(self, tick_ns: int) -> None:
        """Take the loop's tick: the period must be a whole number of ticks."""
        ticks, rest = divmod(self.period_ns, tick_ns)
        if ticks < 1:
            raise ConfigError(f"rate group {self.name}: its period {_ms(self.period_ns)} is "
                              f"shorter than the loop's tick ({_ms(tick_ns)}); make the "
                              "tick shorter (--tick-us)")
        if rest:
            raise ConfigError(
                f"rate group {self.name}: its period {_ms(self.period_ns)} is not a whole "
                f"number of ticks of {_ms(tick_ns)} ({self.period_ns / tick_ns:.3g} ticks): "
                f"pyrt does not round a group's rate; choose a tick that divides "
                f"{_ms(self.period_ns)} (--tick-us)")
        self.ticks = self._left = ticks

    # -- where the group is in its period -------------------------------------

    @property
    def left(self) -> int:
        """Ticks until the group's next release (1: the next tick releases it).
        Inside a tick the tick is counted already, as it is between ticks."""
        if self._offset is None:
            return self._left
        return (self._offset - self._loop.phase) % self.ticks + 1

    def snapshot_state(self) -> list[Any]:
        """What :meth:`restore_state` puts back: ``[name, left, released_at]``
        (plain values, for a snapshot's JSON)."""
        return [self.name, self.left, self.released_at]

    def restore_state(self, state: Sequence[Any]) -> None:
        """Put back what :meth:`snapshot_state` gave (with the loop stopped):
        the ticks to the next release and the time of the last one; a name
        that is not this group's or a count outside 1..:attr:`ticks` is
        refused (ValueError) and nothing changes."""
        name, left, released = state
        if name != self.name:
            raise ValueError(f"rate group {self.name}: the state given is of {name!r}")
        left, released = int(left), int(released)
        if not 1 <= left <= self.ticks:
            raise ValueError(f"rate group {self.name}: {left} ticks to the next release "
                             f"is outside 1..{self.ticks}")
        loop = self._loop
        if loop is not None and loop.running:
            raise PyrtError(f"rate group {self.name}: restore its state with its loop stopped")
        self._left, self.released_at = left, released
        if self._offset is not None:
            self._offset = None
            loop.reschedule()

    def scheduled(self, phase: int | None) -> None:
        """The loop's schedule releases the group from now on, the ticks to its
        next release kept, at the loop's ``phase`` now; None: no longer (the
        group counts down itself, :meth:`tick`).  The loop's part."""
        left = self.left
        if phase is None:
            self._offset = None
            self._left = left
        else:
            self._offset = (phase + left - 1) % self.ticks

    def releases_at(self, phase: int) -> bool:
        """True if the loop's schedule releases the group in the tick of ``phase``."""
        return self._offset is not None and phase % self.ticks == self._offset

    def set_timer(self, timer: Callable[[], int] | None) -> None:
        """Time each release with ``timer`` (None: timing off, no cost)."""
        self._timer = timer

    def add_run(self, fn: Handler, record: Callable[[int], None], name: str = "", *,
                own: bool = True) -> None:
        """Run ``fn`` at each release; ``record`` takes its duration (the loop's
        part; ``own``: it is the member's own entry, else only part of the
        release, as a queue's stretch is); ``name`` is what the loop's
        :attr:`~pyrt.scheduler.loop.Loop.current` says while it runs (by
        default the group's name)."""
        self._handlers.append(fn)
        self._names.append(name or self.name)
        self._plan.append((fn, record))
        self._own.append(own)

    def release_entries(self, timed: bool) -> list[tuple[Handler, Callable[[int], None] | None,
                                                          str]]:
        """What a loop's schedule runs at a release, ``(fn, record, name)`` each
        member: with ``timed``, each ``record`` takes the member's duration for
        its own entry and the release's time (their sum) is recorded with the
        last; without, no record (None)."""
        names = self._names
        if not timed:
            return [(fn, None, name) for fn, name in zip(self._handlers, names, strict=True)]
        total = self.timing.samples.append
        if len(self._plan) == 1 and not self._own[0]:  # one queue: its stretch is the release
            return [(self._plan[0][0], total, names[0])]
        last = len(self._plan) - 1
        acc = [0]
        return [(fn, _summing(record if own else None, acc, total if i == last else None), name)
                for i, ((fn, record), own, name)
                in enumerate(zip(self._plan, self._own, names, strict=True))]

    # -- the release ---------------------------------------------------------

    def tick(self, now_ns: int) -> None:
        """The loop's tick: every :attr:`ticks`-th call, release the group."""
        left = self._left - 1
        if left:
            self._left = left
            return
        self._left = self.ticks
        self.released_at = now_ns
        timing = self.timing
        timing.releases += 1
        timer = self._timer
        loop = self._loop
        if loop is None:  # released by hand, not by a loop: nobody asks who runs
            for h in self._handlers:
                h(now_ns)
            return
        names = self._names
        if timer is None:
            for h, name in zip(self._handlers, names):  # noqa: B905 - the same length
                loop.current = name
                h(now_ns)
            return
        t0 = start = timer()
        for (h, record), name in zip(self._plan, names):  # noqa: B905 - the same length
            loop.current = name
            h(now_ns)
            t1 = timer()
            record(t1 - t0)
            t0 = t1
        timing.samples.append(t0 - start)

    def skip(self, ticks: int) -> int:
        """``ticks`` deadlines of the loop were skipped (an overrun): the
        releases among them are missed; returns how many.  The next release
        keeps the group's grid (of a group the loop's schedule releases, the
        loop moves its phase on by ``ticks`` after asking every group)."""
        left = self.left - ticks
        k = self.ticks
        missed = 0 if left > 0 else -left // k + 1
        if self._offset is None:
            self._left = left if left > 0 else left % k or k
        return missed


def _summing(record: Callable[[int], None] | None, acc: list[int],
             total: Callable[[int], None] | None) -> Callable[[int], None]:
    """A member's record in a release of several members (or of one handler):
    its own ``record`` (if any) and the release's running sum in ``acc``;
    the last member's (``total`` given) records the sum and starts it again."""
    if total is None:
        if record is None:
            def add(d: int) -> None:
                acc[0] += d
            return add

        def add_own(d: int) -> None:
            record(d)
            acc[0] += d
        return add_own

    def close(d: int) -> None:
        if record is not None:
            record(d)
        total(acc[0] + d)
        acc[0] = 0
    return close


def rate_monotonic(entries: list[tuple[int | None, Any]]) -> list[Any]:
    """Entries ``(period_ns or None, item)`` in attach order, arranged to run:
    the groups (a period) fill the places where groups were attached, fastest
    first (equal periods in attach order); the others (None) keep theirs."""
    slots = [i for i, (p, _) in enumerate(entries) if p is not None]
    groups = sorted((entries[i] for i in slots), key=lambda e: e[0] or 0)
    out = [item for _, item in entries]
    for i, (_, item) in zip(slots, groups, strict=True):
        out[i] = item
    return out
