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

__all__ = ["NeckRing", "Ring", "ring_contact"]

Vec = tuple[float, float, float]
#: (centre, unit axis pointing out of the vessel, interior radius), global cm.
Ring = tuple[Vec, Vec, float]

_ITERATIONS = 12


class NeckRing:
    """The neck ring with a fixed frame, for repeated contact searches.

    :meth:`contact` solves for the rim angle with Newton's method; given the
    angle found for the same rope at the last poll (``hint``) it converges in
    one or two steps instead of four to six from the crossing radius.
    """

    def __init__(self, centre: Vec, axis: Vec, radius: float):
        n = math.sqrt(axis[0] ** 2 + axis[1] ** 2 + axis[2] ** 2)
        if not n > 0:
            raise ValueError("ring axis must be a non-zero vector")
        a = (axis[0] / n, axis[1] / n, axis[2] / n)
        # any unit vector perpendicular to the axis, then e2 = a x e1
        helper = (1.0, 0.0, 0.0) if abs(a[0]) < 0.9 else (0.0, 1.0, 0.0)
        d = helper[0] * a[0] + helper[1] * a[1] + helper[2] * a[2]
        e1 = (helper[0] - d * a[0], helper[1] - d * a[1], helper[2] - d * a[2])
        m = math.sqrt(e1[0] ** 2 + e1[1] ** 2 + e1[2] ** 2)
        self.e1 = (e1[0] / m, e1[1] / m, e1[2] / m)
        x = self.e1
        self.e2 = (a[1] * x[2] - a[2] * x[1], a[2] * x[0] - a[0] * x[2], a[0] * x[1] - a[1] * x[0])
        self.centre = (float(centre[0]), float(centre[1]), float(centre[2]))
        self.axis = a
        self.radius = float(radius)

    def contact(self, t: Vec, q: Vec, hint: float | None = None) -> tuple[Vec, float] | None:
        """``(rim point, rim angle)`` the rope ``t -> q`` bears on, or None."""
        rad = self.radius
        if rad <= 0.0:
            return None
        ax0, ax1, ax2 = self.axis
        cx0, cy0, cz0 = self.centre
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
        if rx * rx + ry * ry + rz * rz <= rad * rad:
            return None
        e1x, e1y, e1z = self.e1
        e2x, e2y, e2z = self.e2
        if hint is None:
            phi = math.atan2(rx * e2x + ry * e2y + rz * e2z, rx * e1x + ry * e1y + rz * e1z)
        else:
            phi = hint
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
            if -1e-10 < step < 1e-10:
                break
        cs, sn = cos(phi), sin(phi)
        return ((cx0 + rad * (cs * e1x + sn * e2x), cy0 + rad * (cs * e1y + sn * e2y),
                 cz0 + rad * (cs * e1z + sn * e2z)), phi)


def ring_contact(ring: Ring | None, t: Vec, q: Vec) -> Vec | None:
    """The rim point the rope ``t -> q`` bears on, or None if it runs free."""
    if ring is None or ring[2] <= 0.0:
        return None
    found = NeckRing(*ring).contact(t, q)
    return None if found is None else found[0]
