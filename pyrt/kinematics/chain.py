"""A kinematic chain (a joint set): its description and its C-backed algorithms.

A :class:`Chain` is the constant description of a serial arm's movable
joints (fixed joints are folded into the next joint's origin or the tool),
the base and tool transforms, the joint offsets and the limits, plus one
workspace for the C kernels (csrc/kinematics.c) allocated when the chain is
made: the description/buffers split of Pinocchio's Model/Data.  No
algorithm allocates beyond its result, and none does when given ``out=``.

Joint i's child frame is ``F_i = F_{i-1} . origin_i . M_i(q_i + offset_i)``
with ``F_0 = base``, ``M_i`` a rotation about (revolute) or a translation
along (prismatic) the joint's axis; the tool pose is ``F_n . tool``.  Every
pose, Jacobian and gravity vector is in the world frame, the frame that
``base`` is given in.  Metres, radians, kilograms, seconds.

Per call from Python the cost is mostly the call itself: pass float64
arrays, and for a loop pass the same preallocated arrays every time (``q``
written in place, ``out=`` reused).  The chain binds such an array on first
use and reuses its pointer while the same array comes back (it then holds a
reference to it, and numpy will not resize it); lists and other dtypes work
too, converted on every call.

A chain is immutable: :meth:`Chain.replace` makes a new one (calibration
changes origins, base, tool and offsets that way).  Its workspace serves one
call at a time: a chain is not for two threads at once (make one per thread
with ``chain.replace()``).
"""

from __future__ import annotations

import math
import threading
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, replace
from os import PathLike
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike

from pyrt.errors import ConfigError, NativeError
from pyrt.kinematics.joint import Inertial, Joint
from pyrt.native import ChainKernels
from pyrt.native._kinematics import (
    GRAVITY,
    IK_DEFAULT_MAX_ITER,
    IK_DEFAULT_NULL_TOL,
    IK_DEFAULT_TOL,
)

if TYPE_CHECKING:
    from pyrt.kinematics.dh import DHRow

__all__ = ["GRAVITY", "Chain", "ClosedForm", "IKResult"]

@runtime_checkable
class ClosedForm(Protocol):
    """An analytic inverse a chain may carry, with named configurations
    (RCCL's lefty/righty, above/below, flip/noflip for the PUMA)."""

    configurations: tuple[str, ...]

    def solve(self, pose: np.ndarray, config: str) -> np.ndarray | None:
        """Joint values of *config* whose tool pose is *pose*, or None when
        that configuration cannot reach it."""

    def config_of(self, q: np.ndarray) -> str:
        """The configuration joint values *q* are in."""


@dataclass(frozen=True)
class IKResult:
    """The numerical inverse's answer: joint values ``q``, ``ok`` when the
    pose error's norm reached the tolerance (else ``q`` is the best point
    met), the ``iterations`` taken and that ``residual`` (m and rad)."""

    q: np.ndarray
    ok: bool
    iterations: int
    residual: float


def _pose(name: str, value: ArrayLike | None) -> np.ndarray:
    t = np.eye(4) if value is None else np.array(value, dtype=float)
    if t.shape != (4, 4) or not np.isfinite(t).all():
        raise ConfigError(f"{name}: expected a finite 4x4 transform, got shape {t.shape}")
    if not np.array_equal(t[3], (0.0, 0.0, 0.0, 1.0)):
        raise ConfigError(f"{name}: a transform's last row is 0 0 0 1")
    r = t[:3, :3]
    if not np.allclose(r @ r.T, np.eye(3), rtol=0.0, atol=1e-6) or np.linalg.det(r) < 0:
        raise ConfigError(f"{name}: the rotation part is not a rotation")
    t.setflags(write=False)
    return t


def _frozen(arr: np.ndarray) -> np.ndarray:
    arr.setflags(write=False)
    return arr


#: Guards the making of a chain's :meth:`Chain.planning_copy`.
_PLANNING_LOCK = threading.Lock()


class Chain:
    """A serial chain of revolute and prismatic joints; see the module doc.

    Attributes: ``name``, ``joints`` (tuple of :class:`Joint`), ``n``,
    ``base`` and ``tool`` (4, 4), ``offsets``, ``lower`` and ``upper`` (n,),
    ``closed_form`` (a :class:`ClosedForm` or None).  The arrays are
    read-only.
    """

    def __init__(self, name: str, joints: Iterable[Joint], *, base: ArrayLike | None = None,
                 tool: ArrayLike | None = None, offsets: ArrayLike | None = None,
                 closed_form: ClosedForm | None = None):
        self.name = str(name)
        self.joints: tuple[Joint, ...] = tuple(joints)
        n = len(self.joints)
        if n == 0:
            raise ConfigError(f"chain {self.name!r}: no movable joint")
        names = [j.name for j in self.joints]
        dup = sorted({x for x in names if names.count(x) > 1})
        if dup:
            raise ConfigError(f"chain {self.name!r}: joint names used twice: {dup}")
        self.n = n
        self.base = _pose("base", base)
        self.tool = _pose("tool", tool)
        offs = np.zeros(n) if offsets is None else np.array(offsets, dtype=float)
        if offs.shape != (n,) or not np.isfinite(offs).all():
            raise ConfigError(f"offsets: expected {n} finite numbers, got shape {offs.shape}")
        self.offsets = _frozen(offs)
        self.lower = _frozen(np.array([j.lower for j in self.joints]))
        self.upper = _frozen(np.array([j.upper for j in self.joints]))
        self.closed_form = closed_form
        try:
            self._k = ChainKernels(
                [j.kind for j in self.joints],
                np.array([j.origin for j in self.joints]),
                np.array([j.axis for j in self.joints]),
                self.offsets, self.base, self.tool, self.lower, self.upper,
                np.array([j.inertial.mass for j in self.joints]),
                np.array([j.inertial.com for j in self.joints]),
                np.array([j.inertial.inertia for j in self.joints]),
            )
        except NativeError as exc:
            raise ConfigError(f"chain {self.name!r}: {exc}") from None
        self._planning: tuple[Chain, threading.Lock] | None = None
        # The per-call path goes straight to the kernels (same signatures as
        # the methods below, which document them): one Python call less.
        k = self._k
        self.fk = k.fk  # type: ignore[method-assign]
        self.jacobian = k.jacobian  # type: ignore[method-assign]
        self.rnea = k.rnea  # type: ignore[method-assign]
        self.gravity_torque = k.gravity_torque  # type: ignore[method-assign]
        self.aba = k.forward_dynamics  # type: ignore[method-assign]

    # ------------------------------------------------------------ constructors

    @classmethod
    def from_urdf(cls, source: str | PathLike[str], base_link: str | None = None,
                  tip_link: str | None = None) -> Chain:
        """The chain from *base_link* (default: the root) to *tip_link*
        (default: the one leaf) of a URDF, given as its text or a path;
        :func:`pyrt.kinematics.urdf.read_urdf` says what is read."""
        from pyrt.kinematics.urdf import read_urdf

        d = read_urdf(source, base_link=base_link, tip_link=tip_link)
        return cls(d.name, d.joints, tool=d.tool)

    @classmethod
    def from_dh(cls, rows: Sequence[DHRow], modified: bool = False, *, name: str = "dh",
                base: ArrayLike | None = None, tool: ArrayLike | None = None) -> Chain:
        """The chain of a Denavit-Hartenberg table (standard, or Craig's
        modified with ``modified=True``); see :mod:`pyrt.kinematics.dh`."""
        from pyrt.kinematics.dh import dh_chain

        joints, offsets, last = dh_chain(rows, modified=modified)
        t = last if tool is None else last @ _pose("tool", tool)
        return cls(name, joints, base=base, tool=t, offsets=offsets)

    def planning_copy(self) -> tuple[Chain, threading.Lock]:
        """A copy of this chain (:meth:`replace` with no change: kernels and
        workspace of its own) for planning beside the loop, which uses this
        one, and the lock its users hold while they plan with it.  Made once
        and kept: every motion queue of this chain plans with the same copy
        (a queue made for each move from rest would otherwise copy the chain
        each time); made again if the chain's closed form was changed."""
        with _PLANNING_LOCK:
            kept = self._planning
            if kept is None or kept[0].closed_form is not self.closed_form:
                kept = self._planning = (self.replace(), threading.Lock())
            return kept

    def replace(self, **changes: Any) -> Chain:
        """A new chain with some of: ``name``, ``joints``, ``origins`` (n
        transforms, one per joint), ``base``, ``tool``, ``offsets``,
        ``closed_form``.  A closed form is kept only while it describes the
        new geometry: one that can be made again for it (``for_chain``) is,
        any other is dropped (the numerical inverse answers)."""
        allowed = {"name", "joints", "origins", "base", "tool", "offsets", "closed_form"}
        bad = sorted(set(changes) - allowed)
        if bad:
            raise TypeError(f"replace: unknown field(s) {bad}; expected some of {sorted(allowed)}")
        joints = tuple(changes.get("joints", self.joints))
        if "origins" in changes:
            origins = list(changes["origins"])
            if len(origins) != len(joints):
                raise ConfigError(f"origins: expected {len(joints)} transforms, "
                                  f"got {len(origins)}")
            try:
                joints = tuple(replace(j, origin=o) for j, o in zip(joints, origins, strict=True))
            except ValueError as exc:
                raise ConfigError(f"origins: {exc}") from None
        offsets = changes.get("offsets", self.offsets if len(joints) == self.n else None)
        chain = Chain(changes.get("name", self.name), joints,
                      base=changes.get("base", self.base), tool=changes.get("tool", self.tool),
                      offsets=offsets, closed_form=changes.get("closed_form"))
        if "closed_form" in changes or self.closed_form is None:
            return chain
        if not set(changes) & {"joints", "origins", "base", "tool", "offsets"}:
            chain.closed_form = self.closed_form
            return chain
        # The geometry changed: a closed form made for the old one would give the
        # old arm's answers.  One that can be made again for the new geometry
        # (``for_chain``, which checks itself against the chain) is; any other
        # is dropped, and the chain's numerical inverse answers instead.
        remake = getattr(type(self.closed_form), "for_chain", None)
        if remake is not None:
            try:
                chain.closed_form = remake(chain)
            except (ValueError, ConfigError):
                chain.closed_form = None
        return chain

    # ------------------------------------------------------------ description

    @property
    def joint_names(self) -> tuple[str, ...]:
        """The joints' names, base to tip."""
        return tuple(j.name for j in self.joints)

    @property
    def inertials(self) -> tuple[Inertial, ...]:
        """Each joint's link inertial, in its child frame."""
        return tuple(j.inertial for j in self.joints)

    def limit_violation(self, q: ArrayLike) -> str | None:
        """Why joint values *q* are outside the limits (the first joint out),
        or None when they are within."""
        qa = np.asarray(q, dtype=float)
        if qa.shape != (self.n,):
            return f"expected {self.n} joint values, got shape {qa.shape}"
        for j, v in zip(self.joints, qa.tolist(), strict=True):  # plain floats: quicker
            if not math.isfinite(v):
                return f"joint {j.name}: {v} is not a number"
            if v < j.lower or v > j.upper:
                return f"joint {j.name}: {v:.6g} is outside [{j.lower:.6g}, {j.upper:.6g}]"
        return None

    def __reduce__(self) -> tuple[Any, ...]:
        """Pickled (and copied) as its description: the copy has a workspace
        of its own."""
        return (_rebuild, (self.name, self.joints, self.base, self.tool, self.offsets,
                           self.closed_form))

    def __repr__(self) -> str:
        kinds = "".join("R" if j.kind == "revolute" else "P" for j in self.joints)
        return f"Chain({self.name!r}, {self.n} joints {kinds})"

    # ------------------------------------------------------------ kinematics

    def fk(self, q: ArrayLike, out: np.ndarray | None = None) -> np.ndarray:
        """Tool pose (4, 4) in the world at joint values *q*."""
        return self._k.fk(q, out)

    def frames(self, q: ArrayLike, out: np.ndarray | None = None) -> np.ndarray:
        """(n + 1, 4, 4): the base, then each joint's child frame, in the world."""
        return self._k.frames(q, out)

    def jacobian(self, q: ArrayLike, out: np.ndarray | None = None) -> np.ndarray:
        """Geometric Jacobian (6, n) in the world: rows (v; w), v the velocity
        of the tool's origin."""
        return self._k.jacobian(q, out)

    def ik(self, pose: ArrayLike, seed: ArrayLike, *, tol: float = IK_DEFAULT_TOL,
           max_iter: int = IK_DEFAULT_MAX_ITER, null_tol: float = IK_DEFAULT_NULL_TOL,
           out: np.ndarray | None = None) -> IKResult:
        """Joint values whose tool pose is *pose*, nearest *seed*.

        Damped least squares (Levenberg-Marquardt) from *seed*, each step
        clamped to the joint limits; stops when the pose error (position,
        and the rotation vector between the poses) has a norm <= *tol*.  A
        redundant chain (more than six joints) also moves along its
        self-motion toward the seed, so the answer minimises joint motion
        (to *null_tol*).  Not converging is an answer with ``ok`` False.
        """
        q, outcome = self._k.ik(pose, seed, out, tol=tol, null_tol=null_tol, max_iter=max_iter)
        return IKResult(q, outcome.ok, outcome.iterations, outcome.residual)

    # ------------------------------------------------------------ dynamics

    def rnea(self, q: ArrayLike, qd: ArrayLike | None, qdd: ArrayLike | None,
             gravity: ArrayLike | None = GRAVITY, out: np.ndarray | None = None) -> np.ndarray:
        """Inverse dynamics (recursive Newton-Euler): the joint forces (n,)
        that give the motion (q, qd, qdd) under *gravity* (world frame; None
        = none; qd or qdd None = zero).  Rigid bodies only: joint damping
        and friction are not in it."""
        return self._k.rnea(q, qd, qdd, gravity, out)

    def gravity_torque(self, q: ArrayLike, gravity: ArrayLike | None = GRAVITY,
                       out: np.ndarray | None = None) -> np.ndarray:
        """The joint forces (n,) that hold the arm still at *q*."""
        return self._k.rnea(q, None, None, gravity, out)

    def mass_matrix(self, q: ArrayLike, out: np.ndarray | None = None) -> np.ndarray:
        """Joint-space mass matrix (n, n), symmetric positive (semi)definite."""
        return self._k.mass_matrix(q, out)

    def aba(self, q: ArrayLike, qd: ArrayLike | None, tau: ArrayLike,
            gravity: ArrayLike | None = GRAVITY, out: np.ndarray | None = None) -> np.ndarray:
        """Forward dynamics: joint accelerations (n,) for joint forces *tau*
        (the mass matrix and a Cholesky solve).  Raises
        :class:`~pyrt.native.SingularError` when a joint moves no inertia."""
        return self._k.forward_dynamics(q, qd, tau, gravity, out)


def _rebuild(name: str, joints: tuple[Joint, ...], base: np.ndarray, tool: np.ndarray,
             offsets: np.ndarray, closed_form: ClosedForm | None) -> Chain:
    return Chain(name, joints, base=base, tool=tool, offsets=offsets, closed_form=closed_form)


def inertia_bound(chain: Chain, armature: np.ndarray) -> np.ndarray:
    """Each joint's largest inertia over a spread of joint values (kg m^2 or kg),
    ``armature`` (the rotors') included: what a servo's gains and an arm's
    acceleration limits are sized for."""
    lo = np.where(np.isfinite(chain.lower), chain.lower, -math.pi)
    hi = np.where(np.isfinite(chain.upper), chain.upper, math.pi)
    rng = np.random.default_rng(0)
    best = np.zeros(chain.n)
    for u in rng.random((64, chain.n)):
        best = np.maximum(best, np.diag(chain.mass_matrix(lo + u * (hi - lo))))
    return np.maximum(best + armature, 1e-4)
