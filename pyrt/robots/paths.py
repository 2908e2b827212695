"""The hare's path: one or two straight segments, the speed profile, the neck turn (000, section 5).

``to()`` moves along at most two straight segments: one when start and end
are both in the vessel or both in the neck, two when the source passes
between them, through a point just below the neck (:data:`VIA_BELOW` under
the neck ring, on its axis).  The *hare* runs along the path and the source
(the hound) is driven after it.  The hare's speed rises linearly to
``speed`` (HARE_SPEED, 2.0 cm/s) over the first ``ramp`` cm (HARE_RAMP,
20 cm) and falls likewise over the last ``ramp`` cm of each segment: a
constant acceleration ``speed**2 / (2 ramp)`` (0.1 cm/s2), so the speed at
distance ``s`` from either end is ``speed * sqrt(s / ramp)``.  (Read as
linear in *distance* the profile would be 0 at the start and never begin;
linear in time reaches the same top speed at the same 20 cm.)  At the neck
turn the hare stops and waits until the source has come to rest at the turn
before the second segment starts.

Beyond the document (selectable per move): the two segments may be joined
by a smooth transition instead of stopping, as RCCL's trajectory generator
joins path segments (001, after R. Paul, *Robot Manipulators*, 1981): over
the last ``d`` cm before the corner and the first ``d`` after it the path is
``B + d1*s + (d2 - d1) * 2d * g(u)``, ``u = (s + d) / 2d``, with Paul's
quartic ``g(u) = u**3 - u**4 / 2``: position, direction and curvature are
continuous at both ends, and the hare keeps its speed through the turn.

:class:`HarePath` is this path as pyrt's built-in manipulator motion type
(``hare_path``, :mod:`pyrt.scheduler.motion`): ``to x y z [blend]`` queues
``MotionRecord("hare_path", {"x": x, "y": y, "z": z, "blend": 0 or 1})``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Any

from pyrt.errors import CommandError
from pyrt.scheduler.motion import MotionRecord, MotionType, register_motion_type

__all__ = [
    "END_SNAP",
    "VIA_BELOW",
    "Hare",
    "HarePath",
    "Segment",
    "hare_path_record",
    "path_target",
    "paul_blend",
    "paul_g",
    "plan_segments",
]

Vec = tuple[float, float, float]

#: How far below the neck ring the turn point lies (cm): "just below the neck".
VIA_BELOW = 5.0
#: Within this distance (cm) of a segment's end the hare steps onto it.
END_SNAP = 1e-3


def _sub(a: Sequence[float], b: Sequence[float]) -> Vec:
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def _norm(a: Sequence[float]) -> float:
    return math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])


@dataclass(frozen=True)
class Segment:
    """One straight piece of the path (global cm)."""

    start: Vec
    end: Vec

    @cached_property
    def length(self) -> float:
        """cm (computed once: the control poll asks every poll)."""
        return _norm(_sub(self.end, self.start))

    def at(self, s: float) -> Vec:
        """The point ``s`` cm from the start."""
        n = self.length
        if n <= 0.0:
            return self.end
        f = s / n
        a, b = self.start, self.end
        return (a[0] + (b[0] - a[0]) * f, a[1] + (b[1] - a[1]) * f, a[2] + (b[2] - a[2]) * f)


def plan_segments(start: Vec, end: Vec, in_neck: Callable[[Vec], bool], via: Vec) -> list[Segment]:
    """One segment, or two through ``via`` when exactly one end is in the neck."""
    if in_neck(start) == in_neck(end):
        return [Segment(start, end)]
    return [Segment(start, via), Segment(via, end)]


def paul_g(u: float) -> float:
    """Paul's quartic transition: g(0)=g'(0)=g''(0)=0, g(1)=1/2, g'(1)=1, g''(1)=0."""
    return u * u * u - 0.5 * u * u * u * u


def paul_blend(corner: Vec, d1: Vec, d2: Vec, half: float, s: float) -> Vec:
    """The blended point ``s`` cm from the corner (``-half <= s <= half``)
    along unit directions ``d1`` (in) and ``d2`` (out)."""
    u = (s + half) / (2.0 * half)
    g = 2.0 * half * paul_g(u)
    return tuple(corner[k] + d1[k] * s + (d2[k] - d1[k]) * g for k in range(3))  # type: ignore[return-value]


class Hare:
    """The moving set point (see the module text).

    ``advance(dt)`` moves it on and returns its position.  ``settled()`` is
    asked at the neck turn: the second segment starts when it returns True.
    With ``blend`` two segments are run as one, with Paul's transition at
    the corner.
    """

    def __init__(self, segments: Sequence[Segment], speed: float, ramp: float,
                 *, blend: bool = False):
        if not segments:
            raise ValueError("a path needs at least one segment")
        if not (speed > 0 and ramp > 0):
            raise ValueError(f"hare speed and ramp must be positive, got {speed}, {ramp}")
        self.segments = list(segments)
        self.speed = float(speed)
        self.ramp = float(ramp)
        self.blend = bool(blend and len(self.segments) == 2)
        self.index = 0
        self.s = 0.0
        self.v = 0.0
        self.waiting = False
        self.position: Vec = self.segments[0].start
        self._acc = self.speed * self.speed / (2.0 * self.ramp)
        self._half = 0.0
        self._total = sum(seg.length for seg in self.segments)
        if self.blend:
            a, b = self.segments
            la, lb = a.length, b.length
            self._half = min(ramp, 0.5 * la, 0.5 * lb)
            if self._half <= 1e-6:
                self.blend = False
            else:
                da, db = _sub(a.end, a.start), _sub(b.end, b.start)
                self._d1: Vec = (da[0] / la, da[1] / la, da[2] / la)
                self._d2: Vec = (db[0] / lb, db[1] / lb, db[2] / lb)

    @property
    def end(self) -> Vec:
        return self.segments[-1].end

    @property
    def length(self) -> float:
        return self._span()

    def _span(self) -> float:
        if self.blend:
            return self._total
        return self.segments[self.index].length

    @property
    def finished(self) -> bool:
        """The hare is at the end of the last segment."""
        last = self.blend or self.index == len(self.segments) - 1
        return last and self.s >= self._span()

    @property
    def at_turn(self) -> bool:
        """The hare waits at the neck turn for the source to come to rest."""
        return self.waiting

    @property
    def acceleration(self) -> float:
        """cm/s2: the top speed is reached over ``ramp`` cm."""
        return self._acc

    def speed_at(self, s: float, span: float) -> float:
        """The profile's speed ``s`` cm along a segment of ``span`` cm."""
        a2 = 2.0 * self.acceleration
        return min(self.speed, math.sqrt(a2 * max(0.0, s)), math.sqrt(a2 * max(0.0, span - s)))

    def advance(self, dt: float, settled: Callable[[], bool] | None = None) -> Vec:
        """Move on by ``dt`` seconds; return the hare's position."""
        span = self._span()
        if self.waiting:
            if settled is None or settled():
                self.waiting = False
                self.index += 1
                self.s = 0.0
                self.v = 0.0
                span = self._span()
            else:
                return self.position
        if self.s < span:
            a = self._acc
            # accelerate, but never faster than the ramp down allows
            v = min(self.speed, self.v + a * dt,
                    math.sqrt(2.0 * a * max(0.0, span - self.s)) + 0.5 * a * dt)
            self.v = v
            self.s += v * dt
            if self.s >= span - END_SNAP:
                self.s = span
                self.v = 0.0
        elif not self.blend and self.index < len(self.segments) - 1:
            self.waiting = True
        self.position = self._point(self.s)
        return self.position

    def _point(self, s: float) -> Vec:
        if not self.blend:
            return self.segments[self.index].at(s)
        a, b = self.segments
        la = a.length
        h = self._half
        if s <= la - h:
            return a.at(s)
        if s >= la + h:
            return b.at(s - la)
        return paul_blend(a.end, self._d1, self._d2, h, s - la)

    def sample(self, step: float = 5.0) -> list[Vec]:
        """Points along the whole path every ``step`` cm (for containment checks)."""
        pts: list[Vec] = []
        if self.blend:
            total = self._span()
            n = max(1, math.ceil(total / step))
            return [self._point(total * i / n) for i in range(n + 1)]
        for seg in self.segments:
            n = max(1, math.ceil(seg.length / step))
            pts.extend(seg.at(seg.length * i / n) for i in range(n + 1))
        return pts


def _coordinate(params: Mapping[str, Any], key: str) -> float:
    if key not in params:
        raise CommandError(f"hare_path: parameter {key!r} missing (x, y, z in cm)")
    v = params[key]
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        raise CommandError(f"hare_path: {key} must be a finite number of cm, got {v!r}")
    return float(v)


def path_target(params: Mapping[str, Any]) -> tuple[Vec, bool]:
    """``(target, blend)`` of a ``hare_path`` record; CommandError if malformed."""
    unknown = sorted(set(params) - {"x", "y", "z", "blend"})
    if unknown:
        raise CommandError(f"hare_path: unknown parameter(s) {', '.join(unknown)}; "
                           "takes x, y, z and blend")
    target = (_coordinate(params, "x"), _coordinate(params, "y"), _coordinate(params, "z"))
    blend = params.get("blend", False)
    if blend not in (0, 1):  # True, False, 0, 1, 0.0, 1.0
        raise CommandError(f"hare_path: blend must be 0 or 1, got {blend!r}")
    return target, bool(blend)


def hare_path_record(target: Sequence[float], blend: bool = False) -> MotionRecord:
    """The motion record of ``to x y z [blend]``."""
    return MotionRecord(HarePath.name, {"x": float(target[0]), "y": float(target[1]),
                                        "z": float(target[2]), "blend": int(bool(blend))})


class HarePath(MotionType):
    """The manipulator's straight-line move (``to``) as a motion type.

    ``start`` plans the path from where the source is (one or two segments,
    the neck turn, blended if asked) through the PolyAxis's checks, which
    refuse a target or a path it may not take; ``step`` runs the hare on by
    the poll's ``dt`` and sets ``robot.hare_position``, the point the error
    signals chase.  The move never ends by itself: the PolyAxis's stop
    conditions (ENDPOINT_STOP and the others) end it.
    """

    name = "hare_path"

    def __init__(self) -> None:
        super().__init__()
        self.hare: Hare | None = None
        #: Where the move ends: ENDPOINT_STOP and STUCK_STOP measure from it.
        self.endpoint: Vec | None = None

    @classmethod
    def check(cls, robot: Any, params: Mapping[str, Any]) -> None:
        """Refuse now (CommandError) a record that could never start."""
        target, _ = path_target(params)
        robot.check_target(target)

    def start(self, robot: Any, record: MotionRecord, now_ns: int) -> None:
        target, blend = path_target(record.params)
        self.robot = robot
        self.hare = robot.plan_path(target, blend=blend)
        self.endpoint = target

    def step(self, now_ns: int) -> None:
        robot = self.robot
        hare = self.hare
        assert hare is not None
        robot.hare_position = hare.advance(robot.dt, robot.settled_at_turn)


register_motion_type(HarePath.name, HarePath)
