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
OFFSIDE_TENSION, the others balancing the weight); the encoders' zero
lengths are set to the world's rope lengths (as ``setZeroLength`` would be
after surveying the source in), and ZEROLENGTH write-back keeps them.
``FUZZY_<NAME>`` keys of an AXIS entry override that axis's fuzzy
parameters as used at the 50 ms poll.
"""

from __future__ import annotations

import sys
import threading
from collections.abc import Callable, Generator
from pathlib import Path
from typing import Any, TextIO

from pyrt.boards.simboards import SimDataConcentrator, SimTIO10
from pyrt.db import Station, load_station
from pyrt.errors import CommandError, ConfigError, NativeError, PyrtError
from pyrt.native import FuzzyParams, NativeInputError
from pyrt.robots.av import AV
from pyrt.robots.axis import Axis
from pyrt.robots.polyaxis import PolyAxis, parse_pattern
from pyrt.robots.stops import StopRecord
from pyrt.scheduler import Loop, ReadyQueue, SimClock
from pyrt.scheduler.runner import MotionQueue
from pyrt.scope import Source
from pyrt.sim.manipulator import ManipulatorPlant, rig_from_station
from pyrt.sim.sensors import Imperfections
from pyrt.tasks import SyncWriter, ThreadWriter, WriteBack
from pyrt.tasks.manipulator import attach_manipulator

__all__ = [
    "AXIS_POLL_S",
    "POLL_S",
    "TICK_NS",
    "ManipulatorStation",
    "MessageSink",
]

TICK_NS = 1_000_000
POLL_S = 0.05
AXIS_POLL_S = 0.01


class MessageSink:
    """A text stream for the loop side: whole lines go to ``target`` (the
    runner's ``post``), so device output never garbles the console."""

    def __init__(self, target: Callable[[str], None] | None = None):
        self.target = target
        self._buf = ""
        self._lock = threading.Lock()
        self.pending: list[str] = []

    def write(self, text: str) -> int:
        with self._lock:
            self._buf += text
            *lines, self._buf = self._buf.split("\n")
        for line in lines:
            if self.target is not None:
                self.target(line)
            else:
                self.pending.append(line)
        return len(text)

    def flush(self) -> None:
        """Lines are passed on as they complete."""

    def connect(self, target: Callable[[str], None]) -> None:
        """Send lines to ``target`` from now on (and the ones held so far)."""
        self.target = target
        held, self.pending = self.pending, []
        for line in held:
            target(line)


class ManipulatorStation:
    """One manipulator on one loop (see the module text).

    ``directory``: the station database (written back while running);
    ``loop``: an existing loop (a SimClock loop with ``tick_ns`` by default);
    ``imperfections``: the sensors' (default: realistic, seeded);
    ``writer``: ``"sync"`` (SimClock default), ``"thread"`` (wall clock
    default) or a :class:`pyrt.tasks.Writer`; ``liquid_level``: z of the D2O
    surface for the world and the controller (default: the neck ring for a
    source with volume, else in air).
    """

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
        stdout: TextIO | None = None,
    ):
        self.directory = Path(directory)
        self.station: Station = load_station(self.directory)
        self.loop = loop if loop is not None else Loop(SimClock(), period_ns=tick_ns)
        tick_s = self.loop.period_ns * 1e-9
        self.messages = MessageSink()
        self.stdout = stdout if stdout is not None else self.messages
        st = self.station
        pa_rec = st.polyaxis()
        self.av = AV.from_record(st.av_of(pa_rec))
        if liquid_level is None and pa_rec.source_volume > 0:
            liquid_level = self.av.neck_ring_position[2]
        self.liquid_level = liquid_level

        # Level 1: boards.  Level 3-4: devices and axes (encoders reset their counters).
        self.tio10 = SimTIO10()
        self.dc = SimDataConcentrator()
        self.axes: list[Axis] = []
        fuzzy: list[FuzzyParams] = []
        base = FuzzyParams().for_poll_period(poll_s)
        for rec in st.axes_of(pa_rec):
            axis = Axis.from_records(rec.name.lower(), rec, st, self.tio10, self.dc, av=self.av,
                                     stdout=self.stdout)
            self.axes.append(axis)
            try:
                fuzzy.append(FuzzyParams.from_mapping(dict(rec.fuzzy), base=base))
            except NativeInputError as exc:
                raise rec.where.error(None, f"AXIS {rec.name}: {exc}") from None
        self.polyaxis = PolyAxis.from_record(
            pa_rec, self.axes, self.av, poll_s=poll_s, fuzzy=fuzzy,
            liquid_level=liquid_level, stdout=self.stdout)
        self.polyaxis.name = pa_rec.name.lower()
        pa = self.polyaxis

        # The world behind the boards, holding the source where the database says.
        pos = pa_rec.position
        tensions, _ = pa.equilibrium_tensions(pos)
        tensions = [max(t, pa.low_tension + 1.0) for t in tensions]
        payouts = []
        for i, a in enumerate(self.axes):
            g = pa.rope_geometry(i, pos)[0]
            payouts.append((a.dead_length + g) / (1.0 + a.stretch * tensions[i]))
        self.rig = rig_from_station(st, liquid_level=liquid_level)
        self.plant = ManipulatorPlant(self.rig, self.tio10, self.dc,
                                      imperfections=imperfections, payouts=payouts)
        for a, p in zip(self.axes, payouts, strict=True):
            a.encoder.reset()
            a.encoder.zero_length = p

        # The motion queue the mailbox fills (Runner(loop, motion_queue=...)).
        self.motion = MotionQueue(capacity=16)
        pa.motion = self.motion

        # Level 4+: the ready queue and its tasks; write-back.
        self.queue = ReadyQueue(capacity=4, divisor=1, name=pa.name)
        self.queue.reflex = pa.reflex
        pa.on_fault = self._trip
        attach_manipulator(self.queue, pa,
                           poll_checks=_checks(poll_s, tick_s, "control poll"),
                           axis_poll_checks=_checks(axis_poll_s, tick_s, "axis poll"))
        if writer is None:
            writer = "sync" if self.loop.clock.virtual else "thread"
        if writer == "sync":
            writer = SyncWriter(st)
        elif writer == "thread":
            writer = ThreadWriter(st)
        self.writeback = WriteBack(st, writer)
        for a, rec in zip(self.axes, st.axes_of(pa_rec), strict=True):
            self.writeback.watch_length(rec.name, _length_reader(a))
            self.writeback.watch_zerolength(st.encoder_of(rec).name, a.encoder.length)
            a.loadcell.write_back = _calibration_writer(self.writeback, st.loadcell_of(rec).name,
                                                        self.loop)
        self.writeback.watch_position(pa_rec.name, lambda: (pa.position, pa.active))
        self.loop.attach(self.plant.step, name="plant")
        self.loop.attach(self.queue, name=f"queue:{pa.name}")
        self._writeback_failure: str | None = None
        self.loop.attach(self._write_back, name="writeback")

        self.objects: dict[str, object] = {pa.name: pa, self.av.name.lower(): self.av}
        for a in self.axes:
            for obj in (a, a.motor, a.encoder, a.loadcell):
                self.objects[obj.name.lower()] = obj
        self.log_path: Path | None = None
        self._log_file: TextIO | None = None
        self.stops: list[StopRecord] = []
        pa.on_stop.append(self.stops.append)
        pa.on_stop.append(self._report_stop)
        try:  # the first status line shows real tensions and lengths
            pa.measure()
        except NativeError as exc:
            pa.position_error = f"position finder failed: {exc}"

    def _report_stop(self, rec: StopRecord) -> None:
        """Every stop is reported as it happens (asynchronous output)."""
        self.stdout.write(f"{self.polyaxis.name} stopped: {rec}\n")

    # -- faults ----------------------------------------------------------------------

    def _write_back(self, now_ns: int) -> None:
        """Loop handler: the database write-back; a refused value (a length set
        to nonsense by hand) is a fault of the manipulator, reported once."""
        try:
            self.writeback.poll(now_ns)
        except PyrtError as exc:
            cause = f"database write-back refused: {exc}"
            if cause != self._writeback_failure:
                self._writeback_failure = cause
                self.queue.now_ns = now_ns
                self.queue.trip(cause, source="WRITEBACK")
        else:
            self._writeback_failure = None

    def _trip(self, cause: str, source: str) -> None:
        self.queue.trip(cause, source=source)

    @property
    def fault(self):
        """The fault that stopped the manipulator, or None."""
        return self.queue.fault

    def acknowledge(self) -> str:
        """Clear the fault; the routines start again (the motors stay stopped)."""
        if self.queue.fault is None:
            return "no fault to acknowledge"
        self.polyaxis.stop_motors()
        self.queue.acknowledge()
        return "fault acknowledged; motors stopped, control polls running"

    def stop_all(self) -> None:
        """Every motor stopped, windings off, queued moves dropped (``quit``)."""
        self.motion.clear()
        pa = self.polyaxis
        if pa.active:
            pa.stop()
        else:
            pa.stop_motors()

    def busy(self) -> bool:
        """A move runs or waits on the motion queue."""
        return self.polyaxis.active or len(self.motion) > 0

    def motors_running(self) -> list[str]:
        """Names of the motors that are stepping or have windings on."""
        return [a.motor.name for a in self.axes if a.motor.running]

    # -- commands ----------------------------------------------------------------------

    def lookup(self, name: str) -> object:
        """The object called ``name`` (case-insensitive), or CommandError."""
        obj = self.objects.get(name.lower())
        if obj is None:
            raise CommandError(f"no object named {name!r}; objects: {', '.join(self.names())}")
        return obj

    def names(self) -> list[str]:
        """Object names in the document's spelling (``axis0Motor``)."""
        return [getattr(o, "name", k) for k, o in self.objects.items()]

    def check_ready(self, what: str) -> None:
        """Refuse a motion command while a fault is not acknowledged."""
        if self.queue.fault is not None:
            raise CommandError(f"{what}: refused: the manipulator is stopped by a fault "
                               f"({self.queue.fault.cause}); give 'ack' first; nothing moved")

    def pattern_job(self, path: str | Path) -> Generator[None, None, list]:
        """Read a pattern file (first line: log file) and return its job."""
        log, points = parse_pattern(path)
        try:
            log.parent.mkdir(parents=True, exist_ok=True)
            log.open("a", encoding="utf-8").close()
        except OSError as exc:
            raise CommandError(f"pattern: cannot write the log {str(log)!r}: "
                               f"{exc.strerror}") from None
        self.pattern_log = log
        return self.polyaxis.pattern(points, log, lambda: self.loop.now_ns * 1e-9)

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

    # -- scope channels --------------------------------------------------------------------

    def resolve_channel(self, name: str) -> Source:
        """A scope channel: ``prototype.x|y|z|distErr|netForce``,
        ``axis0.tension|length|errorLength|errorTension|velocity``,
        ``axis0Motor.velocity|desiredVelocity|speed``,
        ``axis0Encoder.length``, ``axis0Loadcell.tension`` (case-insensitive)."""
        obj_name, dot, field = name.strip().partition(".")
        if not dot or not field:
            raise ValueError(f"channel {name!r}: expected OBJECT.FIELD, e.g. axis0.tension")
        obj = self.objects.get(obj_name.lower())
        if obj is None:
            raise ValueError(f"channel {name!r}: no object {obj_name!r}")
        f = field.lower()
        pa = self.polyaxis
        if obj is pa:
            table: dict[str, Callable[[], float]] = {
                "x": lambda: pa.position[0], "y": lambda: pa.position[1],
                "z": lambda: pa.position[2], "disterr": lambda: pa.dist_err,
                "netforce": lambda: pa.net_force_magnitude,
            }
            if f in table:
                return Source.call(table[f])
        elif isinstance(obj, Axis):
            i = self.axes.index(obj)
            lists = {"tension": pa.tensions, "length": pa.lengths,
                     "errorlength": pa.error_lengths, "errortension": pa.error_tensions}
            if f in lists:
                return Source.item(lists[f], i)
            if f == "velocity":
                return Source.attr(obj.motor, "velocity")
        elif obj in [a.motor for a in self.axes]:
            attrs = {"velocity": "velocity", "desiredvelocity": "desired_velocity"}
            if f in attrs:
                return Source.attr(obj, attrs[f])
            if f == "speed":
                return Source.call(obj.speed)  # type: ignore[attr-defined]
        elif obj in [a.encoder for a in self.axes] and f == "length":
            return Source.call(obj.length)  # type: ignore[attr-defined]
        elif obj in [a.loadcell for a in self.axes] and f == "tension":
            return Source.call(obj.tension)  # type: ignore[attr-defined]
        raise ValueError(f"channel {name!r}: {getattr(obj, 'name', obj_name)} has no "
                         f"channel {field!r}")

    # -- status and shutdown -------------------------------------------------------------

    def status(self) -> str:
        """The status line (position, distErr, residual force, tensions, time)."""
        line = self.polyaxis.status_line()
        if self.queue.fault is not None:
            line += f"  FAULT: {self.queue.fault.cause}"
        return line

    def close(self) -> None:
        """Stop the motors, write pending database values, close the log."""
        self.stop_all()
        try:
            self.writeback.poll(self.loop.now_ns + 10**12)
        except PyrtError as exc:  # the file keeps its last good value
            self.stdout.write(f"database write-back refused at shutdown: {exc}\n")
        finally:
            self.writeback.close()
            self.stop_log()


def _checks(period_s: float, tick_s: float, what: str) -> int:
    n = round(period_s / tick_s)
    if not 1 <= n <= 255:
        raise ConfigError(f"{what} of {period_s:g} s is {n} ticks of {tick_s * 1e3:g} ms; "
                          "it must be 1..255 ticks")
    return n


def _length_reader(axis: Axis) -> Callable[[], tuple[float, bool]]:
    def read() -> tuple[float, bool]:
        return axis.getLength(), axis.motor.running
    return read


def _calibration_writer(wb: WriteBack, loadcell: str, loop: Loop
                        ) -> Callable[[float, float], None]:
    def write(slope: float, offset: float) -> None:
        wb.loadcell_calibrated(loadcell, slope, offset, now_ns=loop.now_ns)
    return write


def _stderr_sink(line: str) -> None:  # pragma: no cover - used without a console
    sys.stderr.write(line + "\n")
