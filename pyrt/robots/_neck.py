"""Where a rope bears on the neck ring (000, section 5, ``neckIntersection``).

The top segment of a rope runs from its top pulley ``t`` down to the
carriage pulley ``q``.  When the straight line would cross the neck-ring
plane outside the ring, the rope bears on the ring instead; the ring is
frictionless (the document's assumption), so the rope takes the shortest
path ``t -> c -> q`` over a point ``c`` of the ring's rim and lies in a plane
through a ring radius.  ``c`` is found by Newton's method on the rim angle,
from the radius through the straight line's crossing point (the same
construction the physics uses, so control and world agree on lengths).

The PolyAxis uses the contact point as the rope's *effective top*: the
position finder sees a rope from ``c`` with the measured length less
``|t - c|``.
"""

from __future__ import annotations

import math

__all__ = ["Ring", "ring_contact"]

Vec = tuple[float, float, float]
#: (centre, unit axis pointing out of the vessel, interior radius), global cm.
Ring = tuple[Vec, Vec, float]

_ITERATIONS = 12


def ring_contact(ring: Ring | None, t: Vec, q: Vec) -> Vec | None:
    """The rim point the rope ``t -> q`` bears on, or None if it runs free."""
    if ring is None:
        return None
    cen, ax, rad = ring
    if rad <= 0.0:
        return None
    ax0, ax1, ax2 = ax
    cx0, cy0, cz0 = cen
    tx, ty, tz = t
    qx, qy, qz = q
    tcx, tcy, tcz = tx - cx0, ty - cy0, tz - cz0
    ht = tcx * ax0 + tcy * ax1 + tcz * ax2
    if ht <= 0.0:
        return None
    qcx, qcy, qcz = qx - cx0, qy - cy0, qz - cz0
    hq = qcx * ax0 + qcy * ax1 + qcz * ax2
    if hq >= 0.0:
        return None
    s = ht / (ht - hq)
    rx, ry, rz = tcx + s * (qcx - tcx), tcy + s * (qcy - tcy), tcz + s * (qcz - tcz)
    xr = rx * ax0 + ry * ax1 + rz * ax2
    rx, ry, rz = rx - xr * ax0, ry - xr * ax1, rz - xr * ax2
    rr2 = rx * rx + ry * ry + rz * rz
    if rr2 <= rad * rad:
        return None
    rr = math.sqrt(rr2)
    e1x, e1y, e1z = rx / rr, ry / rr, rz / rr
    e2x, e2y, e2z = ax1 * e1z - ax2 * e1y, ax2 * e1x - ax0 * e1z, ax0 * e1y - ax1 * e1x
    phi = 0.0
    sqrt, cos, sin = math.sqrt, math.cos, math.sin
    for _ in range(_ITERATIONS):
        cs, sn = cos(phi), sin(phi)
        ux, uy, uz = cs * e1x + sn * e2x, cs * e1y + sn * e2y, cs * e1z + sn * e2z
        px, py, pz = -sn * e1x + cs * e2x, -sn * e1y + cs * e2y, -sn * e1z + cs * e2z
        cx, cy, cz = cx0 + rad * ux, cy0 + rad * uy, cz0 + rad * uz
        ax_, ay_, az_ = cx - tx, cy - ty, cz - tz
        bx, by, bz = cx - qx, cy - qy, cz - qz
        da = sqrt(ax_ * ax_ + ay_ * ay_ + az_ * az_)
        db = sqrt(bx * bx + by * by + bz * bz)
        if da < 1e-9 or db < 1e-9:
            break
        pa = rad * (ax_ * px + ay_ * py + az_ * pz) / da
        pb = rad * (bx * px + by * py + bz * pz) / db
        f1 = pa + pb
        f2 = (rad * rad - pa * pa) / da + (rad * rad - pb * pb) / db
        f2 -= rad * (ux * (ax_ / da + bx / db) + uy * (ay_ / da + by / db)
                     + uz * (az_ / da + bz / db))
        step = -f1 / f2 if f2 > 0.0 else (-0.1 if f1 > 0.0 else 0.1)
        step = -0.5 if step < -0.5 else (0.5 if step > 0.5 else step)
        phi += step
        if -1e-12 < step < 1e-12:
            break
    cs, sn = cos(phi), sin(phi)
    return (cx0 + rad * (cs * e1x + sn * e2x), cy0 + rad * (cs * e1y + sn * e2y),
            cz0 + rad * (cs * e1z + sn * e2z))
