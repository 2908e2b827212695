"""What a station publishes: the end of every move and its components' messages.

:class:`StationEvents` is the part of :class:`~pyrt.station.base.Station`
that watches the robot's motion and publishes the end of every move as one
event (:class:`~pyrt.station.moves.MoveEnded`) to its subscribers
(:meth:`StationEvents.subscribe_moves`): ``wait`` takes it in one mailbox
call (:meth:`StationEvents.watch_move`), the console, the DAQ server and
EPICS each show it once; and that publishes what its components say
(:class:`~pyrt.component.Message`) to the runner's lines that the console
shows, the server and the ``pyrt.messages`` log.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, final

from pyrt.component import Message
from pyrt.station.moves import MessageLine, MoveEnded, MoveLine, MoveWatch

if TYPE_CHECKING:
    from pyrt.errors import Fault
    from pyrt.scheduler import Loop, ReadyQueue
    from pyrt.scheduler.runner import Runner
    from pyrt.station.domain import Robot
    from pyrt.station.profile import ShellProfile

__all__ = ["MESSAGE_LOG", "StationEvents"]

#: The log every station's messages go to (at their level); silent until the
#: application gives it a handler.
MESSAGE_LOG = logging.getLogger("pyrt.messages")
MESSAGE_LOG.addHandler(logging.NullHandler())
_LOG_LEVELS = {"info": logging.INFO, "warning": logging.WARNING, "error": logging.ERROR}


class StationEvents:
    """The events of a station (see the module text); a part of ``Station``."""

    if TYPE_CHECKING:  # the Station's, used here
        name: str
        loop: Loop
        runner: Runner | None
        profile: ShellProfile
        queues: list[ReadyQueue]
        _robots: list[Robot]
        _declared: bool

        @property
        def fault(self) -> Fault | None: ...
        def busy(self) -> bool: ...
        def where(self, robot: str | None = None) -> str: ...
        def robot(self, name: str) -> Robot: ...

    def _init_events(self) -> None:
        #: The subscribers of the components' messages (:meth:`subscribe`),
        #: replaced whole on a change (the loop reads it without a lock).
        self._listeners: tuple[Callable[[Message], None], ...] = ()
        #: The subscribers of the move-ended event (:meth:`subscribe_moves`).
        self._move_listeners: tuple[Callable[[MoveEnded], None], ...] = ()
        self._subscribing = threading.Lock()
        self._moving = False
        self._move_seq = 0
        self._watches: list[MoveWatch] = []
        #: Move-ended events since the robot last became busy (``ended`` reads it:
        #: a move already said need not be said again when the robot goes idle).
        self.moves_this_period = 0
        #: The last move's end (:class:`~pyrt.station.moves.MoveEnded`), or None.
        self.last_move: MoveEnded | None = None
        #: Where the robots of a station of several are, as one line (given to
        #: ``adopt``), or None: each robot's.
        self._say_where: Callable[[], str] | None = None

    # -- the end of a move ------------------------------------------------------------

    @final
    def subscribe_moves(self, listener: Callable[[MoveEnded], None]) -> Callable[[], None]:
        """Hand every :class:`~pyrt.station.moves.MoveEnded` to ``listener(event)``
        from now on (loop thread: it must not block); returns what ends it."""
        with self._subscribing:
            self._move_listeners = (*self._move_listeners, listener)

        def unsubscribe() -> None:
            with self._subscribing:
                self._move_listeners = tuple(x for x in self._move_listeners
                                             if x is not listener)
        return unsubscribe

    @final
    def waits_pending(self) -> int:
        """How many ``wait`` watches are still collecting (loop thread)."""
        return sum(1 for w in self._watches if not w.done)

    @final
    def watch_move(self, robot: str | None = None) -> MoveWatch:
        """``wait``'s one mailbox call (loop thread): a watch of what runs now. It
        collects every move-ended event until the robot is idle, then is done;
        idle at once (with the last move's event and where the robot is) when
        nothing runs; a refusal when nothing can end (a ready queue of the
        robot is frozen: its clock interrupt is off).  ``robot``: of one robot
        of the station (its events, until it is idle); None: every robot."""
        one = self.robot(robot) if robot is not None and self._declared else None
        busy = one.busy() if one is not None else self.busy()
        name = one.name if one is not None else ""
        if not busy:
            last = one.last_move if one is not None else self.last_move
            where = one.where() if one is not None else self.where()
            return MoveWatch(True, last, where=where, robot=name)
        queues = one.queues if one is not None else self.queues
        frozen = next((q for q in queues if not q.interrupts_enabled), None)
        if frozen is not None:
            return MoveWatch(False, self.last_move,
                             f"the clock interrupt is OFF (the ready queue {frozen.name} is "
                             "frozen): the move cannot end until it is on", robot=name)
        if not self._moving:
            self.loop.clock.moving(True)
        self._moving = True  # queued in this tick, after the watch ran: it is a move
        if one is not None:
            one.moving = True
        watch = MoveWatch(False, self.last_move, robot=name)
        self._watches.append(watch)
        return watch

    @final
    def end_move(self, reason: str, report: Sequence[str] = (), robot: str = "") -> MoveEnded:
        """Publish the end of a move (loop thread): ``reason`` how it ended, in
        the operator's words, ``report`` the lines ``wait`` says (default: the
        reason); where the robot was left and the fault that ended it are
        added here.  A configuration calls it from its motion executor's
        ``on_done`` (or its controller's stop listener); a move that is not a
        motion (a job, a move of one axis) ends when the robot goes idle, as
        ``ended`` (given to :meth:`adopt`) says.  ``robot``: the robot of a
        station of several whose move it was ('': the station's)."""
        one = self.robot(robot) if robot and self._declared else None
        try:
            where = one.where() if one is not None else self.where()
        except Exception as exc:  # a report must never stop the tick
            where = f"(where is not known: {exc!r})"
        fault = one.fault if one is not None else self.fault
        self._move_seq += 1
        self.moves_this_period += 1
        event = MoveEnded(one.name if one is not None else self.name, self._move_seq, reason,
                          where, fault.id if fault is not None else 0,
                          tuple(report) or (reason,), self.loop.now_ns)
        self.last_move = event
        mine = one if one is not None else (self._robots[0] if not self._declared and
                                            self._robots else None)
        if mine is not None:  # its last_stop signal
            mine.last_move = event
        for watch in self._watches:
            watch.collect(event)
        for listener in self._move_listeners:
            try:
                listener(event)
            except Exception as exc:
                self._move_listeners = tuple(x for x in self._move_listeners
                                             if x is not listener)
                MESSAGE_LOG.error("%s: a move subscriber failed and was dropped: %r",
                                  self.name, exc)
        return event

    def _watch_moves(self, now_ns: int) -> None:
        """Loop handler ``moves``: when the robot goes idle, what ended and was not
        a motion is published (``ended`` says whether there is any), and the
        waits are done."""
        if self._declared:
            self._watch_robots()
        busy = self.busy()
        if busy == self._moving:  # every tick but a move's first and last: nothing to do
            return
        if self._moving and not busy:
            if not self._declared and self._robots:
                try:
                    reason, report = self._robots[0].ended()
                except Exception as exc:  # a report must never stop the tick
                    reason, report = f"ended (its report failed: {exc!r})", ()
                if reason or report:
                    self.end_move(reason, report)
            watches, self._watches = self._watches, []
            for watch in watches:
                watch.finish()
            self.moves_this_period = 0
        elif busy and not self._moving:
            self.moves_this_period = 0
        if busy != self._moving:
            self.loop.clock.moving(busy)
        self._moving = busy

    def _watch_robots(self) -> None:
        """Each robot of several that went idle: how its move ended, published as its
        event; the waits for it alone are done."""
        for r in self._robots:
            busy = r.busy()
            if r.moving and not busy:
                try:
                    reason, report = r.ended()
                except Exception as exc:  # a report must never stop the tick
                    reason, report = f"ended (its report failed: {exc!r})", ()
                if reason or report:
                    self.end_move(reason, report, robot=r.name)
                mine = [w for w in self._watches if w.robot.lower() == r.name.lower()]
                self._watches = [w for w in self._watches if w not in mine]
                for watch in mine:
                    watch.finish()
            r.moving = busy

    # -- messages -------------------------------------------------------------------

    @final
    def subscribe(self, listener: Callable[[Message], None]) -> Callable[[], None]:
        """Hand every message of the station's components to ``listener(message)``
        from now on (in the thread that says it, the loop's as a rule: it must
        not block); returns what ends the subscription."""
        with self._subscribing:
            self._listeners = (*self._listeners, listener)

        def unsubscribe() -> None:
            with self._subscribing:
                self._listeners = tuple(x for x in self._listeners if x is not listener)
        return unsubscribe

    @final
    def publish(self, message: Message) -> None:
        """Give ``message`` to the log and to every subscriber; a subscriber that
        raises is dropped (and the log says so), the others still hear it."""
        MESSAGE_LOG.log(_LOG_LEVELS.get(message.level, logging.INFO), "%s: %s",
                        message.source, message.text)
        for listener in self._listeners:
            try:
                listener(message)
            except Exception as exc:
                self._listeners = tuple(x for x in self._listeners if x is not listener)
                MESSAGE_LOG.error("%s: a message subscriber failed and was dropped: %r",
                                  self.name, exc)

    @final
    def say(self, text: str, level: str = "info") -> None:
        """Tell the operator ``text`` as the station itself (what no component owns:
        the write-back at close), published as the components' messages are."""
        self.publish(Message(self.name, level, text))

    def _move_to_console(self, event: MoveEnded) -> None:
        """The end of a move among the console's lines, as it comes (a station
        whose profile announces stops), unless a ``wait`` waits for it."""
        runner = self.runner
        if runner is None or not self.profile.announce_stops:
            return
        if any(w.waiting for w in self._watches):
            return
        for text in event.report:
            runner.post(MoveLine(text, event.seq))

    def _to_console(self, message: Message) -> None:
        """The runner's asynchronous lines: what the console shows as it happens."""
        runner = self.runner
        if runner is not None:
            runner.post(MessageLine(message.text))

