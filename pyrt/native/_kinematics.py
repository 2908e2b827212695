"""Serial-chain kinematics and dynamics (csrc/kinematics.c).

:class:`ChainKernels` binds one chain's constant description (copied into
arrays it owns) and its workspace once; its methods are the per-call path:
they take float64 arrays of the right shape (anything else is converted
once, or refused with :class:`NativeInputError`), write into output arrays
that the caller may supply (``out=``, reused: no allocation), and turn every
C status code into an exception.  One ``ChainKernels`` serves one call at a
time per thread: its workspace, argument structs and result buffers are
shared by all its methods, so a call from a thread other than the one that
built it (a planner in the console's thread while the loop's thread runs
the trajectory) goes to a copy of the same description with a workspace of
that thread's own, made on its first call there.  The building thread's
calls pay one thread-identity check.
"""

from __future__ import annotations

import threading
from typing import Any, NamedTuple

import numpy as np

from pyrt.errors import NativeError
from pyrt.native._arrays import F64, as_f64
from pyrt.native._errors import (
    NativeInputError,
    NonFiniteError,
    SingularError,
    converged,
    raise_for_status,
)
from pyrt.native._lib import ffi, lib

__all__ = ["GRAVITY", "IK_DEFAULT_MAX_ITER", "IK_DEFAULT_NULL_TOL", "IK_DEFAULT_TOL", "MAX_JOINTS",
           "ChainKernels", "IKOutcome"]

MAX_JOINTS: int = lib.PYRT_KIN_MAX_JOINTS
REVOLUTE: int = lib.PYRT_KIN_REVOLUTE
PRISMATIC: int = lib.PYRT_KIN_PRISMATIC
IK_DEFAULT_TOL: float = lib.PYRT_KIN_DEFAULT_TOL
IK_DEFAULT_NULL_TOL: float = lib.PYRT_KIN_DEFAULT_NULL_TOL
IK_DEFAULT_MAX_ITER: int = lib.PYRT_KIN_DEFAULT_MAX_ITER
AXIS_TOL: float = lib.PYRT_KIN_AXIS_TOL

_NDARRAY = np.ndarray
_UNBOUND = object()  # an argument slot's array before the first call
#: Gravity in the world frame by default (m/s^2): z up.
GRAVITY = (0.0, 0.0, -9.81)
_KINDS = {"revolute": REVOLUTE, "prismatic": PRISMATIC}
_get_ident = threading.get_ident
#: Copies kept for other threads at most (a thread's identity can be reused
#: once it has ended: past this many the copies are forgotten and made again).
_MAX_THREAD_COPIES = 16


def _check_why(exc: NativeError) -> str:
    if isinstance(exc, NonFiniteError):
        return "NaN or infinity in an origin, axis, offset, base, tool or inertial"
    return "refused (kinds, unit axes, ordered limits, masses >= 0)"


def _fd_why(exc: NativeError) -> str | None:
    if isinstance(exc, SingularError):
        return "the mass matrix is not positive definite (a joint that moves no mass or inertia)"
    return None


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
        self._args = (list(kinds), origins, axes, offsets, base, tool, lower, upper, masses,
                      coms, inertias)
        self._owner = _get_ident()
        self._copies: dict[int, ChainKernels] = {}
        self._copies_lock = threading.Lock()
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
        size = ffi.new("int32_t *")
        raise_for_status(lib.pyrt_kin_workspace_size(n, size), "workspace_size")
        self._ws = np.zeros(size[0], dtype=F64)
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
        raise_for_status(lib.pyrt_kin_check(c), f"chain of {n} joints", _check_why)
        self._opts = ffi.new("pyrt_kin_ik_opts *")
        self._gravity = np.zeros(3, F64)
        self._gbuf = _buf(self._gravity)
        self._g_last: object = None
        self._qshape = (n,)
        # argument slots (one shape each): q, qd, qdd or tau, target, seed;
        # then the out= of fk, jacobian, ik, rnea, forward_dynamics
        self._objs: list[object] = [_UNBOUND] * 10
        self._cds: list[Any] = [None] * 10
        # results computed here and copied out when the caller gives no out=
        self._pose = np.empty((4, 4), F64)
        self._jac_buf = np.empty((6, n), F64)
        self._vec_buf = np.empty(n, F64)
        self._pose_p = _buf(self._pose)
        # fk and jacobian through pyrt_kin_call: one argument struct each for
        # results copied out and for the caller's out=, filled when the
        # arrays change (_bind), so a call passes one pointer
        self._call = lib.pyrt_kin_call
        self._held: dict[tuple[int, str], Any] = {}
        self._fk_new = self._call_args(lib.PYRT_KIN_OP_FK, self._pose_p)
        self._fk_out = self._call_args(lib.PYRT_KIN_OP_FK, ffi.NULL)
        self._jac_new = self._call_args(lib.PYRT_KIN_OP_JACOBIAN, ffi.NULL)
        self._jac_out = self._call_args(lib.PYRT_KIN_OP_JACOBIAN, ffi.NULL)
        self._fk_new_q: object = _UNBOUND
        self._fk_out_q: object = _UNBOUND
        self._fk_out_o: object = _UNBOUND
        self._jac_new_q: object = _UNBOUND
        self._jac_out_q: object = _UNBOUND
        self._jac_out_o: object = _UNBOUND
        self._jac_p = _buf(self._jac_buf)
        self._jac_new.out = self._jac_p
        self._vec_p = _buf(self._vec_buf)
        self._rnea = lib.pyrt_kin_rnea
        self._fd = lib.pyrt_kin_forward_dynamics
        for a in arrays[:-1]:
            a.flags.writeable = False

    # ------------------------------------------------------------ threads

    def _elsewhere(self) -> ChainKernels:
        """The copy of this chain's kernels that the calling thread (not the
        building one) uses: the same description, a workspace of its own."""
        ident = _get_ident()
        mine = self._copies.get(ident)
        if mine is None:
            with self._copies_lock:
                mine = self._copies.get(ident)
                if mine is None:
                    if len(self._copies) >= _MAX_THREAD_COPIES:
                        self._copies.clear()
                    mine = ChainKernels(*self._args)
                    mine._owner = ident
                    self._copies[ident] = mine
        return mine

    # ------------------------------------------------------------ arguments

    def _call_args(self, op: int, out: Any) -> Any:
        a = ffi.new("pyrt_kin_call_args *")
        a.op = op
        a.chain = self._c
        a.ws = self._w
        a.out = out
        return a

    def _bind(self, a: Any, field: str, name: str, value: object, shape: tuple[int, ...],
              out: bool = False) -> object:
        """Point *a*.*field* at *value*'s data; return *value* when it is the
        caller's own float64 array (bound: the next call with it skips
        this), else a converted copy is pointed at and nothing is bound."""
        bound: object = value
        if (value.__class__ is _NDARRAY and value.dtype is F64  # type: ignore[attr-defined]
                and value.shape == shape  # type: ignore[attr-defined]
                and value.flags.c_contiguous  # type: ignore[attr-defined]
                and (not out or value.flags.writeable)):  # type: ignore[attr-defined]
            cd = ffi.from_buffer("double[]", value)
        elif out:
            raise NativeInputError(
                f"{name}: expected a writeable C-contiguous float64 array of shape {shape}")
        else:
            cd = ffi.from_buffer("double[]", as_f64(name, value, shape))
            bound = _UNBOUND
        setattr(a, field, cd)
        self._held[(id(a), field)] = cd  # the struct's pointer stays valid
        return bound

    def _ptr(self, slot: int, name: str, value: object, shape: tuple[int, ...]) -> Any:
        """A C pointer to *value*'s float64 data of *shape*.

        The caller's own array is bound once: while the same array object
        comes back in this argument's *slot* (a preallocated buffer, as a
        control loop passes), its pointer is reused without a check (the
        binding keeps the array from being resized).  Anything else is
        checked and, when need be, converted (a list, another dtype).
        """
        if value is self._objs[slot]:
            return self._cds[slot]
        if (value.__class__ is _NDARRAY and value.dtype is F64  # type: ignore[attr-defined]
                and value.shape == shape  # type: ignore[attr-defined]
                and value.flags.c_contiguous):  # type: ignore[attr-defined]
            cd = ffi.from_buffer("double[]", value)
            self._objs[slot] = value
            self._cds[slot] = cd
            return cd
        return ffi.from_buffer("double[]", as_f64(name, value, shape))

    def _out_ptr(self, slot: int, name: str, out: np.ndarray, shape: tuple[int, ...]) -> Any:
        if out is self._objs[slot]:
            return self._cds[slot]
        if (out.__class__ is not _NDARRAY or out.dtype is not F64 or out.shape != shape
                or not out.flags.c_contiguous or not out.flags.writeable):
            raise NativeInputError(
                f"{name}: expected a writeable C-contiguous float64 array of shape {shape}")
        cd = ffi.from_buffer("double[]", out)
        self._objs[slot] = out
        self._cds[slot] = cd
        return cd

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
        if _get_ident() != self._owner:
            return self._elsewhere().fk(q, out)
        if out is None:
            a = self._fk_new
            if q is not self._fk_new_q:
                self._fk_new_q = self._bind(a, "q", "q", q, self._qshape)
            rc = self._call(a)
            raise_for_status(rc, "fk")
            return self._pose.copy()
        a = self._fk_out
        if q is not self._fk_out_q:
            self._fk_out_q = self._bind(a, "q", "q", q, self._qshape)
        if out is not self._fk_out_o:
            self._fk_out_o = self._bind(a, "out", "out", out, (4, 4), out=True)
        rc = self._call(a)
        raise_for_status(rc, "fk")
        return out

    def frames(self, q: object, out: np.ndarray | None = None) -> np.ndarray:
        """Base and each joint's child frame in the world, (n + 1, 4, 4)."""
        if _get_ident() != self._owner:
            return self._elsewhere().frames(q, out)
        fr = self._out("out", out, (self.n + 1, 4, 4))
        raise_for_status(lib.pyrt_kin_frames(self._c, self._w, self._ptr(0, "q", q, self._qshape),
                                             _buf(fr)), "frames")
        return fr

    def jacobian(self, q: object, out: np.ndarray | None = None) -> np.ndarray:
        """Geometric Jacobian (6, n), world frame, rows (v; w) at the tool."""
        if _get_ident() != self._owner:
            return self._elsewhere().jacobian(q, out)
        if out is None:
            a = self._jac_new
            if q is not self._jac_new_q:
                self._jac_new_q = self._bind(a, "q", "q", q, self._qshape)
            rc = self._call(a)
            raise_for_status(rc, "jacobian")
            return self._jac_buf.copy()
        a = self._jac_out
        if q is not self._jac_out_q:
            self._jac_out_q = self._bind(a, "q", "q", q, self._qshape)
        if out is not self._jac_out_o:
            self._jac_out_o = self._bind(a, "out", "out", out, (6, self.n), out=True)
        rc = self._call(a)
        raise_for_status(rc, "jacobian")
        return out

    def ik(self, target: object, seed: object, out: np.ndarray | None = None, *,
           tol: float = IK_DEFAULT_TOL, null_tol: float = IK_DEFAULT_NULL_TOL,
           max_iter: int = IK_DEFAULT_MAX_ITER) -> tuple[np.ndarray, IKOutcome]:
        """Joint values whose tool pose is *target*, from *seed*; see
        ``pyrt_kin_ik``.  Non-convergence is not an error: the outcome says."""
        if _get_ident() != self._owner:
            return self._elsewhere().ik(target, seed, out, tol=tol, null_tol=null_tol,
                                        max_iter=max_iter)
        tp = self._ptr(3, "target", target, (4, 4))
        sp = self._ptr(4, "seed", seed, self._qshape)
        q = np.empty(self._qshape, F64) if out is None else out
        qp = self._out_ptr(7, "out", q, self._qshape) if out is not None else _buf(q)
        o = self._opts
        if tol != o.tol or null_tol != o.null_tol or max_iter != o.max_iter:
            self._ik_options(tol, null_tol, max_iter)
        rc = lib.pyrt_kin_ik(self._c, self._w, tp, sp, qp, o)
        ok = converged(rc, "ik")
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

    def rnea(self, q: object, qd: object | None, qdd: object | None,
             gravity: object | None = GRAVITY, out: np.ndarray | None = None) -> np.ndarray:
        """Joint forces (n,) for the motion (q, qd, qdd); None = zero."""
        if _get_ident() != self._owner:
            return self._elsewhere().rnea(q, qd, qdd, gravity, out)
        shape = self._qshape
        objs, cds = self._objs, self._cds
        qp = cds[0] if q is objs[0] else self._ptr(0, "q", q, shape)
        qdp = (cds[1] if qd is objs[1] else ffi.NULL if qd is None
               else self._ptr(1, "qd", qd, shape))
        qddp = (cds[2] if qdd is objs[2] else ffi.NULL if qdd is None
                else self._ptr(2, "qdd", qdd, shape))
        gp = self._gbuf if gravity is self._g_last else self._set_gravity(gravity)
        if out is None:
            rc = self._rnea(self._c, self._w, qp, qdp, qddp, gp, self._vec_p)
            raise_for_status(rc, "rnea")
            return self._vec_buf.copy()
        op = cds[8] if out is objs[8] else self._out_ptr(8, "out", out, shape)
        rc = self._rnea(self._c, self._w, qp, qdp, qddp, gp, op)
        raise_for_status(rc, "rnea")
        return out

    def gravity_torque(self, q: object, gravity: object | None = GRAVITY,
                       out: np.ndarray | None = None) -> np.ndarray:
        """Joint forces (n,) that hold the chain still at *q*."""
        return self.rnea(q, None, None, gravity, out)

    def mass_matrix(self, q: object, out: np.ndarray | None = None) -> np.ndarray:
        """Joint-space mass matrix (n, n)."""
        if _get_ident() != self._owner:
            return self._elsewhere().mass_matrix(q, out)
        m = self._out("out", out, (self.n, self.n))
        raise_for_status(lib.pyrt_kin_mass_matrix(self._c, self._w,
                                                  self._ptr(0, "q", q, self._qshape), _buf(m)),
                         "mass_matrix")
        return m

    def forward_dynamics(self, q: object, qd: object | None, tau: object,
                         gravity: object | None = GRAVITY, out: np.ndarray | None = None
                         ) -> np.ndarray:
        """Joint accelerations (n,) for joint forces *tau*."""
        if _get_ident() != self._owner:
            return self._elsewhere().forward_dynamics(q, qd, tau, gravity, out)
        shape = self._qshape
        objs, cds = self._objs, self._cds
        qp = cds[0] if q is objs[0] else self._ptr(0, "q", q, shape)
        qdp = (cds[1] if qd is objs[1] else ffi.NULL if qd is None
               else self._ptr(1, "qd", qd, shape))
        tp = cds[2] if tau is objs[2] else self._ptr(2, "tau", tau, shape)
        gp = self._gbuf if gravity is self._g_last else self._set_gravity(gravity)
        if out is None:
            rc = self._fd(self._c, self._w, qp, qdp, tp, gp, self._vec_p)
            result = self._vec_buf
        else:
            op = cds[9] if out is objs[9] else self._out_ptr(9, "out", out, shape)
            rc = self._fd(self._c, self._w, qp, qdp, tp, gp, op)
            result = out
        raise_for_status(rc, "forward_dynamics", _fd_why)
        return result.copy() if out is None else out
