"""Pure-Python reference of csrc/statics.c: rope geometry, tensions and net force.

Written independently of the C kernel: the neck-ring contact point is found
by a dense scan of the ring followed by golden-section refinement (not
Newton), and the net force is summed from the rope directions directly.
"""

from __future__ import annotations

import math

Vec = tuple[float, float, float]


def _sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _norm(a):
    return math.sqrt(_dot(a, a))


def _unit(a):
    n = _norm(a)
    return (a[0] / n, a[1] / n, a[2] / n)


def _cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def top_path(top: Vec, q: Vec, ring) -> tuple[float, Vec, bool]:
    """Length of a segment from q to its far end ``top``, the point it leaves q toward,
    whether it wraps over the ring."""
    if ring is not None:
        centre, axis, radius = ring
        axis = _unit(axis)
        ht = _dot(_sub(top, centre), axis)
        hq = _dot(_sub(q, centre), axis)
        if ht > 0 > hq or hq > 0 > ht:
            s = ht / (ht - hq)
            x = tuple(top[k] + s * (q[k] - top[k]) for k in range(3))
            r = _sub(x, centre)
            r = _sub(r, tuple(_dot(r, axis) * a for a in axis))
            if _norm(r) > radius:
                e1 = _unit(r)
                e2 = _cross(axis, e1)

                def point(phi):
                    return tuple(centre[k] + radius * (math.cos(phi) * e1[k]
                                                       + math.sin(phi) * e2[k]) for k in range(3))

                def f(phi):
                    c = point(phi)
                    return _norm(_sub(c, top)) + _norm(_sub(c, q))

                best = min((f(p), p) for p in (2 * math.pi * i / 720 for i in range(720)))[1]
                lo, hi = best - 2 * math.pi / 720, best + 2 * math.pi / 720
                g = (math.sqrt(5) - 1) / 2
                for _ in range(80):
                    a = hi - g * (hi - lo)
                    b = lo + g * (hi - lo)
                    if f(a) < f(b):
                        hi = b
                    else:
                        lo = a
                phi = (lo + hi) / 2
                return f(phi), point(phi), True
    return _norm(_sub(top, q)), top, False


def rope(top, bottom, offset, x, ring):
    """(g, pull direction on the source per newton of tension, wrapped)."""
    q = tuple(x[k] + offset[k] for k in range(3))
    lt, leave, wrapped = top_path(top, q, ring)
    pull = _unit(_sub(leave, q))
    g = lt
    if bottom is not None:
        lb, leave_b, wrapped_b = top_path(bottom, q, ring)
        g += lb
        ub = _unit(_sub(leave_b, q))
        pull = tuple(pull[k] + ub[k] for k in range(3))
        wrapped = wrapped or wrapped_b
    return g, pull, wrapped


def tensions_and_force(tops, bottoms, offsets, dead, compliance, payout, x, weight, ring=None,
                       intact=None):
    """Tensions (N) and the net force on the source (N) at position x."""
    n = len(tops)
    intact = intact or [True] * n
    force = [0.0, 0.0, -weight]
    ts, gs, ws = [], [], []
    for i in range(n):
        g, pull, wrapped = rope(tops[i], bottoms[i], offsets[i], x, ring)
        s = dead[i] + g - payout[i]
        t = s / (compliance[i] * payout[i]) if (s > 0 and intact[i]) else 0.0
        for k in range(3):
            force[k] += t * pull[k]
        ts.append(t)
        gs.append(g)
        ws.append(wrapped)
    return ts, tuple(force), gs, ws
