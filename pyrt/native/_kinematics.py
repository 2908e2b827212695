"""Serial-chain kinematics and dynamics (csrc/kinematics.c).

:class:`ChainKernels` binds one chain's constant description (copied into
arrays it owns) and its workspace once; its methods are the per-call path:
they take float64 arrays of the right shape (anything else is converted
once, or refused with :class:`NativeInputError`), write into output arrays
that the caller may supply (``out=``, reused: no allocation), and turn every
C status code into an exception.  One ``ChainKernels`` serves one call at a
time (its workspace is shared by all its methods).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from pyrt.native._arrays import F64, as_f64
from pyrt.native._errors import NativeInputError, Status, converged, raise_for_status
from pyrt.native._lib import ffi, lib

__all__ = ["IK_DEFAULT_MAX_ITER", "IK_DEFAULT_NULL_TOL", "IK_DEFAULT_TOL", "MAX_JOINTS",
           "ChainKernels", "IKOutcome"]

MAX_JOINTS: int = lib.PYRT_KIN_MAX_JOINTS
REVOLUTE: int = lib.PYRT_KIN_REVOLUTE
PRISMATIC: int = lib.PYRT_KIN_PRISMATIC
IK_DEFAULT_TOL: float = lib.PYRT_KIN_DEFAULT_TOL
IK_DEFAULT_NULL_TOL: float = lib.PYRT_KIN_DEFAULT_NULL_TOL
IK_DEFAULT_MAX_ITER: int = lib.PYRT_KIN_DEFAULT_MAX_ITER
AXIS_TOL: float = lib.PYRT_KIN_AXIS_TOL

_NDARRAY = np.ndarray
_KINDS = {"revolute": REVOLUTE, "prismatic": PRISMATIC}
_CHECK_WHY = {
    Status.EINVAL: "refused (kinds, unit axes, ordered limits, masses >= 0)",
    Status.ENONFINITE: "NaN or infinity in an origin, axis, offset, base, tool or inertial",
}


class IKOutcome(NamedTuple):
    """What the numerical inverse did: converged, iterations, pose error norm."""

    ok: bool
    iterations: int
    residual: float


def _buf(arr: np.ndarray) -> Any:
    return ffi.cast("double *", ffi.from_buffer(arr))


class ChainKernels:
    """One chain bound to the C kernels, with its workspace.

    Arguments: ``kinds`` (n names, "revolute" or "prismatic"), ``origins``
    (n, 4, 4), ``axes`` (n, 3), ``offsets``, ``lower``, ``upper``,
    ``masses`` (n,), ``coms`` (n, 3), ``inertias`` (n, 3, 3), ``base`` and
    ``tool`` (4, 4); see csrc/kinematics.h for their meaning.
    """

    def __init__(self, kinds: list[str], origins: object, axes: object, offsets: object,
                 base: object, tool: object, lower: object, upper: object, masses: object,
                 coms: object, inertias: object):
        n = len(kinds)
        if not 1 <= n <= MAX_JOINTS:
            raise NativeInputError(f"a chain has 1 to {MAX_JOINTS} movable joints, got {n}")
        try:
            codes = [_KINDS[k] for k in kinds]
        except KeyError as exc:
            raise NativeInputError(
                f"joint kind {exc.args[0]!r}: expected 'revolute' or 'prismatic'") from None
        self.n = n
        self._kinds = np.array(codes, dtype=np.int32)
        self._origins = as_f64("origins", origins, (n, 4, 4)).copy()
        self._axes = as_f64("axes", axes, (n, 3)).copy()
        self._offsets = as_f64("offsets", offsets, (n,)).copy()
        self._base = as_f64("base", base, (4, 4)).copy()
        self._tool = as_f64("tool", tool, (4, 4)).copy()
        self._lower = as_f64("lower", lower, (n,)).copy()
        self._upper = as_f64("upper", upper, (n,)).copy()
        self._masses = as_f64("masses", masses, (n,)).copy()
        self._coms = as_f64("coms", coms, (n, 3)).copy()
        self._inertias = as_f64("inertias", inertias, (n, 3, 3)).copy()
        self._ws = np.zeros(lib.pyrt_kin_workspace_size(n), dtype=F64)
        arrays = (self._origins, self._axes, self._offsets, self._base, self._tool,
                  self._lower, self._upper, self._masses, self._coms, self._inertias, self._ws)
        self._keep = [ffi.from_buffer(a) for a in (self._kinds, *arrays)]
        c = ffi.new("pyrt_kin_chain *")
        c.n = n
        c.kinds = ffi.cast("int32_t *", self._keep[0])
        (c.origins, c.axes, c.offsets, c.base, c.tool, c.lower, c.upper, c.masses, c.coms,
         c.inertias) = (ffi.cast("double *", b) for b in self._keep[1:-1])
        self._c = c
        self._w = ffi.cast("double *", self._keep[-1])
        rc = lib.pyrt_kin_check(c)
        if rc:
            raise_for_status(rc, f"chain of {n} joints", lambda exc: _CHECK_WHY.get(Status(rc)))
        self._opts = ffi.new("pyrt_kin_ik_opts *")
        self._gravity = np.zeros(3, F64)
        self._gbuf = _buf(self._gravity)
        self._g_last: object = None
        self._qshape = (n,)
        self._fk = lib.pyrt_kin_fk
        self._jac = lib.pyrt_kin_jacobian
        self._rnea = lib.pyrt_kin_rnea
        self._fd = lib.pyrt_kin_forward_dynamics
        for a in arrays[:-1]:
            a.flags.writeable = False

    # ------------------------------------------------------------ arguments

    def _vec(self, name: str, value: object) -> np.ndarray:
        """*value* as a float64 (n,) array: as it is when it already is one."""
        if (value.__class__ is _NDARRAY and value.dtype is F64  # type: ignore[attr-defined]
                and value.shape == self._qshape  # type: ignore[attr-defined]
                and value.flags.c_contiguous):  # type: ignore[attr-defined]
            return value  # type: ignore[return-value]
        return as_f64(name, value, self._qshape)

    def _out(self, name: str, out: np.ndarray | None, shape: tuple[int, ...]) -> np.ndarray:
        if out is None:
            return np.empty(shape, F64)
        if (out.__class__ is not _NDARRAY or out.dtype is not F64 or out.shape != shape
                or not out.flags.c_contiguous or not out.flags.writeable):
            raise NativeInputError(
                f"{name}: expected a writeable C-contiguous float64 array of shape {shape}")
        return out

    def _set_gravity(self, gravity: object) -> Any:
        if gravity is self._g_last:
            return self._gbuf
        if gravity is None:
            return ffi.NULL
        self._gravity[...] = as_f64("gravity", gravity, (3,))
        if gravity.__class__ is tuple:  # immutable: the same object, the same vector
            self._g_last = gravity
        return self._gbuf

    # ------------------------------------------------------------ kernels

    def fk(self, q: object, out: np.ndarray | None = None) -> np.ndarray:
        """Tool pose (4, 4) in the world at joint values *q*."""
        qa = self._vec("q", q)
        pose = self._out("out", out, (4, 4))
        rc = self._fk(self._c, self._w, ffi.from_buffer("double[]", qa),
                      ffi.from_buffer("double[]", pose))
        if rc:
            raise_for_status(rc, "fk")
        return pose

    def frames(self, q: object, out: np.ndarray | None = None) -> np.ndarray:
        """Base and each joint's child frame in the world, (n + 1, 4, 4)."""
        qa = self._vec("q", q)
        fr = self._out("out", out, (self.n + 1, 4, 4))
        raise_for_status(lib.pyrt_kin_frames(self._c, self._w, _buf(qa), _buf(fr)), "frames")
        return fr

    def jacobian(self, q: object, out: np.ndarray | None = None,
                 pose: np.ndarray | None = None) -> np.ndarray:
        """Geometric Jacobian (6, n), world frame, rows (v; w) at the tool;
        *pose* (4, 4), when given, receives the tool pose."""
        qa = self._vec("q", q)
        jac = self._out("out", out, (6, self.n))
        pp = ffi.NULL if pose is None else ffi.from_buffer(
            "double[]", self._out("pose", pose, (4, 4)))
        rc = self._jac(self._c, self._w, ffi.from_buffer("double[]", qa),
                       ffi.from_buffer("double[]", jac), pp)
        if rc:
            raise_for_status(rc, "jacobian")
        return jac

    def ik(self, target: object, seed: object, out: np.ndarray | None = None, *,
           tol: float = IK_DEFAULT_TOL, null_tol: float = IK_DEFAULT_NULL_TOL,
           max_iter: int = IK_DEFAULT_MAX_ITER) -> tuple[np.ndarray, IKOutcome]:
        """Joint values whose tool pose is *target*, from *seed*; see
        ``pyrt_kin_ik``.  Non-convergence is not an error: the outcome says."""
        t = target
        if not (t.__class__ is _NDARRAY and t.dtype is F64  # type: ignore[attr-defined]
                and t.shape == (4, 4) and t.flags.c_contiguous):  # type: ignore[attr-defined]
            t = as_f64("target", target, (4, 4))
        s = self._vec("seed", seed)
        q = self._out("out", out, self._qshape)
        o = self._opts
        if tol != o.tol or null_tol != o.null_tol or max_iter != o.max_iter:
            self._ik_options(tol, null_tol, max_iter)
        rc = lib.pyrt_kin_ik(self._c, self._w, ffi.from_buffer("double[]", t),
                             ffi.from_buffer("double[]", s), ffi.from_buffer("double[]", q), o)
        ok = True if not rc else converged(rc, "ik")
        return q, IKOutcome(ok, o.iterations, o.residual)

    def _ik_options(self, tol: float, null_tol: float, max_iter: int) -> None:
        for name, v in (("tol", tol), ("null_tol", null_tol)):
            if not (isinstance(v, (int, float, np.floating)) and np.isfinite(v) and v > 0):
                raise NativeInputError(f"{name}: expected a finite number > 0, got {v!r}")
        if (not isinstance(max_iter, (int, np.integer)) or isinstance(max_iter, bool)
                or not 1 <= max_iter <= 2**31 - 1):
            raise NativeInputError(f"max_iter: expected an integer >= 1, got {max_iter!r}")
        self._opts.tol = float(tol)
        self._opts.null_tol = float(null_tol)
        self._opts.max_iter = int(max_iter)

    def rnea(self, q: object, qd: object | None, qdd: object | None, gravity: object | None,
             out: np.ndarray | None = None) -> np.ndarray:
        """Joint forces (n,) for the motion (q, qd, qdd); None = zero."""
        qa = self._vec("q", q)
        qdp = ffi.NULL if qd is None else ffi.from_buffer("double[]", self._vec("qd", qd))
        qddp = ffi.NULL if qdd is None else ffi.from_buffer("double[]", self._vec("qdd", qdd))
        tau = self._out("out", out, self._qshape)
        rc = self._rnea(self._c, self._w, ffi.from_buffer("double[]", qa), qdp, qddp,
                        self._set_gravity(gravity), ffi.from_buffer("double[]", tau))
        if rc:
            raise_for_status(rc, "rnea")
        return tau

    def mass_matrix(self, q: object, out: np.ndarray | None = None) -> np.ndarray:
        """Joint-space mass matrix (n, n)."""
        qa = self._vec("q", q)
        m = self._out("out", out, (self.n, self.n))
        raise_for_status(lib.pyrt_kin_mass_matrix(self._c, self._w, _buf(qa), _buf(m)),
                         "mass_matrix")
        return m

    def forward_dynamics(self, q: object, qd: object | None, tau: object,
                         gravity: object | None, out: np.ndarray | None = None) -> np.ndarray:
        """Joint accelerations (n,) for joint forces *tau*."""
        qa = self._vec("q", q)
        qdp = ffi.NULL if qd is None else ffi.from_buffer("double[]", self._vec("qd", qd))
        ta = self._vec("tau", tau)
        qdd = self._out("out", out, self._qshape)
        rc = self._fd(self._c, self._w, ffi.from_buffer("double[]", qa), qdp,
                      ffi.from_buffer("double[]", ta), self._set_gravity(gravity),
                      ffi.from_buffer("double[]", qdd))
        if rc:
            raise_for_status(rc, "forward_dynamics",
                             lambda exc: "the mass matrix is not positive definite (a joint "
                             "that moves no mass or inertia)" if rc == Status.ESINGULAR
                             else None)
        return qdd
