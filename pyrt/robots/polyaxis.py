"""Co-ordinated control of the ropes: the PolyAxis of 000, section 5.

The manipulator wing is three parts, one module each:

* :mod:`pyrt.robots.ropes`: the rope model, stateless (geometry, statics,
  the refusal checks, the stretch formula, one Gauss-Newton);
* :mod:`pyrt.robots.estimator`: the position estimate (measure, integrity,
  ``survey`` and ``setpos``);
* this module: the :class:`PolyAxis` controller (motion, drive, stops and
  the commands), which owns its control poll.

Every control poll (:meth:`PolyAxis.poll`, run by the polyaxis-poll task,
:mod:`pyrt.tasks.polyaxis_poll`, which :meth:`PolyAxis.tasks` declares
beside axis-poll), in this order:

1. the time since the previous poll (``dt``; the poll period on the first);
2. the estimator measures: each Axis's tension and stretch-corrected length
   are read; rope segments that bear on the neck ring get their contact
   point as effective top (upper segment) or effective bottom (lower
   segment, with the source up in the neck): the finder sees the rope from
   there, its measured length less the piece beyond the contact.  The model
   is the world's (csrc/neck.h, both segments; ``ring_segments`` names where
   a controller deliberately knows less).  Then ``findPositionL`` runs
   through the prepared C solver (:class:`pyrt.native.PositionFinder`,
   freeze mask from the bottom attachments): position and distErr (the RMS
   length residual); the residual net force on the source is the sum of the
   measured tensions along the ropes plus the net weight (buoyancy in D2O
   when submerged).  A position finder that fails keeps the last position
   and refuses moves; during a move it is a fault of the whole manipulator,
   and the poll ends there.  Then the estimate is checked
   (:meth:`~pyrt.robots.estimator.PositionEstimator.check`), moving or not;
3. the running motion (:mod:`pyrt.scheduler.motion`: the built-in
   ``hare_path`` of :mod:`pyrt.robots.paths`, or any plug-in motion type) is
   stepped by the PolyAxis's :class:`MotionExecutor`, which takes the queued
   motion records in order; the motion sets the hare (``hare_position``),
   the point the source is driven after;
4. during a move, the error signals are set (``errorSignal``: length errors
   against the hare on every rope, off-side ropes driven toward
   OFFSIDE_TENSION, the others free; or ``errorSignalAll``: every rope driven
   toward the equilibrium tensions), the ten fuzzy rules run for every Axis
   in one batched C call (:class:`pyrt.native.FuzzyBatch`), each Motor gets
   its new desired velocity and applies DV_LIMIT and the speed limits in its
   poll; the five stop conditions (:mod:`pyrt.robots.stops`) are checked,
   here and not in the motion, so no motion type can bypass the safety stops;
5. the encoders of the ropes under PolyAxis control are polled (axis-poll
   skips those axes);
6. with ``debug`` on, a status line every second.

The numeric work of step 2 (after the device reads) and of step 4 (up to
the motors) is two C calls per poll (:class:`pyrt.native.PolyControl`,
csrc/polyctl.c, which calls the prepared finder and the fuzzy batch from
C): Python reads the devices, steps the motion, sets the motors and checks
the stops.

A motion type for the manipulator gets the PolyAxis as its robot.  It may
read ``position``, ``dist_err``, ``tensions``, ``lengths``,
``net_force``, ``now_s`` and ``dt`` (the time since the last poll, s), may
call ``check_target``, and sets ``hare_position`` in each ``step``; an
``endpoint`` attribute (None by default) arms ENDPOINT_STOP and STUCK_STOP.
An exception in its ``step``, or a hare that is not a finite point inside
the vessel or neck, is a fault of the manipulator (the reflex: every motor
stopped, windings off, queued motions dropped); a motion that ends itself
stops the motors with ``DONE`` and its reason.

Any stop stops every motor of the manipulator (windings off) and hands the
axes back to standalone control.  The safety stops (tension, net force),
a lost estimate and a failing motion are also faults, reported only
through :meth:`~pyrt.component.Component.fail` (the station's one fault
path): the reflex runs, and the manipulator stays stopped until
acknowledged.  Targets are refused before anything moves when outside the
vessel, out of a planar station's plane, within TENSION_MARGIN of the
tension bounds, or when the path passes points where the source could not
be held (:meth:`pyrt.robots.ropes.RopeModel.target_refusal`).

Patterns (``pattern FILE``: endpoint after endpoint, with a log) run as a
foreground job from :mod:`pyrt.robots.pattern`; the log is written through
a writer, off the loop thread unless the clock is simulated.

Everything a PolyAxis works with is given to its constructor: the motion
queue, the loop's ``spawn``, the pattern writer, the stop listeners, the
task periods.

The corrected length of 000 is the measured length less the rope's length
residual, so that errors of the position estimate do not appear as error
terms; errors are actual - desired.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Generator, Sequence
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from pyrt.component import Arg, Component, Limits, Signal, command, finite
from pyrt.db import defaults
from pyrt.devices.motor import STEP_MODE
from pyrt.errors import CommandError, ConfigError, NativeError
from pyrt.native import (
    FuzzyBatch,
    FuzzyInput,
    FuzzyParams,
    PolyControl,
    PositionFinder,
)
from pyrt.robots.av import AV
from pyrt.robots.axis import POLYAXIS, Axis
from pyrt.robots.estimator import SLIP_COUNTS, SNAPSHOT_POLLS, PositionEstimator
from pyrt.robots.paths import Hare, HarePath, hare_path_record, plan_segments
from pyrt.robots.pattern import log_writer, read_pattern, run_pattern
from pyrt.robots.ropes import GRAVITY, MIN_TOP_SEGMENT, RopeModel, Vec, dist
from pyrt.robots.stops import SAFETY_STOPS, StopCheck, StopReason, StopRecord
from pyrt.scheduler import Job, Task
from pyrt.scheduler.motion import MotionExecutor, MotionRecord, MotionType, get_motion_type
from pyrt.scheduler.runner import MotionQueue
from pyrt.tasks import axis_poll, polyaxis_poll

__all__ = [
    "GRAVITY",
    "MIN_TOP_SEGMENT",
    "NEAR_END_CM",
    "SLIP_COUNTS",
    "SNAPSHOT_POLLS",
    "PolyAxis",
]

#: POLYAXIS.dat's defaults (the schema is their one home).
_DEFAULT = defaults("POLYAXIS")
#: NEAR_END truth falls from 1 at the endpoint to 0 at this distance (cm).
NEAR_END_CM = 10.0

_FI = FuzzyInput
#: How the pattern log may be written (:func:`pyrt.robots.pattern.log_writer`).
_PATTERN_WRITERS = ("thread", "sync")


def _cm(axis: str) -> Callable[[str], float]:
    return finite(f"{axis} in cm", units="cm")


def _point(p: Sequence[float] | None) -> Vec:
    assert p is not None
    return (float(p[0]), float(p[1]), float(p[2]))


class _ModelLimit:
    """A limit the rope model holds (its one home), read and set through the
    PolyAxis: a value set while running is the one every check uses from then."""

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name

    def __get__(self, pa: PolyAxis | None, owner: type | None = None) -> Any:
        if pa is None:
            return self
        return getattr(pa.model, self.name)

    def __set__(self, pa: PolyAxis, value: float) -> None:
        setattr(pa.model, self.name, float(value))


class PolyAxis(Component):
    """The co-ordinated manipulator (see the module text).

    ``axes`` are the :class:`Axis` objects in database order (the central rope
    has no bottom attachment); lengths cm, forces N, masses kg, volumes cm3,
    times s.  ``poll_s`` is the control poll period the fuzzy rules are
    scaled to.  ``liquid_level``: z of the D2O surface (None: in air).

    What it works with, given here and never set afterwards: ``motion``, the
    queue of motion records ``to`` and the runner fill; ``spawn``, the loop's
    (patterns run as foreground jobs); ``pattern_writer``, how the pattern
    log is written (``"thread"``: off the loop thread, ``"sync"``: at once,
    for simulated-clock runs); ``on_stop``, called with every StopRecord;
    ``task_periods``, the (polyaxis-poll, axis-poll) periods in queue checks.
    """

    low_tension = _ModelLimit()
    max_tension = _ModelLimit()
    tension_margin = _ModelLimit()
    net_forcelimit = _ModelLimit()
    offside_tension = _ModelLimit()
    end_error = _ModelLimit()

    def __init__(
        self,
        name: str,
        axes: Sequence[Axis],
        av: AV,
        *,
        source_mass: float,
        source_volume: float,
        position: Sequence[float],
        end_error: float = _DEFAULT["end_error"],
        low_tension: float = _DEFAULT["low_tension"],
        max_tension: float = _DEFAULT["max_tension"],
        net_forcelimit: float = _DEFAULT["net_forcelimit"],
        offside_tension: float = _DEFAULT["offside_tension"],
        hare_speed: float = _DEFAULT["hare_speed"],
        hare_ramp: float = _DEFAULT["hare_ramp"],
        stuck_time: float = _DEFAULT["stuck_time"],
        find_tolerance: float = _DEFAULT["find_tolerance"],
        dist_err_limit: float = _DEFAULT["dist_err_limit"],
        tension_margin: float = _DEFAULT["tension_margin"],
        d2o_density: float = _DEFAULT["d2o_density"],
        liquid_level: float | None = None,
        poll_s: float = 0.05,
        fuzzy: Sequence[FuzzyParams] | None = None,
        ring_segments: int | None = None,
        motion: MotionQueue | None = None,
        spawn: Callable[[str, Generator[Any, Any, Any]], Job] | None = None,
        pattern_writer: str = "thread",
        on_stop: Sequence[Callable[[StopRecord], None]] = (),
        task_periods: tuple[int, int] | None = None,
    ):
        if not axes:
            raise ConfigError(f"polyaxis {name}: no axes")
        if not (poll_s > 0 and math.isfinite(poll_s)):
            raise ConfigError(f"polyaxis {name}: poll period must be > 0 s, got {poll_s!r}")
        if pattern_writer not in _PATTERN_WRITERS:
            raise ConfigError(f"polyaxis {name}: pattern writer must be 'thread' or 'sync', "
                              f"got {pattern_writer!r}")
        self.name = name
        self.axes = list(axes)
        self.n = len(self.axes)
        self.av = av
        self.hare_speed = float(hare_speed)
        self.hare_ramp = float(hare_ramp)
        self.stuck_time = float(stuck_time)
        self.find_tolerance = float(find_tolerance)
        self.dist_err_limit = float(dist_err_limit)
        self.poll_s = float(poll_s)

        # geometry (global co-ordinates: bottoms carried through av.vtog)
        tops: list[Vec] = [_point(a.top) for a in self.axes]
        bottoms: list[Vec | None] = [None if a.bottom is None else _point(a.bottom)
                                     for a in self.axes]
        offsets: list[Vec] = [_point(a.offset) for a in self.axes]
        #: The rope segments the controller lets bear on the neck ring: by default
        #: both, as the world does (one geometry in two roles); a smaller mask is
        #: a controller that deliberately knows less (UPPER: lower segments straight).
        self.ring_segments = (PolyControl.RING_SEGMENTS if ring_segments is None
                              else int(ring_segments))
        nan = math.nan
        try:
            finder = PositionFinder(
                np.array(tops, float),
                np.array([(nan, nan, nan) if b is None else b for b in bottoms], float),
                np.array(offsets, float), tol=self.find_tolerance)
        except NativeError as exc:
            raise ConfigError(f"polyaxis {name}: {exc}") from None
        #: The rope model: geometry, statics, the refusal checks (stateless).
        self.model = RopeModel(
            av, [a.name for a in self.axes], tops, bottoms, offsets,
            [a.dead_length for a in self.axes], [a.stretch for a in self.axes],
            freeze=finder.freeze, ring_segments=self.ring_segments,
            source_mass=source_mass, source_volume=source_volume,
            d2o_density=d2o_density, liquid_level=liquid_level,
            low_tension=low_tension, max_tension=max_tension,
            tension_margin=tension_margin, net_forcelimit=net_forcelimit,
            offside_tension=offside_tension, end_error=end_error)
        model = self.model
        model.check_plane(name, position, self.find_tolerance)
        self.tops = model.tops
        self.offsets = model.offsets
        self.plane = model.plane
        self.via = model.via
        self._names = model.names

        params = list(fuzzy) if fuzzy is not None else [
            FuzzyParams().for_poll_period(self.poll_s)] * self.n
        if len(params) != self.n:
            raise ConfigError(f"polyaxis {name}: {len(params)} fuzzy parameter sets "
                              f"for {self.n} axes")
        self.batch = FuzzyBatch(params, self.n)
        inp = self.batch.inputs
        inp[:, _FI.TENSION_LOW] = self.low_tension
        inp[:, _FI.TENSION_HIGH] = self.max_tension
        self._motors = [a.motor for a in self.axes]
        # The poll's numeric work in two C calls (pyrt.native.PolyControl):
        # corrected lengths, ring contacts, the solve and the net force; then
        # the error signals, fuzzy inputs and the batched fuzzy step.
        rf = model.neck
        ring = (*rf.centre, *rf.axis, *rf.e1, *rf.e2, rf.radius)
        wet = (model.source_volume > 0 and liquid_level is not None)
        try:
            self._ctl = PolyControl(
                finder, self.batch, tops=tops, bottoms=bottoms,
                offsets=offsets, stretch=model.stretch,
                dead=model.dead_lengths, ring=ring,
                axis_point=model.axis_point[:2], weight_air=model.weight(math.inf),
                weight_liquid=model.weight(-math.inf),
                liquid_level=liquid_level if wet else None,
                offside_tension=self.offside_tension, near_end_cm=NEAR_END_CM,
                position=position, ring_segments=self.ring_segments)
        except NativeError as exc:
            raise ConfigError(f"polyaxis {name}: {exc}") from None
        #: The position estimate (measure, integrity, survey, setpos).
        self.estimator = PositionEstimator(
            name, self.axes, model, finder, self._ctl, position,
            find_tolerance=self.find_tolerance, dist_err_limit=self.dist_err_limit)

        # control state
        self.desired_tensions = [0.0] * self.n
        self.error_lengths = [0.0] * self.n
        self.error_tensions = [0.0] * self.n
        self.free = [1.0] * self.n
        self.active = False
        self.hare: Hare | None = None
        self.hare_position: Vec | None = None
        self.endpoint: Vec | None = None
        self.stops: StopCheck | None = None
        self.tension_stop = True
        self.signal_all = False
        self.last_stop: StopRecord | None = None
        self.moves = 0
        self.polls = 0
        self.now_s = 0.0
        self.last_poll_s: float | None = None
        #: Called with (StopRecord) after every stop.
        self.on_stop: list[Callable[[StopRecord], None]] = list(on_stop)
        #: The motion queue of MotionRecords, emptied by the executor between
        #: moves and cleared by any abnormal stop.
        self.motion = motion
        #: The station's ``loop.spawn`` (patterns run as foreground jobs).
        self.spawn = spawn
        #: The running (or last) pattern job and its log file.
        self.pattern_job: Job | None = None
        self.pattern_log: Path | None = None
        #: How the pattern log is written: ``"thread"`` (off the loop thread) or
        #: ``"sync"`` (at once: deterministic, for simulated-clock runs).
        self.pattern_writer = pattern_writer
        for i, a in enumerate(axes):
            a.group = self
            a.group_index = i
        #: Starts queued motion records one at a time and steps the running one.
        self.executor = MotionExecutor(self, self._take_motion, self._motion_done,
                                       self._motion_failed)
        #: The motion driving the source now (None between moves).
        self.running: MotionType | None = None
        #: Seconds since the previous control poll (what a motion steps by).
        self.dt = self.poll_s
        #: Where the state log goes (one line at a time), or None: switched by
        #: the station's ``log`` command while running.
        self.log: Callable[[str], object] | None = None
        self.debug = False
        self.debug_next = 0.0
        #: (polyaxis-poll, axis-poll) periods in queue checks (set_task_periods).
        self.task_periods: tuple[int, int] | None = None
        if task_periods is not None:
            self.set_task_periods(*task_periods)

    @classmethod
    def from_record(cls, record: Any, axes: Sequence[Axis], av: AV, **kw: Any) -> PolyAxis:
        """A PolyAxis from a :class:`pyrt.db.PolyAxisRecord` (``name``: the
        record's by default)."""
        return cls(
            kw.pop("name", record.name), axes, av,
            source_mass=record.source_mass, source_volume=record.source_volume,
            position=record.position, end_error=record.end_error,
            low_tension=record.low_tension, max_tension=record.max_tension,
            net_forcelimit=record.net_forcelimit, offside_tension=record.offside_tension,
            hare_speed=record.hare_speed, hare_ramp=record.hare_ramp,
            stuck_time=record.stuck_time, find_tolerance=record.find_tolerance,
            d2o_density=record.d2o_density, dist_err_limit=record.dist_err_limit,
            tension_margin=record.tension_margin, **kw,
        )

    # -- the rope model's answers for a caller that holds the PolyAxis (the force map) --

    def refusal(self, x: Sequence[float]) -> str | None:
        """Why the source may not be at ``x``, or None (:meth:`RopeModel.refusal`)."""
        return self.model.refusal(x)

    def force_directions(self, x: Sequence[float]) -> list[Vec]:
        """Per rope, the force per newton of tension at ``x`` (the model's)."""
        return self.model.force_directions(x)

    def equilibrium_tensions(self, x: Sequence[float]) -> tuple[list[float], float]:
        """The tensions that hold the source at ``x`` and the force left over (the model's)."""
        return self.model.equilibrium_tensions(x)

    # -- the estimate (the estimator's, read here) ---------------------------------------

    @property
    def position(self) -> Vec:
        """The source position estimate (cm)."""
        return self.estimator.position

    @property
    def dist_err(self) -> float:
        """The RMS rope-length residual of the estimate (cm)."""
        return self.estimator.dist_err

    @property
    def tensions(self) -> list[float]:
        """Every rope's measured tension (N; a list updated in place)."""
        return self.estimator.tensions

    @property
    def lengths(self) -> list[float]:
        """Every rope's stretch-corrected length (cm; a list updated in place)."""
        return self.estimator.lengths

    @property
    def net_force(self) -> Vec:
        """The residual net force on the source (N)."""
        return self.estimator.net_force

    @property
    def net_force_magnitude(self) -> float:
        """Its magnitude (N)."""
        return self.estimator.net_force_magnitude

    @property
    def position_error(self) -> str | None:
        """Why the last poll could not find the position (None: it could)."""
        return self.estimator.position_error

    @property
    def estimate_lost(self) -> str | None:
        """Why the estimate is not trusted, or None (moves refused until re-established)."""
        return self.estimator.estimate_lost

    # -- the component contract ------------------------------------------------------------

    def children(self) -> list[Component]:
        return [*self.axes, self.av]

    def position_limits(self, k: int) -> Limits:
        """The display range of co-ordinate ``k`` (0, 1, 2: x, y, z) of a point
        inside the vessel or its neck, cm."""
        av = self.av
        centre = av.vtog((0.0, 0.0, 0.0))
        top = max(av.neck_ring_position[k] + av.neck_length * av.neck_axis[k],
                  centre[k] + av.vessel_radius)
        return Limits(centre[k] - av.vessel_radius, top)

    def signals(self) -> list[Signal]:
        pos = self.position
        lim = self.net_forcelimit
        return [
            Signal("x", "cm", lambda: self.position[0], "source position x (estimate)",
                   limits=self.position_limits(0)),
            Signal("y", "cm", lambda: self.position[1], "source position y (estimate)",
                   limits=self.position_limits(1)),
            Signal("z", "cm", lambda: self.position[2], "source position z (estimate)",
                   limits=self.position_limits(2)),
            # An estimate less consistent than END_ERROR cannot claim ENDPOINT: MINOR.
            Signal.attr("distErr", "cm", self, "dist_err",
                        "rope-length residual of the position estimate",
                        limits=Limits(0.0, 4.0 * self.end_error, high=self.end_error)),
            # NET_FORCELIMIT is the net-force stop (MAJOR); MINOR at 80 %.
            Signal.attr("netForce", "N", self, "net_force_magnitude",
                        "residual net force on the source",
                        limits=Limits(0.0, 2.0 * lim, high=0.8 * lim, hihi=lim)),
            Signal.attr("active", "bool", self, "active", "a move is running", "d"),
        ] if pos is not None else []

    def reflex(self) -> None:
        """The manipulator's reflex: the move ended (a FAULT stop), every motor stopped."""
        if self.active:
            self.halt(StopReason.FAULT, "stopped by the reflex action")
        else:
            self.stop_motors()
        self.executor.abort("stopped by the reflex action")
        self.pattern_job_cancel()

    # -- commands (Table 2) ----------------------------------------------------------

    @command(Arg("x", _cm("x")), Arg("y", _cm("y")), Arg("z", _cm("z")),
             Arg("blend", str.lower, optional=True, choices=("blend", "stop")),
             name="to", moves=True)
    def cmd_to(self, x: float, y: float, z: float, mode: str = "") -> str:
        """to x y z [blend]: move the source to (x, y, z) cm.

        'blend' joins the turn into the neck smoothly instead of stopping
        at the corner; a move already running is followed, not replaced."""
        job = self.pattern_job
        if job is not None and not job.done:
            raise CommandError(f"{self.name} to: a pattern is running ('{self.name} stop' ends "
                               "it); nothing moved")
        target = (x, y, z)
        waiting = self.active or (self.motion is not None and len(self.motion) > 0)
        record = hare_path_record(target, blend=mode == "blend")
        if waiting:  # it starts from wherever the move before it ends
            self.check_target(target)
            assert self.motion is not None
            self.motion.put(record)
            return f"{self.name}: to ({x:g}, {y:g}, {z:g}) queued ({len(self.motion)} waiting)"
        self.plan_path(target, blend=mode == "blend")  # refuses a blocked path too
        self.begin(record)  # now, in this tick: a 'wait' that follows sees it running
        hare = self.hare
        assert hare is not None
        n = len(hare.segments)
        how = " blended" if hare.blend else ""
        total = sum(seg.length for seg in hare.segments)
        return (f"{self.name}: to ({x:g}, {y:g}, {z:g}): {n}{how} "
                f"segment{'s' if n > 1 else ''}, {total:.1f} cm")

    @command(name="tensionFind", reads_only=True)
    def cmd_tension_find(self) -> str:
        """tensionFind: find and display the position from the tensions."""
        x = self.tension_find()
        return f"{self.name}: position from tensions ({x[0]:.2f}, {x[1]:.2f}, {x[2]:.2f})"

    @command(name="tensions", reads_only=True)
    def cmd_tensions(self) -> str:
        """tensions: find and display the desired tensions."""
        t, resid = self.model.equilibrium_tensions(self.position)
        parts = " ".join(f"{a.name} {v:.2f} N" for a, v in zip(self.axes, t, strict=True))
        return f"{self.name}: desired tensions {parts} (unbalanced {resid:.2f} N)"

    @command(Arg("x", _cm("x"), optional=True), Arg("y", _cm("y"), optional=True),
             Arg("z", _cm("z"), optional=True), name="netForce", reads_only=True)
    def cmd_net_force(self, *args: float) -> str:
        """netForce [x y z]: net force magnitude at (x, y, z) or at the current position."""
        if len(args) not in (0, 3):
            raise CommandError(f"{self.name} netForce: takes 0 or 3 arguments, got {len(args)}")
        x = tuple(args) if args else self.position
        f = self.model.net_force_at(x, self.tensions)
        mag = math.sqrt(f[0] ** 2 + f[1] ** 2 + f[2] ** 2)
        return (f"{self.name}: net force {mag:.2f} N ({f[0]:.2f}, {f[1]:.2f}, {f[2]:.2f}) at "
                f"({x[0]:.2f}, {x[1]:.2f}, {x[2]:.2f})")

    @command(Arg("FILE", read_pattern, rest=True), name="pattern", moves=True)
    def cmd_pattern(self, pattern: tuple[Path, list[Vec], str]) -> str:
        """pattern FILE: run through a pattern of endpoints (first line: the log file)."""
        log, points, shown = pattern
        job = self.pattern_job
        if job is not None and not job.done:
            raise CommandError(f"{self.name} pattern: a pattern is already running")
        if self.active or (self.motion is not None and len(self.motion) > 0):
            raise CommandError(f"{self.name} pattern: a move is running; wait for it or "
                               "stop it first")
        if self.spawn is None:
            raise CommandError(f"{self.name} pattern: no loop to run it on")
        self.refuse_if_lost("pattern")
        self.pattern_log = log
        kind = self.pattern_writer
        self.pattern_job = self.spawn("pattern", run_pattern(
            self, points, lambda: log_writer(log, kind), lambda: self.now_s))
        return f"{self.name}: pattern {shown} started; log {log}"

    def pattern_job_cancel(self) -> None:
        """End a running pattern (a stop or a fault does)."""
        job = self.pattern_job
        if job is not None and not job.done:
            job.cancel()

    @command(name="stop", anyone=True)
    def cmd_stop(self) -> str:
        """stop: stop all motors."""
        self.stop()
        self.pattern_job_cancel()
        return f"{self.name}: stopped"

    @command(name="tensionStop")
    def cmd_tension_stop(self) -> str:
        """tensionStop: toggle stop-on-tension."""
        self.tension_stop = not self.tension_stop
        if self.stops is not None:
            self.stops.tension_stops = self.tension_stop
        return f"{self.name}: tension stops {'on' if self.tension_stop else 'OFF'}"

    @command(name="errorSignalAll")
    def cmd_error_signal_all(self) -> str:
        """errorSignalAll: toggle driving every rope toward its equilibrium tension."""
        self.signal_all = not self.signal_all
        return (f"{self.name}: error signals "
                f"{'on every rope (errorSignalAll)' if self.signal_all else 'off-side only'}")

    # -- moving ----------------------------------------------------------------------

    def check_target(self, target: Sequence[float]) -> None:
        """Refuse (CommandError with the reason) a target that cannot be reached."""
        tgt = tuple(float(c) for c in target)
        if len(tgt) != 3 or not all(math.isfinite(c) for c in tgt):
            raise CommandError(f"{self.name} to: target must be three finite numbers")
        if self.position_error is not None:
            raise CommandError(f"{self.name} to: refused: the source position is unknown "
                               f"({self.position_error}); nothing moved")
        self.refuse_if_lost("to")
        why = self.model.target_refusal((tgt[0], tgt[1], tgt[2]))
        if why is not None:
            raise CommandError(f"{self.name} to: refused: {why}; nothing moved")

    def refuse_if_lost(self, word: str) -> None:
        """CommandError while the position estimate is not trusted, or while a
        rope's loadcell is being calibrated (the rope is off it then)."""
        cal = [a.loadcell.name for a in self.axes if a.loadcell.calibrating]
        if cal:
            raise CommandError(f"{self.name} {word}: refused: {', '.join(cal)} in calibration "
                               f"mode (its rope carries the calibration loads); finish with "
                               f"'{cal[0]} calibrate'; nothing moved")
        if self.estimate_lost is not None:
            raise CommandError(f"{self.name} {word}: refused: the position estimate is not "
                               f"trusted ({self.estimate_lost}); re-establish it with 'survey' "
                               "or 'setpos X Y Z'; nothing moved")

    def plan_path(self, target: Sequence[float], *, blend: bool = False) -> Hare:
        """The hare for a move from here to ``target`` after every check: the
        target's (:meth:`check_target`), then every point on the way inside the
        vessel and, from a start held within the tension bounds, holdable within
        them (CommandError with the reason if refused; nothing changes)."""
        self.check_target(target)
        tgt: Vec = tuple(float(c) for c in target)  # type: ignore[assignment]
        start = self.position
        model = self.model
        segs = plan_segments(start, tgt, model.in_neck, model.via)
        hare = Hare(segs, self.hare_speed, self.hare_ramp, blend=blend)
        # the tensions on the way are checked when they are within bounds here (a
        # source held where they are not may always move out: the stops guard it)
        held = model.tension_refusal(start) is None
        for p in hare.sample():
            why = model.refusal(p)
            if why is None and held and dist(p, start) > 2.0 * self.end_error:
                why = model.tension_refusal(p)
            if why is not None and dist(p, start) > 2.0 * self.end_error:
                raise CommandError(
                    f"{self.name} to: refused: the path passes ({p[0]:.1f}, {p[1]:.1f}, "
                    f"{p[2]:.1f}), {why}; nothing moved")
        return hare


    def to(self, target: Sequence[float], *, blend: bool = False) -> Hare:
        """Start a move to ``target`` (global cm) now, after the checks: the
        ``hare_path`` motion; re-arms the tension stops.  Every Axis goes to
        PolyAxis control (000's polyActivate)."""
        motion = self.begin(hare_path_record(target, blend))
        assert isinstance(motion, HarePath) and motion.hare is not None
        return motion.hare

    def begin(self, record: MotionRecord) -> MotionType:
        """Start ``record`` now instead of queueing it (a running motion is
        replaced, as a new ``to`` re-targets a move); CommandError if refused,
        and then nothing changes."""
        self.refuse_if_lost(record.type)
        cls = get_motion_type(record.type)
        motion = cls()
        try:
            motion.start(self, record, round(self.now_s * 1e9))
        except CommandError:
            raise
        except Exception as exc:
            raise CommandError(f"{self.name} {record.type}: refused: "
                               f"{type(exc).__name__}: {exc}") from None
        tgt = self._endpoint_of(motion)
        old, self.running = self.running, None
        ex = self.executor
        if old is not None and ex.current is old:
            ex.abort(f"replaced by {record.type}")
        ex.current = motion
        ex.record = record
        self.hare_position = None
        self._engage(motion, tgt)
        return motion

    def _take_motion(self) -> MotionRecord | None:
        q = self.motion
        return None if q is None else q.get()

    def _endpoint_of(self, motion: MotionType) -> Vec | None:
        """The motion's ``endpoint`` (None: it has none); CommandError if it is
        not a finite point."""
        endpoint = getattr(motion, "endpoint", None)
        if endpoint is None:
            return None
        try:
            tgt = tuple(float(c) for c in endpoint)
        except (TypeError, ValueError):
            tgt = ()
        if len(tgt) != 3 or not all(math.isfinite(c) for c in tgt):
            raise CommandError(f"{self.name} {motion.name}: refused: its endpoint "
                               f"{endpoint!r} is not a finite point; nothing moved")
        return tgt  # type: ignore[return-value]

    def _engage(self, motion: MotionType, tgt: Vec | None) -> None:
        """A motion has started: every Axis under PolyAxis control, the stop
        conditions armed (tension stops on again), the hare where the source is;
        CommandError (nothing moved) while the estimate is not trusted."""
        self.refuse_if_lost(motion.name or type(motion).__name__)
        for a in self.axes:
            if a.mode != POLYAXIS:
                a.poly_activate()
        hare = getattr(motion, "hare", None)
        self.hare = hare if isinstance(hare, Hare) else None
        if self.hare_position is None:  # not stepped yet: the hare starts at the source
            self.hare_position = self.hare.position if self.hare is not None else self.position
        self.endpoint = tgt
        self.tension_stop = True
        self.stops = StopCheck(self.position, tgt, end_error=self.end_error,
                               find_tolerance=self.find_tolerance, stuck_time=self.stuck_time,
                               low_tension=self.low_tension, max_tension=self.max_tension,
                               net_force_limit=self.net_forcelimit, tension_stops=True)
        self._ctl.reset_rates()
        self._ctl.set_endpoint(tgt)
        self.running = motion
        self.active = True
        self.moves += 1
        if self.hare is not None and tgt is not None:
            self._log(f"TO {self.now_s:.3f} {tgt[0]:.4f} {tgt[1]:.4f} {tgt[2]:.4f} "
                      f"{len(self.hare.segments)} {int(self.hare.blend)}")
        else:
            self._log(f"MOTION {self.now_s:.3f} {motion.name or type(motion).__name__}")

    def _motion_done(self, motion: MotionType) -> None:
        """The executor's on_done: a refused record is reported; a motion that
        ended itself stops the manipulator (DONE)."""
        reason = motion.stop_reason or ""
        if motion is not self.running:
            if reason.startswith("refused"):
                self.say(f"queued move dropped: {reason.removeprefix('refused: ')}", "warning")
            return
        self.running = None
        if self.active and not reason.startswith("failed"):
            self.halt(StopReason.DONE, reason or f"{motion.name} done")

    def _motion_failed(self, cause: str, motion: MotionType) -> None:
        """The executor's on_error: a motion raised; a fault of the manipulator."""
        self._fault(f"motion {motion.name or type(motion).__name__} failed: {cause}")

    def _fault(self, detail: str) -> None:
        self.running = None
        self.halt(StopReason.FAULT, detail)
        self.fail(detail)

    def stop(self) -> None:
        """The ``stop`` command: every motor stopped, the move ended."""
        self.halt(StopReason.STOP, "stop command")

    def stop_motors(self) -> None:
        """Every motor off (windings off) and every axis back to standalone."""
        for a in self.axes:
            a.motor.stop()
            if a.mode == POLYAXIS:
                a.poly_deactivate()
            a.target = None
            a.motor.mode = STEP_MODE

    def halt(self, reason: StopReason, detail: str) -> StopRecord:
        """End the move: stop every motor, record and report why."""
        was_active = self.active
        self.active = False
        running, self.running = self.running, None
        if running is not None and self.executor.current is running:
            self.executor.abort(f"{reason.value}: {detail}")
        self.stop_motors()
        rec = StopRecord(reason, detail, self.position, self.now_s, self.endpoint)
        if was_active or reason in (StopReason.STOP, StopReason.FAULT):
            self.last_stop = rec
            self._log(f"STOP {self.now_s:.3f} {reason.value} {detail}")
            for fn in self.on_stop:
                fn(rec)
        if reason in SAFETY_STOPS or reason in (StopReason.STOP, StopReason.FAULT):
            dropped = self.motion.clear() if self.motion is not None else 0
            if dropped:
                self.say(f"{self.name}: {dropped} queued move(s) dropped", "warning")
        if reason in SAFETY_STOPS:
            self.fail(f"{reason.value}: {detail}")
        return rec

    @property
    def moving(self) -> bool:
        """A move is in progress."""
        return self.active

    # -- the tasks (pyrt.tasks: polyaxis_poll, axis_poll) ----------------------------

    def set_task_periods(self, poll_checks: int, axis_poll_checks: int) -> None:
        """The periods of polyaxis-poll and axis-poll in queue checks (1..255),
        from the control and axis poll periods and the station's tick."""
        for label, n in (("poll_checks", poll_checks), ("axis_poll_checks", axis_poll_checks)):
            if not 1 <= n <= 255:
                raise ValueError(f"{label} must be 1..255 queue checks, got {n}")
        self.task_periods = (int(poll_checks), int(axis_poll_checks))

    def tasks(self) -> list[Task]:
        """POLYAXIS (polyaxis-poll, 0100) and AXES (axis-poll over the axes under
        standalone control, 0101), each first run one period after it is
        registered; the periods are :meth:`set_task_periods`'."""
        if self.task_periods is None:
            raise ConfigError(f"polyaxis {self.name}: the task periods are not set "
                              "(set_task_periods)")
        poll, axes = self.task_periods
        return [
            Task(polyaxis_poll.NAME, polyaxis_poll.ADDRESS,
                 partial(polyaxis_poll.polyaxis_poll, self), poll, first=poll, timed=True),
            Task(axis_poll.NAME, axis_poll.ADDRESS, partial(axis_poll.axis_poll, self.axes),
                 axes, first=axes, timed=True),
        ]

    # -- the control poll ------------------------------------------------------------

    def poll(self, now_s: float) -> None:
        """One control poll at ``now_s`` seconds, in the order of the module text
        (the polyaxis-poll routine's body)."""
        self.now_s = now_s
        last = self.last_poll_s
        dt = self.poll_s if last is None else max(0.0, now_s - last)
        self.last_poll_s = now_s
        self.polls += 1
        self.dt = dt
        est = self.estimator
        try:
            est.measure()
        except NativeError as exc:
            self.position_lost(f"position finder failed: {exc}")
            return
        est.position_error = None
        if est.estimate_lost is None:  # the estimate's integrity, every poll
            detail = est.check()
            if detail is not None:
                self._estimate_fault(detail)
        self.step_motion(now_s)
        if self.active:
            self.drive_motors(now_s, dt)
        for a in self.axes:
            if a.mode == POLYAXIS:
                a.encoder.poll(now_s)
        if self.debug and now_s >= self.debug_next:
            self.debug_next = now_s + 1.0
            self.say(self.status_line())

    def measure(self) -> None:
        """Read every Axis and find the source position (the estimator's
        measure); a position finder that fails is noted (moves refused)."""
        est = self.estimator
        try:
            est.measure()
        except NativeError as exc:
            est.position_error = f"position finder failed: {exc}"

    def position_lost(self, cause: str) -> None:
        """The position finder failed (``cause``): keep the last position, refuse
        moves; during a move it is a fault of the whole manipulator."""
        self.estimator.position_error = cause
        if self.active:
            self.halt(StopReason.FAULT, cause)
            self.fail(cause)

    def _estimate_fault(self, detail: str) -> None:
        """The estimator found the estimate lost (checked after every measure,
        moving or not: :meth:`~pyrt.robots.estimator.PositionEstimator.check`):
        a fault of the manipulator naming the axis; moves are refused from then
        until ``survey`` or ``setpos`` re-establishes the position."""
        if self.active:
            self._fault(detail)
        else:
            self.fail(detail)

    def _refuse_reestablish(self, word: str) -> None:
        if self.active or any(a.motor.running for a in self.axes):
            raise CommandError(f"{self.name} {word}: a motor is moving; stop it first; "
                               "nothing changed")

    @command(Arg("x", _cm("x")), Arg("y", _cm("y")), Arg("z", _cm("z")), name="setpos")
    def cmd_setpos(self, x: float, y: float, z: float) -> str:
        """setpos X Y Z: the source is at (X, Y, Z) cm (the operator has seen it):
        every encoder is re-zeroed to agree and moves are allowed again."""
        self._refuse_reestablish("setpos")
        return self.estimator.setpos(x, y, z)

    @command(name="survey")
    def cmd_survey(self) -> str:
        """survey: re-establish the position from the redundant ropes: the
        position from every rope but the one the last estimate fault named (or
        the one whose length disagrees most), that rope's encoder re-zeroed."""
        self._refuse_reestablish("survey")
        return self.estimator.survey()

    def step_motion(self, now_s: float) -> None:
        """The motion executor's turn in the poll: start the next queued motion
        record between moves, step the running one (it sets the hare), check
        a plug-in motion's hare."""
        ex = self.executor
        if ex.current is not None or (self.motion is not None and len(self.motion)):
            if ex.current is None:  # a new motion sets the hare in its first step
                self.hare_position = None
            ex.poll(round(now_s * 1e9))
            m = ex.current
            if m is not None and m is not self.running:
                try:
                    self._engage(m, self._endpoint_of(m))
                except CommandError as exc:  # nothing moved: dropped as a refusal
                    ex.abort(f"refused: {exc}")
            if self.active and self.running is not None and not isinstance(self.running,
                                                                            HarePath):
                why = self._hare_refusal(self.hare_position)
                if why is not None:
                    self._fault(f"motion {self.running.name} {why}")

    def settled_at_turn(self) -> bool:
        """The source has come to rest at the neck turn (the hare may go on)."""
        return dist(self.position, self.model.via) <= max(self.find_tolerance, self.end_error)

    def _hare_refusal(self, hp: object) -> str | None:
        """Why a plug-in motion's hare may not be chased, or None."""
        try:
            x = tuple(float(c) for c in hp)  # type: ignore[attr-defined]
        except (TypeError, ValueError):
            return f"set the hare to {hp!r}, not a point"
        if len(x) != 3 or not all(math.isfinite(c) for c in x):
            return f"set the hare to {hp!r}, not a finite point"
        why = self.model.refusal(x)
        if why is not None:
            return f"put the hare at ({x[0]:.1f}, {x[1]:.1f}, {x[2]:.1f}), {why}"
        self.hare_position = x  # type: ignore[assignment]
        return None

    def drive_motors(self, now_s: float, dt: float) -> None:
        """During a move: error signals, the batched fuzzy step, every motor, the stops."""
        stops = self.stops
        assert stops is not None
        est = self.estimator
        hp = self.hare_position
        if hp is None:
            hp = self.hare_position = est.position
        motors = self._motors
        if self.signal_all:
            want, _ = self.model.equilibrium_tensions(hp)
            self.desired_tensions[:] = want
            self.free[:] = [0.0] * self.n
        dvs = self._ctl.drive(
            hp, [m.velocity for m in motors], 1.0 / (dt if dt > 0 else self.poll_s),
            self.error_lengths, self.error_tensions,
            self.desired_tensions, self.free, signal_all=self.signal_all)
        for m, dv in zip(motors, dvs, strict=True):
            m.set_desired_velocity((m.velocity if m.running else m.desired_velocity) + dv)
            m.poll()
        if self.log is not None:
            self._log_state(now_s, dvs)
        hit = stops.check(now_s, est.position, est.dist_err, est.tensions,
                          est.net_force_magnitude, self._names)
        if hit is not None:
            self.halt(*hit)

    def tension_find(self) -> Vec:
        """``tensionFind``: the position where the measured tensions balance the
        weight (from the current estimate, in the free directions)."""
        return self.model.position_from_tensions(self.position, self.tensions)

    # -- logging and status --------------------------------------------------------------

    def _log(self, line: str) -> None:
        if self.log is not None:
            self.log(line)

    def _log_state(self, now_s: float, dvs: Sequence[float]) -> None:
        log = self.log
        assert log is not None
        x = self.position
        h = self.hare_position or x
        log(f"P {now_s:.3f} {x[0]:.4f} {x[1]:.4f} {x[2]:.4f} {self.dist_err:.4f} "
            f"{h[0]:.4f} {h[1]:.4f} {h[2]:.4f} {self.net_force_magnitude:.3f}")
        rules = self.batch.rules
        for i, a in enumerate(self.axes):
            log(f"S {now_s:.3f} {i} {self.lengths[i]:.4f} {self.tensions[i]:.3f} "
                f"{self.error_lengths[i]:.4f} {self.error_tensions[i]:.3f} "
                f"{a.motor.velocity:.4f} {dvs[i]:.4f} {self.desired_tensions[i]:.2f} "
                f"{self.free[i]:.0f}")
            log(f"R {now_s:.3f} {i} " + " ".join(f"{v:.5f}" for v in rules[i].tolist()))

    def status_line(self) -> str:
        """Source position, distErr, residual net force, tensions and time."""
        x = self.position
        t = " ".join(f"{v:.1f}" for v in self.tensions)
        state = "moving" if self.active else (self.last_stop.reason.value
                                              if self.last_stop else "idle")
        if self.position_error is not None:
            state += f"  POSITION UNKNOWN: {self.position_error}"
        elif self.estimate_lost is not None:
            state += "  POSITION NOT TRUSTED ('survey' or 'setpos X Y Z')"
        return (f"t={self.now_s:9.2f} s  pos ({x[0]:8.2f} {x[1]:8.2f} {x[2]:8.2f}) cm  "
                f"distErr {self.dist_err:.3f} cm  net {self.net_force_magnitude:6.2f} N  "
                f"T [{t}] N  {state}")


# The straight-line move drives a PolyAxis (paths.py cannot name the class: it is
# imported by this module).
HarePath.drives = (PolyAxis,)
