"""A station's robots and their faults: :class:`StationRobots`, a part of
:class:`~pyrt.station.base.Station`.

A station holds one or more robots (:class:`~pyrt.station.domain.Robot`,
each a fault domain), declared by :meth:`StationRobots.add_robot` before the
tree is adopted; a station that declares none is one robot.  Here are the
robots' faults (:meth:`StationRobots.trip`: the first cause kept, an id,
published once; the reflex of that robot's components only, in the same
tick; every robot if the station declares them coupled or the cause cannot
be attributed), the acknowledgement of one or all (``ack NAME``), the stop
of one (``stop NAME``), and the boards' read and write phases over every
robot's boards (a lost link trips the robot that owns the board).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterable, Sequence
from typing import TYPE_CHECKING, final

from pyrt.errors import BoardError, CommandError, ConfigError, Fault, PyrtError
from pyrt.scheduler.runner import MotionQueue
from pyrt.station.domain import Robot, boards_clash

if TYPE_CHECKING:
    from pyrt.boards import Boards
    from pyrt.component import Component
    from pyrt.scheduler import Loop, ReadyQueue
    from pyrt.scheduler.motion import MotionExecutor
    from pyrt.scheduler.runner import Runner

__all__ = ["StationRobots"]


class StationRobots:
    """The robots of a station and their faults (see the module text); a part of ``Station``."""

    #: Robots declared coupled: a fault on one stops every robot of the station.
    coupled: bool = False

    if TYPE_CHECKING:  # the Station's, used here
        name: str
        loop: Loop
        runner: Runner | None
        motion: MotionQueue
        board_sets: list[Boards]
        board_error: BoardError | None
        _robots: list[Robot]
        _declared: bool

        def attach_boards(self, boards: Boards, *more: Boards) -> None: ...
        def components(self) -> list[Component]: ...
        def stop(self) -> str: ...

    def _owner_of_boards(self, boards: Boards) -> Robot | None:
        return next((r for r in self._robots if any(b is boards for b in r.boards)), None)

    def _poll_boards(self, now_ns: int, sets: Sequence[Boards] = ()) -> None:
        """Loop handler ``io:read``: the inputs of every set in ``sets`` for this
        tick.  A BoardError trips the robot that owns the set (every robot if
        none does; once per fault: after ``ack`` the next failure trips again)."""
        for boards in sets:
            if not boards.can_fail:  # in this process: nothing to reach
                boards.read_phase(now_ns)
                continue
            if boards.down is not None and self._stopped_by(boards):
                continue  # stopped, and nothing to reach: the fault says why
            try:
                boards.read_phase(now_ns)
            except BoardError as exc:
                self._board_failed(exc, boards)

    def _flush_boards(self, now_ns: int) -> None:
        """Loop handler ``io:write`` (the last): the outputs this tick changed, every set."""
        for boards in self.board_sets:
            if not boards.can_fail:
                boards.write_phase(now_ns)
                continue
            if boards.down is not None and self._stopped_by(boards):
                continue
            try:
                boards.write_phase(now_ns)
            except BoardError as exc:
                self._board_failed(exc, boards)

    def _stopped_by(self, boards: Boards) -> bool:
        owner = self._owner_of_boards(boards)
        return owner.fault is not None if owner is not None else self.fault is not None

    def _board_failed(self, exc: BoardError, boards: Boards | None = None) -> None:
        if self.board_error is None:
            self.board_error = exc
        owner = self._owner_of_boards(boards) if boards is not None else None
        if owner is not None:
            if owner.fault is None:
                self.trip(str(exc), source="boards", robot=owner.name)
        elif any(r.fault is None for r in self._robots) or not self._robots:
            self.trip(str(exc), source="boards")

    @final
    def add_robot(self, name: str, root: Component, *, queues: Iterable[ReadyQueue] = (),
                  executors: Iterable[MotionExecutor] = (),
                  boards: Iterable[Boards] = (),
                  motion: MotionQueue | None = None,
                  parts: Iterable[Component] = (),
                  stop: Callable[[], str] | None = None,
                  busy: Callable[[], bool] | None = None,
                  where: Callable[[], str] | None = None,
                  status: Callable[[], str] | None = None,
                  ended: Callable[[], tuple[str, Sequence[str]]] | None = None) -> Robot:
        """Declare a robot of this station (a fault domain, :class:`Robot`) before
        :meth:`adopt`: ``root`` its component subtree (and ``parts`` beside it),
        its ready ``queues``, its motion ``executors`` and ``motion`` queue (a
        queue of its own by default), its ``boards`` (attached to the station
        already, or attached now).  ``stop``, ``busy``, ``where``, ``status``
        and ``ended`` say what the operator reads of it (defaults:
        :class:`Robot`).  A board serves one robot: boards given to another
        robot already (the same object, or the same URL outside this process)
        are refused with ConfigError, as is a second robot of the same name."""
        if self.runner is not None:
            raise PyrtError(f"{self.name}: declare robots before adopt()")
        key = name.lower()
        if not key or any(r.name.lower() == key for r in self._robots):
            raise ConfigError(f"robot {name!r}: " + ("a robot needs a name" if not key else
                                                     "two robots of one station have that name"))
        given = list(boards)
        for b in given:
            for other in self._robots:
                if any(boards_clash(b, mine) for mine in other.boards):
                    raise ConfigError(
                        f"board {b.url!r} is given to robot {other.name!r} and to robot "
                        f"{name!r}: a board serves one robot (004); give each robot "
                        "boards of its own")
            if not any(x is b for x in self.board_sets):
                self.attach_boards(b)
        robot = Robot(name, root, motion=motion if motion is not None else MotionQueue(),
                      queues=queues, executors=executors, boards=given, parts=parts,
                      stop=stop, busy=busy, where=where, status=status, ended=ended)
        self._robots.append(robot)
        self._declared = True
        return robot

    def _owner_of_queue(self, queue: ReadyQueue) -> Robot | None:
        if not self._declared:
            return None
        return next((r for r in self._robots if any(q is queue for q in r.queues)), None)

    def _robot_queue_error(self, robot: Robot) -> Callable[[str, str, str], None]:
        def error(cause: str, source: str, tb: str) -> None:
            self.trip(cause, source, tb, robot=robot.name)
        return error

    def _robot_trip(self, robot: Robot) -> Callable[[str, str], Fault]:
        def trip(cause: str, source: str = "") -> Fault:
            return self.trip(cause, source, robot=robot.name)
        return trip

    # -- the robots -------------------------------------------------------------------

    @final
    @property
    def robots(self) -> list[Robot]:
        """The station's robots (fault domains), in the order declared; one (the
        station itself) when it declared none."""
        return list(self._robots)

    @final
    def robot(self, name: str) -> Robot:
        """The robot called ``name`` (case-insensitive), or CommandError naming them."""
        key = name.strip().lower()
        for r in self._robots:
            if r.name.lower() == key or (not self._declared and self.name.lower() == key):
                return r
        raise CommandError(f"no robot named {name[:40]!r}; robots: "
                           f"{', '.join(r.name for r in self._robots) or 'none'}")

    @final
    def robot_names(self) -> list[str]:
        """The robots' names."""
        return [self._robot_name(r) for r in self._robots]

    def _robot_name(self, robot: Robot) -> str:
        return robot.name if self._declared else self.name

    @final
    def robot_of(self, component: Component) -> Robot | None:
        """The robot ``component`` belongs to (the first that owns it), or None."""
        return next((r for r in self._robots if r.owns(component)), None)

    # -- faults (loop thread) ---------------------------------------------------------

    @final
    @property
    def fault(self) -> Fault | None:
        """The fault that stopped the robot (of several robots, the oldest fault not
        acknowledged), or None."""
        faults = [r.fault for r in self._robots if r.fault is not None]
        return min(faults, key=lambda f: f.id) if faults else None

    @property
    def _fault(self) -> Fault | None:
        return self.fault

    @final
    def trip(self, cause: str, source: str = "", tb: str = "",
             robot: str | None = None) -> Fault:
        """The one fault path (every component's :meth:`~pyrt.component.Component.fail`,
        a task that raised, a board that cannot be reached, a motion that
        failed, the loop's consecutive overruns all come here): halt the
        robot's queues, run its components' reflex and end its motions, in
        this tick.  ``robot``: the robot that faulted (a component's fault,
        its queue's error and its boards' loss name their own); None: every
        robot (what cannot be attributed: the loop's overruns).  A station
        whose robots are :attr:`coupled` stops them all.  Each robot's first
        fault is kept and published once, as one event with an id
        (:attr:`~pyrt.errors.Fault.id`) that the shell, the server and EPICS
        each show once; a later cause while it is stopped runs the reflex
        again and is not news.  Returns the (first) robot's fault."""
        if robot is None:
            targets = list(self._robots)
        else:
            first_hit = self.robot(robot)
            targets = [first_hit] + ([r for r in self._robots if r is not first_hit]
                                     if self.coupled else [])
        if not targets:  # not adopted yet: nothing to stop but a record
            fault = self.loop.make_fault(self.name, cause, source, tb)
            self.loop.report_fault(fault)
            return fault
        faults = []
        for i, r in enumerate(targets):
            why = cause if i == 0 or robot is None else f"{cause} (coupled to {targets[0].name})"
            faults.append(self._trip_robot(r, why, source, tb))
        return faults[0]

    def _trip_robot(self, r: Robot, cause: str, source: str, tb: str) -> Fault:
        first = r.fault is None
        for q in r.queues:
            q.halt()
        if first:  # recorded first: a move the reflex ends, ends by this fault
            r.fault = self.loop.make_fault(self._robot_name(r), cause, source, tb)
        failed = self._robot_reflex(r, f"fault: {cause}")
        fault = r.fault
        assert fault is not None
        if not first:
            return fault
        if failed:
            fault = r.fault = dataclasses.replace(
                fault, cause=f"{cause}; reflex action failed: {failed}")
        self.loop.report_fault(fault)
        return fault

    def _queue_error(self, cause: str, source: str, tb: str) -> None:
        self.trip(cause, source, tb)

    def _robot_reflex(self, r: Robot, why: str) -> str:
        failed = r.reflex(why)
        if self.board_error is None and r.board_error is not None:
            self.board_error = r.board_error
        return failed

    @final
    def reflex(self, why: str = "stop") -> str:
        """Every actuator of every robot stopped now: every component's reflex, the
        running motions ended, queued ones dropped.  Returns the reflex errors
        ('' if none); a failing reflex never keeps the others from running."""
        errors = [e for r in self._robots if (e := self._robot_reflex(r, why))]
        owned = {id(c) for r in self._robots for c in r.components}
        for c in reversed(self.components()):  # what no robot owns (the world's parts)
            if id(c) in owned:
                continue
            try:
                c.reflex()
            except Exception as exc:
                errors.append(f"{c.name}: {exc!r}")
        if not self._robots:
            self.motion.clear()
        return "; ".join(errors)

    @final
    def acknowledge(self, robot: str | None = None) -> str:
        """Clear the fault of ``robot`` (None: of every faulted robot); its
        routines start again, nothing moves."""
        if robot is not None:
            targets = [self.robot(robot)]
        else:
            targets = [r for r in self._robots if r.fault is not None]
        faulted = [r for r in targets if r.fault is not None]
        if not faulted:
            named = robot is not None and self._declared
            who = f"{self._robot_name(targets[0])}: " if named else ""
            return f"{who}no fault to acknowledge"
        lines = []
        for r in faulted:
            assert r.fault is not None
            cause = r.fault.cause
            self._robot_reflex(r, "acknowledge")
            r.fault = None
            for q in r.queues:
                q.resume(restart=True)
            who = f"{r.name}: " if self._declared else ""
            lines.append(f"{who}fault acknowledged ({cause}); every motor stopped, "
                         "routines running")
        return "\n".join(lines)

    @final
    def stop_robot(self, name: str) -> str:
        """The operator's stop of one robot (``stop NAME``): its own stop; the
        others go on."""
        r = self.robot(name)
        return r.stop() if self._declared else self.stop()
