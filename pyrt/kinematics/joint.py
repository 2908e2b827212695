"""A chain's joints and link inertials, and the homogeneous transforms they use.

Units: metres, radians, kilograms (a prismatic joint's values in metres);
transforms are 4x4 float arrays; ``rpy`` are fixed-axis rotations about x,
then y, then z, as URDF's ``<origin rpy>``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["Inertial", "Joint", "JointKind", "rotation", "rpy_matrix", "rpy_of", "transform"]

JointKind = Literal["revolute", "prismatic"]


def _array(value: ArrayLike, shape: tuple[int, ...]) -> np.ndarray:
    arr = np.array(value, dtype=float)
    arr.setflags(write=False)
    if arr.shape != shape:
        raise ValueError(f"expected shape {shape}, got {arr.shape}")
    return arr


def rpy_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """Rotation ``Rz(yaw) Ry(pitch) Rx(roll)`` (URDF's rpy)."""
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return np.array([
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ])


def rpy_of(pose: ArrayLike) -> tuple[float, float, float]:
    """(roll, pitch, yaw) of a rotation or transform, pitch in [-pi/2, pi/2]."""
    r = np.asarray(pose, dtype=float)[:3, :3]
    pitch = math.atan2(-r[2, 0], math.hypot(r[0, 0], r[1, 0]))
    if math.cos(pitch) > 1e-9:
        return math.atan2(r[2, 1], r[2, 2]), pitch, math.atan2(r[1, 0], r[0, 0])
    # gimbal lock: only roll -+ yaw is defined; report it as the roll
    return math.atan2(-r[1, 2], r[1, 1]) * (1.0 if pitch > 0 else -1.0), pitch, 0.0


def rotation(axis: ArrayLike, angle: float) -> np.ndarray:
    """Rotation matrix of *angle* about the unit vector *axis*."""
    x, y, z = np.asarray(axis, dtype=float)
    k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * (k @ k)


def transform(xyz: ArrayLike = (0.0, 0.0, 0.0), rpy: ArrayLike = (0.0, 0.0, 0.0)) -> np.ndarray:
    """The 4x4 transform of a translation *xyz* and a rotation *rpy* (URDF's
    ``<origin xyz rpy>``)."""
    t = np.eye(4)
    r, p, y = np.asarray(rpy, dtype=float)
    t[:3, :3] = rpy_matrix(float(r), float(p), float(y))
    t[:3, 3] = np.asarray(xyz, dtype=float)
    return t


@dataclass(frozen=True)
class Inertial:
    """A link's mass (kg), centre of mass (3,) and inertia (3, 3) about the
    centre of mass (kg m^2), both in the link's frame: the child frame of the
    joint that moves it."""

    mass: float = 0.0
    com: np.ndarray = field(default_factory=lambda: _array((0.0, 0.0, 0.0), (3,)))
    inertia: np.ndarray = field(default_factory=lambda: _array(np.zeros((3, 3)), (3, 3)))

    def __post_init__(self) -> None:
        object.__setattr__(self, "mass", float(self.mass))
        object.__setattr__(self, "com", _array(self.com, (3,)))
        object.__setattr__(self, "inertia", _array(self.inertia, (3, 3)))
        if not (math.isfinite(self.mass) and self.mass >= 0.0):
            raise ValueError(f"mass must be a finite number >= 0 kg, got {self.mass}")
        if not (np.isfinite(self.com).all() and np.isfinite(self.inertia).all()):
            raise ValueError("centre of mass and inertia must be finite")
        if not np.allclose(self.inertia, self.inertia.T, rtol=0.0,
                           atol=1e-9 * max(1.0, float(np.abs(self.inertia).max()))):
            raise ValueError("inertia must be symmetric")
        if np.linalg.eigvalsh(self.inertia).min() < -1e-9 * max(
                1.0, float(np.abs(self.inertia).max())):
            raise ValueError("inertia must be positive semi-definite")

    def moved(self, pose: ArrayLike) -> Inertial:
        """The same body seen from a frame in which its frame is at *pose*."""
        p = np.asarray(pose, dtype=float)
        r = p[:3, :3]
        return Inertial(self.mass, r @ self.com + p[:3, 3], r @ self.inertia @ r.T)

    def __add__(self, other: Inertial) -> Inertial:
        """Two bodies (in the same frame) rigidly joined."""
        m = self.mass + other.mass
        if m == 0.0:
            return Inertial(0.0, np.zeros(3), self.inertia + other.inertia)
        c = (self.mass * self.com + other.mass * other.com) / m
        total = np.zeros((3, 3))
        for body in (self, other):
            d = body.com - c
            total += body.inertia + body.mass * (float(d @ d) * np.eye(3) - np.outer(d, d))
        return Inertial(m, c, total)


@dataclass(frozen=True)
class Joint:
    """One movable joint of a chain and the link it moves.

    ``origin`` is the fixed transform from the previous joint's child frame
    (the chain's base frame for the first joint) to this joint's frame at
    zero motion; ``axis`` the unit axis in that frame (rotation about it for
    a revolute joint, translation along it for a prismatic one).  Limits in
    rad or m (``lower`` may be -inf, ``upper`` +inf: a continuous joint);
    ``velocity`` (rad/s or m/s) and ``effort`` (N m or N) as URDF's
    ``<limit>``; ``damping`` (N m s/rad or N s/m) and ``friction`` (N m or
    N) as its ``<dynamics>``: they describe the joint, the rigid-body
    algorithms leave them to the caller.
    """

    name: str
    kind: JointKind
    origin: np.ndarray
    axis: np.ndarray
    lower: float = -math.inf
    upper: float = math.inf
    velocity: float = math.inf
    effort: float = math.inf
    damping: float = 0.0
    friction: float = 0.0
    inertial: Inertial = field(default_factory=Inertial)

    def __post_init__(self) -> None:
        if self.kind not in ("revolute", "prismatic"):
            raise ValueError(f"joint {self.name!r}: kind must be 'revolute' or 'prismatic', "
                             f"got {self.kind!r}")
        origin = _array(self.origin, (4, 4))
        if not np.isfinite(origin).all():
            raise ValueError(f"joint {self.name!r}: origin must be finite")
        if not np.array_equal(origin[3], (0.0, 0.0, 0.0, 1.0)):
            raise ValueError(f"joint {self.name!r}: origin's last row must be 0 0 0 1")
        r = origin[:3, :3]
        if not np.allclose(r @ r.T, np.eye(3), rtol=0.0, atol=1e-6) or np.linalg.det(r) < 0:
            raise ValueError(f"joint {self.name!r}: origin's rotation is not a rotation")
        axis = np.array(self.axis, dtype=float)
        norm = float(np.linalg.norm(axis)) if axis.shape == (3,) else 0.0
        if not (math.isfinite(norm) and norm > 1e-12):
            raise ValueError(f"joint {self.name!r}: axis must be a non-zero 3-vector, "
                             f"got {self.axis!r}")
        object.__setattr__(self, "origin", origin)
        object.__setattr__(self, "axis", _array(axis / norm, (3,)))
        for name in ("lower", "upper", "velocity", "effort", "damping", "friction"):
            object.__setattr__(self, name, float(getattr(self, name)))
        if math.isnan(self.lower) or math.isnan(self.upper) or self.lower > self.upper:
            raise ValueError(f"joint {self.name!r}: limits must satisfy lower <= upper, "
                             f"got {self.lower} and {self.upper}")
        for name in ("velocity", "effort", "damping", "friction"):
            v = getattr(self, name)
            if math.isnan(v) or v < 0:
                raise ValueError(f"joint {self.name!r}: {name} must be >= 0, got {v}")
