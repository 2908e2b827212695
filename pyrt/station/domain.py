"""A robot of a station: one **fault domain** (004: "any error on one robot
joint will affect the entire robot"; "each motion control board will provide
axis control for no more than 1 robot").

A :class:`Robot` is what one fault stops: its name, its components (a
subtree of the station's tree, and any parts beside it), its ready queues,
its motion queue and motion executors, its boards, and its own fault (the
first cause kept, with an id, published once).  Its **reflex** runs the
reflex of its own components only (leaves first), writes its own boards'
outputs at once, ends its motions and drops its queued ones.

A station declares its robots with :meth:`Station.add_robot
<pyrt.station.base.Station.add_robot>` before it adopts its tree; a station
that declares none is one robot (the station's name, every component, every
queue and board), exactly as a single-robot station always was.  What the
operator reads of one robot (its ``stop``, ``busy``, ``where``, ``status``
line and how its move ended) is given when it is declared; each has a
default.

Where the robot is, how its last move ended and its status line are the
robot's **text signals** (:meth:`Robot.signals`: ``where``, ``last_stop``,
``statusline``), served as signals of its root component: the console's
``status``, ``show``, the DAQ server and EPICS read these three, and
nothing else says them.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterable, Sequence
from typing import TYPE_CHECKING

from pyrt.component import Component, Signal, walk
from pyrt.errors import BoardError, Fault

if TYPE_CHECKING:
    from pyrt.boards import Boards
    from pyrt.scheduler import ReadyQueue
    from pyrt.scheduler.motion import MotionExecutor
    from pyrt.scheduler.runner import MotionQueue
    from pyrt.station.moves import MoveEnded

__all__ = ["ROBOT_SIGNALS", "Robot", "boards_clash"]

#: The names of every robot's text signals: where it is, how its last move
#: ended, its status line.
ROBOT_SIGNALS = ("where", "last_stop", "statusline")


def boards_clash(a: Boards, b: Boards) -> bool:
    """True when ``a`` and ``b`` are one board: the same object, or the same URL of
    boards that live outside this process (two ``sim:`` sets are two boards)."""
    if a is b:
        return True
    return not a.in_process and not b.in_process and a.url == b.url


class Robot:
    """One fault domain of a station (see the module text).  Made by
    :meth:`Station.add_robot <pyrt.station.base.Station.add_robot>`."""

    def __init__(self, name: str, root: Component, *, motion: MotionQueue,
                 queues: Iterable[ReadyQueue] = (),
                 executors: Iterable[MotionExecutor] = (),
                 boards: Iterable[Boards] = (),
                 parts: Iterable[Component] = (),
                 stop: Callable[[], str] | None = None,
                 busy: Callable[[], bool] | None = None,
                 where: Callable[[], str] | None = None,
                 status: Callable[[], str] | None = None,
                 ended: Callable[[], tuple[str, Sequence[str]]] | None = None) -> None:
        self.name = name
        self.root = root
        self.motion = motion
        self.queues: list[ReadyQueue] = list(queues)
        self.executors: list[MotionExecutor] = list(executors)
        self.boards: list[Boards] = list(boards)
        self.parts: list[Component] = list(parts)
        self._stop = stop
        self._busy = busy
        self._where = where
        self._status = status
        self._ended = ended
        #: The fault that stopped this robot (the first cause), or None.
        self.fault: Fault | None = None
        #: The first BoardError its reflex met, or None.
        self.board_error: BoardError | None = None
        #: Busy at the last look of the station's move watch (loop thread).
        self.moving = False
        #: The end of its last move (the station's move-ended event), or None.
        self.last_move: MoveEnded | None = None
        self._signals = [
            Signal.text("where", self.where, "where the robot is"),
            Signal.text("last_stop", self.last_stop, "how its last move ended"),
            Signal.text("statusline", self.status, "its status line"),
        ]
        self.components: list[Component] = []
        self.refresh()

    def refresh(self) -> None:
        """Its components, from its root and parts as they stand (each once, in tree order)."""
        seen: dict[int, Component] = {}
        for top in [self.root, *self.parts]:
            for c in walk(top):
                seen.setdefault(id(c), c)
        self.components = list(seen.values())

    def owns(self, component: Component) -> bool:
        """``component`` is one of this robot's."""
        return any(c is component for c in self.components)

    # -- what the operator reads (loop thread) ------------------------------------------

    def signals(self) -> list[Signal]:
        """Its text signals (:data:`ROBOT_SIGNALS`), read in the loop thread: served as
        signals of its root component."""
        return list(self._signals)

    def last_stop(self) -> str:
        """How its last move ended, in the operator's words ('' before any): its last
        move-ended event's reason."""
        last = self.last_move
        return last.reason if last is not None else ""

    def busy(self) -> bool:
        """A move of this robot runs or waits."""
        if self._busy is not None:
            return self._busy()
        return len(self.motion) > 0 or any(ex.busy for ex in self.executors)

    def where(self) -> str:
        """Where the robot is, in the operator's words ('' if it cannot say)."""
        return self._where() if self._where is not None else ""

    def ended(self) -> tuple[str, Sequence[str]]:
        """How its move that has just ended ended: (reason, report lines)."""
        if self._ended is not None:
            return self._ended()
        if self.fault is not None:
            return f"fault: {self.fault.cause}", ()
        return "ended", ()

    def status(self) -> str:
        """Its status line: as given, else its root's signals; its fault while it is
        not acknowledged."""
        if self._status is not None:
            line = self._status()
        else:
            line = "  ".join(f"{s.name}={s.format(s.read())}" for s in self.root.signals())
        return f"{line}  FAULT: {self.fault.cause}" if self.fault is not None else line

    # -- the reflex (loop thread) ---------------------------------------------------------

    def reflex(self, why: str = "stop") -> str:
        """Every actuator of this robot stopped now: its components' reflexes (leaves
        first), its boards' outputs written at once, its motions ended and its
        queued ones dropped.  Returns the reflex errors ('' if none); a failing
        reflex never keeps the others from running."""
        errors = []
        for c in reversed(self.components):
            try:
                c.reflex()
            except BoardError as exc:
                self.board_error = self.board_error or exc
                errors.append(f"{c.name}: {exc}")
            except Exception as exc:
                errors.append(f"{c.name}: {exc!r}")
        for boards in self.boards:
            try:  # the reflex's outputs go out now, not at the end of the tick
                boards.write_now()
            except BoardError as exc:
                self.board_error = self.board_error or exc
                errors.append(f"boards: {exc}")
        for ex in self.executors:
            with contextlib.suppress(Exception):
                ex.abort(why)
        self.motion.clear()
        return "; ".join(errors)

    def stop(self) -> str:
        """The operator's stop of this robot: as given, else its reflex (no fault)."""
        if self._stop is not None:
            return self._stop()
        failed = self.reflex("stop command")
        said = f"{self.name}: every motor stopped" + (f" ({failed})" if failed else "")
        here = self.where()
        return f"{said}; {here}" if here else said

    def __repr__(self) -> str:
        return f"Robot({self.name!r}, fault={self.fault is not None})"
