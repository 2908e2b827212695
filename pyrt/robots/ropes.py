"""The rope model of the manipulator: geometry, statics and the refusal checks, stateless.

A :class:`RopeModel` is the manipulator's fixed geometry (top pulleys,
bottom attachments, carriage offsets, the neck ring, the vessel), its ropes'
elastic constants and the source's weight, and nothing that changes while
it runs.  Every method is a pure function of its arguments:

* rope geometry (:meth:`RopeModel.rope_geometry`, :meth:`~RopeModel.length_at`,
  :meth:`~RopeModel.lengths_at`): the rope's length beyond its top pulley
  with the source at a point, over the neck ring where it bears on it (the
  one model of csrc/neck.h);
* statics: the weight (buoyancy in D2O), the force per newton of tension,
  the residual net force, the equilibrium tensions (off-side ropes at
  OFFSIDE_TENSION, the others by least squares);
* the refusal checks: containment (vessel and neck), a planar station's
  plane, the top pulleys, the tension bounds; each returns the reason or
  None, and the command that asked says it refused;
* the one stretch formula (:func:`corrected_length`, :func:`payout`): the
  rope stretches in proportion to its tension and its unstretched length
  from the spindle (csrc/polyctl.c does the same sum, checked by
  tests/test_ropes.py);
* one Gauss-Newton (:func:`gauss_newton`) over a residual in the free
  directions: the position from the tensions (``tensionFind``) and the
  position from every rope's length but one (``survey``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np

from pyrt.errors import ConfigError, NativeError
from pyrt.native import StaticsSolver
from pyrt.robots._neck import NeckRing
from pyrt.robots.av import AV
from pyrt.robots.paths import VIA_BELOW

if TYPE_CHECKING:
    from pyrt.db import PolyAxisRecord

__all__ = [
    "GRAVITY",
    "MIN_TOP_SEGMENT",
    "RopeModel",
    "Vec",
    "corrected_length",
    "dist",
    "gauss_newton",
    "payout",
]

GRAVITY = 9.80665
#: A target closer than this to a top pulley (cm) is refused.
MIN_TOP_SEGMENT = 5.0

Vec = tuple[float, float, float]


def dist(a: Sequence[float], b: Sequence[float]) -> float:
    """Distance between two points (cm)."""
    return math.sqrt((a[0] - b[0]) ** 2 + (a[1] - b[1]) ** 2 + (a[2] - b[2]) ** 2)


def _vec(p: np.ndarray) -> Vec:
    return (float(p[0]), float(p[1]), float(p[2]))


def corrected_length(encoder_length: float, tension: float, stretch: float,
                     dead_length: float) -> float:
    """The rope's length beyond its top pulley (cm) from the encoder's unstretched
    length from the spindle, stretched by ``stretch`` per newton of ``tension``
    (a negative tension reads as none), less the dead length."""
    t = tension if tension > 0.0 else 0.0
    return encoder_length * (1.0 + stretch * t) - dead_length


def payout(length: float, tension: float, stretch: float, dead_length: float) -> float:
    """The unstretched rope from the spindle (cm) that is ``length`` beyond the top
    pulley at ``tension``: the inverse of :func:`corrected_length`."""
    t = tension if tension > 0.0 else 0.0
    return (length + dead_length) / (1.0 + stretch * t)


def gauss_newton(resid: Callable[[np.ndarray], np.ndarray], x0: Sequence[float],
                 free: Sequence[int], *, iterations: int, tol: float,
                 h: float = 0.01, max_step: float = 20.0) -> tuple[np.ndarray, np.ndarray]:
    """Minimise ``|resid(x)|`` from ``x0`` moving only the ``free`` directions
    (forward differences of ``h`` cm, steps clipped to ``max_step`` cm), until a
    step is shorter than ``tol`` cm or after ``iterations``: (x, resid(x))."""
    x = np.asarray(x0, dtype=np.float64)
    r = resid(x)
    for _ in range(iterations):
        jac = np.zeros((len(r), len(free)))
        for j, k in enumerate(free):
            dx = np.zeros(3)
            dx[k] = h
            jac[:, j] = (resid(x + dx) - r) / h
        step = np.zeros(3)
        step[list(free)] = np.linalg.lstsq(jac, -r, rcond=None)[0]
        norm = float(np.linalg.norm(step))
        if norm > max_step:
            step *= max_step / norm
        x = x + step
        r = resid(x)
        if norm < tol:
            break
    return x, r


class RopeModel:
    """The manipulator's ropes and source as geometry and statics (see the module
    text).  Lengths cm, forces N, masses kg, volumes cm3.

    ``tops``, ``bottoms`` (None: the central rope) and ``offsets`` are global
    co-ordinates; ``freeze`` is the position finder's mask (a direction it
    holds: a planar station); ``ring_segments`` the segments the controller
    lets bear on the neck ring; ``names`` name the ropes in messages.
    ``record`` (a :class:`~pyrt.db.PolyAxisRecord`) gives the source (mass,
    volume), the D2O density and the limits; the limits are the model's from
    then (the PolyAxis sets MAX_TENSION and END_ERROR here while running).
    """

    def __init__(
        self,
        av: AV,
        names: Sequence[str],
        tops: Sequence[Vec],
        bottoms: Sequence[Vec | None],
        offsets: Sequence[Vec],
        dead_lengths: Sequence[float],
        stretch: Sequence[float],
        *,
        freeze: Sequence[int],
        ring_segments: int,
        record: PolyAxisRecord,
        liquid_level: float | None,
    ):
        self.av = av
        self.names = list(names)
        self.n = len(self.names)
        self.tops = list(tops)
        self.bottoms = list(bottoms)
        self.offsets = list(offsets)
        self.dead_lengths = [float(d) for d in dead_lengths]
        self.stretch = [float(s) for s in stretch]
        self.freeze = tuple(freeze)
        #: The directions the position finder solves in.
        self.free = [k for k in range(3) if not self.freeze[k]]
        self.ring_segments = int(ring_segments)
        self.source_mass = float(record.source_mass)
        self.source_volume = float(record.source_volume)
        self.d2o_density = float(record.d2o_density)
        self.liquid_level = liquid_level
        self.low_tension = float(record.low_tension)
        self.max_tension = float(record.max_tension)
        self.tension_margin = float(record.tension_margin)
        self.net_forcelimit = float(record.net_forcelimit)
        self.offside_tension = float(record.offside_tension)
        self.end_error = float(record.end_error)
        self.ring = av.neck_ring()
        self.neck = NeckRing(*self.ring)
        centre = av.vtog((0.0, 0.0, 0.0))
        #: The central axis (the vessel centre's global position).
        self.axis_point: Vec = centre
        #: The turn point just below the neck ring where paths into the neck turn.
        self.via: Vec = (av.neck_ring_position[0] - VIA_BELOW * av.neck_axis[0],
                         av.neck_ring_position[1] - VIA_BELOW * av.neck_axis[1],
                         av.neck_ring_position[2] - VIA_BELOW * av.neck_axis[2])
        # "far side of the central axis": the bottom's horizontal direction
        self._bdir: list[tuple[float, float] | None] = [
            None if b is None else (b[0] - centre[0], b[1] - centre[1]) for b in self.bottoms]
        # The statics kernel as a rope-geometry evaluator: every rope's length at
        # a point, over the ring where it bears on it, in one C call (its
        # tensions and payouts are not used).
        self._geometry = StaticsSolver(
            self.tops, self.bottoms, self.offsets, self.dead_lengths, self.stretch,
            [d + 1000.0 for d in self.dead_lengths], ring=self.ring)
        #: A planar manipulator's held directions and their values (cm).
        self.plane: dict[int, float] = {}
        side = [b for b in self.bottoms if b is not None]
        for k in range(3):
            if self.freeze[k] and side:
                self.plane[k] = sum(b[k] for b in side) / len(side)

    def check_plane(self, who: str, position: Sequence[float], tolerance: float) -> None:
        """A planar manipulator must have every top pulley, the neck ring and the
        start ``position`` in the held plane (the bottoms' mean there), within
        ``tolerance``: a pulley out of it hangs the source where the controller
        can neither see nor move it (ConfigError naming the place)."""
        for k, held in self.plane.items():
            axis = "xyz"[k]
            places: list[tuple[str, Sequence[float]]] = [
                (f"{name} top pulley (AXIS.dat TOP)", top)
                for name, top in zip(self.names, self.tops, strict=True)]
            places += [("the neck ring centre (AV.dat)", self.ring[0]),
                       ("the source (POLYAXIS.dat POSITION)", position)]
            for what, p in places:
                if abs(float(p[k]) - held) > tolerance:
                    raise ConfigError(
                        f"polyaxis {who}: {what} is at {axis} = {float(p[k]):g} cm, out of the "
                        f"plane {axis} = {held:g} cm the position finder holds (every bottom "
                        f"attachment is there); the source would hang out of the plane the "
                        f"controller can measure and move in: put it in the plane")

    # -- the source's weight and the ropes' pull -------------------------------------

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
        path = self.neck.rope_path(self.tops[i], b, q, self.ring_segments)
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

    def length_at(self, i: int, x: Sequence[float]) -> float:
        """Rope ``i``'s length beyond its top pulley with the source at ``x`` (cm),
        over the neck ring where it bears on it (:meth:`rope_geometry`'s length)."""
        o = self.offsets[i]
        q = (x[0] + o[0], x[1] + o[1], x[2] + o[2])
        return self.neck.rope_path(self.tops[i], self.bottoms[i], q, self.ring_segments).length

    def lengths_at(self, x: Sequence[float]) -> list[float]:
        """Every rope's length beyond its top pulley with the source at ``x`` (cm),
        over the neck ring where a rope bears on it: one C call."""
        if self.ring_segments != StaticsSolver.RING_SEGMENTS:  # the controller knows less
            return [self.length_at(i, x) for i in range(self.n)]
        try:
            return self._geometry.evaluate(x)[0]
        except NativeError:  # degenerate (the carriage on a pulley): the Python form
            return [self.length_at(i, x) for i in range(self.n)]

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

    # -- the two inverse problems (one Gauss-Newton) ---------------------------------

    def position_from_tensions(self, x0: Sequence[float], tensions: Sequence[float],
                               iterations: int = 30) -> Vec:
        """``tensionFind``: the position where ``tensions`` balance the weight,
        from ``x0`` in the free directions."""
        def resid(p: np.ndarray) -> np.ndarray:
            return np.asarray(self.net_force_at(_vec(p), tensions), dtype=np.float64)

        x, _ = gauss_newton(resid, x0, self.free, iterations=iterations, tol=1e-3)
        return (float(x[0]), float(x[1]), float(x[2]))

    def position_from_lengths(self, x0: Sequence[float], lengths: Sequence[float],
                              ropes: Sequence[int]) -> tuple[Vec, float]:
        """The position from the ``lengths`` of the ``ropes`` only, from ``x0`` in
        the free directions: (position, RMS length residual cm)."""
        meas = np.asarray([lengths[k] for k in ropes], dtype=np.float64)

        def resid(p: np.ndarray) -> np.ndarray:
            q = _vec(p)
            return meas - np.asarray([self.length_at(k, q) for k in ropes], dtype=np.float64)

        x, r = gauss_newton(resid, x0, self.free, iterations=50, tol=1e-4)
        rms = float(np.sqrt(np.mean(r * r))) if len(r) else 0.0
        return (float(x[0]), float(x[1]), float(x[2])), rms

    # -- containment and the refusal checks ------------------------------------------

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

    def target_refusal(self, tgt: Vec) -> str | None:
        """Why ``tgt`` may not be a move's endpoint, or None: outside the vessel or
        the neck, out of the plane, too near a top pulley, or where the source
        cannot be held within TENSION_MARGIN of the tension bounds."""
        where = f"({tgt[0]:g}, {tgt[1]:g}, {tgt[2]:g})"
        why = self.refusal(tgt) or self.plane_refusal(tgt)
        if why is not None:
            return f"{where} is {why}"
        for name, top, o in zip(self.names, self.tops, self.offsets, strict=True):
            q = (tgt[0] + o[0], tgt[1] + o[1], tgt[2] + o[2])
            if dist(q, top) < MIN_TOP_SEGMENT:
                return (f"the carriage would be within {MIN_TOP_SEGMENT:g} cm of {name}'s "
                        "top pulley")
        t, resid = self.equilibrium_tensions(tgt)
        problems = []
        lo = self.low_tension + self.tension_margin
        hi = self.max_tension - self.tension_margin
        margin = f", TENSION_MARGIN {self.tension_margin:g} N" if self.tension_margin else ""
        for name, v in zip(self.names, t, strict=True):
            if v < lo:
                problems.append(f"{name} would need {v:.1f} N (LOW_TENSION "
                                f"{self.low_tension:g} N{margin})")
            elif v > hi:
                problems.append(f"{name} would need {v:.1f} N (MAX_TENSION "
                                f"{self.max_tension:g} N{margin})")
        if resid > self.net_forcelimit:
            problems.append(f"{resid:.1f} N could not be balanced (NET_FORCELIMIT "
                            f"{self.net_forcelimit:g} N)")
        if problems:
            return f"{where} cannot be held within the tension bounds: " + "; ".join(problems)
        return None

    def tension_refusal(self, x: Sequence[float]) -> str | None:
        """Why the source cannot be held at ``x`` on the way (a tension that would
        be out of LOW_TENSION .. MAX_TENSION, or a force left over beyond
        NET_FORCELIMIT: the stops would end the move there), or None."""
        t, resid = self.equilibrium_tensions(x)
        for name, v in zip(self.names, t, strict=True):
            if v < self.low_tension:
                return f"where {name} would need {v:.1f} N (LOW_TENSION {self.low_tension:g} N)"
            if v > self.max_tension:
                return f"where {name} would need {v:.1f} N (MAX_TENSION {self.max_tension:g} N)"
        if resid > self.net_forcelimit:
            return (f"where {resid:.1f} N could not be balanced (NET_FORCELIMIT "
                    f"{self.net_forcelimit:g} N)")
        return None
