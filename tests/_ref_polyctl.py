"""Pure-Python reference of csrc/polyctl.c: the PolyAxis control poll's numeric work.

Operation for operation as the kernel (and as the Python PolyAxis poll it
replaced): the neck-ring contact of csrc/neck.c by Newton on the rim angle
from the last poll's angle, with the one model's constants read from the
C headers (``lib``); the corrected lengths and effective tops and bottoms, the position
solve (tests/_ref_findpos.py), the net force, the error signals, the fuzzy
input rows and the fuzzy step (tests/_ref_fuzzy.py).
"""

from __future__ import annotations

import math

import _ref_findpos as findpos
import _ref_fuzzy as fuzzy
import numpy as np

from pyrt.native._lib import lib

Vec = tuple[float, float, float]

#: The neck model's constants (csrc/neck.h, csrc/pyrt_native.h).
ITERATIONS: int = lib.PYRT_NECK_MAX_ITER
STEP_TOL: float = lib.PYRT_NECK_STEP_TOL
MAX_STEP: float = lib.PYRT_NECK_MAX_STEP
FALLBACK_STEP: float = lib.PYRT_NECK_FALLBACK_STEP
TIE: float = lib.PYRT_NECK_TIE
MIN_SEGMENT: float = lib.PYRT_MIN_SEGMENT_CM
UPPER: int = lib.PYRT_NECK_UPPER
LOWER: int = lib.PYRT_NECK_LOWER
#: The segments the controller lets bear on the ring (csrc/polyctl.h).
CONTROLLER_SEGMENTS: int = lib.PYRT_POLYCTL_RING_SEGMENTS


class Degenerate(RuntimeError):
    """A piece of rope shorter than MIN_SEGMENT: the kernel's PYRT_EDEGENERATE."""


def contact(ring, t, q, hint=None):
    """(rim point, angle) where the segment q -> t bears on the ring, or None;
    ``ring`` is (centre, axis, e1, e2, radius) as 13 numbers."""
    cx0, cy0, cz0, ax0, ax1, ax2, e1x, e1y, e1z, e2x, e2y, e2z, rad = ring
    if not rad > 0.0:
        return None
    tx, ty, tz = t
    qx, qy, qz = q
    tcx, tcy, tcz = tx - cx0, ty - cy0, tz - cz0
    ht = tcx * ax0 + tcy * ax1 + tcz * ax2
    qcx, qcy, qcz = qx - cx0, qy - cy0, qz - cz0
    hq = qcx * ax0 + qcy * ax1 + qcz * ax2
    if not (ht > 0.0 > hq or ht < 0.0 < hq):
        return None
    s = ht / (ht - hq)
    rx, ry, rz = tcx + s * (qcx - tcx), tcy + s * (qcy - tcy), tcz + s * (qcz - tcz)
    xr = rx * ax0 + ry * ax1 + rz * ax2
    rx, ry, rz = rx - xr * ax0, ry - xr * ax1, rz - xr * ax2
    if rx * rx + ry * ry + rz * rz <= rad * rad:
        return None
    if hint is None:
        phi = math.atan2(rx * e2x + ry * e2y + rz * e2z, rx * e1x + ry * e1y + rz * e1z)
    else:
        phi = hint

    def pieces(phi):
        cs, sn = math.cos(phi), math.sin(phi)
        u = (cs * e1x + sn * e2x, cs * e1y + sn * e2y, cs * e1z + sn * e2z)
        p = (-sn * e1x + cs * e2x, -sn * e1y + cs * e2y, -sn * e1z + cs * e2z)
        c = (cx0 + rad * u[0], cy0 + rad * u[1], cz0 + rad * u[2])
        a = (c[0] - tx, c[1] - ty, c[2] - tz)
        b = (c[0] - qx, c[1] - qy, c[2] - qz)
        da = math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
        db = math.sqrt(b[0] * b[0] + b[1] * b[1] + b[2] * b[2])
        if da < MIN_SEGMENT or db < MIN_SEGMENT:
            raise Degenerate("the carriage on the rim")
        return u, p, c, a, b, da, db

    for _ in range(ITERATIONS):
        u, p, _, a, b, da, db = pieces(phi)
        pa = rad * (a[0] * p[0] + a[1] * p[1] + a[2] * p[2]) / da
        pb = rad * (b[0] * p[0] + b[1] * p[1] + b[2] * p[2]) / db
        f1 = pa + pb
        f2 = (rad * rad - pa * pa) / da + (rad * rad - pb * pb) / db
        f2 -= rad * (u[0] * (a[0] / da + b[0] / db) + u[1] * (a[1] / da + b[1] / db)
                     + u[2] * (a[2] / da + b[2] / db))
        if f2 > 0.0:
            step = -f1 / f2
        elif abs(f1) <= TIE * rad:  # a tie (the symmetric point): rounding does not choose
            step = FALLBACK_STEP
        else:
            step = -FALLBACK_STEP if f1 > 0.0 else FALLBACK_STEP
        step = min(MAX_STEP, max(-MAX_STEP, step))
        phi += step
        if abs(step) < STEP_TOL:
            break
    return pieces(phi)[2], phi


def _dist(a, b) -> float:
    return math.sqrt((a[0] - b[0]) ** 2 + (a[1] - b[1]) ** 2 + (a[2] - b[2]) ** 2)


def _segment(ring, far, q, may_bear, hint=None):
    """(length, rim angle or None) of the segment q -> far, over the ring if it may bear."""
    found = contact(ring, far, q, hint) if may_bear else None
    if found is not None:
        c, phi = found
        return _dist(far, c) + _dist(c, q), phi
    d = _dist(far, q)
    if d < MIN_SEGMENT:
        raise Degenerate("the carriage on a pulley or an attachment")
    return d, None


def rope_length(ring, top, bottom, offset, x, segments=CONTROLLER_SEGMENTS) -> float:
    """A rope's length beyond its top pulley with the source at ``x``, the segments
    in the mask ``segments`` over the ring where they bear on it."""
    q = (x[0] + offset[0], x[1] + offset[1], x[2] + offset[2])
    length, _ = _segment(ring, top, q, segments & UPPER)
    if bottom is not None:
        length += _segment(ring, bottom, q, segments & LOWER)[0]
    return length


class RefPolyControl:
    """The reference of :class:`pyrt.native.PolyControl` (same calls, same results)."""

    def __init__(self, params, *, tops, bottoms, offsets, stretch, dead, ring, axis_point,
                 weight_air, weight_liquid, liquid_level, offside_tension, near_end_cm,
                 position, tol=lib.PYRT_FINDPOS_DEFAULT_TOL):
        self.params = params
        self.tops = [tuple(map(float, t)) for t in tops]
        self.bottoms = [None if b is None else tuple(map(float, b)) for b in bottoms]
        self.offsets = [tuple(map(float, o)) for o in offsets]
        self.stretch, self.dead = list(stretch), list(dead)
        self.ring = tuple(ring)
        self.axis_point = tuple(axis_point)
        self.weight_air, self.weight_liquid = weight_air, weight_liquid
        self.liquid_level = -math.inf if liquid_level is None else liquid_level
        self.offside_tension, self.near_end_cm = offside_tension, near_end_cm
        self.position = tuple(position)
        self.tol = tol
        n = self.n = len(self.tops)
        self.phi: list[float | None] = [None] * n
        self.phi_lower: list[float | None] = [None] * n
        self.hare_phi: list[float | None] = [None] * n
        self.prev: tuple[list[float], list[float]] | None = None
        self.last_dv = [0.0] * n
        self.endpoint: Vec | None = None
        self.tensions = [0.0] * n
        self.lengths = [0.0] * n
        self.residuals = [0.0] * n
        self.rules: list[list[float]] = []

    def set_endpoint(self, endpoint):
        self.endpoint = None if endpoint is None else tuple(endpoint)

    def reset_rates(self):
        self.prev = None
        self.last_dv = [0.0] * self.n

    def measure(self, tensions, encoder_lengths, lengths):
        n = self.n
        self.tensions = list(tensions)
        lens = [encoder_lengths[i] * (1.0 + self.stretch[i] * (t if t > 0.0 else 0.0))
                - self.dead[i] for i, t in enumerate(tensions)]
        lengths[:] = lens
        self.lengths = lens
        x = self.position
        eff, effb, lf = [], [], list(lens)
        for i in range(n):
            o, t0, b0 = self.offsets[i], self.tops[i], self.bottoms[i]
            q = (x[0] + o[0], x[1] + o[1], x[2] + o[2])
            found = contact(self.ring, t0, q, self.phi[i]) if CONTROLLER_SEGMENTS & UPPER else None
            if found is None:
                if _dist(t0, q) < MIN_SEGMENT:
                    raise Degenerate("the carriage on a top pulley")
                self.phi[i] = None
                eff.append(t0)
            else:
                c, self.phi[i] = found
                eff.append(c)
                lf[i] -= _dist(t0, c)
            if b0 is None:
                effb.append(None)
                continue
            found = (contact(self.ring, b0, q, self.phi_lower[i])
                     if CONTROLLER_SEGMENTS & LOWER else None)
            if found is None:
                if _dist(b0, q) < MIN_SEGMENT:
                    raise Degenerate("the carriage on a bottom attachment")
                self.phi_lower[i] = None
                effb.append(b0)
            else:
                c, self.phi_lower[i] = found
                effb.append(c)
                lf[i] -= _dist(b0, c)
        nan = math.nan
        bott = np.array([(nan, nan, nan) if b is None else b for b in effb])
        pos, rms, res, _ = findpos.find_position(np.array(eff), bott, np.array(lf),
                                                 np.array(x), offsets=np.array(self.offsets),
                                                 tol=self.tol)
        self.position = x = tuple(float(c) for c in pos)
        self.residuals = [float(r) for r in res]
        w = self.weight_liquid if x[2] < self.liquid_level else self.weight_air
        f = [0.0, 0.0, -w]
        for i in range(n):
            o = self.offsets[i]
            q = (x[0] + o[0], x[1] + o[1], x[2] + o[2])
            for end in (eff[i], effb[i]):
                if end is None:
                    continue
                d = (end[0] - q[0], end[1] - q[1], end[2] - q[2])
                k = tensions[i] / (math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) or 1e-12)
                f = [f[0] + k * d[0], f[1] + k * d[1], f[2] + k * d[2]]
        mag = math.sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2])
        return [x[0], x[1], x[2], float(rms), f[0], f[1], f[2], mag]

    def drive(self, hare, velocities, rate_scale, error_lengths, error_tensions, desired,
              free, *, signal_all=False):
        n, x = self.n, self.position
        if not signal_all:
            hx, hy = x[0] - self.axis_point[0], x[1] - self.axis_point[1]
            for i, b in enumerate(self.bottoms):
                off = b is not None and ((b[0] - self.axis_point[0]) * hx
                                         + (b[1] - self.axis_point[1]) * hy <= 0.0)
                desired[i] = self.offside_tension if off else 0.0
                free[i] = 0.0 if off else 1.0
        for i in range(n):
            want = rope_length(self.ring, self.tops[i], self.bottoms[i], self.offsets[i], hare)
            error_lengths[i] = (self.lengths[i] - self.residuals[i]) - want
            error_tensions[i] = 0.0 if free[i] else self.tensions[i] - desired[i]
        near = 0.0
        if self.endpoint is not None:
            near = max(0.0, 1.0 - _dist(x, self.endpoint) / self.near_end_cm)
        rows = []
        for i in range(n):
            e, te = error_lengths[i], error_tensions[i]
            rows.append([self.tensions[i], desired[i], free[i], e, velocities[i],
                         0.0 if self.prev is None else (e - self.prev[0][i]) * rate_scale,
                         0.0 if self.prev is None else (te - self.prev[1][i]) * rate_scale,
                         self.last_dv[i], near, self.params[i][1], self.params[i][2]])
        self.prev = (list(error_lengths), list(error_tensions))
        dvs, self.rules = fuzzy.fuzzy_step([p for p, _, _ in self.params], rows)
        self.last_dv = list(dvs)
        return list(dvs)
