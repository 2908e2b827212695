"""The task record: what a component declares to run on a ready queue.

A component (:meth:`pyrt.component.Component.tasks`) declares each of its
self-scheduling routines once, as a :class:`Task`, and :func:`install` puts
a list of them on a :class:`~pyrt.scheduler.readyqueue.ReadyQueue`; a
station gathers them from its component tree
(:func:`pyrt.tasks.register_tasks`).

General form, for any station::

    Task(servo, period=1)                 # every tick, named "servo"
    Task(plan, period=10, name="traj")    # every 10th tick
    Task(flush, period=1000)              # once a second at 1 kHz

The period is a whole number of queue checks, 1 or more; on a queue checked
every tick (:meth:`ReadyQueue.general`, divisor 1) that is a number of ticks.
Periods above 255 need the general queue's 32-bit schedule variables.  The
queue assigns the routine address and the name is the function's.

002's form, for the gripper (and the manipulator's two routines, which keep
addresses of their own): ``Task(name, address, fn, period, first, timed)``,
positional, with the routine's EPROM address of 002, Appendix B, and a
period that is a :class:`~pyrt.scheduler.readyqueue.ByteRef` to the RAM byte
002 reads it from (00 there means 256, as in 002); ``first`` defaults to
None (the gripper's power-up schedules its routines, as 002's main program).
"""

from __future__ import annotations

import inspect
import operator
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from functools import partial
from typing import Any, Literal, cast, overload

from pyrt.scheduler.readyqueue import ByteRef, ReadyQueue, Routine

__all__ = ["Period", "Task", "install"]

#: A task's period: a constant, a RAM byte (002), or a callable read at every reschedule.
Period = int | ByteRef | Callable[[], int]

#: ``first`` of a task whose first run is one period after :func:`install`.
FIRST_AFTER_PERIOD: Literal["period"] = "period"


def _general(fn: Callable[..., None], period: Period, *, name: str | None = None,
             address: int | None = None,
             first: int | Literal["period"] | None = FIRST_AFTER_PERIOD,
             timed: bool = False) -> None:
    """Binds the arguments of the general form (never called)."""


def _form_002(name: str, address: int, fn: Callable[..., None], period: Period,
              first: int | None = None, timed: bool = False) -> None:
    """Binds the arguments of 002's positional form (never called)."""


_FORMS = (inspect.signature(_general), inspect.signature(_form_002))


@dataclass(frozen=True, init=False)
class Task:
    """One self-scheduling routine a component declares (see the module text).

    ``fn`` is the body; with ``timed`` it is called with the queue's tick
    time in ns (the time of the check that ran it), else with nothing.
    ``period`` is the number of queue checks from one run to the next
    (an integer of 1 or more, a :class:`ByteRef`, or a callable), read at
    every reschedule.  ``name`` is what ``stats`` and faults show (the
    function's name by default).  ``address`` is the routine address on the
    queue (0001..FFFF; None: the queue assigns one).  ``first`` is the number
    of queue checks to the first run: ``"period"`` (the general form's
    default) waits one period, read at :func:`install`; None (002's form's
    default) leaves the first run to the component.

    A period or ``first`` that is not a whole number, or a period below 1, is
    refused here with the task's name; one that the queue cannot hold (above
    255 on 002's byte queue) is refused by :func:`install`.
    """

    fn: Callable[..., None]
    period: Period
    name: str
    address: int | None
    first: int | Literal["period"] | None
    timed: bool

    @overload
    def __init__(self, fn: Callable[..., None], period: Period, *, name: str | None = None,
                 address: int | None = None,
                 first: int | Literal["period"] | None = FIRST_AFTER_PERIOD,
                 timed: bool = False) -> None: ...

    @overload
    def __init__(self, name: str, address: int, fn: Callable[..., None], period: Period,
                 /, first: int | None = None, timed: bool = False) -> None: ...

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        form = _FORMS[1] if args and isinstance(args[0], str) else _FORMS[0]
        try:
            bound = form.bind(*args, **kwargs)
        except TypeError as exc:
            raise TypeError(f"Task: {exc}") from None
        bound.apply_defaults()
        a = bound.arguments
        fn = a["fn"]
        if not callable(fn):
            label = f" {a['name']}" if isinstance(a["name"], str) else ""
            raise TypeError(f"task{label}: the body must be callable, got {fn!r}")
        name = a["name"] if a["name"] is not None else _name_of(fn)
        if not isinstance(name, str) or not name.strip():
            raise ValueError(f"a task needs a non-empty name, got {name!r}")
        set_ = object.__setattr__
        set_(self, "fn", fn)
        set_(self, "name", name)
        set_(self, "period", _check_period(name, a["period"]))
        set_(self, "address", _check_address(name, a["address"]))
        set_(self, "first", _check_first(name, a["first"]))
        set_(self, "timed", bool(a["timed"]))

    def period_now(self) -> int:
        """The period in queue checks as it reads now."""
        p = self.period
        return int(p()) if callable(p) else int(p)

    def first_now(self) -> int | None:
        """Queue checks to the first run as they read now (None: the component's)."""
        return self.period_now() if self.first == FIRST_AFTER_PERIOD else self.first


def _name_of(fn: Callable[..., None]) -> str:
    while isinstance(fn, partial):
        fn = fn.func
    name = getattr(fn, "__name__", None)
    return name if isinstance(name, str) and name else type(fn).__name__


def _whole(name: str, what: str, value: Any) -> int:
    if isinstance(value, bool):
        raise TypeError(f"{what} of task {name} must be a whole number of queue checks, "
                        f"got {value!r}")
    try:
        return operator.index(value)
    except TypeError:
        raise TypeError(f"{what} of task {name} must be a whole number of queue checks, "
                        f"got {value!r}") from None


def _check_period(name: str, period: Any) -> Period:
    if isinstance(period, ByteRef) or callable(period):
        return cast(Period, period)
    p = _whole(name, "period", period)
    if p < 1:
        raise ValueError(f"period of task {name} must be 1 or more queue checks (ticks), "
                         f"got {p}")
    return p


def _check_address(name: str, address: Any) -> int | None:
    if address is None:
        return None
    a = _whole(name, "address", address)
    if not 1 <= a <= 0xFFFF:
        raise ValueError(f"routine address of task {name} must be 0001..FFFF, got {a:#x}")
    return a


def _check_first(name: str, first: Any) -> int | Literal["period"] | None:
    if first is None:
        return None
    if isinstance(first, str) and first == FIRST_AFTER_PERIOD:
        return FIRST_AFTER_PERIOD
    f = _whole(name, "first run", first)
    if f < 0:
        raise ValueError(f"first run of task {name} must be 0 or more queue checks, got {f}")
    return f


def _range_text(queue: ReadyQueue) -> str:
    lo, hi = queue.schedule_range
    return f"{lo}..{hi} queue checks" if queue.wide else "00..FF queue checks"


def install(queue: ReadyQueue, tasks: Iterable[Task]) -> list[Routine]:
    """Register every task on ``queue`` (in order), then schedule those that
    have a first run (in the same order).  Returns the routines.

    Everything is checked first (periods and first runs against the queue's
    schedule variables, names and addresses against each other and the
    routines already there, free slots for the first runs): a task the
    queue cannot take is refused with its name and nothing is registered."""
    tasks = list(tasks)
    lo, hi = queue.schedule_range
    names = {r.name.upper() for r in queue.routines}
    addresses = {r.address for r in queue.routines}
    firsts: list[int | None] = []
    for t in tasks:
        if not isinstance(t, Task):
            raise TypeError(f"install takes Task records, got {t!r}")
        if isinstance(t.period, int) and t.period > hi:
            raise ValueError(
                f"period of task {t.name} is {t.period} queue checks: the ready queue of "
                f"{queue.name} takes {_range_text(queue)} (002's byte schedule variables); "
                "a longer period needs ReadyQueue.general()")
        first = t.first_now()
        if first is not None and not lo <= first <= hi:
            raise ValueError(f"first run of {t.name} must be {_range_text(queue)}, got {first}")
        firsts.append(first)
        if t.name.upper() in names:
            raise ValueError(f"a routine named {t.name!r} is already on the ready queue of "
                             f"{queue.name}")
        names.add(t.name.upper())
        if t.address is not None:
            if t.address in addresses:
                raise ValueError(f"address {t.address:04X} of task {t.name} is already taken "
                                 f"on the ready queue of {queue.name}")
            addresses.add(t.address)
    if not queue.sized_to_routines:
        free = sum(slot is None for slot in queue.slots())
        need = sum(f is not None for f in firsts)
        if need > free:
            raise ValueError(f"ready queue of {queue.name} has {free} free slot(s); "
                             f"the first runs of these tasks need {need}")
    routines = []
    for t in tasks:
        fn = _timed(t.fn, queue) if t.timed else t.fn
        routines.append(queue.add_periodic(t.address, t.name, fn, t.period))
    for routine, first in zip(routines, firsts, strict=True):
        if first is not None:
            queue.schedule(routine.address, first)
    return routines


def _timed(body: Callable[[int], None], queue: ReadyQueue) -> Callable[[], None]:
    def run() -> None:
        body(queue.now_ns)

    run.__wrapped__ = body  # type: ignore[attr-defined]  # what runs (a journal names it)
    return run
