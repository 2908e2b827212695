"""Co-ordinated control of the ropes: the PolyAxis of 000, section 5.

The manipulator wing is five parts, one module each:

* :mod:`pyrt.robots.ropes`: the rope model, stateless (geometry, statics,
  the refusal checks, the stretch formula, one Gauss-Newton);
* :mod:`pyrt.robots.estimator`: the position estimate (measure, integrity,
  ``survey`` and ``setpos``);
* :mod:`pyrt.robots.polymove`: the move controller (begin, step, drive, the
  stop checks, and one ``halt``, the only way a move's fault fails the
  manipulator);
* :mod:`pyrt.robots.polystatus`: the status line and the state log;
* this module: the :class:`PolyAxis` component (built from its POLYAXIS
  record and one bundle of services, :class:`PolyAxisServices`), its
  signals, params, commands and tasks, the path checks, and its control poll.

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

A PolyAxis is built from its POLYAXIS record (the one spelling of that
entry's fields: the rope model takes the source and the limits from it, the
PolyAxis the rest) and :class:`PolyAxisServices`, everything it works with:
the motion queue, the loop's ``spawn``, the pattern writer, the stop
listeners.  ``to x y z`` is checked and planned once, by the path motion
type (``hare_path``) through :meth:`PolyAxis.plan_path`.

The corrected length of 000 is the measured length less the rope's length
residual, so that errors of the position estimate do not appear as error
terms; errors are actual - desired.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Generator, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from pyrt.component import Arg, Component, Limits, Param, Signal, command, finite
from pyrt.db import PolyAxisRecord
from pyrt.errors import CommandError, ConfigError, NativeError
from pyrt.native import FuzzyBatch, FuzzyInput, FuzzyParams, PolyControl, PositionFinder
from pyrt.robots.av import AV
from pyrt.robots.axis import POLYAXIS, Axis
from pyrt.robots.estimator import SLIP_COUNTS, SNAPSHOT_POLLS, PositionEstimator
from pyrt.robots.paths import Hare, HarePath, hare_path_record
from pyrt.robots.pattern import log_writer, read_pattern, run_pattern
from pyrt.robots.polymove import MoveController
from pyrt.robots.polystatus import PolyAxisStatus
from pyrt.robots.ropes import GRAVITY, MIN_TOP_SEGMENT, RopeModel, Vec, dist
from pyrt.robots.stops import StopReason, StopRecord
from pyrt.scheduler import Job, Task
from pyrt.scope import Source
from pyrt.tasks import axis_poll, polyaxis_poll

if TYPE_CHECKING:
    from pyrt.scheduler.runner import MotionQueue

__all__ = [
    "GRAVITY",
    "MIN_TOP_SEGMENT",
    "NEAR_END_CM",
    "SLIP_COUNTS",
    "SNAPSHOT_POLLS",
    "PolyAxis",
    "PolyAxisServices",
]

#: NEAR_END truth falls from 1 at the endpoint to 0 at this distance (cm).
NEAR_END_CM = 10.0

_FI = FuzzyInput
#: How the pattern log may be written (:func:`pyrt.robots.pattern.log_writer`).
_PATTERN_WRITERS = ("thread", "sync")


def _cm(axis: str) -> Callable[[str], float]:
    return finite(f"{axis} in cm", units="cm")


def _item(obj: Any, name: str, k: int) -> Any:
    """``obj.name[k]``, read now."""
    return getattr(obj, name)[k]


def _point(p: Sequence[float] | None) -> Vec:
    assert p is not None
    return (float(p[0]), float(p[1]), float(p[2]))


@dataclass(frozen=True)
class PolyAxisServices:
    """Everything a PolyAxis works with, given by its station and never set
    afterwards: ``motion``, the queue of motion records ``to`` and the runner
    fill (None: moves only start at once); ``spawn``, the loop's (patterns run
    as foreground jobs); ``pattern_writer``, how the pattern log is written
    (``"thread"``: off the loop thread, ``"sync"``: at once, for
    simulated-clock runs); ``on_stop``, called with every StopRecord."""

    motion: MotionQueue | None = None
    spawn: Callable[[str, Generator[Any, Any, Any]], Job] | None = None
    pattern_writer: str = "thread"
    on_stop: Sequence[Callable[[StopRecord], None]] = ()

    def __post_init__(self) -> None:
        if self.pattern_writer not in _PATTERN_WRITERS:
            raise ConfigError(f"polyaxis: pattern writer must be 'thread' or 'sync', "
                              f"got {self.pattern_writer!r}")


class _Part:
    """An attribute (or method) one part of the PolyAxis holds, its one home
    (the move's state and checks, the log's switches), read and set through
    the PolyAxis."""

    def __init__(self, part: str):
        self.part = part

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name

    def __get__(self, pa: PolyAxis | None, owner: type | None = None) -> Any:
        if pa is None:
            return self
        return getattr(getattr(pa, self.part), self.name)

    def __set__(self, pa: PolyAxis, value: Any) -> None:
        setattr(getattr(pa, self.part), self.name, value)


class _Limit(_Part):
    """A limit the rope model holds, read and set (as a float) through the PolyAxis."""

    def __set__(self, pa: PolyAxis, value: Any) -> None:
        setattr(getattr(pa, self.part), self.name, float(value))


class _Read(_Part):
    """What a part holds and the PolyAxis only reads (the estimate, the move's checks)."""

    def __set__(self, pa: PolyAxis, value: Any) -> None:
        raise AttributeError(f"{self.name} is the {self.part}'s; it is read here, not set")


class PolyAxis(Component):
    """The co-ordinated manipulator (see the module text).

    ``record`` is its POLYAXIS entry (a :class:`pyrt.db.PolyAxisRecord`;
    ``name``: the record's by default); ``axes`` the :class:`Axis` objects
    in database order (the central rope has no bottom attachment); lengths
    cm, forces N, masses kg, volumes cm3, times s.  ``services``: what it
    works with (:class:`PolyAxisServices`).  ``poll_s`` is the control poll
    period the fuzzy rules are scaled to; ``liquid_level`` the z of the D2O
    surface (None: in air); ``task_periods`` the (polyaxis-poll, axis-poll)
    periods in queue checks (:meth:`set_task_periods`).
    """

    # the estimate: the estimator's (cm, N; the lists are updated in place)
    position = _Read("estimator")  # the source position estimate
    dist_err = _Read("estimator")  # the RMS rope-length residual
    tensions = _Read("estimator")  # every rope's measured tension
    lengths = _Read("estimator")  # every rope's stretch-corrected length
    net_force = _Read("estimator")  # the residual net force on the source
    net_force_magnitude = _Read("estimator")  # and its magnitude
    position_error = _Read("estimator")  # why the last poll found none
    estimate_lost = _Read("estimator")  # why it is not trusted (moves refused)
    # the limits: the rope model's (MAX_TENSION and END_ERROR are params)
    low_tension = _Limit("model")
    max_tension = _Limit("model")
    tension_margin = _Limit("model")
    net_forcelimit = _Limit("model")
    offside_tension = _Limit("model")
    end_error = _Limit("model")
    # the move: the move controller's (its checks: a motion type calls them)
    check_target = _Read("mover")
    plan_path = _Read("mover")
    refuse_if_lost = _Read("mover")
    begin = _Read("mover")
    executor = _Read("mover")
    running = _Part("mover")
    active = _Part("mover")
    hare = _Part("mover")
    hare_position = _Part("mover")
    endpoint = _Part("mover")
    stops = _Part("mover")
    tension_stop = _Part("mover")
    signal_all = _Part("mover")
    last_stop = _Part("mover")
    moves = _Part("mover")
    on_stop = _Read("mover")
    desired_tensions = _Part("mover")
    error_lengths = _Part("mover")
    error_tensions = _Part("mover")
    free = _Part("mover")
    # the state log and the debug line: the status part's
    log = _Part("status")
    debug = _Part("status")

    def __init__(
        self,
        record: PolyAxisRecord,
        axes: Sequence[Axis],
        av: AV,
        services: PolyAxisServices | None = None,
        *,
        name: str | None = None,
        poll_s: float = 0.05,
        fuzzy: Sequence[FuzzyParams] | None = None,
        liquid_level: float | None = None,
        ring_segments: int | None = None,
        task_periods: tuple[int, int] | None = None,
    ):
        name = record.name if name is None else name
        if not axes:
            raise ConfigError(f"polyaxis {name}: no axes")
        if not (poll_s > 0 and math.isfinite(poll_s)):
            raise ConfigError(f"polyaxis {name}: poll period must be > 0 s, got {poll_s!r}")
        services = services if services is not None else PolyAxisServices()
        self.name = name
        #: The POLYAXIS entry it was built from (its limits are the rope model's
        #: from here on: MAX_TENSION and END_ERROR may be set while running).
        self.record = record
        self.axes = list(axes)
        self.n = len(self.axes)
        self.av = av
        self.poll_s = float(poll_s)
        position = record.position

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
                np.array(offsets, float), tol=record.find_tolerance)
        except NativeError as exc:
            raise ConfigError(f"polyaxis {name}: {exc}") from None
        #: The rope model: geometry, statics, the refusal checks, the limits.
        self.model = RopeModel(
            av, [a.name for a in self.axes], tops, bottoms, offsets,
            [a.dead_length for a in self.axes], [a.stretch for a in self.axes],
            freeze=finder.freeze, ring_segments=self.ring_segments, record=record,
            liquid_level=liquid_level)
        model = self.model
        model.check_plane(name, position, record.find_tolerance)
        self.tops = model.tops
        self.offsets = model.offsets
        self.plane = model.plane
        self.via = model.via

        params = list(fuzzy) if fuzzy is not None else [
            FuzzyParams().for_poll_period(self.poll_s)] * self.n
        if len(params) != self.n:
            raise ConfigError(f"polyaxis {name}: {len(params)} fuzzy parameter sets "
                              f"for {self.n} axes")
        self.batch = FuzzyBatch(params, self.n)
        inp = self.batch.inputs
        inp[:, _FI.TENSION_LOW] = model.low_tension
        inp[:, _FI.TENSION_HIGH] = model.max_tension
        # The poll's numeric work in two C calls (pyrt.native.PolyControl):
        # corrected lengths, ring contacts, the solve and the net force; then
        # the error signals, fuzzy inputs and the batched fuzzy step.
        rf = model.neck
        ring = (*rf.centre, *rf.axis, *rf.e1, *rf.e2, rf.radius)
        wet = (model.source_volume > 0 and liquid_level is not None)
        try:
            #: The poll's numeric work (csrc/polyctl.c).
            self.control = PolyControl(
                finder, self.batch, tops=tops, bottoms=bottoms,
                offsets=offsets, stretch=model.stretch,
                dead=model.dead_lengths, ring=ring,
                axis_point=model.axis_point[:2], weight_air=model.weight(math.inf),
                weight_liquid=model.weight(-math.inf),
                liquid_level=liquid_level if wet else None,
                offside_tension=model.offside_tension, near_end_cm=NEAR_END_CM,
                position=position, ring_segments=self.ring_segments)
        except NativeError as exc:
            raise ConfigError(f"polyaxis {name}: {exc}") from None
        self._ctl = self.control
        #: The position estimate (measure, integrity, survey, setpos).
        self.estimator = PositionEstimator(
            name, self.axes, model, finder, self.control, position,
            find_tolerance=record.find_tolerance, dist_err_limit=record.dist_err_limit)

        self.now_s = 0.0
        self.last_poll_s: float | None = None
        self.polls = 0
        #: Seconds since the previous control poll (what a motion steps by).
        self.dt = self.poll_s
        #: The motion queue of MotionRecords, emptied by the executor between
        #: moves and cleared by any abnormal stop.
        self.motion = services.motion
        #: The station's ``loop.spawn`` (patterns run as foreground jobs).
        self.spawn = services.spawn
        #: How the pattern log is written (``"thread"`` or ``"sync"``).
        self.pattern_writer = services.pattern_writer
        #: The running (or last) pattern job and its log file.
        self.pattern_job: Job | None = None
        self.pattern_log: Path | None = None
        for i, a in enumerate(axes):
            a.group = self
            a.group_index = i
        #: The status line and the state log.
        self.status = PolyAxisStatus(self)
        #: The move: begin, step, drive, the stop checks, halt.
        self.mover = MoveController(self, services.motion, services.on_stop)
        #: (polyaxis-poll, axis-poll) periods in queue checks (set_task_periods).
        self.task_periods: tuple[int, int] | None = None
        if task_periods is not None:
            self.set_task_periods(*task_periods)

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
        # sampled where the parts keep them (the estimate, the move), not through
        # the PolyAxis's descriptors: the same values, no call a sample
        est = self.estimator
        return [
            *(Signal(c, "cm", partial(_item, est, "position", k),
                     f"source position {c} (estimate)", source=Source.attr_item(est, "position", k),
                     limits=self.position_limits(k)) for k, c in enumerate("xyz")),
            # An estimate less consistent than END_ERROR cannot claim ENDPOINT: MINOR.
            Signal.attr("distErr", "cm", est, "dist_err",
                        "rope-length residual of the position estimate",
                        limits=Limits(0.0, 4.0 * self.end_error, high=self.end_error)),
            # NET_FORCELIMIT is the net-force stop (MAJOR); MINOR at 80 %.
            Signal.attr("netForce", "N", est, "net_force_magnitude",
                        "residual net force on the source",
                        limits=Limits(0.0, 2.0 * lim, high=0.8 * lim, hihi=lim)),
            Signal.attr("active", "bool", self.mover, "active", "a move is running", "d"),
        ] if pos is not None else []

    def params(self) -> list[Param]:
        """MAX_TENSION and END_ERROR (not written back: POLYAXIS.dat keeps its values)."""
        maxloads = [a.loadcell.maxload for a in self.axes if a.loadcell.maxload > 0]
        top = min(maxloads) if maxloads else 10_000.0
        floor = self.low_tension + 2.0 * self.tension_margin

        def set_max(value: float) -> str:
            if value <= floor:
                raise CommandError(f"set {self.name}.MAX_TENSION: {value:g} N leaves no room "
                                   f"above LOW_TENSION {self.low_tension:g} N and the margins "
                                   f"({self.tension_margin:g} N each); nothing changed")
            self.max_tension = float(value)
            self.batch.inputs[:, _FI.TENSION_HIGH] = self.max_tension
            for a in self.axes:
                if a.length_range is not None:
                    a.set_supervision(a.length_range, (self.low_tension, self.max_tension),
                                      a.tension_stops)
            return "the fuzzy rules and every rope's tension stop use it from now"

        def set_end(value: float) -> None:
            self.end_error = float(value)

        return [
            Param("MAX_TENSION", "N", lambda: self.max_tension, set_max, round(floor, 3), top,
                  "the highest rope tension a move may need (tension stop, fuzzy TENSION_HIGH)"),
            Param("END_ERROR", "cm", lambda: self.end_error, set_end, 0.01, 50.0,
                  "a move ends within this distance of its target"),
        ]

    def reflex(self) -> None:
        """The manipulator's reflex: the move ended (a FAULT stop), every motor stopped."""
        mv = self.mover
        if mv.active:
            mv.end(StopReason.FAULT, "stopped by the reflex action")
        else:
            mv.stop_motors()
        mv.executor.abort("stopped by the reflex action")
        self.pattern_job_cancel()

    # -- commands (Table 2) ----------------------------------------------------------

    @command(Arg("x", _cm("x")), Arg("y", _cm("y")), Arg("z", _cm("z")),
             Arg("blend", str.lower, optional=True, choices=("blend", "stop")),
             name="to", moves=True)
    def cmd_to(self, x: float, y: float, z: float, mode: str = "") -> str:
        """to x y z [blend|stop]: move the source to (x, y, z) cm.

        'blend' joins the turn into the neck smoothly; 'stop' (the default)
        stops at the corner; a move already running is followed, not replaced."""
        job = self.pattern_job
        if job is not None and not job.done:
            raise CommandError(f"{self.name} to: a pattern is running ('{self.name} stop' ends "
                               "it); nothing moved")
        target = (x, y, z)
        record = hare_path_record(target, blend=mode == "blend")
        if self.mover.active or (self.motion is not None and len(self.motion) > 0):
            # it starts from wherever the move before it ends: checked now, planned then
            self.check_target(target)
            assert self.motion is not None
            self.motion.put(record)
            return f"{self.name}: to ({x:g}, {y:g}, {z:g}) queued ({len(self.motion)} waiting)"
        hare = self.to(target, blend=mode == "blend")  # now, in this tick: checked, planned once
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
        mv = self.mover
        mv.tension_stop = not mv.tension_stop
        if mv.stops is not None:
            mv.stops.tension_stops = mv.tension_stop
        return f"{self.name}: tension stops {'on' if mv.tension_stop else 'OFF'}"

    @command(name="errorSignalAll")
    def cmd_error_signal_all(self) -> str:
        """errorSignalAll: toggle driving every rope toward its equilibrium tension."""
        mv = self.mover
        mv.signal_all = not mv.signal_all
        return (f"{self.name}: error signals "
                f"{'on every rope (errorSignalAll)' if mv.signal_all else 'off-side only'}")

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

    # -- moving (the move controller's) ---------------------------------------------------

    def to(self, target: Sequence[float], *, blend: bool = False) -> Hare:
        """Start a move to ``target`` (global cm) now: the ``hare_path`` motion,
        checked and planned once (:meth:`plan_path`); re-arms the tension
        stops.  Every Axis goes to PolyAxis control (000's polyActivate)."""
        motion = self.mover.begin(hare_path_record(target, blend))
        assert isinstance(motion, HarePath) and motion.hare is not None
        return motion.hare

    def stop(self) -> None:
        """The ``stop`` command: every motor stopped, the move ended."""
        self.mover.end(StopReason.STOP, "stop command")

    def end_move(self, reason: StopReason, detail: str) -> StopRecord:
        """End the move for ``reason`` (an Axis's ``stop``, or a fault the Axis
        itself reports): every motor stopped, the stop recorded and told."""
        return self.mover.end(reason, detail)

    @property
    def moving(self) -> bool:
        """A move is in progress."""
        return self.mover.active

    def settled_at_turn(self) -> bool:
        """The source has come to rest at the neck turn (the hare may go on)."""
        return (dist(self.position, self.model.via)
                <= max(self.record.find_tolerance, self.model.end_error))

    def tension_find(self) -> Vec:
        """``tensionFind``: the position where the measured tensions balance the
        weight (from the current estimate, in the free directions)."""
        return self.model.position_from_tensions(self.position, self.tensions)

    def status_line(self) -> str:
        """Source position, distErr, residual net force, tensions and time."""
        return self.status.status_line()

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
        mv = self.mover
        try:
            est.measure()
        except NativeError as exc:
            mv.position_lost(f"position finder failed: {exc}")
            return
        est.position_error = None
        if est.estimate_lost is None:  # the estimate's integrity, every poll
            detail = est.check()
            if detail is not None:
                mv.estimate_lost(detail)
        mv.step(now_s)
        if mv.active:
            mv.drive(now_s, dt)
        for a in self.axes:
            if a.mode == POLYAXIS:
                a.encoder.poll(now_s)
        status = self.status
        if status.debug:
            status.poll(now_s)

    def measure(self) -> None:
        """Read every Axis and find the source position (the estimator's
        measure); a position finder that fails is noted (moves refused)."""
        est = self.estimator
        try:
            est.measure()
        except NativeError as exc:
            est.position_error = f"position finder failed: {exc}"


# The straight-line move drives a PolyAxis (paths.py cannot name the class: it is
# imported by this module).
HarePath.drives = (PolyAxis,)
