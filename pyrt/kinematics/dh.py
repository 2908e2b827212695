"""Chains from Denavit-Hartenberg tables, standard and modified.

Standard DH (Paul, Corke's ``DHRobot``): link i's frame is
``A_i = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i)`` after link i-1's.
Modified DH (Craig, ``modified=True``): ``A_i = Rx(alpha_{i-1}) Tx(a_{i-1})
Rz(theta_i) Tz(d_i)``, where row i holds ``a_{i-1}`` and ``alpha_{i-1}``.

The variable is ``theta`` for a revolute joint and ``d`` for a prismatic
one; the row's constant ``theta`` (or ``d``) becomes the joint's offset.
With the modified convention each joint's child frame is DH frame i itself;
with the standard one the joint frame is where the motion happens (DH frame
i-1 turned by theta_i), the rest of A_i becomes the next joint's origin (or
the tool), and a row's inertial, given in DH frame i, is moved there.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from pyrt.errors import ConfigError
from pyrt.kinematics.joint import Inertial, Joint, JointKind

__all__ = ["DHRow", "dh_chain"]

_Z = (0.0, 0.0, 1.0)


@dataclass(frozen=True)
class DHRow:
    """One row of a DH table (m, rad) with the joint's limits and, for
    dynamics, the link's mass, centre of mass (3,) and inertia (3, 3) about
    it, in DH frame i."""

    a: float = 0.0
    alpha: float = 0.0
    d: float = 0.0
    theta: float = 0.0
    kind: JointKind = "revolute"
    lower: float = -math.inf
    upper: float = math.inf
    velocity: float = math.inf
    effort: float = math.inf
    damping: float = 0.0
    friction: float = 0.0
    mass: float = 0.0
    com: ArrayLike = (0.0, 0.0, 0.0)
    inertia: ArrayLike = field(default_factory=lambda: np.zeros((3, 3)))
    name: str | None = None


def _rx(t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    return np.array([[1.0, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1]])


def _rz(t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1.0, 0], [0, 0, 0, 1]])


def _tx(v: float) -> np.ndarray:
    m = np.eye(4)
    m[0, 3] = v
    return m


def _tz(v: float) -> np.ndarray:
    m = np.eye(4)
    m[2, 3] = v
    return m


def dh_chain(rows: Sequence[DHRow], modified: bool = False
             ) -> tuple[list[Joint], np.ndarray, np.ndarray]:
    """(joints, offsets, tool) of a DH table; the tool is the standard
    convention's last ``Tz Tx Rx`` (identity for the modified one)."""
    if not rows:
        raise ConfigError("DH table: no rows")
    joints: list[Joint] = []
    offsets = np.zeros(len(rows))
    after = np.eye(4)  # standard DH: the constant part of the previous row
    for i, row in enumerate(rows):
        if not isinstance(row, DHRow):
            raise ConfigError(f"DH table row {i + 1}: expected a DHRow, got {type(row).__name__}")
        name = row.name or f"joint{i + 1}"
        revolute = row.kind == "revolute"
        offsets[i] = row.theta if revolute else row.d
        if modified:
            origin = _rx(row.alpha) @ _tx(row.a) @ (_tz(row.d) if revolute else _rz(row.theta))
            to_link = np.eye(4)
        else:
            origin = after
            after = ((_tz(row.d) if revolute else _rz(row.theta)) @ _tx(row.a)
                     @ _rx(row.alpha))
            to_link = after
        try:
            inertial = Inertial(row.mass, np.asarray(row.com, dtype=float),
                                np.asarray(row.inertia, dtype=float)).moved(to_link)
            joints.append(Joint(name, row.kind, origin, np.array(_Z), row.lower, row.upper,
                                row.velocity, row.effort, row.damping, row.friction, inertial))
        except ValueError as exc:
            raise ConfigError(f"DH table row {i + 1} ({name}): {exc}") from None
    return joints, offsets, (np.eye(4) if modified else after)
