"""Pure-Python reference of csrc/puma.c: Paul's closed-form inverse of the PUMA 560.

The same mathematics as the C, written with math and numpy: the wrist centre
gives joint 1 from the shoulder offset d3, the planar triangle
shoulder-elbow-wrist joints 2 and 3, and R36 = R03^T R = Rz(q4) Ry(-q5) Rz(q6)
the wrist.  Returns (q, why, detail) as the kernel's wrapper does.
"""

from __future__ import annotations

import math

import numpy as np

REACHED, INSIDE_OFFSET, TOO_FAR, TOO_NEAR, LIMIT = 0, 1, 2, 3, 10
SINGULAR = 1e-12
TWO_PI = 2.0 * math.pi


def _inv(t: np.ndarray) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = t[:3, :3].T
    out[:3, 3] = -t[:3, :3].T @ t[:3, 3]
    return out


def _into_limits(v: float, lo: float, hi: float) -> float | None:
    tol = 1e-9
    if lo - tol <= v <= hi + tol:
        return min(max(v, lo), hi)
    best = None
    for k in range(-2, 3):
        c = v + k * TWO_PI
        if lo - tol <= c <= hi + tol and (best is None or abs(c - v) < abs(best - v)):
            best = c
    return None if best is None else min(max(best, lo), hi)


def inverse(lengths, base, tool, offsets, lower, upper, pose, config: str, seed=None,
            limits: bool = True, nearest: bool = False):
    """(q, why, detail) for ``pose`` in ``config`` ('righty-above-noflip' ...)."""
    d1, a2, a3, d3, d4 = lengths
    arm, elbow, wrist = config.split("-")
    t = _inv(np.asarray(base)) @ np.asarray(pose) @ _inv(np.asarray(tool))
    px, py, pz = t[0, 3], t[1, 3], t[2, 3] - d1
    r = math.hypot(px, py)
    if r < abs(d3) * (1.0 - 1e-12) and not nearest:
        return None, INSIDE_OFFSET, r
    phi = math.atan2(py, px)
    off = math.asin(max(-1.0, min(1.0, d3 / r))) if r > 0 else 0.0
    th1 = phi + off if arm == "righty" else phi + math.pi - off
    c1, s1 = math.cos(th1), math.sin(th1)
    x, y = px * c1 + py * s1, pz
    rho = math.hypot(x, y)
    length2 = a3 * a3 + d4 * d4
    k = (x * x + y * y + a2 * a2 - length2) / (2.0 * a2)
    if rho == 0.0 or (abs(k) > rho * (1.0 + 1e-12) and not nearest):
        return None, (TOO_FAR if rho >= a2 + math.sqrt(length2) else TOO_NEAR), rho
    psi = math.acos(max(-1.0, min(1.0, k / rho)))
    if nearest and abs(k) >= rho:
        psi = max(psi, 0.02)
    beta = math.atan2(y, x)
    up = (elbow == "above") == (arm == "righty")
    th2 = beta + psi if up else beta - psi
    th23 = math.atan2(y - a2 * math.sin(th2), x - a2 * math.cos(th2)) - math.atan2(d4, a3)
    c23, s23 = math.cos(th23), math.sin(th23)
    r03 = np.array([[c1 * c23, -s1, -c1 * s23], [s1 * c23, c1, -s1 * s23], [s23, 0.0, c23]])
    m = r03.T @ t[:3, :3]
    s5 = math.hypot(m[0, 2], m[1, 2])
    th5 = math.atan2(s5, m[2, 2])
    if s5 > SINGULAR:
        th4 = math.atan2(-m[1, 2], -m[0, 2])  # q5 > 0: flipped
        if wrist == "noflip":
            th4 += math.pi
            th5 = -th5
    else:
        th4 = 0.0 if seed is None else seed[3] + offsets[3]
    c4, s4, c5, s5_ = math.cos(th4), math.sin(th4), math.cos(th5), math.sin(th5)
    rz4ry5 = np.array([[c4 * c5, -s4, -c4 * s5_], [s4 * c5, c4, -s4 * s5_], [s5_, 0.0, c5]])
    r6 = rz4ry5.T @ m
    th6 = math.atan2(r6[1, 0], r6[0, 0])
    theta = np.array([th1, th2, th23 - th2, th4, th5, th6])
    q = np.empty(6)
    for i in range(6):
        v = math.remainder(theta[i] - offsets[i], TWO_PI)
        if seed is not None:
            v += TWO_PI * math.floor((seed[i] - v) / TWO_PI + 0.5)
        if limits:
            placed = _into_limits(v, lower[i], upper[i])
            if placed is None:
                return None, LIMIT + i, v
            v = placed
        q[i] = v
    return q, REACHED, 0.0
