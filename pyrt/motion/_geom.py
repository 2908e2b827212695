"""Small rigid-body helpers of the trajectory: rotation vectors and poses.

Drive coordinates: a pose is written ``x = (p, phi)`` about a reference
``(R_c, p_c)``: position ``p_c + p``, rotation ``Exp(phi) R_c``.  A straight
line with its orientation turned about one fixed axis (Paul's drive
transform) is linear in these coordinates.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

Matrix = npt.NDArray[np.float64]
Vector = npt.NDArray[np.float64]


def exp_rot(phi: Vector) -> Matrix:
    """The rotation of the rotation vector ``phi`` (Rodrigues)."""
    x, y, z = float(phi[0]), float(phi[1]), float(phi[2])
    th2 = x * x + y * y + z * z
    if th2 < 1e-24:
        return np.array([[1.0, -z, y], [z, 1.0, -x], [-y, x, 1.0]])
    th = math.sqrt(th2)
    s = math.sin(th) / th
    c = (1.0 - math.cos(th)) / th2
    return np.array([
        [1.0 - c * (y * y + z * z), -s * z + c * x * y, s * y + c * x * z],
        [s * z + c * x * y, 1.0 - c * (x * x + z * z), -s * x + c * y * z],
        [-s * y + c * x * z, s * x + c * y * z, 1.0 - c * (x * x + y * y)],
    ])


def log_rot(r: Matrix) -> Vector:
    """The rotation vector of the rotation ``r`` (angle in [0, pi])."""
    cos = max(-1.0, min(1.0, (float(np.trace(r)) - 1.0) / 2.0))
    th = math.acos(cos)
    w = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    if th < 1e-9:
        return 0.5 * w
    if math.pi - th < 1e-6:
        # near a half turn: the axis from the symmetric part
        m = (r + np.eye(3)) / 2.0
        i = int(np.argmax(np.diag(m)))
        axis = m[:, i] / math.sqrt(max(m[i, i], 1e-300))
        if float(axis @ w) < 0:
            axis = -axis
        return th * axis / float(np.linalg.norm(axis))
    return th / (2.0 * math.sin(th)) * w


def drive_of(pose: Matrix, r_c: Matrix, p_c: Vector) -> Vector:
    """Drive coordinates (6,) of ``pose`` about the reference ``(r_c, p_c)``."""
    out = np.empty(6)
    out[:3] = pose[:3, 3] - p_c
    out[3:] = log_rot(pose[:3, :3] @ r_c.T)
    return out


def pose_of(x: Vector, r_c: Matrix, p_c: Vector, out: Matrix | None = None) -> Matrix:
    """The pose (4, 4) of drive coordinates ``x`` about ``(r_c, p_c)``."""
    if out is None:
        out = np.eye(4)
    out[:3, :3] = exp_rot(x[3:]) @ r_c
    out[:3, 3] = p_c + x[:3]
    return out


def poses_of(xs: Matrix, r_c: Matrix, p_c: Vector) -> Matrix:
    """The poses (m, 4, 4) of the drive coordinates ``xs`` (m, 6) about ``(r_c, p_c)``,
    all at once (Rodrigues on arrays, each product shared by the entries that use it,
    as :func:`exp_rot` forms them one by one; :func:`pose_of` one by one)."""
    xs = np.asarray(xs, dtype=float)
    m = xs.shape[0]
    a, b, c = xs[:, 3], xs[:, 4], xs[:, 5]
    aa, bb, cc = a * a, b * b, c * c
    th2 = aa + bb + cc
    tiny = th2 < 1e-24
    th = np.sqrt(np.where(tiny, 1.0, th2))
    s = np.where(tiny, 1.0, np.sin(th) / th)
    k = np.where(tiny, 0.5, (1.0 - np.cos(th)) / np.where(tiny, 1.0, th2))
    ka, kb = k * a, k * b
    kab, kac, kbc = ka * b, ka * c, kb * c
    sa, sb, sc = s * a, s * b, s * c
    e = np.empty((m, 3, 3))
    np.subtract(1.0, k * (bb + cc), out=e[:, 0, 0])
    np.add(-sc, kab, out=e[:, 0, 1])
    np.add(sb, kac, out=e[:, 0, 2])
    np.add(sc, kab, out=e[:, 1, 0])
    np.subtract(1.0, k * (aa + cc), out=e[:, 1, 1])
    np.add(-sa, kbc, out=e[:, 1, 2])
    np.add(-sb, kac, out=e[:, 2, 0])
    np.add(sa, kbc, out=e[:, 2, 1])
    np.subtract(1.0, k * (aa + bb), out=e[:, 2, 2])
    out = np.zeros((m, 4, 4))
    out[:, :3, :3] = (e.reshape(3 * m, 3) @ r_c).reshape(m, 3, 3)  # one product for all
    out[:, :3, 3] = p_c + xs[:, :3]
    out[:, 3, 3] = 1.0
    return out


def inv(t: Matrix) -> Matrix:
    """The inverse of a rigid transform."""
    out = np.eye(4)
    out[:3, :3] = t[:3, :3].T
    out[:3, 3] = -t[:3, :3].T @ t[:3, 3]
    return out


def angle_between(a: Matrix, b: Matrix) -> float:
    """The angle (rad) of the rotation from ``a``'s orientation to ``b``'s."""
    r = a[:3, :3].T @ b[:3, :3]
    return math.acos(max(-1.0, min(1.0, (float(np.trace(r)) - 1.0) / 2.0)))
