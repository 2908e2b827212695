"""The task record: what a component declares to run on a ready queue.

A component (:meth:`pyrt.component.Component.tasks`) declares each of its
self-scheduling routines once, as a :class:`Task`: the name the ready queue
shows, the routine address (the gripper's EPROM addresses of 002, Appendix
B; the manipulator's own), the period in queue checks (a constant, a
:class:`~pyrt.scheduler.readyqueue.ByteRef` to a RAM byte, or a callable),
the queue checks to its first run, and the body.  :func:`install` puts a
list of them on a :class:`~pyrt.scheduler.readyqueue.ReadyQueue`; a station
gathers them from its component tree (:func:`pyrt.tasks.register_tasks`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass

from pyrt.scheduler.readyqueue import ByteRef, ReadyQueue, Routine

__all__ = ["Task", "install"]


@dataclass(frozen=True)
class Task:
    """One self-scheduling routine a component declares (see the module text).

    ``fn`` is the body; with ``timed`` it is called with the queue's tick
    time in ns (the time of the check that ran it), else with nothing.
    ``period`` is read at every reschedule.  ``first`` is the number of queue
    checks to the first run (1..255; 0 means 256); None means the component
    schedules it itself (the gripper's power-up does, from RAM, as 002's
    main program).
    """

    name: str
    address: int
    fn: Callable[..., None]
    period: int | ByteRef | Callable[[], int]
    first: int | None = None
    timed: bool = False

    def period_now(self) -> int:
        """The period in queue checks as it reads now."""
        p = self.period
        return int(p()) if callable(p) else int(p)


def install(queue: ReadyQueue, tasks: Iterable[Task]) -> list[Routine]:
    """Register every task on ``queue`` (in order), then schedule those that
    have a first run (in the same order).  Returns the routines."""
    tasks = list(tasks)
    for t in tasks:
        if t.first is not None and not 0 <= t.first <= 255:
            raise ValueError(f"first run of {t.name} must be 00..FF queue checks, got {t.first}")
    routines = []
    for t in tasks:
        fn = _timed(t.fn, queue) if t.timed else t.fn
        routines.append(queue.add_periodic(t.address, t.name, fn, t.period))
    for t in tasks:
        if t.first is not None:
            queue.schedule(t.address, t.first)
    return routines


def _timed(body: Callable[[int], None], queue: ReadyQueue) -> Callable[[], None]:
    def run() -> None:
        body(queue.now_ns)

    return run
