"""Co-ordinated control of the ropes: the PolyAxis of 000, section 5.

Every control poll (the polyaxis-poll task, :mod:`pyrt.tasks.polyaxis_poll`,
which :meth:`PolyAxis.tasks` declares beside axis-poll):

1. each Axis's tension and stretch-corrected length are read;
2. rope segments that bear on the neck ring get their contact point as
   effective top (upper segment) or effective bottom (lower segment, with
   the source up in the neck): the finder sees the rope from there, its
   measured length less the piece beyond the contact.  The model is the
   world's (csrc/neck.h, both segments; ``ring_segments`` names where a
   controller deliberately knows less).  Then ``findPositionL`` runs through the prepared C
   solver (:class:`pyrt.native.PositionFinder`, freeze mask from the bottom
   attachments): position and distErr (the RMS length residual);
3. the residual net force on the source is the sum of the measured tensions
   along the ropes plus the net weight (buoyancy in D2O when submerged);
4. during a move the running motion (:mod:`pyrt.scheduler.motion`: the
   built-in ``hare_path`` of :mod:`pyrt.robots.paths`, or any plug-in
   motion type) is stepped by the PolyAxis's :class:`MotionExecutor`, which
   takes the queued motion records in order; the motion sets the hare
   (``hare_position``), the point the source is driven after; the error
   signals are set (``errorSignal``: length errors against the hare on every
   rope, off-side ropes driven toward OFFSIDE_TENSION, the others free; or
   ``errorSignalAll``: every rope driven toward the equilibrium tensions),
   the ten fuzzy rules run for every Axis in one batched C call
   (:class:`pyrt.native.FuzzyBatch`), each Motor gets its new desired
   velocity and applies DV_LIMIT and the speed limits in its poll;
5. the five stop conditions (:mod:`pyrt.robots.stops`) are checked, here
   and not in the motion, so no motion type can bypass the safety stops.

The numeric work of steps 1-3 (after the device reads) and of step 4 (up to
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
axes back to standalone control.  The safety stops (tension, net force) are
also faults, reported through :meth:`~pyrt.component.Component.fail` (the
station's one fault path): the reflex runs, and the manipulator stays
stopped until acknowledged.

Estimate integrity (beyond 000).  After every measure, moving or not, the
estimate is checked (:meth:`PolyAxis.check_estimate`): distErr beyond
DIST_ERR_LIMIT, or distErr rising while an encoder falls out of step with
its motor (a slipping or reset encoder), is a fault naming the axis; from
then every move is refused and nothing measured is written back until the
position is re-established: ``survey`` (the position from every rope but
the suspect one, as the redundant rope lets 000's finder do; that rope's
encoder re-zeroed) or ``setpos X Y Z`` (the operator has seen the source;
every encoder re-zeroed to agree).  Targets are refused before anything
moves when outside the vessel, out of a planar station's plane, within
TENSION_MARGIN of the tension bounds, or when the path passes points where
the source could not be held.

Patterns (``pattern FILE``: endpoint after endpoint, with a log) run as a
foreground job from :mod:`pyrt.robots.pattern`; the log is written through
a writer, off the loop thread unless the clock is simulated.

The corrected length of 000 is the measured length less the rope's length
residual, so that errors of the position estimate do not appear as error
terms; errors are actual - desired.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Generator, Sequence
from functools import partial
from pathlib import Path
from typing import TextIO

import numpy as np

from pyrt.component import Arg, Component, Limits, Signal, command, finite
from pyrt.devices._args import parse_number
from pyrt.devices.motor import STEP_MODE
from pyrt.errors import CommandError, ConfigError, NativeError
from pyrt.native import (
    FuzzyBatch,
    FuzzyInput,
    FuzzyParams,
    PolyControl,
    PositionFinder,
    StaticsSolver,
)
from pyrt.robots._neck import NeckRing
from pyrt.robots.av import AV
from pyrt.robots.axis import POLYAXIS, Axis
from pyrt.robots.paths import VIA_BELOW, Hare, HarePath, hare_path_record, plan_segments
from pyrt.robots.pattern import log_writer, read_pattern, run_pattern
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

GRAVITY = 9.80665
#: NEAR_END truth falls from 1 at the endpoint to 0 at this distance (cm).
NEAR_END_CM = 10.0
#: A target closer than this to a top pulley (cm) is refused.
MIN_TOP_SEGMENT = 5.0
#: Control polls between snapshots of a consistent estimate; the older of the
#: last two is the reference of the slip check (so it covers 1-2 s at 50 ms).
SNAPSHOT_POLLS = 20
#: Encoder counts an encoder may fall out of step with its motor since the
#: reference (quantisation makes one) before, with distErr rising by more
#: than FIND_TOLERANCE, its rope's length is taken to be wrong (slip, reset).
SLIP_COUNTS = 2

Vec = tuple[float, float, float]
_FI = FuzzyInput


def _dist(a: Sequence[float], b: Sequence[float]) -> float:
    return math.sqrt((a[0] - b[0]) ** 2 + (a[1] - b[1]) ** 2 + (a[2] - b[2]) ** 2)


def _cm(axis: str) -> Callable[[str], float]:
    return finite(f"{axis} in cm")


class PolyAxis(Component):
    """The co-ordinated manipulator (see the module text).

    ``axes`` are the :class:`Axis` objects in database order (the central rope
    has no bottom attachment); lengths cm, forces N, masses kg, volumes cm3,
    times s.  ``poll_s`` is the control poll period the fuzzy rules are
    scaled to.  ``liquid_level``: z of the D2O surface (None: in air).
    """

    def __init__(
        self,
        name: str,
        axes: Sequence[Axis],
        av: AV,
        *,
        source_mass: float,
        source_volume: float,
        position: Sequence[float],
        end_error: float = 1.0,
        low_tension: float = 2.0,
        max_tension: float = 200.0,
        net_forcelimit: float = 25.0,
        offside_tension: float = 10.0,
        hare_speed: float = 2.0,
        hare_ramp: float = 20.0,
        stuck_time: float = 10.0,
        find_tolerance: float = 0.1,
        dist_err_limit: float = 0.5,
        tension_margin: float = 5.0,
        d2o_density: float = 1.10,
        liquid_level: float | None = None,
        poll_s: float = 0.05,
        fuzzy: Sequence[FuzzyParams] | None = None,
        stdout: TextIO | None = None,
        ring_segments: int | None = None,
    ):
        if not axes:
            raise ConfigError(f"polyaxis {name}: no axes")
        if not (poll_s > 0 and math.isfinite(poll_s)):
            raise ConfigError(f"polyaxis {name}: poll period must be > 0 s, got {poll_s!r}")
        self.name = name
        self.axes = list(axes)
        self.n = len(self.axes)
        self.av = av
        self.source_mass = float(source_mass)
        self.source_volume = float(source_volume)
        self.end_error = float(end_error)
        self.low_tension = float(low_tension)
        self.max_tension = float(max_tension)
        self.net_forcelimit = float(net_forcelimit)
        self.offside_tension = float(offside_tension)
        self.hare_speed = float(hare_speed)
        self.hare_ramp = float(hare_ramp)
        self.stuck_time = float(stuck_time)
        self.find_tolerance = float(find_tolerance)
        self.dist_err_limit = float(dist_err_limit)
        self.tension_margin = float(tension_margin)
        self.d2o_density = float(d2o_density)
        self.liquid_level = liquid_level
        self.poll_s = float(poll_s)
        self.stdout = stdout

        # geometry (global co-ordinates: bottoms carried through av.vtog)
        self.tops: list[Vec] = [a.top for a in self.axes]  # type: ignore[misc]
        self.bottoms: list[Vec | None] = [a.bottom for a in self.axes]
        self.offsets: list[Vec] = [a.offset for a in self.axes]  # type: ignore[misc]
        self.ring = av.neck_ring()
        self._ring = NeckRing(*self.ring)
        #: The rope segments the controller lets bear on the neck ring: by default
        #: both, as the world does (one geometry in two roles); a smaller mask is
        #: a controller that deliberately knows less (UPPER: lower segments straight).
        self.ring_segments = (PolyControl.RING_SEGMENTS if ring_segments is None
                              else int(ring_segments))
        centre = av.vtog((0.0, 0.0, 0.0))
        self.axis_point: Vec = centre
        self.via: Vec = tuple(  # type: ignore[assignment]
            av.neck_ring_position[k] - VIA_BELOW * av.neck_axis[k] for k in range(3))
        nan = math.nan
        bott = np.array([(nan, nan, nan) if b is None else b for b in self.bottoms], float)
        try:
            self.finder = PositionFinder(np.array(self.tops, float), bott,
                                         np.array(self.offsets, float), tol=self.find_tolerance)
        except NativeError as exc:
            raise ConfigError(f"polyaxis {name}: {exc}") from None
        self._check_plane(name, position)
        # The statics kernel as a rope-geometry evaluator: every rope's length at
        # the hare, over the ring where it bears on it, in one C call (its
        # tensions and payouts are not used).
        self._geometry = StaticsSolver(
            self.tops, self.bottoms, self.offsets, [a.dead_length for a in self.axes],
            [a.stretch for a in self.axes], [a.dead_length + 1000.0 for a in self.axes],
            ring=self.ring)
        self._names = [a.name for a in self.axes]
        # "far side of the central axis": the bottom's horizontal direction
        self._bdir: list[tuple[float, float] | None] = []
        for b in self.bottoms:
            if b is None:
                self._bdir.append(None)
            else:
                self._bdir.append((b[0] - centre[0], b[1] - centre[1]))

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
        rf = self._ring
        ring = (*rf.centre, *rf.axis, *rf.e1, *rf.e2, rf.radius)
        wet = (self.source_volume > 0 and liquid_level is not None)
        try:
            self._ctl = PolyControl(
                self.finder, self.batch, tops=self.tops, bottoms=self.bottoms,
                offsets=self.offsets, stretch=[a.stretch for a in self.axes],
                dead=[a.dead_length for a in self.axes], ring=ring,
                axis_point=centre[:2], weight_air=self.weight(math.inf),
                weight_liquid=self.weight(-math.inf), liquid_level=liquid_level if wet else None,
                offside_tension=self.offside_tension, near_end_cm=NEAR_END_CM,
                position=position, ring_segments=self.ring_segments)
        except NativeError as exc:
            raise ConfigError(f"polyaxis {name}: {exc}") from None
        self._read_tension = [a.loadcell.tension for a in self.axes]
        self._read_length = [a.encoder.length for a in self.axes]
        self._encoder_lengths = [0.0] * self.n

        # state
        self.position: Vec = tuple(float(c) for c in position)  # type: ignore[assignment]
        self.dist_err = 0.0
        self.tensions = [0.0] * self.n
        self.lengths = [0.0] * self.n
        self.net_force: Vec = (0.0, 0.0, 0.0)
        self.net_force_magnitude = 0.0
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
        #: Why the last poll could not find the position (None: it could).
        self.position_error: str | None = None
        #: Why the position estimate is not trusted (a slipping or reset encoder,
        #: a rope whose length disagrees), or None; moves are refused until
        #: ``survey`` or ``setpos`` re-establishes it.
        self.estimate_lost: str | None = None
        #: The axis the last estimate fault named (index), for ``survey``.
        self.suspect: int | None = None
        # snapshots (polls, distErr, encoder counts, motor steps) of a consistent
        # estimate, the older one the reference of the slip check
        self._snapshots: list[tuple[float, list[int], list[int]]] = []
        self._snapshot_in = 0
        self.moves = 0
        self.polls = 0
        self.now_s = 0.0
        self.last_poll_s: float | None = None
        #: Called with (cause, source) for a safety stop: the ready queue's trip.
        #: Called with (StopRecord) after every stop.
        self.on_stop: list[Callable[[StopRecord], None]] = []
        #: The motion queue of MotionRecords (set by the station), emptied by
        #: the executor between moves and cleared by any abnormal stop.
        self.motion: MotionQueue | None = None
        #: The station's ``loop.spawn`` (patterns run as foreground jobs).
        self.spawn: Callable[[str, Generator], Job] | None = None
        #: The running (or last) pattern job and its log file.
        self.pattern_job: Job | None = None
        self.pattern_log: Path | None = None
        #: How the pattern log is written: ``"thread"`` (off the loop thread) or
        #: ``"sync"`` (at once: deterministic, for simulated-clock runs).
        self.pattern_writer = "thread"
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
        #: Where the state log goes (one line at a time), or None.
        self.log: Callable[[str], None] | None = None
        self.debug = False
        self.debug_next = 0.0
        #: (polyaxis-poll, axis-poll) periods in queue checks (set_task_periods).
        self.task_periods: tuple[int, int] | None = None

    def _check_plane(self, name: str, position: Sequence[float]) -> None:
        """A planar manipulator (a direction the finder holds: 000's freeze mask)
        must have every top pulley, the neck ring and the start position in the
        held plane (the bottoms' mean there), within FIND_TOLERANCE: a pulley out
        of it hangs the source where the controller can neither see nor move it."""
        self.plane: dict[int, float] = {}
        side = [b for b in self.bottoms if b is not None]
        for k in range(3):
            if not self.finder.freeze[k] or not side:
                continue
            held = sum(b[k] for b in side) / len(side)
            self.plane[k] = held
            axis = "xyz"[k]
            places = [(f"{a.name} top pulley (AXIS.dat TOP)", self.tops[i])
                      for i, a in enumerate(self.axes)]
            places += [("the neck ring centre (AV.dat)", self.ring[0]),
                       ("the source (POLYAXIS.dat POSITION)", position)]
            for what, p in places:
                if abs(float(p[k]) - held) > self.find_tolerance:
                    raise ConfigError(
                        f"polyaxis {name}: {what} is at {axis} = {float(p[k]):g} cm, out of the "
                        f"plane {axis} = {held:g} cm the position finder holds (every bottom "
                        f"attachment is there); the source would hang out of the plane the "
                        f"controller can measure and move in: put it in the plane")

    @classmethod
    def from_record(cls, record, axes: Sequence[Axis], av: AV, **kw) -> PolyAxis:
        """A PolyAxis from a :class:`pyrt.db.PolyAxisRecord`."""
        return cls(
            record.name, axes, av,
            source_mass=record.source_mass, source_volume=record.source_volume,
            position=record.position, end_error=record.end_error,
            low_tension=record.low_tension, max_tension=record.max_tension,
            net_forcelimit=record.net_forcelimit, offside_tension=record.offside_tension,
            hare_speed=record.hare_speed, hare_ramp=record.hare_ramp,
            stuck_time=record.stuck_time, find_tolerance=record.find_tolerance,
            d2o_density=record.d2o_density, dist_err_limit=record.dist_err_limit,
            tension_margin=record.tension_margin, **kw,
        )

    # -- physics of the source -----------------------------------------------------

    def weight(self, z: float) -> float:
        """Net downward force on the source at height ``z`` (N)."""
        m = self.source_mass
        if self.source_volume > 0 and self.liquid_level is not None and z < self.liquid_level:
            m -= self.d2o_density * 1e-3 * self.source_volume
        return m * GRAVITY

    def rope_geometry(self, i: int, x: Sequence[float]
                      ) -> tuple[float, Vec | None, Vec, Vec | None]:
        """(length beyond the top pulley, upper segment's ring contact or None, unit
        pull toward the top, unit pull toward the bottom or None) of rope ``i`` for
        the source at ``x``: the one rope model (csrc/neck.h) with the segments the
        controller lets bear on the ring (:attr:`ring_segments`)."""
        o = self.offsets[i]
        q = (x[0] + o[0], x[1] + o[1], x[2] + o[2])
        b = self.bottoms[i]
        path = self._ring.rope_path(self.tops[i], b, q, self.ring_segments)
        t = path.upper if path.upper is not None else self.tops[i]
        d = (t[0] - q[0], t[1] - q[1], t[2] - q[2])
        lt = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) or 1e-12
        ut = (d[0] / lt, d[1] / lt, d[2] / lt)
        if b is None:
            return path.length, path.upper, ut, None
        if path.lower is not None:
            b = path.lower
        e = (b[0] - q[0], b[1] - q[1], b[2] - q[2])
        lb = math.sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2]) or 1e-12
        return path.length, path.upper, ut, (e[0] / lb, e[1] / lb, e[2] / lb)

    def force_directions(self, x: Sequence[float]) -> list[Vec]:
        """Per rope, the force on the source per newton of tension at ``x``."""
        out = []
        for i in range(self.n):
            _, _, ut, ub = self.rope_geometry(i, x)
            out.append(ut if ub is None else (ut[0] + ub[0], ut[1] + ub[1], ut[2] + ub[2]))
        return out

    def net_force_at(self, x: Sequence[float], tensions: Sequence[float]) -> Vec:
        """Residual force on the source at ``x`` with ``tensions`` (N)."""
        f = [0.0, 0.0, -self.weight(x[2])]
        for a, t in zip(self.force_directions(x), tensions, strict=True):
            f[0] += t * a[0]
            f[1] += t * a[1]
            f[2] += t * a[2]
        return (f[0], f[1], f[2])

    def off_side(self, x: Sequence[float]) -> list[bool]:
        """Side ropes whose bottom attachment is on the far side of the central
        axis from ``x`` (or level with it)."""
        hx, hy = x[0] - self.axis_point[0], x[1] - self.axis_point[1]
        return [bd is not None and bd[0] * hx + bd[1] * hy <= 0.0 for bd in self._bdir]

    def equilibrium_tensions(self, x: Sequence[float]) -> tuple[list[float], float]:
        """Tensions that hold the source at ``x``: off-side ropes at
        OFFSIDE_TENSION, the others by least squares; and the force left over (N)."""
        a = np.array(self.force_directions(x), float).T  # 3 x n
        off = self.off_side(x)
        t = np.array([self.offside_tension if o else 0.0 for o in off])
        rhs = np.array([0.0, 0.0, self.weight(x[2])]) - a @ t
        free = [i for i in range(self.n) if not off[i]]
        if free:
            sol = np.linalg.lstsq(a[:, free], rhs, rcond=None)[0]
            t[free] = sol
        resid = a @ t - np.array([0.0, 0.0, self.weight(x[2])])
        return [float(v) for v in t], float(np.linalg.norm(resid))

    # -- containment ----------------------------------------------------------------

    def _vessel_frame(self, x: Sequence[float]) -> tuple[float, float]:
        """(radial distance from the neck axis, height above the neck ring), cm."""
        v = self.av.gtov(x)
        c = self.av.neck_ring_static_position
        return math.hypot(v[0] - c[0], v[1] - c[1]), v[2] - c[2]

    def in_neck(self, x: Sequence[float]) -> bool:
        """In the neck for path planning: inside the neck radius, at or above the
        turn point just below the ring."""
        r, h = self._vessel_frame(x)
        return r <= self.av.neck_radius and h >= -VIA_BELOW

    def refusal(self, x: Sequence[float]) -> str | None:
        """Why the source may not be at ``x``, or None.

        Allowed: inside the vessel sphere, or inside the neck (within
        NECK_RADIUS of its axis, up to NECK_LENGTH above the ring).  The
        column under the ring inside the neck radius counts as neck: in the
        prototype (Table 5) the ring is 44 cm above the top of the 3.20 m
        sphere and the source must pass there to reach the neck; in the full
        vessel that column lies inside the sphere anyway.
        """
        if self.av.in_vessel(x):
            return None
        r, h = self._vessel_frame(x)
        v = self.av.gtov(x)
        if v[2] >= 0.0 and h <= self.av.neck_length:
            if r <= self.av.neck_radius:
                return None
            if h >= 0.0:
                return (f"outside the neck's allowed radius ({r:.2f} cm from the neck axis, "
                        f"NECK_RADIUS {self.av.neck_radius:g} cm)")
        return "outside the vessel"

    def plane_refusal(self, x: Sequence[float]) -> str | None:
        """Why ``x`` is out of a planar manipulator's plane (more than END_ERROR
        from it in a held direction), or None."""
        for k, held in self.plane.items():
            if abs(float(x[k]) - held) > self.end_error:
                return (f"out of the manipulator's plane ({'xyz'[k]} = {held:g} cm: every rope "
                        f"lies in it, so the source cannot leave it)")
        return None

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

    def parse_point(self, args: Sequence[str], what: str) -> Vec:
        """Three words as a point (cm); CommandError naming the bad one."""
        return tuple(parse_number(a, f"{self.name} {what}", f"{c} in cm")  # type: ignore[return-value]
                     for a, c in zip(args, "xyz", strict=True))

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
    def cmd_tensionfind(self) -> str:
        """tensionFind: find and display the position from the tensions."""
        x = self.tension_find()
        return f"{self.name}: position from tensions ({x[0]:.2f}, {x[1]:.2f}, {x[2]:.2f})"

    @command(name="tensions", reads_only=True)
    def cmd_tensions(self) -> str:
        """tensions: find and display the desired tensions."""
        t, resid = self.equilibrium_tensions(self.position)
        parts = " ".join(f"{a.name} {v:.2f} N" for a, v in zip(self.axes, t, strict=True))
        return f"{self.name}: desired tensions {parts} (unbalanced {resid:.2f} N)"

    @command(Arg("x", _cm("x"), optional=True), Arg("y", _cm("y"), optional=True),
             Arg("z", _cm("z"), optional=True), name="netForce", reads_only=True)
    def cmd_netforce(self, *args: float) -> str:
        """netForce [x y z]: net force magnitude at (x, y, z) or at the current position."""
        if len(args) not in (0, 3):
            raise CommandError(f"{self.name} netForce: takes 0 or 3 arguments, got {len(args)}")
        x = tuple(args) if args else self.position
        f = self.net_force_at(x, self.tensions)
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
    def cmd_tensionstop(self) -> str:
        """tensionStop: toggle stop-on-tension."""
        self.tension_stop = not self.tension_stop
        if self.stops is not None:
            self.stops.tension_stops = self.tension_stop
        return f"{self.name}: tension stops {'on' if self.tension_stop else 'OFF'}"

    @command(name="errorSignalAll")
    def cmd_errorsignalall(self) -> str:
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
        why = self.refusal(tgt) or self.plane_refusal(tgt)
        if why is not None:
            raise CommandError(f"{self.name} to: refused: ({tgt[0]:g}, {tgt[1]:g}, {tgt[2]:g}) "
                               f"is {why}; nothing moved")
        for i, a in enumerate(self.axes):
            o = self.offsets[i]
            q = (tgt[0] + o[0], tgt[1] + o[1], tgt[2] + o[2])
            if _dist(q, self.tops[i]) < MIN_TOP_SEGMENT:
                raise CommandError(f"{self.name} to: refused: the carriage would be within "
                                   f"{MIN_TOP_SEGMENT:g} cm of {a.name}'s top pulley; "
                                   "nothing moved")
        t, resid = self.equilibrium_tensions(tgt)
        problems = []
        lo = self.low_tension + self.tension_margin
        hi = self.max_tension - self.tension_margin
        margin = f", TENSION_MARGIN {self.tension_margin:g} N" if self.tension_margin else ""
        for a, v in zip(self.axes, t, strict=True):
            if v < lo:
                problems.append(f"{a.name} would need {v:.1f} N (LOW_TENSION "
                                f"{self.low_tension:g} N{margin})")
            elif v > hi:
                problems.append(f"{a.name} would need {v:.1f} N (MAX_TENSION "
                                f"{self.max_tension:g} N{margin})")
        if resid > self.net_forcelimit:
            problems.append(f"{resid:.1f} N could not be balanced (NET_FORCELIMIT "
                            f"{self.net_forcelimit:g} N)")
        if problems:
            raise CommandError(f"{self.name} to: refused: ({tgt[0]:g}, {tgt[1]:g}, {tgt[2]:g}) "
                               "cannot be held within the tension bounds: "
                               + "; ".join(problems) + "; nothing moved")

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
        segs = plan_segments(start, tgt, self.in_neck, self.via)
        hare = Hare(segs, self.hare_speed, self.hare_ramp, blend=blend)
        # the tensions on the way are checked when they are within bounds here (a
        # source held where they are not may always move out: the stops guard it)
        held = self._tension_refusal(start) is None
        for p in hare.sample():
            why = self.refusal(p)
            if why is None and held and _dist(p, start) > 2.0 * self.end_error:
                why = self._tension_refusal(p)
            if why is not None and _dist(p, start) > 2.0 * self.end_error:
                raise CommandError(
                    f"{self.name} to: refused: the path passes ({p[0]:.1f}, {p[1]:.1f}, "
                    f"{p[2]:.1f}), {why}; nothing moved")
        return hare

    def _tension_refusal(self, x: Sequence[float]) -> str | None:
        """Why the source cannot be held at ``x`` on the way (a tension that would
        be out of LOW_TENSION .. MAX_TENSION, or a force left over beyond
        NET_FORCELIMIT: the stops would end the move there), or None."""
        t, resid = self.equilibrium_tensions(x)
        for a, v in zip(self.axes, t, strict=True):
            if v < self.low_tension:
                return f"where {a.name} would need {v:.1f} N (LOW_TENSION {self.low_tension:g} N)"
            if v > self.max_tension:
                return f"where {a.name} would need {v:.1f} N (MAX_TENSION {self.max_tension:g} N)"
        if resid > self.net_forcelimit:
            return (f"where {resid:.1f} N could not be balanced (NET_FORCELIMIT "
                    f"{self.net_forcelimit:g} N)")
        return None

    def to(self, target: Sequence[float], *, blend: bool = False) -> Hare:
        """Start a move to ``target`` (global cm) now, after the checks: the
        ``hare_path`` motion; re-arms the tension stops.  Every Axis goes to
        PolyAxis control (polyActivate)."""
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
                a.polyActivate()
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
            if reason.startswith("refused") and self.stdout is not None:
                self.stdout.write(f"queued move dropped: {reason.removeprefix('refused: ')}\n")
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
        if self.adopted:
            self.fail(detail)

    def stop(self) -> None:
        """The ``stop`` command: every motor stopped, the move ended."""
        self.halt(StopReason.STOP, "stop command")

    def stop_motors(self) -> None:
        """Every motor off (windings off) and every axis back to standalone."""
        for a in self.axes:
            a.motor.stop()
            if a.mode == POLYAXIS:
                a.polyDeactivate()
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
            if dropped and self.stdout is not None:
                self.stdout.write(f"{self.name}: {dropped} queued move(s) dropped\n")
        if reason in SAFETY_STOPS and self.adopted:
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

    def measure(self) -> None:
        """Read every Axis and find the source position (steps 1-3 of the poll):
        the loadcells and encoders here, the rest in one C call."""
        tens = self.tensions
        tens[:] = [f() for f in self._read_tension]
        raw = self._encoder_lengths
        raw[:] = [f() for f in self._read_length]
        x, y, z, self.dist_err, fx, fy, fz, self.net_force_magnitude = self._ctl.measure(
            tens, raw, self.lengths)
        self.position = (x, y, z)
        self.net_force = (fx, fy, fz)

    def poll(self, now_s: float) -> None:
        """One control poll at ``now_s`` seconds, by hand (the polyaxis-poll
        routine's body, :func:`pyrt.tasks.polyaxis_poll.control_poll`)."""
        polyaxis_poll.control_poll(self, now_s)

    def position_lost(self, cause: str) -> None:
        """The position finder failed (``cause``): keep the last position, refuse
        moves; during a move it is a fault of the whole manipulator."""
        self.position_error = cause
        if self.active:
            self.halt(StopReason.FAULT, cause)
            if self.adopted:
                self.fail(cause)

    # -- estimate integrity ---------------------------------------------------------------

    def check_estimate(self) -> None:
        """After every measure, moving or not: the estimate is lost (a fault of
        the manipulator naming the axis) when distErr exceeds DIST_ERR_LIMIT, or
        when it has risen by more than FIND_TOLERANCE since the reference while
        an encoder has fallen SLIP_COUNTS counts out of step with its motor (an
        encoder slipping on its rope, or reset).  Moves are refused from then
        until ``survey`` or ``setpos`` re-establishes the position."""
        if self.estimate_lost is not None:
            return
        de = self.dist_err
        snaps = self._snapshots
        disc: list[float] | None = None
        if de > self.dist_err_limit:
            cause = f"distErr {de:.3f} cm above DIST_ERR_LIMIT {self.dist_err_limit:g} cm"
        elif snaps and de > snaps[0][0] + self.find_tolerance:
            disc = self._disagreement()
            i = max(range(self.n), key=lambda k: abs(disc[k]))  # type: ignore[index]
            if abs(disc[i]) < SLIP_COUNTS * self.axes[i].encoder.slope:
                self._snapshot(de)
                return
            cause = f"distErr rose from {snaps[0][0]:.3f} to {de:.3f} cm"
        else:
            self._snapshot(de)
            return
        if disc is None:
            disc = self._disagreement() if snaps else [0.0] * self.n
        i = max(range(self.n), key=lambda k: abs(disc[k]))  # type: ignore[index]
        if abs(disc[i]) >= SLIP_COUNTS * self.axes[i].encoder.slope:
            why = (f"its encoder is {disc[i]:+.2f} cm out of step with its motor "
                   "(encoder slip or reset)")
        else:
            res = [float(r) for r in self.finder.residuals]
            i = max(range(self.n), key=lambda k: abs(res[k]))
            why = f"its length disagrees most ({res[i]:+.2f} cm)"
        self.suspect = i
        name = self.axes[i].name
        self.estimate_lost = f"{name}: {cause}; {why}"
        detail = (f"{name}: position estimate lost: {cause}; {why}; moves refused until "
                  "'survey' or 'setpos X Y Z'")
        if self.active:
            self._fault(detail)
        elif self.adopted:
            self.fail(detail)
        else:
            self.stop_motors()

    def _snapshot(self, de: float) -> None:
        """Every SNAPSHOT_POLLS polls of a consistent estimate: distErr, encoder
        counts and motor steps (the last two kept)."""
        self._snapshot_in -= 1
        if self._snapshot_in > 0 and self._snapshots:
            return
        self._snapshot_in = SNAPSHOT_POLLS
        snap = (de, [a.encoder.count() for a in self.axes],
                [a.motor.position_steps for a in self.axes])
        self._snapshots.append(snap)
        if len(self._snapshots) > 2:
            del self._snapshots[0]

    def _disagreement(self) -> list[float]:
        """Per axis, rope the encoder saw less the rope the motor moved since the
        reference snapshot (cm)."""
        _, counts, steps = self._snapshots[0]
        return [(a.encoder.count() - c) * a.encoder.slope
                - (a.motor.position_steps - s) / a.motor.steps_per_cm
                for a, c, s in zip(self.axes, counts, steps, strict=True)]

    def establish(self, x: Sequence[float]) -> list[float]:
        """The source is at ``x``: every encoder re-zeroed so that its corrected
        length is the rope's length there (at the measured tension), the finder
        restarted from ``x``, the estimate trusted again.  Returns each encoder's
        change of zero length (cm)."""
        p: Vec = (float(x[0]), float(x[1]), float(x[2]))
        changes = []
        for i, a in enumerate(self.axes):
            g = self.length_at(i, p)
            t = max(self.tensions[i], 0.0)
            want = (g + a.dead_length) / (1.0 + a.stretch * t)
            enc = a.encoder
            new = want - enc.slope * enc.count()
            changes.append(new - enc.zero_length)
            enc.zero_length = new
        self._ctl.set_position(p)
        self.position = p
        self.estimate_lost = None
        self.suspect = None
        self.position_error = None
        self._snapshots.clear()
        self._snapshot_in = 0
        self.measure()
        return changes

    def _refuse_reestablish(self, word: str) -> None:
        if self.active or any(a.motor.running for a in self.axes):
            raise CommandError(f"{self.name} {word}: a motor is moving; stop it first; "
                               "nothing changed")

    @command(Arg("x", _cm("x")), Arg("y", _cm("y")), Arg("z", _cm("z")), name="setpos")
    def cmd_setpos(self, x: float, y: float, z: float) -> str:
        """setpos X Y Z: the source is at (X, Y, Z) cm (the operator has seen it):
        every encoder is re-zeroed to agree and moves are allowed again."""
        self._refuse_reestablish("setpos")
        p = (x, y, z)
        why = self.refusal(p) or self.plane_refusal(p)
        if why is not None:
            raise CommandError(f"{self.name} setpos: ({x:g}, {y:g}, {z:g}) is {why}; "
                               "nothing changed")
        changes = self.establish(p)
        moved = ", ".join(f"{a.name} {c:+.2f}" for a, c in zip(self.axes, changes, strict=True))
        return (f"{self.name}: position set to ({x:g}, {y:g}, {z:g}); encoders re-zeroed "
                f"({moved} cm); distErr {self.dist_err:.3f} cm; moves allowed")

    @command(name="survey")
    def cmd_survey(self) -> str:
        """survey: re-establish the position from the redundant ropes: the
        position from every rope but the one the last estimate fault named (or
        the one whose length disagrees most), that rope's encoder re-zeroed."""
        self._refuse_reestablish("survey")
        if self.suspect is not None:
            bad = self.suspect
        else:
            res = [float(r) for r in self.finder.residuals]
            bad = max(range(self.n), key=lambda k: abs(res[k]))
        others = [k for k in range(self.n) if k != bad]
        free = [k for k in range(3) if not self.finder.freeze[k]]
        name = self.axes[bad].name
        if len(others) < len(free):
            raise CommandError(f"{self.name} survey: without {name} {len(others)} ropes cannot "
                               f"fix {len(free)} directions; use 'setpos X Y Z'; nothing changed")
        x, rms = self._solve_without(bad, free)
        why = self.refusal(x) or self.plane_refusal(x)
        if rms > self.dist_err_limit or why is not None or not all(map(math.isfinite, x)):
            raise CommandError(
                f"{self.name} survey: the ropes but {name} do not agree on a position "
                f"(residual {rms:.3f} cm{'; ' + why if why else ''}); use 'setpos X Y Z'; "
                "nothing changed")
        change = self.establish(x)[bad]
        return (f"{self.name}: survey: position ({x[0]:.2f}, {x[1]:.2f}, {x[2]:.2f}) from every "
                f"rope but {name} (residual {rms:.3f} cm); {name}'s encoder re-zeroed by "
                f"{change:+.2f} cm; distErr {self.dist_err:.3f} cm; moves allowed")

    def _solve_without(self, bad: int, free: list[int]) -> tuple[Vec, float]:
        """Gauss-Newton from the estimate on every rope's corrected length but
        ``bad``'s, in the free directions: (position, RMS residual cm)."""
        others = [k for k in range(self.n) if k != bad]
        meas = np.array([self.lengths[k] for k in others], float)
        x = np.array(self.position, float)

        def resid(p: np.ndarray) -> np.ndarray:
            return meas - np.array([self.length_at(k, p) for k in others], float)

        r = resid(x)
        for _ in range(50):
            jac = np.zeros((len(others), len(free)))
            for j, k in enumerate(free):
                dx = np.zeros(3)
                dx[k] = 0.01
                jac[:, j] = (resid(x + dx) - r) / 0.01
            step = np.zeros(3)
            step[free] = np.linalg.lstsq(jac, -r, rcond=None)[0]
            norm = float(np.linalg.norm(step))
            if norm > 20.0:
                step *= 20.0 / norm
            x = x + step
            r = resid(x)
            if norm < 1e-4:
                break
        rms = float(np.sqrt(np.mean(r * r))) if len(r) else 0.0
        return (float(x[0]), float(x[1]), float(x[2])), rms

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
        return _dist(self.position, self.via) <= max(self.find_tolerance, self.end_error)

    def _hare_refusal(self, hp: object) -> str | None:
        """Why a plug-in motion's hare may not be chased, or None."""
        try:
            x = tuple(float(c) for c in hp)  # type: ignore[attr-defined]
        except (TypeError, ValueError):
            return f"set the hare to {hp!r}, not a point"
        if len(x) != 3 or not all(math.isfinite(c) for c in x):
            return f"set the hare to {hp!r}, not a finite point"
        why = self.refusal(x)
        if why is not None:
            return f"put the hare at ({x[0]:.1f}, {x[1]:.1f}, {x[2]:.1f}), {why}"
        self.hare_position = x  # type: ignore[assignment]
        return None

    def lengths_at(self, x: Sequence[float]) -> list[float]:
        """Every rope's length beyond its top pulley with the source at ``x`` (cm),
        over the neck ring where a rope bears on it: one C call."""
        if self.ring_segments != StaticsSolver.RING_SEGMENTS:  # the controller knows less
            return [self.length_at(i, x) for i in range(self.n)]
        try:
            return self._geometry.evaluate(x)[0]
        except NativeError:  # degenerate (the carriage on a pulley): the Python form
            return [self.length_at(i, x) for i in range(self.n)]

    def length_at(self, i: int, x: Sequence[float]) -> float:
        """Rope ``i``'s length beyond its top pulley with the source at ``x`` (cm),
        over the neck ring where it bears on it (:meth:`rope_geometry`'s length)."""
        o = self.offsets[i]
        q = (x[0] + o[0], x[1] + o[1], x[2] + o[2])
        return self._ring.rope_path(self.tops[i], self.bottoms[i], q, self.ring_segments).length

    def drive_motors(self, now_s: float, dt: float) -> None:
        """During a move: error signals, the batched fuzzy step, every motor, the stops."""
        stops = self.stops
        assert stops is not None
        hp = self.hare_position
        if hp is None:
            hp = self.hare_position = self.position
        motors = self._motors
        if self.signal_all:
            want, _ = self.equilibrium_tensions(hp)
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
        hit = stops.check(now_s, self.position, self.dist_err, self.tensions,
                          self.net_force_magnitude, self._names)
        if hit is not None:
            self.halt(*hit)

    # -- tension find --------------------------------------------------------------------

    def tension_find(self, iterations: int = 30) -> Vec:
        """``tensionFind``: the position where the measured tensions balance the
        weight (Gauss-Newton from the current estimate, in the free directions)."""
        x = np.array(self.position, float)
        free = [k for k in range(3) if not self.finder.freeze[k]]
        for _ in range(iterations):
            f0 = np.array(self.net_force_at(x, self.tensions))
            jac = np.zeros((3, 3))
            for k in free:
                dx = np.zeros(3)
                dx[k] = 0.01
                jac[:, k] = (np.array(self.net_force_at(x + dx, self.tensions)) - f0) / 0.01
            step = np.zeros(3)
            step[free] = np.linalg.lstsq(jac[:, free], -f0, rcond=None)[0]
            n = float(np.linalg.norm(step))
            if n > 20.0:
                step *= 20.0 / n
            x = x + step
            if n < 1e-3:
                break
        return (float(x[0]), float(x[1]), float(x[2]))

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
