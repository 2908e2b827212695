"""The simulated arm's integration step (csrc/armworld.c): every internal
step of one ``ArmWorld.step(dt)`` in one call.

:class:`ArmKernel` holds the C description, the state and every buffer,
allocated once; its arrays are the C kernel's own memory (numpy views):
:attr:`~ArmKernel.q` and :attr:`~ArmKernel.qd` (the caller may write them,
then :meth:`~ArmKernel.publish`), the truth (:attr:`~ArmKernel.torque`,
:attr:`~ArmKernel.current`, :attr:`~ArmKernel.contact`,
:attr:`~ArmKernel.wrench`) and the board's registers (:attr:`~ArmKernel.dac`
and :attr:`~ArmKernel.enable` in, :attr:`~ArmKernel.count` and
:attr:`~ArmKernel.ft` out).  See ``csrc/armworld.h`` for the physics, the
order of the step and the sensor's noise generator (splitmix64 and
Box-Muller, reproducible in any language).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from pyrt.errors import NativeError
from pyrt.native._arrays import F64, as_f64
from pyrt.native._errors import NativeInputError, NonFiniteError, SingularError, raise_for_status
from pyrt.native._kinematics import ChainKernels
from pyrt.native._lib import ffi, lib

__all__ = ["ARM_ROWS", "OPTIONAL_ROWS", "ArmKernel"]

MAX_JOINTS: int = lib.PYRT_ARM_MAX_JOINTS
NROWS: int = lib.PYRT_ARM_NROWS

#: The per-joint parameter rows, in the order of csrc/armworld.h.
ARM_ROWS: tuple[str, ...] = ("armature", "damping", "friction", "stop_lo", "stop_hi", "stop_k",
                             "stop_c", "nm_per_count", "amps_per_count", "effort", "counts")
#: Rows that may be left out (zero): the brakes' holding torques.
OPTIONAL_ROWS: tuple[str, ...] = ("brake",)
_ROWS = {name: getattr(lib, f"PYRT_ARM_{name.upper()}") for name in ARM_ROWS + OPTIONAL_ROWS}
if sorted(_ROWS.values()) != list(range(NROWS)):  # pragma: no cover - header out of step
    raise ImportError("csrc/armworld.h's parameter rows differ from pyrt.native's")

_U64 = (1 << 64) - 1


def _check_why(exc: Exception) -> str:
    if isinstance(exc, NonFiniteError):
        return ("NaN or infinity in a parameter or the state (only an end stop may be "
                "infinite)")
    return ("a parameter out of its range (a count, torque or step not > 0, a damping, "
            "friction, stiffness or mass < 0, an end stop above the other)")


def _step_why(exc: Exception) -> str | None:
    if isinstance(exc, SingularError):
        return "the step's matrix is not positive definite (a joint that moves no inertia)"
    if isinstance(exc, NonFiniteError):
        return "NaN or infinity in dt, the state or the motion (the integration blew up)"
    return None


class ArmKernel:
    """One simulated arm bound to the C step (see the module text).

    ``chain`` the chain's kernels (inertials with any payload folded into
    the last link); ``params`` a mapping of every :data:`ARM_ROWS` name to
    ``n`` values; the rest as ``pyrt_arm`` in csrc/armworld.h:
    ``max_step`` s, ``friction_velocity``, ``gravity`` (3), ``tip`` (3),
    the table's ``table_stiffness``, ``table_damping``,
    ``table_friction``, the sensor's ``ft_scale``, ``ft_offsets`` and
    ``ft_sigma`` (6 each), the generator's ``seed`` (0 .. 2**64 - 1).
    The arm starts at rest at zero; NativeInputError for anything refused.
    """

    def __init__(self, chain: ChainKernels, params: Mapping[str, ArrayLike], *,
                 max_step: float, friction_velocity: float, gravity: ArrayLike,
                 tip: ArrayLike, table_stiffness: float, table_damping: float,
                 table_friction: float, ft_scale: ArrayLike, ft_offsets: ArrayLike,
                 ft_sigma: ArrayLike, seed: int = 0):
        if not isinstance(chain, ChainKernels):
            raise NativeInputError(f"chain: expected ChainKernels, got {type(chain).__name__}")
        n = chain.n
        self.n = n
        missing = sorted(set(ARM_ROWS) - set(params))
        extra = sorted(set(params) - set(ARM_ROWS) - set(OPTIONAL_ROWS))
        if missing or extra:
            raise NativeInputError(f"params: missing {missing}, unknown {extra}; "
                                   f"expected {' '.join(ARM_ROWS)}")
        self.params = np.zeros((NROWS, n), F64)
        for name, row in _ROWS.items():
            if name in params:
                self.params[row] = as_f64(name, params[name], (n,))
        size = ffi.new("int32_t *")
        raise_for_status(lib.pyrt_arm_work_size(n, size), "arm work size")
        self._work = np.zeros(size[0], F64)
        self.q = np.zeros(n, F64)
        self.qd = np.zeros(n, F64)
        self.torque = np.zeros(n, F64)
        self.current = np.zeros(n, F64)
        self.contact = np.zeros(3, F64)
        self.wrench = np.zeros(6, F64)
        self.dac = np.zeros(n, np.int32)
        self.enable = np.zeros(n, np.int32)
        self.count = np.zeros(n, np.int32)
        self.ft = np.zeros(6, np.int32)
        #: Each joint's brake: released (1) or engaged (0); used once :meth:`use_brakes`.
        self.release = np.ones(n, np.int32)
        doubles = (self.params, self.q, self.qd, self.torque, self.current, self.contact,
                   self.wrench, self._work)
        ints = (self.dac, self.enable, self.count, self.ft, self.release)
        self._keep = [ffi.from_buffer(a) for a in (*doubles, *ints)]
        c = ffi.new("pyrt_arm *")
        c.n = n
        (c.params, c.q, c.qd, c.torque, c.current, c.contact, c.wrench, c.work) = (
            ffi.cast("double *", b) for b in self._keep[:8])
        (c.dac, c.enable, c.count, c.ft, self._release_p) = (
            ffi.cast("int32_t *", b) for b in self._keep[8:])
        c.release = ffi.NULL
        self._c = c
        self._dac_p = c.dac
        self._on_p = c.enable
        self._count_p = c.count
        self._ft_p = c.ft
        self._bind_chain(chain)
        c.max_step = self._number("max_step", max_step)
        c.friction_vs = self._number("friction_velocity", friction_velocity)
        c.gravity = as_f64("gravity", gravity, (3,)).tolist()
        c.tip = as_f64("tip", tip, (3,)).tolist()
        c.table = 0
        c.table_z = 0.0
        c.table_k = self._number("table_stiffness", table_stiffness)
        c.table_c = self._number("table_damping", table_damping)
        c.table_mu = self._number("table_friction", table_friction)
        c.payload = 0.0
        c.ft_scale = as_f64("ft_scale", ft_scale, (6,)).tolist()
        c.ft_offsets = as_f64("ft_offsets", ft_offsets, (6,)).tolist()
        c.ft_sigma = as_f64("ft_sigma", ft_sigma, (6,)).tolist()
        self.seed(seed)
        raise_for_status(lib.pyrt_arm_check(c), f"arm of {n} joints", _check_why)
        self._step = lib.pyrt_arm_step
        self._step_dac = lib.pyrt_arm_step_dac
        self._unpack = ffi.unpack

    @staticmethod
    def _number(name: str, value: object) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float, np.floating)):
            raise NativeInputError(f"{name}: expected a number, got {value!r}")
        return float(value)

    def _bind_chain(self, chain: ChainKernels) -> None:
        if chain.n != self.n:
            raise NativeInputError(f"chain: expected {self.n} joints, got {chain.n}")
        self._chain = chain  # keeps its description and workspace alive
        self._c.chain = chain._c
        self._c.ws = chain._w

    # ------------------------------------------------------------ the world

    def seed(self, seed: int) -> None:
        """Restart the sensor noise's generator from ``seed`` (0 .. 2**64 - 1)."""
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) \
                or not 0 <= int(seed) <= _U64:
            raise NativeInputError(f"seed: expected an integer 0 .. 2**64 - 1, got {seed!r}")
        self._c.rng = int(seed)

    @property
    def rng_state(self) -> int:
        """The noise generator's state (64 bits)."""
        return int(self._c.rng)

    def _checked(self, what: str, undo: Any) -> None:
        try:
            raise_for_status(lib.pyrt_arm_check(self._c), what, _check_why)
        except NativeError:
            undo()
            raise

    def set_table(self, z: float | None) -> None:
        """The table at height ``z`` (m, world), or none; refused and unchanged on NaN."""
        c = self._c
        old = (c.table, c.table_z)

        def undo() -> None:
            c.table, c.table_z = old

        if z is None:
            c.table, c.table_z = 0, 0.0
        else:
            c.table, c.table_z = 1, self._number("table height", z)
        self._checked("table", undo)

    def set_payload(self, mass: float, chain: ChainKernels) -> None:
        """A payload of ``mass`` kg at the tip, ``chain`` the chain with it folded in."""
        c = self._c
        old = (c.payload, self._chain)

        def undo() -> None:
            c.payload = old[0]
            self._bind_chain(old[1])

        c.payload = self._number("payload", mass)
        self._bind_chain(chain)
        self._checked("payload", undo)

    def use_brakes(self, release: np.ndarray | None = None) -> None:
        """Let the brakes act (their holding torques are the ``brake`` row):
        engaged where ``release`` (``n`` int32, this kernel's :attr:`release`
        by default, or another of its own arrays such as :attr:`enable`) is 0."""
        if release is None:
            self._c.release = self._release_p
            return
        if release is self.enable:
            self._c.release = self._c.enable
            return
        if release is self.release:
            self._c.release = self._release_p
            return
        raise NativeInputError("release: one of the kernel's own arrays (release, enable)")

    def set_drive(self, dac: Sequence[int], enable: Sequence[int]) -> None:
        """The board's DAC counts and enables (``n`` integers each), held over the next steps."""
        self.set_dac(dac)
        self.set_enable(enable)

    def set_dac(self, dac: Sequence[int]) -> None:
        """The board's DAC counts (``n`` integers), held over the next steps."""
        self._ints("dac", self._dac_p, dac)

    def set_enable(self, enable: Sequence[int]) -> None:
        """The board's amplifier enables (``n`` integers, 0 off), held over the next steps."""
        self._ints("enable", self._on_p, enable)

    def _ints(self, name: str, ptr: Any, values: Sequence[int]) -> None:
        n = self.n
        if len(values) != n:
            raise NativeInputError(f"{name}: expected {n} integers, got {len(values)}")
        try:
            ptr[0:n] = values
        except (TypeError, OverflowError) as exc:
            raise NativeInputError(f"{name}: expected 32-bit integers ({exc})") from None

    # ------------------------------------------------------------ time

    def step(self, dt: float) -> None:
        """Advance by ``dt`` s (>= 0) in equal internal steps of at most
        ``max_step``, then publish the inputs; refused and unchanged on error."""
        raise_for_status(self._step(self._c, dt), "arm step", _step_why)

    def step_dac(self, dt: float, dac: Sequence[int]) -> None:
        """:meth:`set_dac` then :meth:`step` in one call (the servo rate's step: the
        DACs change every tick while the arm moves); refused and unchanged on
        error, the DACs included."""
        if len(dac) != self.n:
            raise NativeInputError(f"dac: expected {self.n} integers, got {len(dac)}")
        try:
            rc = self._step_dac(self._c, dt, dac)
        except (TypeError, OverflowError) as exc:
            raise NativeInputError(f"dac: expected 32-bit integers ({exc})") from None
        raise_for_status(rc, "arm step", _step_why)

    def publish(self) -> None:
        """Publish the inputs at the present :attr:`q`, :attr:`qd` (one noise draw)."""
        raise_for_status(lib.pyrt_arm_publish(self._c), "arm publish", _step_why)

    def counts(self) -> list[int]:
        """The encoder counters (a list, register order)."""
        return self._unpack(self._count_p, self.n)  # type: ignore[no-any-return]

    def ft_counts(self) -> list[int]:
        """The wrist sensor's counts fx fy fz tx ty tz (a list)."""
        return self._unpack(self._ft_p, 6)  # type: ignore[no-any-return]

    @property
    def max_step(self) -> float:
        """The longest internal step (s)."""
        return float(self._c.max_step)

    def __repr__(self) -> str:
        return f"ArmKernel({self.n} joints, {self._c.max_step * 1e3:g} ms)"

