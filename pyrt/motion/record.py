"""001's motion record, whole, and what a queued record reports back.

A :class:`MotionSpec` carries every field of RCCL's motion record (001,
"Motion Records"); each is checked when the record is made and is either
honoured by the planner and the evaluator or refused by name with the
reason (none is silently ignored):

==================  ======================================================
field               what pyrt does with it
==================  ======================================================
``transition``      the transition (acceleration) half-time tau in s; None:
                    the least the limits allow.  A time shorter than the
                    limits need is refused, naming both times.
``segment_time``    the segment's time in s; None: the least the limits
                    allow.  A time the limits cannot meet is refused.
``equation``        the position equation moved to (its POS value, read
                    when the record is queued, is the target); None: the
                    last one queued.
``mode``            ``"cart"`` (a straight line of the tool frame, its
                    orientation turned about one axis: Paul's drive
                    transform) or ``"joint"`` (a straight line in joints).
``config``          an arm configuration change (a closed form's name such
                    as ``"lefty-above-noflip"``): joint mode only; a
                    Cartesian line cannot change configuration (refused).
``update``          a term of the equation whose transform is solved for at
                    the end of the segment, from the T6 reached (a guarded
                    or monitored move then remembers where it stopped);
                    must be varb or hold.
``monitor``         a function called every trajectory tick of the segment
                    with the knot; it returns None to go on, or a word that
                    stops the motion (braking along the path) with that
                    word as the termination code.
``sample_rate``     a new trajectory rate in Hz from this segment on (10 ..
                    1000); None: keep the last.
``mass``            the carried object's mass (kg): each knot carries it and
                    the joint torques that hold it (the servo's gravity
                    feed-forward); above the planner's payload: refused.
``force_limits``    six limits (N, N m; inf: none) on the wrist's force and
                    torque: a guarded move.  Honoured when the evaluator has
                    a force sensor (``tick(wrench=...)``): the motion stops
                    with code ``force``; refused otherwise.
``comply``          a comply specification (:class:`Comply`): the tool
                    frame's directions held at a force (an admittance on
                    the wrist's wrench moves the tool along them, off its
                    path) while the others follow the path.  Cartesian
                    records only, with a force sensor (refused otherwise);
                    the next record is queued once it has ended (the arm is
                    where the force put it).
``max_diff``        the maximum differential motion: (metres, radians) the
                    tool may move in one trajectory tick; the segment is
                    slowed to keep within it.
``distance``        the distance modifier: (dx, dy, dz, rx, ry, rz) in the
                    tool frame (m, rad; rx ry rz fixed-axis as URDF's rpy)
                    applied to the target (an approach point above it).
``buffer``          PLCopen's buffer mode: ``aborting``, ``buffered``,
                    ``blending``.
``speed``           a fraction 0 < speed <= 1 of every velocity limit.
``tolerance``       the largest distance (m) a blend may take the tool
                    from the unblended path (the two lines); None: no
                    bound but the limits'.  A corner that cannot meet it within the
                    limits stops exactly there instead.
``target``          joint mode only: a joint vector to move to instead of
                    an equation.
``sets``            joint mode only: the joint sets (kinematic chains, a
                    :class:`~pyrt.kinematics.JointSets` the arm declares)
                    the record moves; None: all.  ``target`` then gives
                    only those sets' joints (in the joint vector's order);
                    the other joints hold the values the queue leaves them
                    at.  An unknown set is refused when the record is queued.
==================  ======================================================

A queued record is copied whole (001: copied first, then queued); the
handle :class:`Move` reports its termination code, its progress 0 -> 1 and
a reached event (and so does its position equation).
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, fields, replace
from enum import StrEnum
from typing import Any

import numpy as np
import numpy.typing as npt

from pyrt.frames import PositionEquation, Transform, TransformType

__all__ = [
    "BufferMode",
    "Comply",
    "Mode",
    "MotionSpec",
    "Move",
    "RecordError",
    "Termination",
]

Vector = npt.NDArray[np.float64]


class RecordError(ValueError):
    """A motion record field is wrong or refused; the message names the field."""


class Mode(StrEnum):
    """001's motion modes."""

    CART = "cart"
    JOINT = "joint"


class BufferMode(StrEnum):
    """What a new record does to the motion before it (PLCopen's names)."""

    ABORTING = "aborting"
    BUFFERED = "buffered"
    BLENDING = "blending"


class Termination(StrEnum):
    """How a record's motion ended (its position equation's termination code)."""

    REACHED = "reached"
    STOPPED = "stopped"
    ABORTED = "aborted"
    FORCE = "force"
    #: A monitor stopped it (the code is the monitor's own word).
    MONITOR = "monitor"


Monitor = Callable[[Any], "str | None"]


def _time(name: str, value: Any, *, low: float = 0.0) -> float | None:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise RecordError(f"{name}: expected seconds, got {value!r}")
    v = float(value)
    if not (math.isfinite(v) and v > low):
        raise RecordError(f"{name}: expected a finite time > {low:g} s, got {value!r}")
    return v


def _vec(name: str, value: Any, n: int, *, positive: bool = False,
         allow_inf: bool = False) -> tuple[float, ...] | None:
    if value is None:
        return None
    try:
        arr = np.array(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise RecordError(f"{name}: expected {n} numbers, got {value!r}") from None
    if arr.shape != (n,):
        raise RecordError(f"{name}: expected {n} numbers, got {arr.size}")
    if np.isnan(arr).any() or (not allow_inf and not np.isfinite(arr).all()):
        raise RecordError(f"{name}: expected finite numbers, got {arr.tolist()}")
    if positive and (arr <= 0).any():
        raise RecordError(f"{name}: every value must be > 0, got {arr.tolist()}")
    return tuple(float(x) for x in arr)


#: The largest force a comply specification may hold (N).
MAX_COMPLY_FORCE = 1000.0


@dataclass(frozen=True)
class Comply:
    """001's comply specification: ``axes`` of the tool frame (some of ``x``,
    ``y``, ``z``) held at ``force`` (N, one per axis: the force the tool
    exerts on what it touches along +axis; the wrist feels the opposite)
    while the other directions follow the path.

    An admittance: each trajectory tick the tool is moved along each axis
    by ``gain`` (m/s per N) times the force error, at most ``speed`` m/s and
    at most ``travel`` m from its path; at the end of the line it holds on
    at rest for ``dwell`` s before the record is reached (what braking
    stirred up settles under the loop).  The loop's time constant is
    1 / (gain x the stiffness of what it touches): the default gain suits
    contacts of 10^4 .. 10^5 N/m at 100 Hz; a stiffer contact needs a lower
    gain.  Torque directions (rx ry rz) are not offered.
    """

    axes: str
    force: Sequence[float] | float
    gain: float = 5e-4
    travel: float = 0.05
    speed: float = 0.05
    dwell: float = 0.3

    def __post_init__(self) -> None:
        put = object.__setattr__
        axes = self.axes.lower() if isinstance(self.axes, str) else ""
        if not axes or any(a not in "xyz" for a in axes) or len(set(axes)) != len(axes):
            raise RecordError(f"comply: axes: expected some of x y z once each (forces along "
                              f"the tool frame's axes; torques are not offered), got "
                              f"{self.axes!r}")
        put(self, "axes", axes)
        f = self.force
        values = [f] * len(axes) if isinstance(f, int | float) and not isinstance(f, bool) \
            else f
        try:
            arr = np.array(values, dtype=np.float64).reshape(-1)
        except (TypeError, ValueError):
            raise RecordError(f"comply: force: expected newtons, got {f!r}") from None
        if arr.shape != (len(axes),) or not np.isfinite(arr).all() or (
                np.abs(arr) > MAX_COMPLY_FORCE).any():
            raise RecordError(f"comply: force: expected {len(axes)} finite value(s) within "
                              f"+-{MAX_COMPLY_FORCE:g} N (one per axis), got {f!r}")
        put(self, "force", tuple(float(x) for x in arr))
        for name, hi, unit in (("gain", 1e-2, "m/(N s)"), ("travel", 0.5, "m"),
                               ("speed", 0.5, "m/s")):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not (
                    math.isfinite(v) and 0.0 < v <= hi):
                raise RecordError(f"comply: {name}: expected 0 < {name} <= {hi:g} {unit}, "
                                  f"got {v!r}")
            put(self, name, float(v))
        d = self.dwell
        if isinstance(d, bool) or not isinstance(d, int | float) or not (
                math.isfinite(d) and 0.0 <= d <= 10.0):
            raise RecordError(f"comply: dwell: expected 0 .. 10 s, got {d!r}")
        put(self, "dwell", float(d))

    @property
    def forces(self) -> tuple[float, ...]:
        """The force of each axis (N), in the order of :attr:`axes`."""
        return tuple(self.force)  # type: ignore[arg-type]  # a tuple once checked

    def index(self) -> list[int]:
        """The tool-frame components (0 x, 1 y, 2 z) held at a force."""
        return ["xyz".index(a) for a in self.axes]


@dataclass(frozen=True)
class MotionSpec:
    """One motion record (the module doc says what each field does).

    Lengths in metres, angles in radians, times in seconds.  Made checked:
    a field that is malformed raises :class:`RecordError` naming it.
    """

    mode: Mode | str = Mode.JOINT
    equation: PositionEquation | None = None
    target: tuple[float, ...] | None = None
    transition: float | None = None
    segment_time: float | None = None
    config: str | None = None
    update: Transform | str | None = None
    monitor: Monitor | None = None
    sample_rate: float | None = None
    mass: float = 0.0
    force_limits: tuple[float, ...] | None = None
    comply: Comply | None = None
    max_diff: tuple[float, ...] | None = None
    distance: tuple[float, ...] | None = None
    buffer: BufferMode | str = BufferMode.BLENDING
    speed: float = 1.0
    tolerance: float | None = None
    name: str = ""
    sets: tuple[str, ...] | None = None

    def __post_init__(self) -> None:
        put = object.__setattr__
        try:
            put(self, "mode", Mode(self.mode))
        except ValueError:
            raise RecordError(f"mode: expected 'cart' or 'joint', got {self.mode!r}") from None
        try:
            put(self, "buffer", BufferMode(self.buffer))
        except ValueError:
            raise RecordError(f"buffer: expected one of aborting, buffered, blending, "
                              f"got {self.buffer!r}") from None
        if self.equation is not None and not isinstance(self.equation, PositionEquation):
            raise RecordError(f"equation: expected a PositionEquation, got {self.equation!r}")
        if self.target is not None:
            if self.mode is not Mode.JOINT:
                raise RecordError("target: a joint vector is a joint-mode target; a "
                                  "Cartesian record moves to its position equation")
            try:
                t = np.array(self.target, dtype=np.float64).reshape(-1)
            except (TypeError, ValueError):
                raise RecordError(f"target: expected joint values, got {self.target!r}") from None
            if t.size == 0 or not np.isfinite(t).all():
                raise RecordError(f"target: expected finite joint values, got {self.target!r}")
            put(self, "target", tuple(float(x) for x in t))
        put(self, "transition", _time("transition", self.transition))
        put(self, "segment_time", _time("segment_time", self.segment_time))
        if self.config is not None:
            if not isinstance(self.config, str) or not self.config.strip():
                raise RecordError(f"config: expected a configuration name, got {self.config!r}")
            if self.mode is Mode.CART:
                raise RecordError(f"config: a straight line cannot change the arm's "
                                  f"configuration (to {self.config!r}); change it by a "
                                  "joint-mode record")
        if self.update is not None and not isinstance(self.update, Transform | str):
            raise RecordError(f"update: expected a transform or its name, got {self.update!r}")
        if self.monitor is not None and not callable(self.monitor):
            raise RecordError(f"monitor: {self.monitor!r} is not callable")
        if self.sample_rate is not None:
            r = self.sample_rate
            if isinstance(r, bool) or not isinstance(r, int | float) or not (10.0 <= r <= 1000.0):
                raise RecordError(f"sample_rate: expected 10 .. 1000 Hz, got {r!r}")
            put(self, "sample_rate", float(r))
        m = self.mass
        if isinstance(m, bool) or not isinstance(m, int | float) or not (
                math.isfinite(m) and m >= 0):
            raise RecordError(f"mass: expected a finite mass >= 0 kg, got {m!r}")
        put(self, "mass", float(m))
        fl = _vec("force_limits", self.force_limits, 6, positive=True, allow_inf=True)
        put(self, "force_limits", fl)
        if self.comply is not None:
            if not isinstance(self.comply, Comply):
                raise RecordError(f"comply: expected a Comply (axes, force), got "
                                  f"{self.comply!r}")
            if self.mode is not Mode.CART:
                raise RecordError("comply: a joint-mode record cannot comply: its directions "
                                  "are the tool frame's, on a Cartesian record")
        put(self, "max_diff", _vec("max_diff", self.max_diff, 2, positive=True))
        put(self, "distance", _vec("distance", self.distance, 6))
        s = self.speed
        if isinstance(s, bool) or not isinstance(s, int | float) or not 0.0 < s <= 1.0:
            raise RecordError(f"speed: expected a fraction 0 < speed <= 1, got {s!r}")
        put(self, "speed", float(s))
        if self.tolerance is not None:
            tol = self.tolerance
            if isinstance(tol, bool) or not isinstance(tol, int | float) or not (
                    math.isfinite(tol) and tol >= 0):
                raise RecordError(f"tolerance: expected a distance >= 0 m, got {tol!r}")
            put(self, "tolerance", float(tol))
        if not isinstance(self.name, str):
            raise RecordError(f"name: expected a string, got {self.name!r}")
        if self.sets is not None:
            sets = (self.sets,) if isinstance(self.sets, str) else self.sets
            try:
                names = tuple(sets)
            except TypeError:
                raise RecordError(f"sets: expected joint set names, got {self.sets!r}") from None
            if not names or not all(isinstance(x, str) and x for x in names):
                raise RecordError(f"sets: expected one or more joint set names, got "
                                  f"{self.sets!r}")
            if len(set(names)) != len(names):
                raise RecordError(f"sets: a joint set named twice in {list(names)}")
            if self.mode is not Mode.JOINT:
                raise RecordError("sets: a Cartesian record moves the tool, and so every "
                                  "joint; name joint sets on a joint-mode record")
            put(self, "sets", names)

    def copy(self, **changes: Any) -> MotionSpec:
        """A whole copy (with some fields changed, checked again)."""
        known = {f.name for f in fields(self)}
        bad = sorted(set(changes) - known)
        if bad:
            raise RecordError(f"unknown field(s) {bad}; a motion record has {sorted(known)}")
        return replace(self, **changes)

    def update_transform(self) -> Transform | None:
        """The transform of the ``update`` field in this record's equation, checked."""
        if self.update is None:
            return None
        eq = self.equation
        if eq is None:
            raise RecordError("update: needs the record's position equation")
        name = self.update.name if isinstance(self.update, Transform) else self.update
        hit = [t for t in eq.transforms if t.name == name]
        if not hit:
            raise RecordError(f"update: no term {name!r} in equation {eq.name!r}")
        t = hit[0]
        if t is eq.t6:
            raise RecordError("update: T6 is the arm's, not a term to update")
        if t.type not in (TransformType.VARB, TransformType.HOLD):
            raise RecordError(f"update: transform {name!r} is {t.type.value}; only a varb or "
                              "hold transform can be updated")
        return t


@dataclass
class Move:
    """A queued record's handle: its copy of the record, termination code,
    progress 0 -> 1 (1 only when it ended) and reached event."""

    spec: MotionSpec
    index: int
    code: str | None = None
    progress: float = 0.0
    reached: threading.Event = field(default_factory=threading.Event)
    #: The T6 and joint values the segment ended at (set when it ends).
    end_t6: Vector | None = None
    end_q: Vector | None = None
    #: The largest corner cut of the blend that ends this segment (m), as planned.
    blend_error: float = 0.0
    #: The buffer mode it was planned with (a blend the limits or the tolerance
    #: do not allow is made buffered: an exact stop) and, then, why.
    buffer: str = ""
    note: str = ""

    def finish(self, code: str, t6: Vector | None = None, q: Vector | None = None) -> None:
        if self.code is not None:
            return
        self.code = code
        self.progress = 1.0
        self.end_t6 = t6
        self.end_q = q
        self.reached.set()
        eq = self.spec.equation
        if eq is not None:
            eq.finish(code)

    @property
    def done(self) -> bool:
        return self.code is not None


def as_vector(values: Sequence[float] | Vector) -> Vector:
    return np.asarray(values, dtype=np.float64)
