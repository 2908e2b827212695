"""The end of a move as one event: :class:`MoveEnded`, and ``wait``'s watch of it.

A station watches its robot's motion (every tick, after the robot's handlers:
the motion executor, the ready queues and their jobs): when it goes from
busy (a move, a job, a queued record) to idle, the move has ended and the
station publishes **one** :class:`MoveEnded` with how it ended (``reason``,
the operator's words), where the robot was left (``where``) and the id of
the fault that ended it (``fault_id``, 0 if none).  Its ``report`` is the
line or lines an operator reads about it.

Everything that tells the operator how a move ended subscribes to this one
event (:meth:`~pyrt.station.base.Station.subscribe_moves`): ``wait`` (one
mailbox call, :meth:`~pyrt.station.base.Station.watch_move`), the console
between waits, the DAQ server (a ``STATUS STOP`` line to each subscribed
client) and EPICS (``STOP_REASON``).  Each shows each event once, by its
``seq``.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["MessageLine", "MoveEnded", "MoveLine", "MoveWatch"]


@dataclass(frozen=True)
class MoveEnded:
    """One end of a move (see the module text)."""

    #: The robot (the station's name).
    robot: str
    #: The event's number on its station (1, 2, ...).
    seq: int
    #: How the move ended, in the operator's words (EPICS's ``STOP_REASON``).
    reason: str
    #: Where the robot was left, in the operator's words.
    where: str
    #: The id of the fault that ended the move (:attr:`pyrt.errors.Fault.id`), or 0.
    fault_id: int = 0
    #: What ``wait`` says about it: one or more lines.
    report: tuple[str, ...] = ()
    #: The loop's time when it ended, ns.
    time_ns: int = 0


class MoveWatch:
    """What one ``wait`` holds (made in the loop thread by ``watch_move``).

    ``idle`` is True when nothing ran when the watch was made (``last`` is then
    the last move's event, or None, and ``where`` where the robot is);
    ``refusal`` says why what runs cannot end (a frozen ready queue), or is
    None.  Otherwise :attr:`ended` collects the :class:`MoveEnded` events
    until the robot is idle, and then :attr:`done` (both in the loop thread)."""

    __slots__ = ("done", "ended", "idle", "last", "refusal", "robot", "waiting", "where")

    def __init__(self, idle: bool, last: MoveEnded | None, refusal: str | None = None,
                 where: str = "", robot: str = ""):
        #: The robot it waits for ('': every robot of the station).
        self.robot = robot
        self.idle = idle
        self.last = last
        self.refusal = refusal
        #: Where the robot is (said when it is idle).
        self.where = where
        #: The moves that ended while it waited, in order.
        self.ended: list[MoveEnded] = []
        #: The robot is idle: everything it waited for has ended.
        self.done = False
        #: Its wait still waits (False once it has given up: the console then says
        #: the ends as they come).
        self.waiting = True

    def collect(self, event: MoveEnded) -> None:
        """A move ended (loop thread): kept if it is of the robot it waits for."""
        if not self.robot or event.robot.lower() == self.robot.lower():
            self.ended.append(event)

    def finish(self) -> None:
        """The robot is idle (loop thread)."""
        self.done = True


class MoveLine(str):
    """A line of a move-ended event's report among the runner's lines for the
    console (``seq``: its event), so that a ``wait`` that said it can leave it out."""

    seq: int

    def __new__(cls, text: str, seq: int) -> MoveLine:
        line = super().__new__(cls, text)
        line.seq = seq
        return line


class MessageLine(str):
    """A component's message among the runner's lines for the console (the
    ``pyrt.messages`` log has it already: a headless service does not log it again)."""
