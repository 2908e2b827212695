"""The on-board servo of a hardware (a) board (csrc/drive.c): setpoints at the
trajectory rate in, interpolation and the servo at the board's own rate.

:class:`DriveKernel` holds the C board and every array it works on,
allocated once: the board's output registers (:attr:`~DriveKernel.setpoint`,
:attr:`~DriveKernel.velocity`, :attr:`~DriveKernel.torque`,
:attr:`~DriveKernel.felim` and the scalars given to
:meth:`~DriveKernel.set_registers`), the encoders
(:attr:`~DriveKernel.count`), the amplifiers (:attr:`~DriveKernel.dac`,
:attr:`~DriveKernel.amp`) and the input registers (:attr:`~DriveKernel.status`,
:attr:`~DriveKernel.ferr`).  Bound to an :class:`~pyrt.native.ArmKernel`, the
encoders and the amplifiers are the arm's own arrays and
:meth:`~DriveKernel.run` advances the arm with the board ticking every
period.  See ``csrc/drive.h`` for the registers, the enable and fault
logic and the interpolation.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from pyrt.native._armworld import ArmKernel
from pyrt.native._arrays import F64, as_f64
from pyrt.native._errors import NativeInputError, raise_for_status
from pyrt.native._lib import ffi, lib
from pyrt.native._servo import Servo

__all__ = ["DRIVE_ENABLED", "DRIVE_FAULT", "DRIVE_LATE", "DRIVE_REFUSED", "DriveKernel"]

#: The status word's bits (csrc/drive.h).
DRIVE_ENABLED: int = lib.PYRT_DRIVE_ENABLED
DRIVE_FAULT: int = lib.PYRT_DRIVE_FAULT
DRIVE_LATE: int = lib.PYRT_DRIVE_LATE
DRIVE_REFUSED: int = lib.PYRT_DRIVE_REFUSED
JOINT_SHIFT: int = lib.PYRT_DRIVE_JOINT_SHIFT
MAX_JOINTS: int = lib.PYRT_DRIVE_MAX_JOINTS
NWORK: int = lib.PYRT_DRIVE_NWORK

_I32 = np.dtype(np.int32)


def _why(exc: Any) -> str:
    return ("a parameter not > 0 or not finite, a pointer missing, or the arm's encoders "
            "and amplifiers not the board's: every output off")


class DriveKernel:
    """One hardware (a) board of ``n`` joints ticking every ``period`` s (see
    the module text).  ``counts`` encoder counts per rad (or m) and
    ``nm_per_count`` joint torque per DAC count, per joint; ``gains`` the
    board's servo tuning (as :class:`~pyrt.native.Servo` takes it; ``felim``
    is the register's); ``arm`` the simulated arm whose encoders and
    amplifiers it uses (None: arrays of its own).  NativeInputError for
    anything refused."""

    def __init__(self, n: int, period: float, *, counts: ArrayLike, nm_per_count: ArrayLike,
                 gains: dict[str, ArrayLike] | None = None, arm: ArmKernel | None = None):
        if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= MAX_JOINTS:
            raise NativeInputError(f"a drive serves 1 to {MAX_JOINTS} joints, got {n!r}")
        if arm is not None and arm.n != n:
            raise NativeInputError(f"arm: expected {n} joints, got {arm.n}")
        self.n = n
        self.servo = Servo(n, period, gains=gains)
        self.period = self.servo.period
        self.params = np.empty((lib.PYRT_DRIVE_NROWS, n), F64)
        self.params[lib.PYRT_DRIVE_COUNTS] = as_f64("counts", counts, (n,))
        self.params[lib.PYRT_DRIVE_NM_PER_COUNT] = as_f64("nm_per_count", nm_per_count, (n,))
        if not (np.isfinite(self.params).all() and (self.params > 0).all()):
            raise NativeInputError("counts and nm_per_count: expected numbers > 0")
        self.setpoint = np.zeros(n, _I32)
        self.velocity = np.zeros(n, _I32)
        self.torque = np.zeros(n, _I32)
        self.felim = np.zeros(n, _I32)
        self.ferr = np.zeros(n, _I32)
        if arm is not None:
            self.count, self.dac, self.amp = arm.count, arm.dac, arm.enable
        else:
            self.count = np.zeros(n, _I32)
            self.dac = np.zeros(n, _I32)
            self.amp = np.zeros(n, _I32)
        self.work = np.zeros((NWORK, n), F64)
        arrays = (self.params, self.work, self.servo.gains, self.servo.state, self.setpoint,
                  self.velocity, self.torque, self.felim, self.count, self.dac, self.amp,
                  self.ferr)
        self._keep = [ffi.from_buffer(a) for a in arrays]
        c = ffi.new("pyrt_drive *")
        c.n = n
        c.period = self.period
        c.params, c.work = (ffi.cast("double *", b) for b in self._keep[:2])
        c.servo.n = n
        c.servo.period = self.period
        c.servo.gains, c.servo.state = (ffi.cast("double *", b) for b in self._keep[2:4])
        (c.setpoint, c.velocity, c.torque, c.felim, c.count, c.dac, c.amp, c.ferr) = (
            ffi.cast("int32_t *", b) for b in self._keep[4:])
        self._c = c
        self._arm = arm
        self._tick = lib.pyrt_drive_tick
        self._run = lib.pyrt_drive_run

    # ------------------------------------------------------------ the registers

    def set_registers(self, *, enable: int | None = None, sync: int | None = None,
                      period_us: int | None = None) -> None:
        """The board's scalar output registers (those given)."""
        c = self._c
        for name, v in (("enable", enable), ("sync", sync), ("period_us", period_us)):
            if v is None:
                continue
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) \
                    or not -(1 << 31) <= int(v) < 1 << 31:
                raise NativeInputError(f"{name}: expected a 32-bit integer, got {v!r}")
            setattr(c, name, int(v))

    def set_outputs(self, name: str, values: Sequence[int]) -> None:
        """One per-joint output register (setpoint velocity torque felim) from ``n`` integers."""
        if name not in ("setpoint", "velocity", "torque", "felim"):
            raise NativeInputError(f"unknown register {name!r}")
        if len(values) != self.n:
            raise NativeInputError(f"{name}: expected {self.n} integers, got {len(values)}")
        try:
            v = [int(x) for x in values if not isinstance(x, bool)]
        except (TypeError, ValueError) as exc:
            raise NativeInputError(f"{name}: expected integers ({exc})") from None
        if len(v) != self.n or not all(-(1 << 31) <= x < 1 << 31 for x in v):
            raise NativeInputError(f"{name}: expected {self.n} 32-bit integers, got {values!r}")
        getattr(self, name)[:] = v

    @property
    def status(self) -> int:
        """The status word (:data:`DRIVE_ENABLED` ..., the tripped joint 1-based in bits 8..15)."""
        return int(self._c.status)

    @property
    def on(self) -> bool:
        """Whether the power stage is on."""
        return bool(self._c.on)

    @property
    def fault_joint(self) -> int | None:
        """The joint (0-based) whose following error tripped the board, or None."""
        j = int(self._c.fault_joint)
        return j - 1 if self._c.faulted and j > 0 else None

    @property
    def late(self) -> int:
        """Board ticks the reference has held its last knot (the next setpoint late)."""
        return int(self._c.servo.late)

    # ------------------------------------------------------------ time

    def tick(self) -> None:
        """One board tick on :attr:`count`: :attr:`dac`, :attr:`amp`, :attr:`status`,
        :attr:`ferr`.  A refused tick raises with every output off."""
        raise_for_status(self._tick(self._c), "drive tick", _why)

    def run(self, dt: float) -> None:
        """Advance the bound arm by ``dt`` s, the board ticking every period."""
        arm = self._arm
        if arm is None:
            raise NativeInputError("run: the drive is not bound to an arm")
        if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt >= 0):
            raise NativeInputError(f"dt: expected seconds >= 0, got {dt!r}")
        raise_for_status(self._run(self._c, arm._c, float(dt)), "drive run", _why)

    def __repr__(self) -> str:
        return f"DriveKernel({self.n} joints, {self.period * 1e3:g} ms)"
