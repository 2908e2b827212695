"""A station: one loop, one component tree, one plant, one or more robots.

Both robots are a :class:`Station` plus a configuration
(:mod:`pyrt.station.gripper`, :mod:`pyrt.station.manipulator`).  The station

* owns the loop, the component tree (:mod:`pyrt.component`), the plant
  behind the boards (``None`` on real hardware), the motion queue and the
  runner (the mailbox the consoles and the server talk through);
* holds one or more **robots** (:class:`~pyrt.station.domain.Robot`,
  declared by :meth:`add_robot`; a station that declares none is one robot),
  each a fault domain with its components, queues, motion queue, executors
  and boards (a board serves one robot): a fault on one stops that robot's
  actuators in the same tick and leaves the others running, unless the
  station declares them :attr:`coupled`; what cannot be attributed (the
  loop's overruns) stops them all; ``ack NAME`` and ``stop NAME`` address one;
* holds each robot's **fault state**: :meth:`trip` records the first fault,
  halts the robot's ready queues, runs **every** component's reflex in the
  same tick (004: one joint's error stops the whole robot), ends the
  running motion, drops queued ones and reports the fault once to the
  application (the next mailbox call raises it as
  :class:`~pyrt.errors.FaultError`); :meth:`acknowledge` clears it;
* executes command records in the loop thread (:meth:`execute`): the check
  (fault, moving while faulted) and the act in one mailbox call;
* derives everything that lists signals or commands from the tree:
  :meth:`components`, :meth:`signals`, :meth:`resolve_signal`; where each
  robot is, how its last move ended and its status line are text signals of
  the robot's root component (:meth:`signals_of`: ``where``, ``last_stop``,
  ``statusline``), which the console, the DAQ server and EPICS read;
* owns the robot's **boards** (:func:`pyrt.boards.open_boards`, chosen by
  URL) when a configuration gives them to :meth:`attach_boards`, and runs
  every tick in three phases (a process image, :mod:`pyrt.boards.image`):

  1. ``io:read`` (the first loop handler): every input of every board read
     into the image, one exchange per back end;
  2. the tasks: the robot's handlers, its ready queues and motions, the
     scope, the mailbox (consoles, server): reads and writes of board
     registers go to the image and never block on I/O;
  3. ``io:write`` (the last loop handler): the outputs the tick changed
     written, one exchange per back end.

  The reflex (:meth:`reflex`, run by :meth:`trip` and :meth:`stop`) writes
  its outputs at once, not at the end of the tick.  Each phase is a named
  loop handler, timed on its own in ``stats``.  A
  :class:`~pyrt.errors.BoardError` in a phase trips the robot (the message
  names the back end's URL); :meth:`close` closes the boards last.  The
  in-process ``sim:`` boards have no I/O: they attach no phase;
* watches its robot's motion and publishes the end of every move as one
  event (:class:`~pyrt.station.moves.MoveEnded`: how it ended, where the
  robot was left, the fault that ended it) to its subscribers
  (:meth:`subscribe_moves`): ``wait`` takes it in one mailbox call
  (:meth:`watch_move`), the console, the DAQ server and EPICS each show it once;
* publishes what its components say (:meth:`~pyrt.component.Component.say`,
  a :class:`~pyrt.component.Message`) to its subscribers (:meth:`subscribe`):
  the runner's asynchronous lines that the console shows, the server, and the
  log (the ``pyrt.messages`` logger, at the message's level);
* starts and stops in one order (:meth:`start`, :meth:`close`).
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterable, Sequence
from functools import partial
from pathlib import Path
from typing import Any, final

from pyrt.boards import Boards
from pyrt.component import Command, Component, Signal, command, serve_prepared, walk
from pyrt.errors import BoardError, CommandError, ConfigError, PyrtError
from pyrt.scheduler import Loop, ReadyQueue
from pyrt.scheduler.motion import MotionExecutor
from pyrt.scheduler.runner import MotionQueue, Runner
from pyrt.scope import Scope
from pyrt.station.domain import ROBOT_SIGNALS, Robot
from pyrt.station.events import StationEvents
from pyrt.station.profile import ShellProfile
from pyrt.station.requests import StationRequests
from pyrt.station.robots import StationRobots
from pyrt.station.snapshot import SnapshotError

__all__ = ["BoardWorld", "Robot", "Station", "refuse_sim_options"]


def _plain_end() -> tuple[str, Sequence[str]]:
    """How a move ended when the station does not say: ``ended``."""
    return "ended", ()


def refuse_sim_options(boards: Boards, given: Iterable[str]) -> None:
    """ConfigError naming ``boards``' URL if any option in ``given`` (those
    of the in-process simulation that were set) was set for boards whose
    world runs elsewhere; nothing for in-process boards."""
    names = list(given)
    if boards.simulated is not None or not names:
        return
    raise ConfigError(f"board URL {boards.url!r}: the world behind these boards is not "
                      f"simulated in this process: {', '.join(names)} cannot be set here "
                      "(over tcp:// they are options of 'pyrt board-sim')")


class BoardWorld(Component):
    """``sim`` for boards whose world runs elsewhere (``pyrt board-sim``):
    its state as the back end tells it.  The world's settings and faults
    are board-sim's options; nothing here changes it."""

    name = "sim"

    def __init__(self, boards: Boards):
        self.boards = boards

    @command(name="show", reads_only=True)
    def show(self) -> str:
        """sim: the simulated world's state as board-sim tells it (the world runs in that
        process: set it up with pyrt board-sim's options)."""
        try:
            info = self.boards.info()
        except BoardError as exc:
            raise CommandError(str(exc)) from None
        return f"board-sim at {self.boards.url}: " + " ".join(f"{k}={v}" for k, v in info.items())


class Station(StationRobots, StationEvents, StationRequests):
    """See the module text.  A configuration builds its tree and calls
    :meth:`adopt` last (after every loop handler is attached)."""

    #: The robot's name (``gripper``, ``prototype``, ``sno``).
    name: str = "robot"
    #: How its console reads (prompt, letter level, words, ``wait``'s words):
    #: presentation, given by the module that assembles the station.
    profile: ShellProfile = ShellProfile()
    #: Where the station's files are (its databases), or None; a served
    #: station keeps its audit log there.
    directory: Path | None = None

    def __init__(self, loop: Loop, *, motion_capacity: int = 16):
        self.loop = loop
        self.motion = MotionQueue(capacity=motion_capacity)
        self.scope = Scope()
        self.root: Component = Component()
        self.extras: list[Component] = []
        self.queues: list[ReadyQueue] = []
        self.executors: list[MotionExecutor] = []
        self.plant: Any = None
        #: The station's first boards (every set it owns: :attr:`board_sets`).
        self.boards: Boards | None = None
        #: Every set of boards the station owns, in the order attached.
        self.board_sets: list[Boards] = []
        #: The first BoardError seen (a poll, a reflex, the stop at close), or None.
        self.board_error: BoardError | None = None
        #: Where :meth:`close` reports what it could not do (boards already
        #: gone); default: the runner's messages.
        self.close_report: Callable[[str], None] | None = None
        self.runner: Runner | None = None
        #: What building the station did that the operator should know, said
        #: as ``start-up:`` lines before the console opens (the manipulator's
        #: reconciled ZEROLENGTH and LENGTH); none by default.
        self.startup_notes: list[str] = []
        self._robots: list[Robot] = []
        self._declared = False
        self._by_name: dict[str, Component] = {}
        self._closed = False
        self._init_events()

    # -- assembly -------------------------------------------------------------------

    @final
    def attach_boards(self, boards: Boards, *more: Boards) -> None:
        """Own ``boards`` (and ``more`` sets): attach the read phase (``io:read``,
        one handler that reads every set given) to the loop now (call it before
        the robot's handlers: the inputs of a tick come in first); :meth:`adopt`
        attaches the write phase (``io:write``) last.  The back end derives its
        timeouts from the loop's tick.  A station may own several sets (each
        robot its own: :meth:`add_robot`); give them in one call, so that one
        handler reads them; :meth:`close` closes them all."""
        sets = [boards, *more]
        for b in sets:
            self._own_boards(b)
        if len(sets) == 1 and not boards.can_fail:
            # in this process, nothing to reach: the phase itself is the handler
            self.loop.attach(boards.read_phase, name="io:read")
        else:
            self.loop.attach(partial(self._poll_boards, sets=sets), name="io:read")

    def _own_boards(self, boards: Boards) -> None:
        if boards.realtime:
            clock = self.loop.clock
            speed = getattr(clock, "speed", 1.0)
            if clock.virtual or speed != 1.0:
                what = "virtual time (--speed max)" if clock.virtual else f"--speed {speed:g}"
                raise ConfigError(f"board URL {boards.url!r}: the boards and their world run "
                                  f"in another process at real time: {what} is refused; run "
                                  "at real time (--speed 1)")
        if any(b is boards for b in self.board_sets):
            raise ConfigError(f"board URL {boards.url!r}: these boards are attached already")
        self.board_sets.append(boards)
        if self.boards is None:
            self.boards = boards
        boards.set_tick(self.loop.period_ns / 1e9)

    @final
    def attach_world(self, step: Callable[[int], None], name: str = "world",
                     boards: Boards | None = None) -> None:
        """Attach the simulated world's ``step(now_ns)`` at the one place it
        steps in the tick: the start of its boards' read phase (the back end's
        :meth:`~pyrt.boards.backend.Backend.attach_world`), so that the tick
        reads the world as it stands; in a replay not at all (the recorded
        inputs stand in for the world).  A back end that steps no world leaves
        it to the loop, as handler ``name`` (call it after
        :meth:`attach_boards`, before the robot's handlers).  ``boards``: the
        set the world is behind (default: the station's first)."""
        behind = boards if boards is not None else self.boards
        if behind is not None and behind.attach_world(step):
            return
        self.loop.attach(step, name=name)

    @final
    def adopt(self, root: Component, *, queues: Iterable[ReadyQueue] = (),
              executors: Iterable[MotionExecutor] = (),
              extras: Iterable[Component] = (),
              where: Callable[[], str] | None = None,
              ended: Callable[[], tuple[str, Sequence[str]]] | None = None,
              status: Callable[[], str] | None = None) -> Runner:
        """Take ``root`` (and ``extras``, e.g. the simulation's component) as
        the station's tree; own ``queues``' errors; attach the move watch, the
        scope and the mailbox to the loop (in that order, after the robot's
        handlers).

        A station that declared no robot (:meth:`add_robot`) is one robot:
        its name, every component, queue, executor and board.  Otherwise each
        declared robot's components must be in the tree, and its queues'
        errors and its components' faults trip that robot alone.

        What the operator reads of the robot is given here, once (loop
        thread, each returns text): ``where`` the robot is; how the move that
        has just ended ended, ``ended() -> (reason, report lines)``, asked
        once per move when the move-ended event is made; the ``status``
        line (default: the root's signals).  They become the robot's text
        signals (:meth:`signals_of`).  Of a station of several robots (each
        gives its own to :meth:`add_robot`), ``where`` is the station's line
        (default: each robot's, ``NAME WHERE; ...``) and ``ended`` and
        ``status`` are not taken."""
        if where is not None:
            self._say_where = where
        self.root = root
        self.extras = list(extras)
        self._by_name = {}
        for top in [root, *self.extras]:
            for c in walk(top):
                key = c.name.lower()
                if not key:
                    raise PyrtError(f"a component of {self.name} has no name: {c!r}")
                if key in self._by_name and self._by_name[key] is not c:
                    raise PyrtError(f"two components of {self.name} are called {c.name!r}")
                self._by_name[key] = c
        if not self._declared:
            self._robots = [Robot(self.name, root, motion=self.motion, queues=queues,
                                  executors=executors, boards=self.board_sets,
                                  parts=self.extras, where=where, status=status,
                                  ended=ended if ended is not None else _plain_end)]
        for r in self._robots:
            r.refresh()
            stray = [c.name for c in r.components if self._by_name.get(c.name.lower()) is not c]
            if stray:
                raise PyrtError(f"robot {r.name!r}: {', '.join(stray)} not in {self.name}'s tree")
            taken = [s.name for s in r.root.signals() if s.name in ROBOT_SIGNALS]
            if taken:
                raise PyrtError(f"robot {r.name!r}: its root {r.root.name} has a signal called "
                                f"{', '.join(taken)}, a name of the robot's own text signals")
        self.queues = list(queues) + [q for r in self._robots for q in r.queues
                                      if not any(q is x for x in queues)]
        self.executors = list(executors) + [e for r in self._robots for e in r.executors
                                            if not any(e is x for x in executors)]
        for q in self.queues:
            owner = self._owner_of_queue(q)
            q.on_error = self._queue_error if owner is None else self._robot_queue_error(owner)
        self.loop.trip_handlers.append(self.trip)
        self.loop.attach(self._watch_moves, name="moves")
        self.scope.attach_to(self.loop)  # its handler runs only while it acquires
        self.runner = Runner(self.loop, motion_queue=self.motion)
        self.subscribe(self._to_console)
        self.subscribe_moves(self._move_to_console)
        for c in self._by_name.values():  # what they said while being built comes now
            owner = self.robot_of(c)
            trip = self.trip if owner is None or not self._declared else self._robot_trip(owner)
            c.connect(trip=trip, tell=self.publish)
        sets = self.board_sets
        if len(sets) == 1 and not sets[0].can_fail:
            self.loop.attach(sets[0].write_phase, name="io:write")
        elif sets:
            self.loop.attach(self._flush_boards, name="io:write")
        return self.runner

    # -- the tree -----------------------------------------------------------------

    @final
    def components(self) -> list[Component]:
        """Every component, the robot's tree first, each once."""
        return list(self._by_name.values())

    @final
    def component(self, name: str) -> Component:
        """The component called ``name`` (case-insensitive), or CommandError."""
        c = self._by_name.get(name.lower())
        if c is None:
            raise CommandError(f"no object named {name[:40]!r}; objects: "
                               f"{', '.join(self.names())}")
        return c

    @final
    def find(self, name: str) -> Component | None:
        """The component called ``name``, or None."""
        return self._by_name.get(name.lower())

    @final
    def names(self) -> list[str]:
        """The components' names, in the tree's order."""
        return [c.name for c in self._by_name.values()]

    @final
    def signals(self) -> list[tuple[str, Signal]]:
        """``(OBJECT.SIGNAL, signal)`` of every signal of every component (a
        robot's root with the robot's text signals: :meth:`signals_of`)."""
        return [(f"{c.name}.{s.name}", s) for c in self.components() for s in self.signals_of(c)]

    @final
    def signals_of(self, component: Component) -> list[Signal]:
        """``component``'s signals; of a robot's root, the robot's text signals after
        them (``where``, ``last_stop``, ``statusline``: :meth:`Robot.signals
        <pyrt.station.domain.Robot.signals>`)."""
        own = component.signals()
        robot = next((r for r in self._robots if r.root is component), None)
        return own if robot is None else [*own, *robot.signals()]

    def _signal_of(self, component: Component, name: str) -> Signal | None:
        found = component.signal(name)
        if found is not None:
            return found
        key = name.lower()
        return next((s for s in self.signals_of(component) if s.name.lower() == key), None)

    @final
    def resolve_signal(self, name: str) -> Signal:
        """``OBJECT.SIGNAL`` (``OBJECT.PART.SIGNAL``: of a part of OBJECT), or a bare
        ``SIGNAL`` of the root component; CommandError if none."""
        text = name.strip()
        obj, dot, field = text.partition(".")
        if dot and field:
            c = self.find(obj)
            if c is None:
                raise CommandError(f"no channel {text[:60]!r}: no object {obj[:40]!r}")
            s = self._signal_of(c, field)
            part, dot2, rest = field.partition(".")
            if s is None and dot2 and rest:  # PARENT.PART.SIGNAL: a signal of a part
                child = next((k for k in c.children() if k.name.lower() == part.lower()), None)
                s = child.signal(rest) if child is not None else None
            if s is None:
                raise CommandError(f"no channel {text[:60]!r}: {c.name} has no signal "
                                   f"{field[:40]!r}; it has "
                                   f"{', '.join(x.name for x in self.signals_of(c)) or 'none'}")
            return s
        s = self._signal_of(self.root, text)
        if s is None:
            raise CommandError(f"no channel {text[:60]!r}; 'scope list' shows them")
        return s

    @final
    def all_commands(self) -> list[tuple[Component, Command]]:
        """Every command record of every component."""
        return [(c, r) for c in self.components() for r in c.commands()]

    def stop(self) -> str:
        """The operator's stop: every motor stopped, the move ended, queued
        moves dropped (no fault); the line says where the robot stopped.  Of
        several robots: each robot's stop (:meth:`stop_robot`), a line each."""
        if self._declared:
            return "\n".join(r.stop() for r in self._robots)
        failed = self.reflex("stop command")
        said = f"{self.name}: every motor stopped" + (f" ({failed})" if failed else "")
        here = self.where()
        return f"{said}; {here}" if here else said

    @final
    def where(self, robot: str | None = None) -> str:
        """Where the robot is, in the operator's words ('' if it cannot say): its
        ``where`` signal.  Of several robots: ``robot``'s, or the station's line
        (as given to :meth:`adopt`, else each robot's: ``NAME WHERE; ...``)."""
        if robot is not None and self._declared:
            return self.robot(robot).where()
        if not self._declared:
            return self._robots[0].where() if self._robots else ""
        if self._say_where is not None:
            return self._say_where()
        return "; ".join(f"{r.name} {here}" for r in self._robots if (here := r.where()))

    @final
    def last_stop(self) -> str:
        """How the last move ended, in the operator's words ('' before any): the
        last move-ended event's reason (the robot's ``last_stop`` signal; of several
        robots, the last of any)."""
        last = self.last_move
        return last.reason if last is not None else ""

    # -- commands (loop thread) -------------------------------------------------------

    @final
    def execute(self, component: Component, record: Command, args: list[Any]) -> Any:
        """Run ``record`` with checked ``args``: refused while faulted if it
        moves (or is not allowed while faulted); one mailbox call checks and acts."""
        owner = self.robot_of(component) if self._declared else None
        fault = owner.fault if owner is not None else self.fault
        if fault is not None and not record.while_faulted:
            who = owner.name if owner is not None else self.name
            raise CommandError(
                f"{component.name} {record.name}: refused: {who} is stopped by a fault "
                f"({fault.cause}); give 'ack' first; nothing moved")
        if record.prepare is not None:  # its snapshot, its hand-over, or all here
            return serve_prepared(record, args, self.__dict__.setdefault("_snapshots", {}))
        return record.handler(*args)

    def check_motion(self, record: Any) -> None:
        """Configuration-specific refusals of a motion record (none by default)."""

    # -- state ------------------------------------------------------------------------

    def busy(self) -> bool:
        """A move runs or waits (configurations say more); of several robots: a
        move of any of them."""
        if self._declared:
            return any(r.busy() for r in self._robots)
        return len(self.motion) > 0 or any(ex.busy for ex in self.executors)

    @final
    def status(self) -> str:
        """The status line: as given to :meth:`adopt` (else the root's signals),
        and the fault while one is not acknowledged.  Of several robots: a
        line each, ``NAME: ...``."""
        if self._declared:
            return "\n".join(f"{r.name}: {r.status()}" for r in self._robots)
        if self._robots:  # its statusline signal
            return self._robots[0].status()
        parts = [f"{s.name}={s.format(s.read())}" for s in self.root.signals()]
        if self._fault is not None:
            parts.append(f"FAULT: {self._fault.cause}")
        return "  ".join(parts)

    def status_fields(self) -> list[tuple[str, Signal, str]]:
        """The server's STATUS fields ``(key, signal, format)``: the root's
        signals and the fault flag (configurations choose their own)."""
        return [*((s.name, s, s.fmt) for s in self.root.signals()), self.fault_field()]

    def served_signals(self) -> list[Signal]:
        """Values of the station itself served beside the status fields and
        every component's signals (EPICS PVs by their names); none by default."""
        return []

    @final
    def fault_field(self) -> tuple[str, Signal, str]:
        """The ``fault`` STATUS field (1 while a fault is not acknowledged)."""
        return ("fault", Signal("fault", "bool", lambda: self._fault is not None,
                                "a fault stopped the robot", "d"), "d")

    # -- life cycle -------------------------------------------------------------------

    def journal_databases(self) -> dict[str, bytes]:
        """The station's database files as they stand (name -> contents), kept in
        a journal's header so that a replay starts from them; none by default."""
        return {}

    def seeds(self) -> dict[str, int]:
        """Every random seed of the run (name -> seed), kept in a journal's
        header; none by default."""
        return {}

    def snapshot_state(self) -> dict[str, Any]:
        """The controller's state between two ticks, as plain data that
        :meth:`restore_state` puts back into a station built the same way (a
        black box carries it, so that ``pyrt replay`` resumes there:
        :mod:`pyrt.station.snapshot`).  Called in the loop thread at the end of
        a tick.  Raise :class:`~pyrt.station.snapshot.SnapshotError` naming
        what cannot be saved; by default a station has no snapshot."""
        raise SnapshotError(f"cannot snapshot: {self.name} has no snapshot")

    def restore_state(self, state: dict[str, Any]) -> None:
        """Put a :meth:`snapshot_state` back (before the loop runs); raise
        :class:`~pyrt.station.snapshot.SnapshotError` if it does not fit."""
        raise SnapshotError(f"cannot restore a snapshot: {self.name} has no snapshot")

    @final
    def start(self) -> Runner:
        """Start the loop (its thread on a wall clock)."""
        assert self.runner is not None, "adopt() the tree first"
        for boards in self.board_sets:
            boards.resync()
        self.runner.start()
        return self.runner

    def close(self) -> None:
        """Every motor stopped, the loop stopped, files written back and
        closed, the boards closed.  Safe to call twice.  Boards that are
        already gone do not make it raise: it says so once (:attr:`close_report`)."""
        if self._closed:
            return
        self._closed = True
        runner = self.runner
        failed: BoardError | None = None
        if runner is not None and runner.running:
            try:
                runner.call(self.stop, take_fault=False, name="stop every motor")
            except BoardError as exc:
                failed = exc
            except PyrtError:
                pass
            runner.stop()
        else:
            with contextlib.suppress(Exception):
                self.reflex("shutdown")
        self.scope.close()  # its live sinks: the UDP stream, the Foxglove server
        try:
            self.write_back()
        finally:
            try:
                self.loop.close()
            finally:
                self._close_boards(failed)

    def _close_boards(self, failed: BoardError | None) -> None:
        for boards in self.board_sets:
            self._close_board_set(boards, failed)

    def _close_board_set(self, boards: Boards, failed: BoardError | None) -> None:
        gone = boards.down
        boards.close()
        if gone is None and failed is None:
            return
        err = failed or self.board_error
        why = str(err) if err is not None else f"board {boards.url}: {gone}"
        if getattr(boards.image, "off_on_loss", True):
            tail = "the board turns its outputs off when its link drops"
        else:  # a Modbus device not said to (modbus:// without off_on_loss=1)
            tail = ("the device is not known to turn its outputs off when its link drops "
                    "(off_on_loss=0): they may still be driven; check them at the device")
        line = f"{self.name}: closed without its boards ({why}); {tail}"
        report = self.close_report
        if report is None and self.runner is not None:
            report = self.runner.post
        if report is not None:
            report(line)

    def closing_note(self) -> str:
        """The end of the one line said on the way out (SIGINT, SIGTERM, end of
        input, quit) after "every motor stopped": where the robot was left and
        what closing did beyond stopping the motors ("; databases written back
        in DIR"); by default "; " and :meth:`where` ('' when it cannot say)."""
        here = self.where()
        return f"; {here}" if here else ""

    def write_back(self) -> None:
        """Write databases back on the way out (configurations that have them)."""
