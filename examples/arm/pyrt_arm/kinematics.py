"""Kinematics of the arm: a two-joint planar arm, forward and inverse, kept consistent.

The arm lies on a table.  Joint 0 (the shoulder, ``q0``) turns link 1 about the base;
joint 1 (the elbow, ``q1``) turns link 2 relative to link 1.  Angles are measured
counter-clockwise, ``q0`` from the table's +x axis, ``q1`` from the line of link 1::

    x = L1 cos(q0) + L2 cos(q0 + q1)
    y = L1 sin(q0) + L2 sin(q0 + q1)

The geometry is 004's MRC II robot in miniature (:data:`GEOMETRY`):

* link 1, shoulder to elbow: L1 = 300 mm;
* link 2, elbow to tip: L2 = 250 mm;
* q0, the shoulder: -170 .. 170 deg (a cable wrap stops it short of a full turn);
* q1, the elbow: -150 .. 150 deg (link 2 folds back no closer than 30 deg to link 1).

The reachable annulus is ``|L1 - L2| <= r <= L1 + L2`` (50 .. 550 mm); within the
elbow's limits the tip reaches ``r >= 150.3 mm``, so a point of the annulus closer
than that is refused as outside the joint limits, not as out of reach.

Elbow solutions: ``elbow="down"`` is ``q1 >= 0`` (the elbow lies clockwise of the
line from the base to the tip), ``elbow="up"`` is ``q1 <= 0`` (counter-clockwise of
it).  Stretched straight (``q1 = 0``) both are the same.

Angles are degrees at this API and radians inside; lengths are millimetres.
:func:`ik` is written from :func:`fk`'s own equations so that ``fk(ik(p)) = p`` and
``ik(fk(q)) = q`` for the matching elbow, to rounding (004: "consistency between
forward and inverse kinematics").
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from importlib.resources import files
from typing import Literal

import numpy as np
import numpy.typing as npt

__all__ = [
    "GEOMETRY",
    "LIMIT_TOL_DEG",
    "REACH_TOL_MM",
    "Elbow",
    "Geometry",
    "JointLimitError",
    "KinematicsError",
    "ReachError",
    "elbow_of",
    "fk",
    "ik",
    "jacobian",
    "urdf",
    "within_limits",
]

#: Which of the two inverse solutions: "up" (q1 <= 0) or "down" (q1 >= 0).
Elbow = Literal["up", "down"]

#: How far (mm) a point may lie outside the annulus and still count as on its edge:
#: fk of a stretched or folded arm lands there only to rounding.
REACH_TOL_MM = 1e-9

#: How far (deg) an inverse solution may lie beyond a joint limit and still count as on
#: it (and be returned as the limit): fk of an arm at its limit comes back only to
#: rounding, and near the stretched arm (a singularity) rounding of r moves the angles
#: by up to a few 1e-6 deg.
LIMIT_TOL_DEG = 1e-5


class KinematicsError(ValueError):
    """A point or a joint position the arm cannot take."""


class ReachError(KinematicsError):
    """A point outside the reachable annulus ``|L1 - L2| <= r <= L1 + L2``."""


class JointLimitError(KinematicsError):
    """A point whose inverse solution puts a joint outside its limits."""


@dataclass(frozen=True)
class Geometry:
    """Link lengths (mm) and joint limits (deg, ``(low, high)``) of a two-joint planar arm."""

    l1_mm: float = 300.0
    l2_mm: float = 250.0
    q0_limits_deg: tuple[float, float] = (-170.0, 170.0)
    q1_limits_deg: tuple[float, float] = (-150.0, 150.0)

    def __post_init__(self) -> None:
        for name in ("l1_mm", "l2_mm"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be a positive length in mm, got {value!r}")
        for name in ("q0_limits_deg", "q1_limits_deg"):
            low, high = getattr(self, name)
            if not (math.isfinite(low) and math.isfinite(high) and -180.0 <= low < high <= 180.0):
                raise ValueError(f"{name} must be (low, high) with -180 <= low < high <= 180 deg, "
                                 f"got {(low, high)!r}")

    @property
    def limits_deg(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """The joint limits, ``(q0_limits_deg, q1_limits_deg)``."""
        return (self.q0_limits_deg, self.q1_limits_deg)

    @property
    def r_min_mm(self) -> float:
        """The inner radius of the reachable annulus, ``|L1 - L2|``."""
        return abs(self.l1_mm - self.l2_mm)

    @property
    def r_max_mm(self) -> float:
        """The outer radius of the reachable annulus, ``L1 + L2``."""
        return self.l1_mm + self.l2_mm


#: The arm's geometry (the table in the module docstring).
GEOMETRY = Geometry()


def _check_finite(**values: float) -> None:
    for name, value in values.items():
        if not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ValueError(f"{name} must be a finite number, got {value!r}")


def fk(q0_deg: float, q1_deg: float, geometry: Geometry = GEOMETRY) -> tuple[float, float]:
    """The tip ``(x, y)`` in mm for joint angles ``q0_deg``, ``q1_deg`` in degrees.

    Any finite angles are accepted (the limits are not checked: see :func:`within_limits`).
    """
    _check_finite(q0_deg=q0_deg, q1_deg=q1_deg)
    a0 = math.radians(q0_deg)
    a01 = a0 + math.radians(q1_deg)
    return (geometry.l1_mm * math.cos(a0) + geometry.l2_mm * math.cos(a01),
            geometry.l1_mm * math.sin(a0) + geometry.l2_mm * math.sin(a01))


def within_limits(q0_deg: float, q1_deg: float, geometry: Geometry = GEOMETRY) -> bool:
    """True if both joints lie within their limits (the limits themselves included)."""
    (lo0, hi0), (lo1, hi1) = geometry.limits_deg
    return lo0 <= q0_deg <= hi0 and lo1 <= q1_deg <= hi1


def elbow_of(q1_deg: float) -> Elbow:
    """The elbow solution a joint position belongs to: "up" for ``q1 < 0``, else "down"."""
    return "up" if q1_deg < 0.0 else "down"


def _wrap_deg(angle_deg: float) -> float:
    """``angle_deg`` brought into (-180, 180]."""
    wrapped = math.fmod(angle_deg, 360.0)
    if wrapped > 180.0:
        wrapped -= 360.0
    elif wrapped <= -180.0:
        wrapped += 360.0
    return wrapped


def ik(x_mm: float, y_mm: float, elbow: Elbow = "up",
       geometry: Geometry = GEOMETRY) -> tuple[float, float]:
    """The joint angles ``(q0, q1)`` in degrees that put the tip at ``(x_mm, y_mm)``.

    ``elbow`` picks the solution: "up" (``q1 <= 0``) or "down" (``q1 >= 0``); ``q0`` is
    given in (-180, 180].  Raises :class:`ReachError` for a point outside the annulus
    ``|L1 - L2| <= r <= L1 + L2`` and :class:`JointLimitError` if the chosen solution
    puts a joint outside its limits; the messages give the numbers.
    """
    _check_finite(x_mm=x_mm, y_mm=y_mm)
    if elbow not in ("up", "down"):
        raise ValueError(f"elbow must be 'up' or 'down', got {elbow!r}")
    l1, l2 = geometry.l1_mm, geometry.l2_mm
    r2 = x_mm * x_mm + y_mm * y_mm
    r = math.sqrt(r2)
    r_min, r_max = geometry.r_min_mm, geometry.r_max_mm
    if not (r_min - REACH_TOL_MM <= r <= r_max + REACH_TOL_MM):
        raise ReachError(
            f"point ({x_mm:.3f}, {y_mm:.3f}) mm is out of reach: it lies {r:.3f} mm from the "
            f"base, and the arm reaches {r_min:.3f} <= r <= {r_max:.3f} mm")
    # cos(q1) from the law of cosines; sin(q1) from the factored form of 1 - cos^2,
    # which keeps its precision near the stretched and the folded arm.
    cos_q1 = (r2 - l1 * l1 - l2 * l2) / (2.0 * l1 * l2)
    sin2 = ((r_max * r_max - r2) * (r2 - r_min * r_min)) / (4.0 * l1 * l1 * l2 * l2)
    sin_q1 = math.sqrt(max(sin2, 0.0))
    if elbow == "up":
        sin_q1 = -sin_q1
    q1 = math.atan2(sin_q1, max(-1.0, min(1.0, cos_q1)))
    q0 = math.atan2(y_mm, x_mm) - math.atan2(l2 * sin_q1, l1 + l2 * math.cos(q1))
    solution = [_wrap_deg(math.degrees(q0)), math.degrees(q1)]
    for j, (low, high) in enumerate(geometry.limits_deg):
        value = solution[j]
        if not low - LIMIT_TOL_DEG <= value <= high + LIMIT_TOL_DEG:
            raise JointLimitError(
                f"point ({x_mm:.3f}, {y_mm:.3f}) mm with the elbow {elbow} needs "
                f"q{j} = {value:.3f} deg, outside its limits [{low:.3f}, {high:.3f}] deg")
        solution[j] = min(max(value, low), high)
    return solution[0], solution[1]


def jacobian(q0_deg: float, q1_deg: float,
             geometry: Geometry = GEOMETRY) -> npt.NDArray[np.float64]:
    """The 2x2 Jacobian ``d(x, y)/d(q0, q1)`` in mm per degree.

    ``J @ (qd0, qd1)`` with joint rates in deg/s is the tip's velocity in mm/s.  Its
    determinant ``L1 L2 sin(q1)`` (times (pi/180)^2) vanishes with the arm stretched or
    folded: there the tip cannot move radially.
    """
    _check_finite(q0_deg=q0_deg, q1_deg=q1_deg)
    a0 = math.radians(q0_deg)
    a01 = a0 + math.radians(q1_deg)
    l1, l2 = geometry.l1_mm, geometry.l2_mm
    per_deg = math.pi / 180.0
    s0, c0, s01, c01 = math.sin(a0), math.cos(a0), math.sin(a01), math.cos(a01)
    return np.array([[-(l1 * s0 + l2 * s01), -l2 * s01],
                     [l1 * c0 + l2 * c01, l2 * c01]], dtype=np.float64) * per_deg


def urdf() -> str:
    """The arm as a URDF: the file ``arm.urdf`` of this package, joints ``shoulder``
    and ``elbow`` about z, links of :data:`GEOMETRY`'s lengths along x (in m) with
    their inertials, limits and friction; for viewers (Foxglove's 3D panel), the
    controller's chain and the simulated arm."""
    return files("pyrt_arm").joinpath("arm.urdf").read_text()
