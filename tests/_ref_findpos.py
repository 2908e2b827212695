"""numpy reference of the position finder and rope geometry (csrc/findpos.c).

The same model (000, Eq. 1-2): predicted length |top - x - offset| plus
|bottom - x - offset| for side ropes; residual = measured - predicted;
Gauss-Newton steps on the normal equations with frozen directions removed,
until the step is below ``tol``.  Used by tests/test_native_findpos.py and
bench/bench_native.py.  Also the test geometries: the prototype of Table 3
(with the mirror-image third rope) and a 5-rope out-of-plane set.
"""

from __future__ import annotations

import numpy as np

NAN = float("nan")

#: Table 3: central rope AXIS0 and side rope AXIS1; AXIS2 is AXIS1 mirrored in x.
PROTO_TOPS = np.array([[0.0, 5.0, 389.0], [50.0, 0.0, 391.0], [-50.0, 0.0, 391.0]])
PROTO_BOTTOMS = np.array([[NAN, NAN, NAN], [317.0, 0.0, 89.53], [-317.0, 0.0, 89.53]])

#: Five ropes: the prototype plus the pair rotated 90 degrees about z.
FIVE_TOPS = np.array([
    [0.0, 5.0, 389.0], [50.0, 0.0, 391.0], [-50.0, 0.0, 391.0],
    [0.0, 50.0, 391.0], [0.0, -50.0, 391.0],
])
FIVE_BOTTOMS = np.array([
    [NAN, NAN, NAN], [317.0, 0.0, 89.53], [-317.0, 0.0, 89.53],
    [0.0, 317.0, 89.53], [0.0, -317.0, 89.53],
])

#: The prototype vessel (Table 5): radius 320 cm about the origin.
VESSEL_RADIUS = 320.0


def segments(x, tops, bottoms, offsets=None):
    """(total, gradient rows a_i = ut + ub) for a source at x."""
    tops = np.asarray(tops, float)
    bottoms = np.asarray(bottoms, float)
    off = np.zeros(tops.shape) if offsets is None else np.asarray(offsets, float)
    p = np.asarray(x, float)[None, :] + off
    dt = tops - p
    lt = np.linalg.norm(dt, axis=1)
    a = dt / lt[:, None]
    total = lt.copy()
    side = ~np.isnan(bottoms[:, 0])
    db = bottoms[side] - p[side]
    lb = np.linalg.norm(db, axis=1)
    total[side] += lb
    a[side] += db / lb[:, None]
    return total, a


def rope_lengths(x, tops, bottoms, offsets=None) -> np.ndarray:
    return segments(x, tops, bottoms, offsets)[0]


def freeze_mask(bottoms) -> tuple[int, int, int]:
    b = np.asarray(bottoms, float)
    side = ~np.isnan(b[:, 0])
    s = np.abs(b[side]).sum(axis=0) if side.any() else np.zeros(3)
    return tuple(int(v < 1.0) for v in s)


def find_position(tops, bottoms, lengths, start, offsets=None, freeze=None, tol=0.1,
                  max_iter=50):
    """(position, rms, residuals, iterations); raises RuntimeError on failure."""
    freeze = freeze_mask(bottoms) if freeze is None else tuple(int(bool(f)) for f in freeze)
    free = [j for j in range(3) if not freeze[j]]
    x = np.array(start, float)
    lengths = np.asarray(lengths, float)
    for it in range(1, max_iter + 1):
        pred, a = segments(x, tops, bottoms, offsets)
        r = lengths - pred
        af = a[:, free]
        d = np.zeros(3)
        d[free] = np.linalg.solve(af.T @ af, -(af.T @ r))
        x = x + d
        if d @ d < tol * tol:
            res = lengths - rope_lengths(x, tops, bottoms, offsets)
            return x, float(np.sqrt(np.mean(res**2))), res, it
    raise RuntimeError("no convergence")
