"""The pieces a planned trajectory is made of, and the frames they move in.

A piece is a polynomial over an interval of trajectory time, in one of two
spaces: joint space (the joint values themselves) or drive space (a pose of
an equation's POS written as drive coordinates about a reference, see
:mod:`pyrt.motion._geom`).  Straight lines are degree 1; Paul's transitions
are his quartic plus, where the two sides do not meet exactly (a transition
between joint and Cartesian motion, a moving frame), a quintic smooth step
that closes the gap with zero velocity and acceleration at both ends.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from pyrt.frames import PositionEquation, Transform, TransformType
from pyrt.motion._geom import exp_rot, inv, poses_of

Matrix = npt.NDArray[np.float64]
Vector = npt.NDArray[np.float64]

JOINT = "joint"
CART = "cart"
FUNC = "func"


def transition_coeffs(x_a: Vector, v_a: Vector, x_b: Vector, v_b: Vector,
                      tau: float) -> Vector:
    """Coefficients (6, d), lowest power first, of Paul's transition over
    ``0 <= s <= 2 tau`` from ``(x_a, v_a)`` to ``(x_b, v_b)``.

    ``x(s) = x_a + v_a s + dv (s^3 / (4 tau^2) - s^4 / (16 tau^3)) + e S(s / 2tau)``
    with ``dv = v_b - v_a``, ``e = x_b - x_a - (v_a + v_b) tau`` (zero when the
    two sides are straight lines through one corner, as Paul has them) and
    ``S`` the quintic smooth step.  Position and velocity meet both sides'
    at the ends, and the acceleration is zero there.
    """
    d = x_a.shape[0]
    c = np.zeros((6, d))
    dv = v_b - v_a
    e = x_b - x_a - (v_a + v_b) * tau
    w = 2.0 * tau
    c[0] = x_a
    c[1] = v_a
    c[3] = dv / (4.0 * tau * tau) + 10.0 * e / w ** 3
    c[4] = -dv / (16.0 * tau ** 3) - 15.0 * e / w ** 4
    c[5] = 6.0 * e / w ** 5
    return c


def line_coeffs(x0: Vector, v: Vector) -> Vector:
    """Coefficients (2, d) of the line ``x0 + v u``."""
    return np.vstack([x0, v])


class Frames:
    """How an equation turns a POS value into T6 and back, at a sample.

    For ``L . T6 . TOOL = COORD . POS . R`` (any of L, TOOL, COORD, R may be
    several terms or none): ``T6 = pre . POS . post`` with ``pre = L^-1 COORD``
    and ``post = R TOOL^-1``.  Functional terms are evaluated at the sample
    (once per sample, 001); at plan time, for a sample not reached yet, their
    value is extrapolated from the last two samples seen (:class:`FrameTracker`).
    """

    def __init__(self, eq: PositionEquation | None, tracker: FrameTracker) -> None:
        self.eq = eq
        self.tracker = tracker
        if eq is None:
            self.before: tuple[Transform, ...] = ()
            self.coord: tuple[Transform, ...] = ()
            self.after: tuple[Transform, ...] = ()
            self.toolpart: tuple[Transform, ...] = ()
        else:
            ring = eq.transforms
            lhs = [t for t in ring if eq.side(t) == "lhs"]
            rhs = list(reversed([t for t in ring if eq.side(t) == "rhs"]))
            i6 = lhs.index(eq.t6)
            ipos = rhs.index(eq.pos)
            self.before = tuple(lhs[:i6])
            self.toolpart = tuple(lhs[i6 + 1:])
            self.coord = tuple(rhs[:ipos])
            self.after = tuple(rhs[ipos + 1:])
        fun = TransformType.FUNCTIONAL
        #: The functional transforms: evaluated once per sample by the loop.
        self.live = tuple(t for t in (*self.before, *self.coord, *self.after, *self.toolpart)
                          if t.type is fun)
        self.moving = bool(self.live)
        self._static: tuple[Matrix, Matrix, Matrix] | None = None
        self._fast: tuple[Transform, Matrix, Matrix] | None = None
        fixed = (TransformType.CONST, TransformType.VARB)
        if (not self.before and len(self.coord) == 1 and self.coord[0].type is fun
                and all(t.type in fixed for t in (*self.after, *self.toolpart))):
            _, post, tool = self._compute(None)
            self._fast = (self.coord[0], post, tool)
        self._pre_identity = self._post_identity = False
        if not self.moving:
            self._static = self._compute(None)
            self._pre_identity = bool(np.array_equal(self._static[0], np.eye(4)))
            self._post_identity = bool(np.array_equal(self._static[1], np.eye(4)))

    def _value(self, t: Transform, sample: float | None) -> Matrix:
        if t.type is TransformType.FUNCTIONAL:
            if sample is None:
                return t.value
            return self.tracker.value(t, sample)
        assert self.eq is not None
        return self.eq.values(t)[1]

    def _compute(self, sample: float | None) -> tuple[Matrix, Matrix, Matrix]:
        lb = np.eye(4)
        for t in self.before:
            lb = lb @ self._value(t, sample)
        co = np.eye(4)
        for t in self.coord:
            co = co @ self._value(t, sample)
        af = np.eye(4)
        for t in self.after:
            af = af @ self._value(t, sample)
        tl = np.eye(4)
        for t in self.toolpart:
            tl = tl @ self._value(t, sample)
        return inv(lb) @ co, af @ inv(tl), tl

    def parts(self, sample: float | None) -> tuple[Matrix, Matrix, Matrix]:
        """``(pre, post, tool)`` at ``sample``."""
        if self._static is not None:
            return self._static
        if self._fast is not None and sample is not None:
            # one moving COORD term, everything else fixed: one product per sample
            conv, post, tool = self._fast
            return self.tracker.value(conv, sample), post, tool
        return self._compute(sample)

    def t6(self, pos: Matrix, sample: float | None) -> Matrix:
        if self._static is not None:
            pre, post, _ = self._static
            out = pos if self._pre_identity else pre @ pos
            return out if self._post_identity else out @ post
        pre, post, _ = self.parts(sample)
        return pre @ pos @ post

    def t6_many(self, poses: Matrix, samples: Sequence[float]) -> Matrix:
        """T6 (m, 4, 4) of the POS values ``poses`` (m, 4, 4) at ``samples``: one
        product for all of them when no term moves, else one sample at a time."""
        if self._static is not None:
            pre, post, _ = self._static
            out = poses if self._pre_identity else pre @ poses
            return out if self._post_identity else out @ post
        return np.array([self.t6(p, n) for p, n in zip(poses, samples, strict=True)])

    def pos(self, t6: Matrix, sample: float | None) -> Matrix:
        if self._pre_identity and self._post_identity:  # T6 itself (exactly I . T6 . I)
            return np.array(t6, dtype=float)
        pre, post, _ = self.parts(sample)
        return inv(pre) @ t6 @ inv(post)

    def tool(self, t6: Matrix, sample: float | None) -> Matrix:
        """The tool frame in the world (T6 . TOOL)."""
        return t6 @ self.parts(sample)[2]


class FrameTracker:
    """The values functional transforms took at the last two samples, to
    predict a later sample's value (constant velocity: 001's assumption that
    the moving frames' velocity is continuous)."""

    def __init__(self, period: float) -> None:
        self.period = period
        self._seen: dict[Transform, list[tuple[int, Matrix]]] = {}

    def evaluate(self, t: Transform, sample: int) -> Matrix:
        """The transform at ``sample`` now (the loop's evaluation), remembered."""
        v = t.evaluate(sample)
        hist = self._seen.get(t, [])
        if not hist or hist[-1][0] != sample:
            # a new list, never one changed in place: a plan reads the history from
            # another thread
            self._seen[t] = [*hist[-1:], (sample, v)]
        return v

    def copy(self) -> FrameTracker:
        """A tracker with the values seen so far (a plan's own)."""
        out = FrameTracker(self.period)
        out._seen = dict(self._seen)
        return out

    def value(self, t: Transform, sample: float) -> Matrix:
        hist = self._seen.get(t)
        if hist and hist[-1][0] == sample:
            return hist[-1][1]
        if not hist:
            return t.value
        if len(hist) == 1:
            return hist[0][1]
        (n0, a), (n1, b) = hist
        k = (sample - n1) / (n1 - n0)
        out = np.array(b)
        out[:3, 3] = b[:3, 3] + k * (b[:3, 3] - a[:3, 3])
        rel = a[:3, :3].T @ b[:3, :3]
        from pyrt.motion._geom import log_rot

        out[:3, :3] = b[:3, :3] @ exp_rot(k * log_rot(rel))
        return out


class Piece:
    """One polynomial of the trajectory over ``[t0, t1)``, in local time
    ``u = t - origin``.  ``c`` holds the coefficients, lowest power first."""

    __slots__ = (
        "_cc",
        "_ref",
        "_rows",
        "c",
        "config",
        "fn",
        "frames",
        "linear",
        "origin",
        "p_c",
        "r_c",
        "runtime",
        "seg",
        "space",
        "t0",
        "t1",
    )

    def __init__(self, space: str, t0: float, t1: float, origin: float, c: Vector,
                 seg: Any, *, frames: Frames | None = None, r_c: Matrix | None = None,
                 p_c: Vector | None = None, config: str | None = None,
                 fn: Callable[[float], Any] | None = None) -> None:
        self.space = space
        self.t0 = t0
        self.t1 = t1
        self.origin = origin
        self.c = c
        self.linear = c.shape[0] == 2
        #: The coefficients as plain floats (the polynomial's rows), for the ``c`` they
        #: were made of: the trajectory tick evaluates on them.
        self._cc: Vector | None = None
        self._rows: list[list[float]] = []
        self.seg = seg
        self.frames = frames
        self.r_c = r_c
        self.p_c = p_c
        self.config = config
        self.fn = fn
        #: Set for a transition whose coefficients are made when it starts.
        self.runtime: Any = None
        self._ref: tuple[tuple[float, ...], tuple[float, ...]] | None = (
            (tuple(float(v) for v in np.asarray(r_c).reshape(9)),
                      tuple(float(v) for v in np.asarray(p_c)))
                     if r_c is not None and p_c is not None else None)

    def x(self, t: float) -> Vector:
        return np.array(self._xs(t))

    def _xs(self, t: float) -> list[float]:
        """The value at ``t`` as plain floats, coordinate by coordinate: a line
        ``c0 + c1 u``, else Horner's rule (the same roundings as on the rows)."""
        u = t - self.origin
        c = self.c
        if c is not self._cc:
            self._cc = c
            self._rows = c.tolist()[:2 if self.linear else 6]
        if self.linear:
            r0, r1 = self._rows
            return [z + a * u for z, a in zip(r0, r1, strict=True)]
        r0, r1, r2, r3, r4, r5 = self._rows
        return [((((e * u + d) * u + f) * u + b) * u + a) * u + z
                for z, a, b, f, d, e in zip(r0, r1, r2, r3, r4, r5, strict=True)]

    def xd(self, t: float) -> Vector:
        u = t - self.origin
        c = self.c
        if self.linear:
            return c[1].copy()
        return (((5 * c[5] * u + 4 * c[4]) * u + 3 * c[3]) * u + 2 * c[2]) * u + c[1]

    def xdd(self, t: float) -> Vector:
        u = t - self.origin
        c = self.c
        if self.linear:
            return np.zeros_like(c[0])
        return ((20 * c[5] * u + 12 * c[4]) * u + 6 * c[3]) * u + 2 * c[2]

    def pose(self, t: float, out: Matrix | None = None) -> Matrix:
        """Drive piece: the POS value at ``t`` (``Exp(phi) R_c``, ``p_c + p``),
        on plain floats: the trajectory tick's hot path."""
        px, py, pz, a, b, c = self._xs(t)
        th2 = a * a + b * b + c * c
        if th2 < 1e-24:
            s, k = 1.0, 0.5
        else:
            th = math.sqrt(th2)
            s, k = math.sin(th) / th, (1.0 - math.cos(th)) / th2
        e00, e01, e02 = 1.0 - k * (b * b + c * c), -s * c + k * a * b, s * b + k * a * c
        e10, e11, e12 = s * c + k * a * b, 1.0 - k * (a * a + c * c), -s * a + k * b * c
        e20, e21, e22 = -s * b + k * a * c, s * a + k * b * c, 1.0 - k * (a * a + b * b)
        assert self._ref is not None
        (r00, r01, r02, r10, r11, r12, r20, r21, r22), (cx, cy, cz) = self._ref
        # one flat run of floats into one array (quicker than nested rows)
        m = np.fromiter((
            e00 * r00 + e01 * r10 + e02 * r20, e00 * r01 + e01 * r11 + e02 * r21,
            e00 * r02 + e01 * r12 + e02 * r22, cx + px,
            e10 * r00 + e11 * r10 + e12 * r20, e10 * r01 + e11 * r11 + e12 * r21,
            e10 * r02 + e11 * r12 + e12 * r22, cy + py,
            e20 * r00 + e21 * r10 + e22 * r20, e20 * r01 + e21 * r11 + e22 * r21,
            e20 * r02 + e21 * r12 + e22 * r22, cz + pz,
            0.0, 0.0, 0.0, 1.0), float, 16).reshape(4, 4)
        if out is not None:
            out[:] = m
            return out
        return m

    def values(self, ts: Sequence[float]) -> Matrix:
        """The polynomial's values (m, d) at the times ``ts``, all at once: the same
        operations in the same order as :meth:`x` (the same roundings)."""
        u = np.asarray(ts, dtype=float)[:, None] - self.origin
        c = self.c
        if self.linear:
            return np.asarray(c[0] + c[1] * u, dtype=float)
        return np.asarray(((((c[5] * u + c[4]) * u + c[3]) * u + c[2]) * u + c[1]) * u + c[0],
                          dtype=float)

    def poses(self, ts: Sequence[float]) -> Matrix:
        """Drive piece: the POS values (m, 4, 4) at the times ``ts``, all at once (the
        planner's checks; :meth:`pose` is the tick's, one at a time)."""
        assert self.r_c is not None and self.p_c is not None
        return poses_of(self.values(ts), np.asarray(self.r_c), np.asarray(self.p_c))

    def copy_until(self, t1: float) -> Piece:
        p = Piece(self.space, self.t0, t1, self.origin, self.c, self.seg, frames=self.frames,
                  r_c=self.r_c, p_c=self.p_c, config=self.config, fn=self.fn)
        p.runtime = self.runtime
        return p


def peak(values: Vector) -> float:
    return float(np.max(np.abs(values))) if values.size else 0.0


def norm(v: Vector) -> float:
    return math.sqrt(float(v @ v))
