"""The self-scheduling routines (one module each) and the tasks built over the robots.

* gripper (002): :mod:`~pyrt.tasks.sensors` (SENSORS, 0473),
  :mod:`~pyrt.tasks.jawmove` (MVJAWS, 04C2), :mod:`~pyrt.tasks.jawwatch`
  (WATCHJAW, 0541), each working on the controller passed to it;
* manipulator (000): :mod:`~pyrt.tasks.polyaxis_poll` (POLYAXIS) and
  :mod:`~pyrt.tasks.axis_poll` (AXES);
* :mod:`~pyrt.tasks.writeback`: database write-back and the writers that
  keep file I/O off the loop thread.

Components declare the routines they run (:meth:`pyrt.component.Component.tasks`);
:func:`register_tasks` puts every task of a component tree on a ready queue.
This package never imports :mod:`pyrt.robots`: the robots import it.
"""

from pyrt.component import Component, walk
from pyrt.scheduler import ReadyQueue, Routine, Task, install
from pyrt.tasks.writeback import (
    MOVING_PERIOD_NS,
    STATIONARY_PERIOD_NS,
    ZEROLENGTH_PERIOD_NS,
    Sink,
    SyncWriter,
    ThreadWriter,
    Watch,
    WriteBack,
    Writer,
)

__all__ = [
    "MOVING_PERIOD_NS",
    "STATIONARY_PERIOD_NS",
    "ZEROLENGTH_PERIOD_NS",
    "Sink",
    "SyncWriter",
    "ThreadWriter",
    "Watch",
    "WriteBack",
    "Writer",
    "register_tasks",
    "tasks_of",
]


def tasks_of(root: Component) -> list[Task]:
    """Every task declared by ``root`` and the components below it, in tree order."""
    return [t for c in walk(root) for t in c.tasks()]


def register_tasks(queue: ReadyQueue, root: Component) -> list[Routine]:
    """Register every task of the tree under ``root`` on ``queue`` and schedule
    the ones with a first run (:func:`pyrt.scheduler.install`)."""
    return install(queue, tasks_of(root))
