"""Pure-Python reference of csrc/kinematics.c: forward kinematics, the
geometric Jacobian, inverse dynamics, the mass matrix and forward dynamics.

Written independently of the C kernel, all in the world frame with plain
4x4 products: the C recursion works in each link's own frame, and its mass
matrix comes from unit accelerations through its own Newton-Euler pass;
here the mass matrix is built from the links' Jacobians
(``sum m Jv'Jv + Jw' R I R' Jw``), the Jacobian from the axes' cross
products, and Newton-Euler propagates world-frame vectors.

A chain here is a plain dict: ``kinds`` (n strings), ``origins`` (n, 4, 4),
``axes`` (n, 3), ``offsets`` (n,), ``base`` and ``tool`` (4, 4), and for
dynamics ``masses`` (n,), ``coms`` (n, 3) and ``inertias`` (n, 3, 3), each
in its joint's child frame.
"""

from __future__ import annotations

import numpy as np


def rotation(axis, angle) -> np.ndarray:
    """Rotation matrix of *angle* about unit *axis* (Rodrigues)."""
    x, y, z = axis
    k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * (k @ k)


def motion(kind: str, axis, value: float) -> np.ndarray:
    """The 4x4 motion of one joint at joint value *value* (offset included)."""
    m = np.eye(4)
    if kind == "revolute":
        m[:3, :3] = rotation(axis, value)
    else:
        m[:3, 3] = np.asarray(axis, float) * value
    return m


def link_frames(chain: dict, q) -> list[np.ndarray]:
    """World poses: base, then each joint's child frame (n + 1 of them)."""
    out = [np.asarray(chain["base"], float)]
    t = out[0]
    for i, kind in enumerate(chain["kinds"]):
        t = t @ chain["origins"][i] @ motion(kind, chain["axes"][i], q[i] + chain["offsets"][i])
        out.append(t)
    return out


def fk(chain: dict, q) -> np.ndarray:
    """Tool pose in the world."""
    return link_frames(chain, q)[-1] @ chain["tool"]


def jacobian(chain: dict, q) -> np.ndarray:
    """Geometric Jacobian (6, n) in the world, rows (v; w) at the tool origin."""
    frames = link_frames(chain, q)
    tip = (frames[-1] @ chain["tool"])[:3, 3]
    n = len(chain["kinds"])
    jac = np.zeros((6, n))
    for i, kind in enumerate(chain["kinds"]):
        joint = frames[i] @ chain["origins"][i]
        z = joint[:3, :3] @ chain["axes"][i]
        if kind == "revolute":
            jac[:3, i] = np.cross(z, tip - joint[:3, 3])
            jac[3:, i] = z
        else:
            jac[:3, i] = z
    return jac


def rnea(chain: dict, q, qd, qdd, gravity=(0.0, 0.0, -9.81)) -> np.ndarray:
    """Joint forces for motion (q, qd, qdd) under *gravity* (world frame),
    by Newton-Euler with every vector in the world frame."""
    n = len(chain["kinds"])
    frames = link_frames(chain, q)
    w = np.zeros(3)
    wd = np.zeros(3)
    acc = -np.asarray(gravity, float)  # acceleration of the previous frame's origin
    prev = frames[0][:3, 3]
    forces, moments, origins, axes = [], [], [], []
    for i, kind in enumerate(chain["kinds"]):
        rot = frames[i + 1][:3, :3]
        o = frames[i + 1][:3, 3]
        z = rot @ chain["axes"][i]
        r = o - prev
        if kind == "revolute":
            acc = acc + np.cross(wd, r) + np.cross(w, np.cross(w, r))
            wd = wd + z * qdd[i] + np.cross(w, z * qd[i])
            w = w + z * qd[i]
        else:
            acc = (acc + np.cross(wd, r) + np.cross(w, np.cross(w, r))
                   + 2.0 * np.cross(w, z * qd[i]) + z * qdd[i])
        c = rot @ chain["coms"][i]
        ac = acc + np.cross(wd, c) + np.cross(w, np.cross(w, c))
        inertia = rot @ chain["inertias"][i] @ rot.T
        forces.append(chain["masses"][i] * ac)
        moments.append(inertia @ wd + np.cross(w, inertia @ w) + np.cross(c, forces[-1]))
        origins.append(o)
        axes.append(z)
        prev = o
    tau = np.zeros(n)
    f = np.zeros(3)
    m = np.zeros(3)
    child = None
    for i in reversed(range(n)):
        if child is not None:
            m = m + np.cross(child - origins[i], f)
        f = f + forces[i]
        m = m + moments[i]
        tau[i] = axes[i] @ (m if chain["kinds"][i] == "revolute" else f)
        child = origins[i]
    return tau


def mass_matrix(chain: dict, q) -> np.ndarray:
    """Joint-space inertia from each link's centre-of-mass Jacobian."""
    n = len(chain["kinds"])
    frames = link_frames(chain, q)
    mm = np.zeros((n, n))
    for k in range(n):
        rot = frames[k + 1][:3, :3]
        com = frames[k + 1][:3, 3] + rot @ chain["coms"][k]
        jv = np.zeros((3, n))
        jw = np.zeros((3, n))
        for i in range(k + 1):
            joint = frames[i] @ chain["origins"][i]
            z = joint[:3, :3] @ chain["axes"][i]
            if chain["kinds"][i] == "revolute":
                jv[:, i] = np.cross(z, com - joint[:3, 3])
                jw[:, i] = z
            else:
                jv[:, i] = z
        inertia = rot @ chain["inertias"][k] @ rot.T
        mm += chain["masses"][k] * jv.T @ jv + jw.T @ inertia @ jw
    return mm


def forward_dynamics(chain: dict, q, qd, tau, gravity=(0.0, 0.0, -9.81)) -> np.ndarray:
    """Joint accelerations for forces *tau*: M(q) qdd = tau - h(q, qd)."""
    bias = rnea(chain, q, qd, np.zeros(len(q)), gravity)
    return np.linalg.solve(mass_matrix(chain, q), np.asarray(tau, float) - bias)


def pose_error(target: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """(position error; rotation vector of target . pose') in the world."""
    err = np.zeros(6)
    err[:3] = target[:3, 3] - pose[:3, 3]
    r = target[:3, :3] @ pose[:3, :3].T
    c = np.clip((np.trace(r) - 1.0) / 2.0, -1.0, 1.0)
    angle = np.arccos(c)
    v = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    if angle < 1e-8:
        err[3:] = v / 2.0
    elif np.pi - angle < 1e-4:
        w, vecs = np.linalg.eigh((r + r.T) / 2.0)
        axis = vecs[:, np.argmax(w)]
        if axis @ v < 0:
            axis = -axis
        err[3:] = axis * angle
    else:
        err[3:] = v * angle / (2.0 * np.sin(angle))
    return err


# --------------------------------------------------- chains for the tests


def random_rotation(rng) -> np.ndarray:
    """A uniformly random rotation matrix."""
    q = rng.normal(size=4)
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def random_pose(rng, reach: float = 0.5) -> np.ndarray:
    """A random 4x4 transform, translation within +-reach."""
    t = np.eye(4)
    t[:3, :3] = random_rotation(rng)
    t[:3, 3] = rng.uniform(-reach, reach, 3)
    return t


def random_inertia(rng, mass: float) -> np.ndarray:
    """The inertia of a solid box of *mass*, turned at random."""
    a, b, c = rng.uniform(0.02, 0.4, 3)
    d = mass / 12.0 * np.array([b * b + c * c, a * a + c * c, a * a + b * b])
    r = random_rotation(rng)
    return r @ np.diag(d) @ r.T


def random_chain(rng, n: int, prismatic: float = 0.25) -> dict:
    """A random chain (dict as above, plus names, lower and upper)."""
    kinds = ["prismatic" if rng.random() < prismatic else "revolute" for _ in range(n)]
    axes = rng.normal(size=(n, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    masses = rng.uniform(0.1, 5.0, n)
    return dict(
        names=[f"j{i + 1}" for i in range(n)],
        kinds=kinds,
        origins=np.array([random_pose(rng) for _ in range(n)]),
        axes=axes,
        offsets=rng.uniform(-1.0, 1.0, n),
        base=random_pose(rng),
        tool=random_pose(rng, 0.2),
        lower=np.array([-3.0 if k == "revolute" else -0.5 for k in kinds]),
        upper=np.array([3.0 if k == "revolute" else 0.5 for k in kinds]),
        masses=masses,
        coms=rng.uniform(-0.2, 0.2, (n, 3)),
        inertias=np.array([random_inertia(rng, m) for m in masses]),
    )
