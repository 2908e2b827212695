"""How a loop is composed: what is attached, its plans, its switches, its state.

:class:`LoopComposition` is the part of :class:`~pyrt.scheduler.loop.Loop`
that attaches handlers, ready queues and rate groups, lays out the groups'
schedule (:mod:`pyrt.scheduler._schedule`) and makes each tick's plan,
switches plain handlers on and off (:meth:`LoopComposition.enable`), and
gives and takes the loop's state for a snapshot.  The tick itself is the
loop's.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any, cast

from pyrt.errors import PyrtError
from pyrt.scheduler import _accounting
from pyrt.scheduler._handlertiming import HandlerTimes, HandlerTiming
from pyrt.scheduler._schedule import Schedule
from pyrt.scheduler.rategroup import GroupTiming, RateGroup, rate_monotonic
from pyrt.scheduler.readyqueue import ReadyQueue

if TYPE_CHECKING:
    from pyrt.errors import Fault
    from pyrt.scheduler.clock import Clock
    from pyrt.scheduler.loop import Loop

__all__ = ["LoopComposition"]

Handler = Callable[[int], None]


class LoopComposition:
    """The composition of a loop (see the module text); a part of ``Loop``."""

    if TYPE_CHECKING:  # the Loop's, used here
        clock: Clock
        period_ns: int
        timing: bool
        running: bool
        tick_index: int
        queues: list[ReadyQueue]
        rate_groups: list[RateGroup]
        _fault_ids: int
        _groups: list[GroupTiming]
        _group_of: dict[int, GroupTiming]
        _bare_queues: list[ReadyQueue]

        def report_fault(self, fault: Fault) -> None: ...
        def make_fault(self, robot: str, cause: str, source: str = "",
                       tb: str = "") -> Fault: ...

    def _init_composition(self) -> None:
        self._handlers: list[Handler] = []
        self._handler_names: list[str] = []
        # Timed ticks run this plan: (handler, record its duration).
        self._plan: list[tuple[Handler, Callable[[int], None]]] = []
        # What ran, in order: a ready queue, a rate group or a handler's timing.
        self._order: list[Any] = []
        # Everything attached, in attach order: (a group's period or None, its parts).
        self._attached: list[tuple[int | None, Any]] = []
        self._entry_group: dict[str, GroupTiming] = {}
        self._times = HandlerTimes()
        # The loop reads its clock between entries (set when the plans are made).
        self._timing_handlers = False
        # What each tick of the groups' cycle runs, and the phase of the next tick.
        self._schedule = Schedule()
        self._phase = 0
        # The schedule must be laid out again before the next run (groups or
        # handlers attached, a group's state restored).
        self._dirty = True
        # The items of the handlers switched off (enable).
        self._off: set[int] = set()
        self._plan_lock = threading.Lock()

    def _loop(self) -> Loop:
        return cast("Loop", self)  # this part of a Loop, as the accounting takes it

    @property
    def phase(self) -> int:
        """The phase of the next tick in the rate groups' cycle (inside a tick:
        of the tick after it); 0 when the loop has no groups."""
        return self._phase

    def attach(self, handler: ReadyQueue | RateGroup | Handler, name: str | None = None, *,
               enabled: bool = True) -> None:
        """Call ``handler(now_ns)`` every tick, after those attached before it.

        A :class:`RateGroup` is released at its own rate, groups in
        rate-monotonic order (:mod:`pyrt.scheduler.rategroup`); its period
        must be a whole number of ticks (:class:`ConfigError` otherwise).  A
        :class:`ReadyQueue` is attached by its clock handler, as a group of
        its own at the tick's rate; its faults are reported to this loop and
        its routines timed when timing is on.  Any other handler is timed as
        an entry of its own, called ``name`` (by default the function's name;
        a second handler of the same name gets ``#2``), switched on or off
        with ``enabled`` and :meth:`enable`.
        """
        if self.running:
            raise PyrtError("attach handlers before the loop runs")
        if isinstance(handler, RateGroup):
            _accounting.attach_group(self._loop(), handler)
        elif isinstance(handler, ReadyQueue):
            label = name or f"queue:{handler.name}"
            group = GroupTiming(_accounting.group_name(self._loop(), label), self.period_ns)
            self._take_queue(handler, group)
            self._add(self.period_ns, label, handler.tick, group.samples.append, handler)
        else:
            self._attach_timed(handler, name or str(getattr(handler, "__name__", "handler")),
                               enabled)

    def _take_queue(self, queue: ReadyQueue, group: GroupTiming) -> None:
        if queue.on_error is None:  # a queue no station owns: its faults are the loop's
            self._bare_queues.append(queue)
            queue.on_error = lambda cause, source, tb, q=queue: self.report_fault(
                self.make_fault(q.name, cause, source, tb))
        queue.timer = self.clock.timer
        queue.enable_timing(self.timing, track_ticks=not self.clock.virtual)
        self.queues.append(queue)
        self._group_of[id(queue)] = group
        if group not in self._groups:
            self._groups.append(group)

    def _join_group_member(self, group: RateGroup, name: str, member: Any) -> None:
        _accounting.join_member(self._loop(), group, name, member)

    def _add(self, period: int | None, name: str, fn: Handler, record: Callable[[int], None],
             item: Any) -> None:
        """Attach ``fn`` (``period``: a group's, None: a plain handler) and
        arrange what runs: groups rate-monotonic, in the groups' places."""
        with self._plan_lock:
            self._attached.append((period, (fn, record, item, name)))
            run = rate_monotonic(self._attached)
            self._handlers[:] = [fn for fn, _, _, _ in run]
            self._plan[:] = [(fn, rec) for fn, rec, _, _ in run]
            self._order[:] = [item for _, _, item, _ in run]
            self._handler_names[:] = [n for _, _, _, n in run]
            if self.running and period is None and not self._dirty:
                # a job spawned while the loop runs: in place, in the plans it
                # runs (a plain handler runs last), so that it runs in this tick
                if id(item) not in self._off:
                    for entries in self._schedule.lists:
                        entries.append((fn, record if self._timing_handlers else None, name))
            else:
                self._changed()

    def _changed(self) -> None:
        """What runs changed: the schedule is laid out again before the next run."""
        self._dirty = True

    def _attach_timed(self, handler: Handler, name: str, enabled: bool = True) -> None:
        entry = self._times.add(name)
        if not enabled:
            self._off.add(id(entry))
        self._add(None, name, handler, entry.samples.append, entry)

    def reschedule(self) -> None:
        """Lay out the rate groups' cycle again (with the loop stopped), each
        group's next release kept, and make the ticks' plans.  The loop does
        it itself before a run when what runs has changed."""
        if self.running:
            raise PyrtError("reschedule the loop while it is stopped")
        with self._plan_lock:
            self._schedule.lay_out(self.rate_groups)
            self._phase = 0
            self._timing_handlers = self._timed_now()
            self._schedule.plan(self._attached, self._timing_handlers, self._off)
            self._dirty = False

    def _timed_now(self) -> bool:
        """Whether the ticks read the clock between entries: timing is on and
        there is more to time than the queues' routines (which time themselves)."""
        return self.timing and bool(self._times.entries or self.rate_groups)

    def enable(self, handler: str | Handler, on: bool = True) -> None:
        """Switch a plain handler on or off, from any thread: ``handler`` the
        function attached or its entry's name in the statistics.  While off it
        is left out of the ticks (not called, not timed); a loop running takes
        the change at its next tick.  KeyError for what is not a plain handler."""
        key = id(self._entry_of(handler))
        with self._plan_lock:
            if (key not in self._off) == bool(on):
                return
            if on:
                self._off.discard(key)
            else:
                self._off.add(key)
            if not self._dirty:
                self._schedule.plan(self._attached, self._timing_handlers, self._off)

    def enabled(self, handler: str | Handler) -> bool:
        """Whether a plain handler runs (:meth:`enable`)."""
        return id(self._entry_of(handler)) not in self._off

    def _entry_of(self, handler: str | Handler) -> Any:
        for _, (fn, _, item, _) in self._attached:
            if isinstance(item, HandlerTiming) and (
                    item.name == handler if isinstance(handler, str) else fn == handler):
                return item
        raise KeyError(f"no handler {handler!r} to switch on or off")

    # -- snapshots -----------------------------------------------------------

    def snapshot_state(self) -> dict[str, Any]:
        """What :meth:`restore_state` puts back into a loop built the same way,
        as plain values: the tick (inside a tick, the next: a snapshot at the
        end of a tick is the state before the next), the last fault's id, and
        each rate group's and ready queue's state
        (:meth:`RateGroup.snapshot_state`, :meth:`ReadyQueue.snapshot_state`)."""
        return {
            "tick": self.tick_index + 1 if self.running else self.tick_index,
            "fault_ids": self._fault_ids,
            "groups": [g.snapshot_state() for g in self.rate_groups],
            "queues": [q.snapshot_state() for q in self.queues],
        }

    def restore_state(self, state: Mapping[str, Any]) -> None:
        """Put back what :meth:`snapshot_state` gave (the loop stopped): a
        state whose rate groups or ready queues are not this loop's, by name
        and number, is refused (ValueError) before anything changes."""
        if self.running:
            raise PyrtError("restore the loop's state while it is stopped")
        groups, queues = state["groups"], state["queues"]
        if [g[0] for g in groups] != [g.name for g in self.rate_groups] \
                or [q[0] for q in queues] != [q.name for q in self.queues]:
            raise ValueError("the state's rate groups and ready queues are not the loop's "
                             f"({', '.join(str(q[0]) for q in queues)} against "
                             f"{', '.join(q.name for q in self.queues)})")
        for g, (_, left, _) in zip(self.rate_groups, groups, strict=True):
            if not 1 <= int(left) <= g.ticks:
                raise ValueError(f"the state's rate group {g.name} is {left} ticks from its "
                                 f"next release, outside 1..{g.ticks}")
        for q, (_, mem, *_) in zip(self.queues, queues, strict=True):
            if len(bytes.fromhex(mem)) != len(q.image.mem):
                raise ValueError(f"the state's image of ready queue {q.name} is not its size")
        self.tick_index = int(state["tick"])
        self._fault_ids = int(state["fault_ids"])
        for g, gs in zip(self.rate_groups, groups, strict=True):
            g.restore_state(gs)
        for q, qs in zip(self.queues, queues, strict=True):
            q.restore_state(qs)

