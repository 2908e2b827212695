"""Paul's closed-form inverse of the PUMA 560 (csrc/puma.c)."""

from __future__ import annotations

import threading

import numpy as np
import numpy.typing as npt

from pyrt.native._arrays import F64, as_f64, require_f64
from pyrt.native._errors import NativeInputError, raise_for_status
from pyrt.native._lib import ffi, lib

__all__ = [
    "PUMA_BELOW",
    "PUMA_FLIP",
    "PUMA_INSIDE_OFFSET",
    "PUMA_LEFTY",
    "PUMA_LIMIT",
    "PUMA_NEAREST",
    "PUMA_NO_LIMITS",
    "PUMA_REACHED",
    "PUMA_SINGULAR",
    "PUMA_TOO_FAR",
    "PUMA_TOO_NEAR",
    "PumaKernel",
    "PumaSolver",
]

PUMA_LEFTY: int = lib.PYRT_PUMA_LEFTY
PUMA_BELOW: int = lib.PYRT_PUMA_BELOW
PUMA_FLIP: int = lib.PYRT_PUMA_FLIP
PUMA_NEAREST: int = lib.PYRT_PUMA_NEAREST
PUMA_NO_LIMITS: int = lib.PYRT_PUMA_NO_LIMITS
PUMA_REACHED: int = lib.PYRT_PUMA_REACHED
PUMA_INSIDE_OFFSET: int = lib.PYRT_PUMA_INSIDE_OFFSET
PUMA_TOO_FAR: int = lib.PYRT_PUMA_TOO_FAR
PUMA_TOO_NEAR: int = lib.PYRT_PUMA_TOO_NEAR
PUMA_LIMIT: int = lib.PYRT_PUMA_LIMIT
#: |sin q5| at or below which the wrist is at its singularity.
PUMA_SINGULAR: float = lib.PYRT_PUMA_SINGULAR


class PumaKernel:
    """One arm's description for the C inverse, made once; :meth:`inverse` per call.

    ``lengths`` are (d1, a2, a3, d3, d4) in metres; ``base_inv`` and
    ``tool_inv`` the inverses of the base and tool (4, 4); ``offsets``,
    ``lower`` and ``upper`` (6,) in radians (limits may be infinite).
    """

    def __init__(self, lengths: npt.ArrayLike, base_inv: npt.ArrayLike, tool_inv: npt.ArrayLike,
                 offsets: npt.ArrayLike, lower: npt.ArrayLike, upper: npt.ArrayLike) -> None:
        ln = as_f64("lengths", lengths, (5,))
        arrays = {
            "base_inv": as_f64("base_inv", base_inv, (4, 4)),
            "tool_inv": as_f64("tool_inv", tool_inv, (4, 4)),
            "offsets": as_f64("offsets", offsets, (6,)),
            "lower": as_f64("lower", lower, (6,)),
            "upper": as_f64("upper", upper, (6,)),
        }
        if not np.all(np.isfinite(ln)) or ln[1] <= 0.0:
            raise NativeInputError(
                f"lengths: expected finite (d1, a2, a3, d3, d4), a2 > 0; got {ln}"
            )
        for name in ("base_inv", "tool_inv", "offsets"):
            if not np.all(np.isfinite(arrays[name])):
                raise NativeInputError(f"{name}: has a non-finite entry")
        if np.any(np.isnan(arrays["lower"])) or np.any(arrays["lower"] > arrays["upper"]):
            raise NativeInputError("lower and upper: expected lower <= upper for each joint")
        arm = ffi.new("pyrt_puma *")
        arm.d1, arm.a2, arm.a3, arm.d3, arm.d4 = (float(v) for v in ln)
        for name, arr in arrays.items():
            ffi.memmove(getattr(arm, name), ffi.from_buffer("double[]", arr.ravel()), arr.nbytes)
        self._arm = arm
        #: The result cells of the building thread's calls (another thread's calls
        #: have their own: the C call runs without the interpreter lock).
        self._owner = threading.get_ident()
        self._why = ffi.new("int32_t *")
        self._detail = ffi.new("double[2]")

    def inverse(self, pose: npt.ArrayLike, config: int,
                seed: npt.ArrayLike | None = None) -> tuple[np.ndarray | None, int, float]:
        """(q, why, detail): q (6,) when ``why`` is PUMA_REACHED, else None
        and the deciding number (a distance in m, or the joint's angle)."""
        p = pose if isinstance(pose, np.ndarray) and pose.dtype == F64 \
            and pose.shape == (4, 4) and pose.flags.c_contiguous else as_f64("pose", pose, (4, 4))
        q = np.empty(6)
        if seed is None:
            sp = ffi.NULL
        else:
            s = as_f64("seed", seed, (6,))
            sp = ffi.from_buffer("double[]", s)
        if threading.get_ident() == self._owner:
            why_p, detail_p = self._why, self._detail
        else:  # another thread (a planner beside the loop): its own result cells
            why_p, detail_p = ffi.new("int32_t *"), ffi.new("double[2]")
        rc = lib.pyrt_puma_inverse(self._arm, ffi.from_buffer("double[]", p), int(config), sp,
                                   ffi.from_buffer("double[]", q), why_p, detail_p)
        raise_for_status(rc, "puma inverse")
        why = int(why_p[0])
        if why != lib.PYRT_PUMA_REACHED:
            return None, why, float(detail_p[0])
        return q, why, 0.0

    def inverse_many(self, poses: np.ndarray, config: int, seed: np.ndarray,
                     out: np.ndarray) -> tuple[int, int, float]:
        """The inverses of ``poses`` (m, 4, 4) into the rows of ``out`` (m, 6), each
        seeded at the one before (the first at ``seed`` (6,)), up to the first pose
        not reached: (how many were, why the next was not (PUMA_REACHED when all
        were), its deciding number).  Float64, C-contiguous arrays (refused
        otherwise); one C call per pose, the arrays bound once."""
        m = poses.shape[0] if isinstance(poses, np.ndarray) else -1
        require_f64("poses", poses, (m, 4, 4))
        require_f64("out", out, (m, 6))
        require_f64("seed", seed, (6,))
        if threading.get_ident() == self._owner:
            why_p, detail_p = self._why, self._detail
        else:
            why_p, detail_p = ffi.new("int32_t *"), ffi.new("double[2]")
        if m == 0:
            return 0, lib.PYRT_PUMA_REACHED, 0.0
        pp = ffi.from_buffer("double[]", poses)
        qp = ffi.from_buffer("double[]", out)
        sp = ffi.from_buffer("double[]", seed)
        f, arm, reached = lib.pyrt_puma_inverse, self._arm, lib.PYRT_PUMA_REACHED
        config = int(config)
        for i in range(m):
            q_i = qp + 6 * i
            raise_for_status(f(arm, pp + 16 * i, config, sp, q_i, why_p, detail_p),
                             "puma inverse")
            if why_p[0] != reached:
                return i, int(why_p[0]), float(detail_p[0])
            sp = q_i
        return m, reached, 0.0


class PumaSolver:
    """One caller's prepared inverse (a trajectory tick's): its own ``pose`` (4, 4),
    ``seed`` (6,) and result ``q`` (6,) arrays and result cells, bound once, so a
    call is the C call alone.  Write the pose and the seed in place, call with the
    configuration's bits: PUMA_REACHED (then ``q`` holds the joints) or why not.
    For one thread at a time (its cells are its own)."""

    __slots__ = ("_arm", "_detail", "_f", "_pp", "_qp", "_sp", "_why", "pose", "q", "seed")

    #: What a call returns for a pose reached.
    REACHED: int = lib.PYRT_PUMA_REACHED

    def __init__(self, kernel: PumaKernel) -> None:
        self.pose = np.eye(4)
        self.seed = np.zeros(6)
        self.q = np.zeros(6)
        self._arm = kernel._arm
        self._f = lib.pyrt_puma_inverse
        self._pp = ffi.from_buffer("double[]", self.pose)
        self._sp = ffi.from_buffer("double[]", self.seed)
        self._qp = ffi.from_buffer("double[]", self.q)
        self._why = ffi.new("int32_t *")
        self._detail = ffi.new("double[2]")

    def __call__(self, config: int) -> int:
        raise_for_status(self._f(self._arm, self._pp, config, self._sp, self._qp, self._why,
                                 self._detail), "puma inverse")
        return int(self._why[0])

    @property
    def detail(self) -> float:
        """The deciding number of the last pose not reached."""
        return float(self._detail[0])
