"""The acrylic vessel: geometry, vessel<->global transforms, containment (000, sections 7, 20).

Vessel co-ordinates have the vessel centre at the origin and the neck
straight up (+z); NECK_RING_STATIC_POSITION is the neck ring's centre in
them.  The vessel's pose in the global system is a position (the vessel
centre, cm) and an orientation (rotations in degrees about the global x, y
and z axes, applied in that order).  :meth:`AV.vtog` and :meth:`AV.gtov`
are the transforms the document prototyped and left empty; every bottom
attachment point is carried through :meth:`AV.vtog` before any computation
(section 20: "All the calculations are done in the global co-ordinate
system").  The pose comes from the AV record until AVPsense measures it;
:meth:`AV.set_pose` changes it.

The neck (section 7) is a cylinder of NECK_RADIUS about the vertical (vessel
z) axis through the neck ring's centre, from the ring up NECK_LENGTH; the source must stay
inside the vessel sphere or inside that cylinder.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

from pyrt.component import Component, command
from pyrt.errors import ConfigError

if TYPE_CHECKING:
    from pyrt.db import AVRecord

__all__ = ["AV", "Vec"]

Vec = tuple[float, float, float]


def _vec(v: Sequence[float], what: str) -> Vec:
    try:
        x, y, z = (float(c) for c in v)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{what} must be three numbers (x, y, z), got {v!r}") from exc
    if not all(math.isfinite(c) for c in (x, y, z)):
        raise ValueError(f"{what} must be finite, got {v!r}")
    return x, y, z


def _rotation(angles_deg: Vec) -> tuple[Vec, Vec, Vec]:
    """Rows of Rz @ Ry @ Rx (rotation about x first)."""
    ax, ay, az = (math.radians(a) for a in angles_deg)
    cx, sx = math.cos(ax), math.sin(ax)
    cy, sy = math.cos(ay), math.sin(ay)
    cz, sz = math.cos(az), math.sin(az)
    return (
        (cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx),
        (sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx),
        (-sy, cy * sx, cy * cx),
    )


class AV(Component):
    """The acrylic vessel (see the module text); lengths in cm."""

    def __init__(
        self,
        name: str,
        neck_ring_static_position: Sequence[float],
        neck_ring_radius: float,
        neck_radius: float,
        neck_length: float,
        vessel_radius: float,
        *,
        position: Sequence[float] = (0.0, 0.0, 0.0),
        orientation: Sequence[float] = (0.0, 0.0, 0.0),
    ):
        for label, v in (("NECK_RING_RADIUS", neck_ring_radius), ("NECK_RADIUS", neck_radius),
                         ("NECK_LENGTH", neck_length), ("VESSEL_RADIUS", vessel_radius)):
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ConfigError(f"AV {name}: {label} must be a positive length, got {v!r}")
        self.name = name
        self.neck_ring_static_position = _vec(neck_ring_static_position,
                                              "NECK_RING_STATIC_POSITION")
        self.neck_ring_radius = float(neck_ring_radius)
        self.neck_radius = float(neck_radius)
        self.neck_length = float(neck_length)
        self.vessel_radius = float(vessel_radius)
        self.set_pose(position, orientation)

    @classmethod
    def from_record(cls, record: AVRecord) -> AV:
        """An AV from a :class:`pyrt.db.AVRecord`."""
        return cls(record.name, record.neck_ring_static_position, record.neck_ring_radius,
                   record.neck_radius, record.neck_length, record.vessel_radius,
                   position=record.position, orientation=record.orientation)

    @command(name="show", reads_only=True)
    def cmd_show(self) -> str:
        """show: the vessel's geometry and pose (the AV takes no other command)."""
        return (f"{self.name}: vessel radius {self.vessel_radius:g} cm, neck ring at "
                f"{tuple(round(c, 2) for c in self.neck_ring_position)} radius "
                f"{self.neck_ring_radius:g} cm, neck radius {self.neck_radius:g} cm, length "
                f"{self.neck_length:g} cm; pose {self.position} {self.orientation}")

    # -- pose ------------------------------------------------------------------------

    def set_pose(self, position: Sequence[float], orientation: Sequence[float]) -> None:
        """The vessel centre (global, cm) and orientation (degrees about x, y, z)."""
        self.position = _vec(position, "vessel position")
        self.orientation = _vec(orientation, "vessel orientation")
        self._r = _rotation(self.orientation)

    def vtog(self, x: Sequence[float]) -> Vec:
        """Vessel co-ordinates to global."""
        v = _vec(x, "point")
        r, p = self._r, self.position
        return (
            r[0][0] * v[0] + r[0][1] * v[1] + r[0][2] * v[2] + p[0],
            r[1][0] * v[0] + r[1][1] * v[1] + r[1][2] * v[2] + p[1],
            r[2][0] * v[0] + r[2][1] * v[1] + r[2][2] * v[2] + p[2],
        )

    def gtov(self, x: Sequence[float]) -> Vec:
        """Global co-ordinates to vessel (the inverse of :meth:`vtog`)."""
        g = _vec(x, "point")
        r, p = self._r, self.position
        d = (g[0] - p[0], g[1] - p[1], g[2] - p[2])
        return (
            r[0][0] * d[0] + r[1][0] * d[1] + r[2][0] * d[2],
            r[0][1] * d[0] + r[1][1] * d[1] + r[2][1] * d[2],
            r[0][2] * d[0] + r[1][2] * d[1] + r[2][2] * d[2],
        )

    def direction_vtog(self, d: Sequence[float]) -> Vec:
        """A direction (not a point) from vessel to global co-ordinates."""
        v = _vec(d, "direction")
        r = self._r
        return (r[0][0] * v[0] + r[0][1] * v[1] + r[0][2] * v[2],
                r[1][0] * v[0] + r[1][1] * v[1] + r[1][2] * v[2],
                r[2][0] * v[0] + r[2][1] * v[1] + r[2][2] * v[2])

    # -- neck ring -------------------------------------------------------------------

    @property
    def neck_ring_position(self) -> Vec:
        """The neck ring's centre, global."""
        return self.vtog(self.neck_ring_static_position)

    @property
    def neck_axis(self) -> Vec:
        """Unit vector up the neck, global."""
        return self.direction_vtog((0.0, 0.0, 1.0))

    def neck_ring(self) -> tuple[Vec, Vec, float]:
        """(centre, axis, interior radius) of the neck ring, global."""
        return self.neck_ring_position, self.neck_axis, self.neck_ring_radius

    # -- containment -------------------------------------------------------------------

    def in_vessel(self, x: Sequence[float]) -> bool:
        """Whether global point ``x`` is inside the vessel sphere."""
        v = self.gtov(x)
        return v[0] * v[0] + v[1] * v[1] + v[2] * v[2] < self.vessel_radius ** 2

    def in_neck(self, x: Sequence[float]) -> bool:
        """Whether global point ``x`` is inside the neck cylinder (the ring up
        NECK_LENGTH, within NECK_RADIUS of the ring's axis)."""
        v = self.gtov(x)
        c = self.neck_ring_static_position
        h = v[2] - c[2]
        if not 0.0 <= h <= self.neck_length:
            return False
        return (v[0] - c[0]) ** 2 + (v[1] - c[1]) ** 2 <= self.neck_radius ** 2

    def contains(self, x: Sequence[float]) -> bool:
        """Whether the source may be at global point ``x`` (vessel or neck)."""
        return self.in_vessel(x) or self.in_neck(x)
