"""The rope manipulator assembled on one loop: database -> boards -> world -> devices -> robots.

:class:`ManipulatorStation` reads a station directory (``pyrt.db``), builds
the simulated TIO10 and dataConcentrator, the physics behind them
(:class:`pyrt.sim.manipulator.ManipulatorPlant`), the Motor/Encoder/Loadcell
of every rope, the Axes, the AV and the PolyAxis, puts the polyaxis-poll
and axis-poll routines on the manipulator's ready queue, owns the motion
queue that ``to`` records go on (give it to the
:class:`~pyrt.scheduler.runner.Runner`), and attaches, in this order, the
plant, the ready queue and the database write-back to the
:class:`~pyrt.scheduler.Loop`.

Numbers.  The control poll is 50 ms, the period the fuzzy rules are tuned
for (000 polled at LOOP_TIME 1e-4 s and says the rules were developed for
a longer poll and that ten times slower would lose nothing); DV_LIMIT (0.5
cm/s) is per control poll, so a motor accelerates at most 10 cm/s2.  The
standalone axis poll is 10 ms (STEP_MODE ramps shorten the period per
step).  The physics steps every base tick: 1 ms by default here; ``pyrt
manipulator`` and the tests use 5 ms, where a motor at its 7.0 cm/s limit
makes 1.4 half-steps a tick (the encoders count 0.24 cm, 10 half-steps), so
nothing the control sees changes, and ``--speed max`` runs a move 50-130
times faster than real time instead of 35-60 (bench/bench_manipulator.py).

The simulated world starts with the source at the database POSITION, held
as the controller leaves it at the end of a move (off-side ropes at
OFFSIDE_TENSION, the others balancing the weight).  The encoders start
from the database ZEROLENGTH, reconciled with the ropes at POSITION: within
RECONCILE_COUNTS counts it is kept, further off it is set from POSITION (as
``setZeroLength`` would be after surveying the source in), and an AXIS
LENGTH that disagrees is noted; each start-up says what it did
(``startup_notes``; ``pyrt manipulator`` prints them as ``start-up:`` lines).  ZEROLENGTH
write-back keeps the encoders' lengths.
``FUZZY_<NAME>`` keys of an AXIS entry override that axis's fuzzy
parameters as used at the 50 ms poll.

Boards.  The TIO10 and dataConcentrator come from a back end chosen by URL
(:func:`pyrt.boards.open_boards`, ``boards=``): ``sim:`` (the default)
builds them in this process with the world above behind them;
``tcp://HOST:PORT`` reaches those of a ``pyrt board-sim prototype|sno``
in another process, whose world (built from the same database) moves at
real time there.  Then the loop must run at real time, the world's
settings (``imperfections``) are board-sim's, and the world it serves must
be this station's (ConfigError otherwise).  The boards' inputs are read
once before anything else reads them and then first in every tick; a
BoardError there faults the manipulator, naming the URL.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable, Sequence
from functools import partial
from operator import attrgetter, call
from pathlib import Path
from typing import Any, TextIO

from pyrt.boards import Boards, open_boards
from pyrt.boards.registers import BoardKind
from pyrt.component import Arg, Component, Signal, command, finite
from pyrt.db import (
    FILES,
    STATIONS,
    DirectoryLock,
    check_startup_correction,
    copy_station,
    default_working_directory,
    load_station,
    lock_directory,
    station_directory,
)
from pyrt.db import Station as StationDB
from pyrt.errors import (
    BoardError,
    CommandError,
    ConfigError,
    DiskError,
    NativeError,
    PyrtError,
    UsageError,
)
from pyrt.native import FuzzyParams, NativeInputError
from pyrt.robots.av import AV
from pyrt.robots.axis import STANDALONE, Axis, tension_alarms
from pyrt.robots.polyaxis import PolyAxis, PolyAxisServices
from pyrt.robots.ropes import MIN_TOP_SEGMENT, RopeModel, payout
from pyrt.robots.stops import StopRecord
from pyrt.scheduler import Loop, ReadyQueue, SimClock
from pyrt.scope import Source
from pyrt.sim.manipulator import ManipulatorPlant, rig_from_station
from pyrt.sim.sensors import Imperfections
from pyrt.sim.world import MANIPULATOR_BOARDS, ManipulatorWorld, World, WorldFactory
from pyrt.station.base import BoardWorld, Station, refuse_sim_options
from pyrt.station.factory import StationFactory
from pyrt.station.profile import ShellProfile
from pyrt.station.snapshot import restore_into, state_of
from pyrt.tasks import SyncWriter, ThreadWriter, WriteBack, register_tasks

__all__ = [
    "AXIS_POLL_S",
    "MANIPULATOR",
    "POLL_S",
    "TICK_NS",
    "ManipulatorFactory",
    "ManipulatorStation",
    "ManipulatorWorlds",
]

TICK_NS = 1_000_000
#: Slack allowed beyond the rope lengths sampled over the vessel and the neck
#: (cm): the sample grid is coarse, and the database geometry is a survey's.
ROPE_RANGE_MARGIN = 5.0
#: The heaviest calibration load ``sim load`` hangs (N): 000's loadcells are
#: 50 lb (222 N) cells; twice that covers an overload test.
MAX_HUNG_LOAD_N = 500.0
#: Start-up: an encoder whose database ZEROLENGTH is within this many counts of
#: the rope with the source at POSITION keeps it (see ``_reconcile``).
RECONCILE_COUNTS = 1.5
#: Start-up belief check (boards in another process, whose world was built
#: from a database of its own): how far the position the rope tensions give
#: (tensionFind) may be from POSITION, cm.  The loadcells' error (zero error,
#: noise, non-linearity: some 2.5 N) moves that position by up to 25 cm near
#: the top of the vessel, where the tensions change little with the position;
#: a world further off than this is said to disagree.
BELIEF_CM = 35.0
_SIM_FAULTS = ("slip", "dead", "stuck", "stall", "break", "none")
POLL_S = 0.05
AXIS_POLL_S = 0.01


def _item_of(read: Callable[[], Sequence[float]], i: int) -> Callable[[], float]:
    """A reader of item ``i`` of what ``read`` returns, read each time."""
    return lambda: read()[i]


class ManipulatorSim(Component):
    """The simulated world as a component: where the source really is, the
    true tensions, and faults to inject (``sim``, ``sim fault ROPE ...``)."""

    name = "sim"

    def __init__(self, plant: ManipulatorPlant, axes: list[Axis]):
        self.plant = plant
        self.axes = axes

    def signals(self) -> list[Signal]:
        p = self.plant
        # each vector the plant's solver computes whole is read once a sample, for
        # all of its columns (Source.call_item), from the solver (what the plant's
        # position and tensions() give)
        solver = p.solver
        where = partial(attrgetter("position"), solver)  # one C call into the property
        tensions = solver.tensions
        out = [Signal(c, "cm", _item_of(where, i), f"true source position {c}",
                      source=Source.call_item(where, i))
               for i, c in enumerate("xyz")]
        out += [Signal(f"tension{i}", "N", _item_of(tensions, i),
                       f"true tension of {a.name}", source=Source.call_item(tensions, i),
                       limits=tension_alarms(a.tension_limits))
                for i, a in enumerate(self.axes)]
        return out

    @command(name="show", reads_only=True)
    def cmd_show(self) -> str:
        """sim: where the source really is and the true tensions."""
        p = self.plant
        pos, t, wrapped = p.position, p.tensions(), p.wrapped()
        ring = [a.name for a, w in zip(self.axes, wrapped, strict=True) if w]
        return (f"true position ({pos[0]:.2f}, {pos[1]:.2f}, {pos[2]:.2f}) cm; tensions "
                + " ".join(f"{v:.2f}" for v in t) + " N"
                + (f"; on the neck ring: {', '.join(ring)}" if ring else ""))

    @command(Arg("ROPE", str), Arg("KIND", str.lower, choices=_SIM_FAULTS),
             Arg("FRACTION", finite("slip fraction", 0.0, 1.0), optional=True, lo=0.0, hi=1.0,
                 what="the share of the rope the encoder misses"), name="fault")
    def cmd_fault(self, rope: str, what: str, fraction: float | None = None) -> str:
        """sim fault ROPE slip [FRACTION]|dead|stuck|stall|break|none: inject a fault.

        ROPE is an axis name (axis1) or index."""
        p = self.plant
        key: int | str = int(rope) if rope.isascii() and rope.isdecimal() else rope
        actions: dict[str, Callable[..., None]] = {
            "slip": p.inject_slip, "dead": p.inject_loadcell_dead,
            "stuck": p.inject_loadcell_stuck, "stall": p.inject_stall,
            "break": p.break_rope, "none": p.clear_faults,
        }
        args: list[Any] = [key]
        if fraction is not None:
            if what != "slip":
                raise CommandError(f"sim fault {what}: takes no more arguments")
            args.append(fraction)
        try:
            actions[what](*args)
        except ValueError as exc:
            raise CommandError(str(exc)) from None
        return f"sim: {what} on {rope}"

    @command(Arg("ROPE", str),
             Arg("NEWTONS", str, lo=0.0, hi=MAX_HUNG_LOAD_N, units="N", what="a hung load"),
             name="load")
    def cmd_load(self, rope: str, newtons: float | str) -> str:
        """sim load ROPE NEWTONS: hang a known load on the rope's loadcell (calibration).

        The loadcell then reads that load (with its offset, non-linearity and
        noise) instead of the source's tension, as on the rig where masses
        hang on the rope; 'sim unload ROPE' takes it off.  Give the loadcell's
        'point' command the same load.  ROPE is an axis name or index."""
        n = float(newtons)
        self._rope_call(self.plant.hang_load, rope, n)
        return f"sim: {n:g} N hangs on {rope}'s loadcell"

    @command(Arg("ROPE", str), name="unload")
    def cmd_unload(self, rope: str) -> str:
        """sim unload ROPE: take the calibration load off the rope's loadcell."""
        self._rope_call(self.plant.hang_load, rope, None)
        return f"sim: {rope}'s loadcell carries the rope again"

    def _rope_call(self, fn: Callable[..., None], rope: str, *args: Any) -> None:
        key: int | str = int(rope) if rope.isascii() and rope.isdecimal() else rope
        try:
            fn(key, *args)
        except ValueError as exc:
            raise CommandError(str(exc)) from None


class ManipulatorWords(Component):
    """The manipulator's own top-level words (000 section 18): ``log``, ``debug``."""

    name = "words"

    def __init__(self, station: ManipulatorStation):
        self.station = station

    @command(Arg("FILE", str, optional=True, rest=True), name="log")
    def cmd_log(self, path: str | None = None) -> str:
        """log [FILE]: toggle logging of per-axis state and rule outputs every poll.

        The default file is manipulator.log in the station directory; split
        it with 'pyrt logsort FILE'."""
        st = self.station
        if st.polyaxis.log is not None:
            return f"logging off; log written to {st.stop_log()}"
        target = Path(path) if path else st.directory / "manipulator.log"
        return f"logging on: {st.start_log(target)}"

    @command(name="debug")
    def cmd_debug(self) -> str:
        """debug: toggle the debugging state (a status line every second)."""
        pa = self.station.polyaxis
        pa.debug = not pa.debug
        return f"debugging {'on' if pa.debug else 'off'}"


class ManipulatorStation(Station):
    """One manipulator on one loop (see the module text).

    ``directory``: the station database (written back while running);
    ``loop``: an existing loop (a SimClock loop with ``tick_ns`` by default);
    ``imperfections``: the sensors' (default: realistic, seeded);
    ``writer``: ``"sync"`` (SimClock default), ``"thread"`` (wall clock
    default) or a :class:`pyrt.tasks.Writer`; ``liquid_level``: z of the D2O
    surface for the world and the controller (default: the neck ring for a
    source with volume, else in air); ``boards``: the board URL (default
    ``sim:``; see the module text).  Boards that cannot be reached raise
    BoardError; a world that is not this station's, ConfigError.

    The station directory is locked for this process while the station
    lives (:func:`pyrt.db.lock_directory`: another process gets a
    ConfigError naming the holder's pid; ``lock=False`` for a station that
    is only read, as board-sim's); ``expect`` names the station the
    caller wants (``--station``): a database of another is a ConfigError.
    A database POSITION where the source may not be (outside the vessel and
    the neck) is a ConfigError naming the file and line.
    """

    #: The station database.
    directory: Path

    def __init__(
        self,
        directory: str | Path,
        *,
        loop: Loop | None = None,
        tick_ns: int = TICK_NS,
        poll_s: float = POLL_S,
        axis_poll_s: float = AXIS_POLL_S,
        imperfections: Imperfections | None = None,
        writer: Any = None,
        liquid_level: float | None = None,
        boards: str | None = None,
        expect: str | None = None,
        lock: bool = True,
    ):
        self.directory = Path(directory)
        # one process per directory (board-sim only reads it: lock=False)
        self._lock = lock_directory(self.directory) if lock else DirectoryLock(self.directory, None)
        try:
            self.station: StationDB = load_station(self.directory)
            pa_rec = self.station.polyaxis()
            if expect is not None and pa_rec.name.lower() != expect.lower():
                raise ConfigError(f"the database holds the {pa_rec.name.lower()!r} station, "
                                  f"not {expect.lower()!r}; give the matching --station or "
                                  "another --db", pa_rec.where.file, pa_rec.where.line)
            super().__init__(loop if loop is not None else Loop(SimClock(), period_ns=tick_ns))
            opened = open_boards(boards, pa_rec.name.lower(), MANIPULATOR_BOARDS)
        except BaseException:
            self._lock.release()
            raise
        try:
            self._build(opened, poll_s, axis_poll_s, imperfections, writer, liquid_level)
        except BaseException:
            try:
                opened.close()
            finally:
                self._lock.release()
            raise

    def close(self) -> None:
        """As :meth:`Station.close`, then the station directory is unlocked."""
        try:
            super().close()
        finally:
            self._lock.release()

    def _build(self, boards: Boards, poll_s: float, axis_poll_s: float,
               imperfections: Imperfections | None, writer: Any, liquid_level: float | None
               ) -> None:
        tick_s = self.loop.period_ns * 1e-9
        st = self.station
        pa_rec = st.polyaxis()
        self.av = AV.from_record(st.av_of(pa_rec))
        if liquid_level is None and pa_rec.source_volume > 0:
            liquid_level = self.av.neck_ring_position[2]
        self.liquid_level = liquid_level

        # Level 1: boards (their inputs read once before anything reads them).
        refuse_sim_options(boards, ["sensor imperfections (--ideal-sensors)"]
                           if imperfections is not None else [])
        want = pa_rec.name.lower()
        elsewhere = boards.simulated is None  # the world is board-sim's, not this process's
        if elsewhere and boards.world and boards.world.lower() != want:
            raise ConfigError(f"board URL {boards.url!r} serves the {boards.world!r} world, not "
                              f"this station's {want!r}: start 'pyrt board-sim {want}' with "
                              f"the same --db")
        self.attach_boards(boards)  # first in the tick: this tick's inputs
        boards.read_inputs(self.loop.now_ns)
        self.tio10 = boards["tio10"]
        self.dc = boards["dc"]
        # Level 3-4: devices and axes (encoders reset their counters).
        self.axes: list[Axis] = []
        fuzzy: list[FuzzyParams] = []
        base = FuzzyParams().for_poll_period(poll_s)
        for rec in st.axes_of(pa_rec):
            axis = Axis.from_records(rec.name.lower(), rec, st, self.tio10, self.dc, av=self.av)
            self.axes.append(axis)
            try:
                fuzzy.append(FuzzyParams.from_mapping(dict(rec.fuzzy), base=base))
            except NativeInputError as exc:
                raise rec.where.error(None, f"AXIS {rec.name}: {exc}") from None
        #: Every motor's armed register, read through its reader (the move watch's).
        self._motors_armed = tuple(a.motor.armed for a in self.axes)
        # Everything the PolyAxis works with is given here: the motion queue the
        # mailbox fills (the station's runner takes it), the loop's spawn and
        # the pattern log's writer, the stop listeners, the task periods.
        self.stops: list[StopRecord] = []
        self.polyaxis = PolyAxis(
            pa_rec, self.axes, self.av, PolyAxisServices(
                motion=self.motion, spawn=self.loop.spawn,
                pattern_writer="sync" if self.loop.clock.virtual else "thread",
                on_stop=(self.stops.append, self._stopped)),
            name=pa_rec.name.lower(), poll_s=poll_s, fuzzy=fuzzy, liquid_level=liquid_level,
            task_periods=(_checks(poll_s, tick_s, "control poll"),
                          _checks(axis_poll_s, tick_s, "axis poll")))
        pa = self.polyaxis
        model = pa.model
        self.name = pa.name

        # The world behind the boards, holding the source where the database says.
        pos = pa_rec.position
        why = model.refusal(pos)
        if why is not None:
            raise pa_rec.where.error("POSITION", f"POLYAXIS {pa_rec.name}: POSITION "
                                     f"({pos[0]:g}, {pos[1]:g}, {pos[2]:g}) cm is {why}")
        tensions = held_tensions(pa, pos)
        payouts = [payout(model.length_at(i, pos), tensions[i], a.stretch, a.dead_length)
                   for i, a in enumerate(self.axes)]
        self.rig = rig_from_station(st, liquid_level=liquid_level)
        sim = boards.simulated
        if sim is not None:  # else the world is board-sim's, built the same way
            self.plant = ManipulatorPlant(self.rig, sim["tio10"], sim["dc"],
                                          imperfections=imperfections, payouts=payouts)
        self.startup_notes = self._reconcile(pa_rec, payouts)
        # Every move of every kind is held to the ropes' physical length
        # ranges and the tension limits (tensionStop), in axis-poll.
        for a, r in zip(self.axes, rope_ranges(model), strict=True):
            a.set_supervision(r, (pa.low_tension, pa.max_tension),
                              lambda: pa.tension_stop)

        # Level 4+: the ready queue and its tasks; write-back.
        self.queue = ReadyQueue(capacity=4, divisor=1, name=pa.name)
        register_tasks(self.queue, pa)  # every task the tree declares
        if writer is None:
            writer = "sync" if self.loop.clock.virtual else "thread"
        if writer == "sync":
            writer = SyncWriter(st)
        elif writer == "thread":
            writer = ThreadWriter(st)
        self.writeback = WriteBack(st, writer)
        # While the position estimate is not trusted (a slipping or reset
        # encoder) nothing measured is written back: each watch reads its last
        # written value until 'survey' or 'setpos' re-establishes the position.
        for a, rec in zip(self.axes, st.axes_of(pa_rec), strict=True):
            read, box = _trusted(pa, _length_reader(a), lambda w: (w.last, False))
            box.append(self.writeback.watch_length(rec.name, read))
            zread, zbox = _trusted(pa, a.encoder.length, lambda w: w.last)
            zbox.append(self.writeback.watch_zerolength(st.encoder_of(rec).name, zread))
            a.loadcell.write_back = _calibration_writer(self.writeback, st.loadcell_of(rec).name,
                                                        self.loop, a.loadcell)
        pread, pbox = _trusted(pa, lambda: (pa.position, pa.active), lambda w: (w.last, False))
        pbox.append(self.writeback.watch_position(pa_rec.name, pread))
        if self.plant is not None:
            self.attach_world(self.plant.step, "plant")
        self.loop.attach(self.queue, name=f"queue:{pa.name}")
        self._writeback_failure: str | None = None
        #: What write-back could not write on the way out (said in the closing line).
        self.shutdown_failure: PyrtError | None = None
        self.loop.attach(self._write_back, name="writeback")

        self.profile = ShellProfile(words=ManipulatorWords(self), announce_stops=True)
        extras: list[Component] = []
        if self.plant is not None:
            extras.append(ManipulatorSim(self.plant, self.axes))
        else:  # the world runs elsewhere: what its back end tells of it
            extras.append(BoardWorld(boards))
        self.adopt(pa, queues=[self.queue], executors=[pa.executor], extras=extras,
                   where=self._where, ended=self._ended, status=pa.status_line)
        self.log_path: Path | None = None
        self._log_file: TextIO | None = None
        boards.read_inputs(self.loop.now_ns)  # the encoders' counters now ride along
        pa.measure()  # the first status line shows real tensions and lengths
        if elsewhere:  # a world built elsewhere, from its own database
            doubt = belief_doubt(pa_rec.position, pa.tensions, held_tensions(pa, pa_rec.position),
                                 pa.tension_find())
            if doubt is not None:
                self._distrust(pa_rec, boards, doubt)

    def _distrust(self, pa_rec: Any, boards: Boards, doubt: str) -> None:
        """The world disagrees with the database at start: the estimate is not
        trusted (moves refused until 'setpos X Y Z'), nothing measured is
        written back, and the start-up note says both positions and what to do."""
        x, y, z = pa_rec.position
        why = (f"the world disagrees with the database at start-up: {doubt}, not at "
               f"POSITION ({x:.2f}, {y:.2f}, {z:.2f}) cm of {self.directory / 'POLYAXIS.dat'}")
        todo = (f"give 'pyrt board-sim {pa_rec.name.lower()}' this station's --db "
                f"{self.directory} and restart both, or, where the source really is (board-sim's "
                f"'sim' shows it), '{self.polyaxis.name} setpos X Y Z'")
        self.polyaxis.estimator.estimate_lost = f"{why}; {todo}"
        self.startup_notes.append(f"moves refused: {why}; {todo}")

    def _reconcile(self, pa_rec: Any, payouts: list[float]) -> list[str]:
        """Start-up: the encoders' ZEROLENGTH and the axes' LENGTH from the
        database, checked against the ropes with the source at POSITION.

        An encoder within RECONCILE_COUNTS counts of its rope keeps its
        database ZEROLENGTH (the counter was reset: the length now is the
        zero length, 000 section 9); one further off is set from POSITION (the
        entry 000 says must be right before a start) and the note says by
        how much.  An AXIS LENGTH that disagrees is noted (write-back rewrites
        it).  Returns the notes (``startup_notes``; ``pyrt manipulator``
        prints them before its prompt)."""
        st = self.station
        notes: list[str] = []
        for a, p, rec in zip(self.axes, payouts, st.axes_of(pa_rec), strict=True):
            a.encoder.reset()
            db_zero = a.encoder.zero_length
            tol = RECONCILE_COUNTS * abs(a.encoder.slope)
            geometric = self.polyaxis.model.length_at(self.axes.index(a), pa_rec.position)
            if abs(db_zero - p) > tol:
                check_startup_correction(
                    st.encoder_of(rec), "ZEROLENGTH", db_zero, p,
                    explained=geometric - rec.length,
                    what="the rope's length with the source at POSITION",
                    check=f"AXIS {rec.name} DEADLENGTH and LENGTH (AXIS.dat)")
                a.encoder.zero_length = p
                notes.append(f"{a.encoder.name} ZEROLENGTH {db_zero:.3f} cm is "
                             f"{db_zero - p:+.3f} cm from the rope with the source at POSITION; "
                             f"set to {p:.3f} cm")
            if abs(rec.length - geometric) > tol:
                notes.append(f"AXIS {rec.name} LENGTH {rec.length:.3f} cm is "
                             f"{rec.length - geometric:+.3f} cm from the rope at POSITION "
                             f"({geometric:.3f} cm); write-back rewrites it")
        if not notes:
            notes.append("encoders and lengths agree with POSITION (ZEROLENGTH and LENGTH kept)")
        return notes

    # -- faults ----------------------------------------------------------------------

    def _write_back(self, now_ns: int) -> None:
        """Loop handler: the database write-back; a refused value (a length set
        to nonsense by hand) is a fault of the manipulator, reported once.
        Nothing while the boards cannot be reached (that fault says why), and
        nothing while the manipulator is faulted: what a dead loadcell or a
        slipping encoder measured is never written (after ``ack`` it resumes)."""
        if self.boards is not None and self.boards.down is not None:
            return
        if self.fault is not None:  # nothing measured while faulted is written back
            return
        try:
            self.writeback.poll(now_ns)
        except DiskError as exc:  # a disk that refuses: a fault each time
            self._writeback_failure = None
            self.trip(str(exc), source="WRITEBACK")
        except PyrtError as exc:
            cause = f"database write-back refused: {exc}"
            if cause != self._writeback_failure:
                self._writeback_failure = cause
                self.trip(cause, source="WRITEBACK")
        else:
            self._writeback_failure = None

    def stop(self) -> str:
        """The operator's stop: the move ended (a STOP), every motor stopped,
        queued moves and a running pattern dropped."""
        pa = self.polyaxis
        try:
            if pa.active:
                pa.stop()
        except BoardError as exc:  # the motors are still stopped below
            self.board_error = self.board_error or exc
        pa.pattern_job_cancel()
        return super().stop()

    stop_all = stop

    def journal_databases(self) -> dict[str, bytes]:
        """The six database files as they stand (a journal starts its replay from them)."""
        out: dict[str, bytes] = {}
        for name in FILES.values():
            path = self.directory / name
            if path.is_file():
                out[name] = path.read_bytes()
        return out

    def seeds(self) -> dict[str, int]:
        """The simulated sensors' seed (none on boards whose world runs elsewhere)."""
        return {"imperfections": int(self.plant.imp.seed)} if self.plant is not None else {}

    def snapshot_state(self) -> dict[str, Any]:
        """The controller's tree (PolyAxis with its estimator, move controller and
        the motion under way, the axes, motors, encoders and loadcells, the AV),
        for a black box that replays (:mod:`pyrt.station.snapshot`)."""
        return state_of(self._snapshot_objects())

    def restore_state(self, state: dict[str, Any]) -> None:
        """Put :meth:`snapshot_state` back."""
        restore_into(self._snapshot_objects(), state)

    def _snapshot_objects(self) -> dict[str, Any]:
        return {c.name: c for c in self.components() if all(c is not x for x in self.extras)}

    def busy(self) -> bool:
        """A move runs or waits, a pattern runs, or an axis moves on its own
        (the move watch asks every tick: each motor's armed register is read
        through its reader, bound once)."""
        pa = self.polyaxis
        if pa.mover.active or super().busy():
            return True
        job = pa.pattern_job
        if job is not None and not job.done:
            return True
        if not any(map(call, self._motors_armed)):  # at rest: no motor armed (C calls only)
            return False
        return any(a.mode == STANDALONE and a.motor.armed() for a in self.axes)

    def motors_running(self) -> list[str]:
        """Names of the motors that are stepping or have windings on."""
        return [a.motor.name for a in self.axes if a.motor.running]

    def check_motion(self, record: Any) -> None:
        pa = self.polyaxis
        job = pa.pattern_job
        if job is not None and not job.done:
            raise CommandError(f"motion {record.type}: a pattern is running ('{pa.name} stop' "
                               "ends it); nothing moved")

    def _where(self) -> str:
        """The source's estimated position (and that it is not trusted, when lost)."""
        x, y, z = self.polyaxis.position
        lost = "; position estimate not trusted" if self.polyaxis.estimate_lost else ""
        return f"source at ({x:.2f}, {y:.2f}, {z:.2f}) cm{lost}"

    def _stopped(self, rec: StopRecord) -> None:
        """The PolyAxis stopped (loop thread): the end of its move, said once."""
        self.end_move(str(rec), [f"{self.polyaxis.name} stopped: {rec}"])

    def _ended(self) -> tuple[str, list[str]]:
        """The manipulator went idle: how the pattern or the axes' own moves
        ended ('' when the PolyAxis's stop has said it all)."""
        pa = self.polyaxis
        job = pa.pattern_job
        if job is not None and job.done:
            pa.pattern_job = None
            if job.error is not None:
                text = f"error: pattern failed: {job.error}"
            else:
                text = f"pattern finished: {len(job.result or [])} endpoints; log {pa.pattern_log}"
            return text, [text]
        moved = [a for a in self.axes if a.moved]
        for a in moved:
            a.moved = False
        if moved and not self.moves_this_period:
            lines = [f"{a.name}: move ended at length {a.length():.3f} cm" for a in moved]
            return lines[0], lines
        return "", []

    # -- logging -------------------------------------------------------------------------

    def start_log(self, path: str | Path) -> Path:
        """Log per-axis state and rule outputs every control poll to ``path``."""
        self.stop_log()
        p = Path(path)
        try:
            fh = open(p, "w", encoding="utf-8")  # noqa: SIM115 - closed by stop_log
        except OSError as exc:
            raise CommandError(f"log: cannot write {str(p)!r}: {exc.strerror}") from None
        fh.write("# pyrt manipulator log: P t x y z distErr hare_x hare_y hare_z netForce; "
                 "S t axis length tension errorLength errorTension velocity dv "
                 "desiredTension free; R t axis rule0..rule9; TO; STOP\n")
        self._log_file = fh
        self.log_path = p
        self.polyaxis.log = lambda line: fh.write(line + "\n")
        return p

    def stop_log(self) -> Path | None:
        """Stop logging; returns the file that was written."""
        self.polyaxis.log = None
        fh, self._log_file = self._log_file, None
        if fh is not None:
            fh.close()
        return self.log_path if fh is not None else None

    # -- status and shutdown -------------------------------------------------------------

    def status_fields(self) -> list[tuple[str, Signal, str]]:
        """STATUS: x y z distErr netForce moving fault, then tension0 ... per rope."""
        pa = self.polyaxis
        sig = {s.name: s for s in pa.signals()}
        fields = [("x", sig["x"], ".2f"), ("y", sig["y"], ".2f"), ("z", sig["z"], ".2f"),
                  ("distErr", sig["distErr"], ".3f"), ("netForce", sig["netForce"], ".2f"),
                  ("moving", Signal("moving", "bool", self.busy, "a move runs or waits", "d"),
                   "d"), self.fault_field()]
        est = pa.estimator
        fields += [(f"tension{i}", Signal(f"tension{i}", "N", _item_of(lambda: pa.tensions, i),
                                          f"measured tension of {a.name}",
                                          source=Source.attr_item(est, "tensions", i),
                                          limits=tension_alarms(a.tension_limits)), ".2f")
                   for i, a in enumerate(self.axes)]
        return fields

    def served_signals(self) -> list[Signal]:
        """The running move's endpoint (NaN between moves): read back only; a move
        is started through CMD with the token."""
        pa = self.polyaxis

        def coord(k: int) -> float:
            end = pa.endpoint if pa.active else None
            return math.nan if end is None else float(end[k])

        return [Signal(f"target_{c}", "cm", partial(coord, k),
                       f"endpoint {c} of the move (NaN: none)", ".2f",
                       limits=pa.position_limits(k))
                for k, c in enumerate("xyz")]

    def closing_note(self) -> str:
        """Where the source was left, and what became of the databases."""
        here = super().closing_note()
        if self.shutdown_failure is not None:
            return (f"{here}; databases in {self.directory} keep the values last written "
                    f"({self.shutdown_failure})")
        if self.fault is not None:
            return (f"{here}; databases in {self.directory} keep the values last written "
                    "before the fault")
        if self.boards is not None and self.boards.down is not None:
            return f"{here}; databases in {self.directory} keep the values last written"
        if self.polyaxis.estimate_lost is not None:
            return (f"{here}; databases written back in {self.directory}, except POSITION, "
                    "LENGTH and ZEROLENGTH (the position estimate is not trusted: they keep "
                    "the values last written before it was lost)")
        return f"{here}; databases written back in {self.directory}"

    def write_back(self) -> None:
        """Write pending database values, close the log (on the way out).
        Boards that cannot be reached leave the values last written."""
        try:
            if self.boards is not None and self.boards.down is not None:
                return
            if self.fault is not None:  # measured while faulted: not written
                return
            self.writeback.poll(self.loop.now_ns + 10**12)
        except PyrtError as exc:  # the file keeps its last good value
            self.shutdown_failure = exc
            self.say(f"database write-back refused at shutdown: {exc}", "error")
        finally:
            self.shutdown_failure = self.writeback.close() or self.shutdown_failure
            self.stop_log()


def held_tensions(pa: PolyAxis, x: Sequence[float]) -> list[float]:
    """The tensions that hold the source at ``x`` as the controller leaves it
    (the world's start: the equilibrium, no rope below LOW_TENSION + 1 N)."""
    tensions, _ = pa.model.equilibrium_tensions(x)
    return [max(t, pa.low_tension + 1.0) for t in tensions]


def belief_doubt(position: Sequence[float], measured: Sequence[float],
                 held: Sequence[float], found: Sequence[float]) -> str | None:
    """Whether the loadcells contradict the source at the database ``position``,
    as far as they can tell: the position the ``measured`` tensions give
    (``found``, tensionFind) is more than BELIEF_CM from it.  Returns what
    they say instead, with the rope whose tension differs most from those
    that hold the source at ``position`` (``held``); None: no contradiction."""
    far = math.dist(found, position)
    if far <= BELIEF_CM:
        return None
    diffs = [m - h for m, h in zip(measured, held, strict=True)]
    worst = max(range(len(diffs)), key=lambda i: abs(diffs[i]))
    return (f"the rope tensions put the source near ({found[0]:.2f}, {found[1]:.2f}, "
            f"{found[2]:.2f}) cm, {far:.0f} cm away (rope {worst} holds "
            f"{measured[worst]:.1f} N where POSITION needs {held[worst]:.1f} N)")


def rope_ranges(model: RopeModel, cells: int = 12) -> list[tuple[float, float]]:
    """Every rope's physical length range (cm): the least and greatest length
    with the source anywhere it may be (the vessel sphere and the neck,
    :meth:`RopeModel.refusal`), sampled on a grid of ``cells`` per vessel
    diameter and over the sphere's surface, widened by ROPE_RANGE_MARGIN."""
    av = model.av
    r = av.vessel_radius
    ring = av.neck_ring_static_position
    pts: list[tuple[float, float, float]] = []
    step = 2.0 * r / cells
    grid = [-r + k * step for k in range(cells + 1)]
    pts += [(x, y, z) for x in grid for y in grid for z in grid]
    for i in range(13):  # the sphere's surface
        th = math.pi * i / 12
        for j in range(24):
            ph = 2.0 * math.pi * j / 24
            pts.append((0.999 * r * math.sin(th) * math.cos(ph),
                        0.999 * r * math.sin(th) * math.sin(ph), 0.999 * r * math.cos(th)))
    nr = av.neck_radius
    # The neck, up to its top, finely: the highest point a move may reach there
    # sets the central ropes' shortest length, so it must be sampled, not
    # bracketed (the margin is for rounding, not for a missed region).
    for h in (av.neck_length * k / 32 for k in range(33)):
        for dx, dy in ((0.0, 0.0), (nr, 0.0), (-nr, 0.0), (0.0, nr), (0.0, -nr)):
            pts.append((ring[0] + 0.999 * dx, ring[1] + 0.999 * dy, ring[2] + h))
    gpts = [av.vtog(v) for v in pts]
    # Where a top pulley is within reach (the central ropes up the neck), a
    # rope is shortest with the carriage MIN_TOP_SEGMENT from its pulley, the
    # closest 'to' allows: sample that sphere too.
    dirs = [(a, b, c) for a in (-1, 0, 1) for b in (-1, 0, 1) for c in (-1, 0, 1) if a or b or c]
    for top, off in zip(model.tops, model.offsets, strict=True):
        for d in dirs:
            k = 1.001 * MIN_TOP_SEGMENT / math.sqrt(d[0] ** 2 + d[1] ** 2 + d[2] ** 2)
            gpts.append((top[0] - off[0] + k * d[0], top[1] - off[1] + k * d[1],
                         top[2] - off[2] + k * d[2]))
    lo = [math.inf] * model.n
    hi = [0.0] * model.n
    for x in gpts:
        if model.refusal(x) is not None:
            continue
        try:
            lengths = model.lengths_at(x)
        except NativeError:  # a sample on a pulley, an attachment or the ring's rim
            continue
        for i, length in enumerate(lengths):
            lo[i] = min(lo[i], length)
            hi[i] = max(hi[i], length)
    return [(round(max(0.0, a - ROPE_RANGE_MARGIN), 1), round(b + ROPE_RANGE_MARGIN, 1))
            for a, b in zip(lo, hi, strict=True)]


def _checks(period_s: float, tick_s: float, what: str) -> int:
    n = round(period_s / tick_s)
    if not 1 <= n <= 255:
        raise ConfigError(f"{what} of {period_s:g} s is {n} ticks of {tick_s * 1e3:g} ms; "
                          "it must be 1..255 ticks")
    return n


def _trusted(pa: PolyAxis, read: Callable[[], Any], held: Callable[[Any], Any]
             ) -> tuple[Callable[[], Any], list[Any]]:
    """``read`` while the estimate is trusted, else ``held(watch)`` (the value last
    written: nothing is written); the watch goes in the returned list."""
    box: list[Any] = []

    def value() -> Any:
        if pa.estimate_lost is not None and box and box[0].last is not None:
            return held(box[0])
        return read()
    return value, box


def _length_reader(axis: Axis) -> Callable[[], tuple[float, bool]]:
    armed = axis.motor.armed  # the motor's armed register, bound once

    def read() -> tuple[float, bool]:
        return axis.length(), armed() != 0
    return read


def _calibration_writer(wb: WriteBack, loadcell: str, loop: Loop, device: Any
                        ) -> Callable[[float, float], None]:
    def write(slope: float, offset: float) -> None:
        wb.loadcell_calibrated(loadcell, slope, offset, now_ns=loop.now_ns,
                               date=device.date or None,
                               points=device.calibration_points or None)
    return write


# -- the factory: ``pyrt manipulator`` -----------------------------------------------------


class ManipulatorWorlds(WorldFactory):
    """A manipulator's boards and world for ``pyrt board-sim manipulator``
    (:class:`ManipulatorFactory` has them): the TIO10 (board ``tio10``) and
    dataConcentrator (board ``dc``) with the rope world of a station database
    behind them, the source at its POSITION; ``board-sim prototype`` and
    ``board-sim sno`` are ``board-sim manipulator --station`` that station.

    The world's rope payouts come from the controller's own equilibrium at
    that POSITION (as the in-process station sets its encoders' zero
    lengths), so the station is built here, reading the database only, and
    its world is served (on boards of its own: those given are closed)."""

    name = "manipulator"
    world_aliases: dict[str, dict[str, Any]] = {
        name: {"station": name} for name in STATIONS}
    #: Which database the last :meth:`world` was built from (board-sim says it).
    world_origin = ""

    def board_kinds(self) -> dict[str, BoardKind]:
        return dict(MANIPULATOR_BOARDS)

    def add_world_arguments(self, parser: argparse.ArgumentParser) -> None:
        g = parser.add_argument_group("manipulator world")
        g.add_argument("--station", choices=STATIONS, default=None,
                       help="packaged station to serve when no --db is given (default "
                            "prototype); with --db, the station the database must hold")
        g.add_argument("--db", metavar="DIR",
                       help="station database to build the world from, read only "
                            "(default: the packaged --station)")
        g.add_argument("--ideal-sensors", action="store_true",
                       help="switch off encoder quantisation and loadcell noise/offsets")

    def world(self, boards: Boards, args: argparse.Namespace) -> World:
        boards.close()
        name = getattr(args, "station", None)
        db = getattr(args, "db", None)
        directory = Path(db) if db else station_directory(name or "prototype")
        imp = Imperfections.ideal() if getattr(args, "ideal_sensors", False) else None
        station = ManipulatorStation(directory, writer="sync", imperfections=imp, lock=False,
                                     expect=name if db else None)
        x, y, z = station.station.polyaxis().position
        here = f"the source at its POSITION ({x:.2f}, {y:.2f}, {z:.2f}) cm"
        self.world_origin = (
            f"world from the database {directory.resolve()}, {here}; run the controller "
            f"with the same --db" if db else
            f"world from the packaged {name or 'prototype'} database ({directory}), {here}; "
            "a controller whose database holds another POSITION refuses to move: give "
            "both the same --db DIR")
        return ManipulatorWorld(station.plant, station.polyaxis.name)


class ManipulatorFactory(ManipulatorWorlds, StationFactory):
    """pyrt manipulator: the SNO source manipulator controller (000) on a simulated world.

Commands are addressed to named objects, as the document's
Hardware::doCommand: prototype to 0 0 150, axis1 up 5, axis0Motor
maxspeed 3, axis0Encoder read, axis0Loadcell calibrate; plus the shared
words (help [object [verb]], wait, sleep, stop, ack, status, statusline, show, stats, scope,
motion, get, set, clear, quit) and the manipulator's log and debug; sim is
the simulated world's object.  Type help.

Without --db DIR the packaged station (--station) is copied to a
working directory first (existing files there are kept: they carry the last
position), and the run says where; --init-db DIR seeds DIR from it the
same way and runs there; the database is written back while the
manipulator runs. One process at a time may run on a database directory (a
second is refused, naming the first one's pid); --station with --db names
the station the database must hold. The base tick defaults to 5 ms for
this robot: the physics steps every tick (a motor at its 7.0 cm/s limit makes
1.4 half-steps a tick), the control poll is 50 ms and the standalone axis poll
10 ms (so a tick is at most 10 ms), and --speed max then runs a move some 50
times faster than real time.

With --boards tcp://HOST:PORT the controller drives the TIO10 and
dataConcentrator of a 'pyrt board-sim prototype|sno' in another process
(give both the same --db DIR; board-sim's first line names the URL):
the world moves there at real time, so only --speed 1 is accepted,
--ideal-sensors is board-sim's option, and its world must be this
station's.
"""

    name = "manipulator"
    summary = ("run the 000 SNO source manipulator controller on a simulated world "
               "(or on pyrt board-sim's, --boards tcp://...)")
    description = __doc__ or ""
    #: The base tick (see the description).
    default_tick_us = 5000
    #: The standalone axis poll runs every AXIS_POLL_S: a longer tick cannot run it.
    max_tick_us = round(AXIS_POLL_S * 1e6)
    max_tick_why = (f"the axis poll runs every {AXIS_POLL_S * 1e3:g} ms and the control poll "
                    f"every {POLL_S * 1e3:g} ms")

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        g = parser.add_argument_group("station database")
        g.add_argument("--db", metavar="DIR", help="station database directory (written back)")
        g.add_argument("--init-db", metavar="DIR",
                       help="seed DIR with the packaged station (--station; database files "
                            "already there are kept), then run on it as --db DIR")
        g.add_argument("--station", choices=STATIONS, default=None,
                       help="packaged station to copy when no --db is given (default "
                            "prototype); with --db, the station the database must hold")
        s = parser.add_argument_group("simulation (sim: boards only)")
        s.add_argument("--ideal-sensors", action="store_true",
                       help="switch off encoder quantisation and loadcell noise/offsets "
                            "(in-process world only)")

    def configure(self, args: argparse.Namespace, say: Callable[[str], None]) -> None:
        """Find, seed or copy the station database; ``args.directory`` is where it is."""
        if args.db and args.init_db:
            raise UsageError("give --db DIR (an existing database) or --init-db DIR (seed "
                             "one), not both")
        if args.init_db:
            args.station = args.station or "prototype"
            try:
                directory = copy_station(args.station, args.init_db)
            except OSError as exc:
                raise ConfigError(f"cannot seed a station database there: {exc.strerror}",
                                  args.init_db) from None
            say(f"pyrt manipulator: {directory} seeded from the packaged {args.station} "
                "station (files already there kept)")
        elif args.db:
            directory = Path(args.db)
            if not (directory / FILES["POLYAXIS"]).is_file():
                what = "no such directory" if not directory.is_dir() else "no station database"
                raise UsageError(f"--db {args.db}: {what}; seed it with 'pyrt manipulator "
                                 f"--init-db {args.db} --station {'|'.join(STATIONS)}'")
        else:
            args.station = args.station or "prototype"
            directory = default_working_directory(args.station)
            copy_station(args.station, directory)
            say(f"pyrt manipulator: working copy of the {args.station} station in {directory}")
        args.directory = Path(directory)

    def build(self, loop: Loop, args: argparse.Namespace) -> ManipulatorStation:
        if getattr(args, "directory", None) is None:
            self.configure(args, lambda _line: None)
        imp = Imperfections.ideal() if args.ideal_sensors else None
        try:
            return ManipulatorStation(args.directory, loop=loop, imperfections=imp,
                                      boards=args.boards, expect=args.station)
        except ConfigError as exc:
            if args.db or args.init_db:
                raise
            # The working copy keeps what earlier runs wrote, and may predate a
            # change to the packaged station: say how to start afresh.
            raise ConfigError(f"{exc.message}; this working copy may come from an earlier "
                              f"pyrt: move {args.directory} aside to start again from the "
                              f"packaged {args.station} station", exc.file, exc.line) from None

    def banner(self, station: Station, args: argparse.Namespace) -> str:
        assert isinstance(station, ManipulatorStation)
        speed = ("max (simulated time)" if args.speed is None
                 else f"{args.speed:g}x real time")
        boards = station.boards
        where = "" if station.plant is not None or boards is None else f", boards at {boards.url}"
        return (f"pyrt manipulator: {station.polyaxis.name}, {len(station.axes)} ropes, "
                f"database {args.directory}{where}; tick {args.tick_us} µs, speed {speed}; "
                f"{self.next_step(args)}")


#: ``pyrt manipulator`` (registered in the entry-point group ``pyrt.stations``).
MANIPULATOR = ManipulatorFactory()
