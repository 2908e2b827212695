"""Kinematic chains: forward and inverse kinematics and rigid-body dynamics
of serial arms, from a URDF or a DH table, computed by C kernels
(csrc/kinematics.c).  See :mod:`pyrt.kinematics.chain` for the conventions.
"""

from pyrt.kinematics.chain import GRAVITY, Chain, ClosedForm, IKResult
from pyrt.kinematics.dh import DHRow
from pyrt.kinematics.joint import (
    Inertial,
    Joint,
    JointKind,
    rotation,
    rpy_matrix,
    rpy_of,
    transform,
)
from pyrt.kinematics.sets import JointSet, JointSets

__all__ = [
    "GRAVITY",
    "Chain",
    "ClosedForm",
    "DHRow",
    "IKResult",
    "Inertial",
    "Joint",
    "JointKind",
    "JointSet",
    "JointSets",
    "rotation",
    "rpy_matrix",
    "rpy_of",
    "transform",
]
