"""The controller of ``pyrt urdf --hardware a``: the arm behind a motion-control board.

:class:`DrivenArm` is :class:`~pyrt.station._urdf_arm.UrdfArm` (the same
moves, commands, signals, limits and faults) on 004's hardware (a)
(:func:`pyrt.boards.armdrive.arm_drive_kind`): the board takes a setpoint
per joint at the trajectory rate and interpolates and servos on its own,
so the host has no servo task.  One task, ``trajectory``
(:data:`TRAJECTORY_S`, every tick when the loop ticks at that period):

* one read of the board's inputs: the encoders (unwrapped, as the servo
  board's), the wrist sensor, the status word and the following errors;
* a FAULT in the status word (the board tripped on a following error and
  switched its amplifiers off in its own tick), or the power stage off
  while the arm should be powered, or a joint beyond its limits: the
  station's fault, whose reflex writes enable 0 in this tick;
* the trajectory's knot (the same evaluator as on hardware (b)) written as
  setpoint (counts), velocity (counts/s) and torque offset (the chain's
  inverse dynamics, DAC counts), then ``sync``: the board's segment.  The
  outputs are written on trajectory ticks only, and only while the arm moves.

Power-on writes the following-error limits (:data:`FOLLOWING_ERROR_DEG` in
counts), the interpolation period, the setpoint where the arm is and its
gravity torque, then enable; an arm still moving is braked to rest (and one
beyond a limit brought back inside) along a quintic sent as setpoints, as
the servo of hardware (b) does it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from pyrt.boards.armdrive import DAC_FULL_SCALE, ENABLED, FAULT, JOINT_SHIFT
from pyrt.component import Param, Signal
from pyrt.errors import ConfigError
from pyrt.motion import Evaluator
from pyrt.scheduler import Task
from pyrt.station._urdf_arm import (
    FOLLOWING_ERROR_DEG,
    ArmJoint,
    Drive,
    UrdfArm,
)

if TYPE_CHECKING:
    from pyrt.station.base import Station

__all__ = ["TRAJECTORY_S", "DriveJoint", "DrivenArm"]

#: The trajectory's period (s): the rate the board takes setpoints at (100 Hz).
TRAJECTORY_S = 0.01
#: The board is enabled by itself after this many readings at the trajectory rate (the
#: arm's speed then known, as on hardware (b)).
POWER_ON_READINGS = 3
#: Trajectory ticks the power stage may take to come on after enable is written.
ENABLE_GRACE = 3

_TWO31 = 1 << 31
_TWO32 = 1 << 32


def _i32(v: int) -> int:
    """``v`` within a signed 32-bit register, wrapped as the counter wraps."""
    return ((v + _TWO31) % _TWO32) - _TWO31


class DriveJoint(ArmJoint):
    """One joint of a hardware (a) arm: its reflex switches the board's power stage off."""

    def params(self) -> list[Param]:
        """None: the servo runs on the board, tuned when the board is built; the
        host's gains would tune a servo that does not run."""
        return []

    def reflex(self) -> None:
        """Enable 0 (every amplifier of the board off), now."""
        self.arm.board.write("enable", 0)


class DrivenArm(UrdfArm):
    """The arm on a motion-control board (see the module text); the arguments are
    :class:`~pyrt.station._urdf_arm.UrdfArm`'s.  ConfigError for a tick that does
    not divide :data:`TRAJECTORY_S`."""

    def __init__(self, station: Station, name: str, chain: Any, board: Any,
                 drives: Sequence[Drive], period_ns: int,
                 wrench: Callable[[Sequence[int]], np.ndarray] | None = None) -> None:
        super().__init__(station, name, chain, board, drives, period_ns, wrench=wrench)
        every = round(TRAJECTORY_S * 1e9 / period_ns)
        if every < 1 or every * period_ns != round(TRAJECTORY_S * 1e9):
            raise ConfigError(f"a tick of {period_ns / 1e3:g} µs does not divide the "
                              f"trajectory's period ({TRAJECTORY_S * 1e3:g} ms)")
        #: Ticks per trajectory tick.
        self.every = every
        self.traj_period_s = TRAJECTORY_S
        n = self.n
        self.joints = tuple(DriveJoint(self, i) for i in range(n))
        layout = [(r.name, i) for r in board.kind.inputs() for i in range(r.count)]
        self._status_at = layout.index(("status", 0))
        f0 = layout.index(("ferr", 0))
        self._ferr_slice = slice(f0, f0 + n)
        self._nm_list = [d.nm_per_count for d in self.drives]
        self._felim_counts = [max(1, math.floor(float(lim) * c)) for lim, c in
                              zip(self._felim_rad(), self._cpu_list, strict=True)]
        #: The board's status word as last read.
        self.status = 0
        self._sync = 0
        self._sent: list[list[int | None]] = [[None] * n, [None] * n, [None] * n]
        self._recover: tuple[np.ndarray, np.ndarray, int, float] | None = None
        self._q_prev: np.ndarray | None = None
        self._powered_at = 0
        #: Powered by a command between trajectory ticks: the board's writes wait for the next.
        self._pending = False

    def _felim_rad(self) -> list[float]:
        return [FOLLOWING_ERROR_DEG * 1e-3 if p else math.radians(FOLLOWING_ERROR_DEG)
                for p in self.prismatic]

    def params(self) -> list[Param]:
        """None: the board's servo is tuned when the board is built (see
        :class:`DriveJoint.params`)."""
        return []

    def signals(self) -> list[Signal]:
        return [*super().signals(),
                Signal("status", "bits", lambda: self.status,
                       "the board's status word: 1 enabled, 2 fault, 4 late, 8 refused; "
                       "bits 8..15 the joint that tripped", "d")]

    def tasks(self) -> list[Task]:
        """The trajectory alone, at every release of its 100 Hz group (no host servo)."""
        return [Task(self.drive_tick, period=1, name="trajectory", timed=True)]

    # -- the board ---------------------------------------------------------------------

    def _send(self, q: Sequence[float], qd: Sequence[float], ff: Sequence[float]) -> None:
        """One knot to the board: the registers that changed, then the strobe."""
        write, cpu, nm = self.board.write, self._cpu_list, self._nm_list
        sp, vel, tq = self._sent
        full = DAC_FULL_SCALE
        for j in range(self.n):
            c = _i32(math.floor(q[j] * cpu[j]))
            if c != sp[j]:
                write("setpoint", c, j)
                sp[j] = c
            v = max(-_TWO31, min(_TWO31 - 1, round(qd[j] * cpu[j])))
            if v != vel[j]:
                write("velocity", v, j)
                vel[j] = v
            t = max(-full, min(full, round(ff[j] / nm[j])))
            if t != tq[j]:
                write("torque", t, j)
                tq[j] = t
        self._sync = (self._sync + 1) & 0xFFFF
        write("sync", self._sync)
        self.servo.q_ref[:] = q
        self.servo.tau[:] = ff

    def follow(self, period: float) -> None:
        """The knot just made (the servo's knots B) as the board's next setpoint."""
        k = self.servo.knots
        self._send(k[3].tolist(), k[4].tolist(), k[7].tolist())

    def power_on(self) -> None:
        """The board's limits and period, the setpoint where the arm is with its
        gravity torque, then enable; the trajectory starts there.  An arm still
        moving is braked to rest, one beyond a limit brought back inside, along a
        quintic sent as setpoints before the trajectory's knots begin."""
        # this tick's encoders (a move may come before the trajectory task's first read)
        self._measure(self.board.snapshot()[self._count_slice])
        q = self.q.copy()
        v = np.zeros(self.n)
        if self._history:
            t_old, q_old = self._history[0]
            if self._now_ns > t_old:
                v = (q - q_old) / ((self._now_ns - t_old) * 1e-9)
        ff = self.chain.gravity_torque(q)
        k = self.servo.knots
        k[...] = 0.0
        k[3] = q
        k[7] = ff
        amax = 0.5 * np.array(self.limits.amax)
        t = float(np.max(np.abs(v) / amax))
        start = np.clip(q + 0.5 * v * t, self.chain.lower, self.chain.upper)
        self.evaluator = Evaluator(self.chain, self.limits, start, period=self.traj_period_s,
                                   force_sensor=self._wrench_of is not None)
        margin = self._margin
        self._history.clear()
        self._bound(np.minimum(self.chain.lower, q) - margin,
                    np.maximum(self.chain.upper, q) + margin)
        self._wide = bool(((q < self.chain.lower) | (q > self.chain.upper)).any())
        self._recover_until = None
        self._recover = None
        out = np.abs(start - q)
        if out.any() or t > 0.0:
            t = max(0.2, t, float(np.max(np.sqrt(5.77 * out / amax))))
            t = math.ceil(t / self.traj_period_s) * self.traj_period_s
            h = start - q
            c = np.array([q, v, np.zeros(self.n), (20 * h - 12 * v * t) / (2 * t ** 3),
                          (-30 * h + 16 * v * t) / (2 * t ** 4),
                          (12 * h - 6 * v * t) / (2 * t ** 5)])
            self._recover = (c, start, self._now_ns, t)
            self._recover_until = self._now_ns + round(t * 1e9)  # from the enable on
        self.dac = [0] * self.n
        self.powered = True
        self.state = "idle"
        self._pending = True  # the board is enabled on the next trajectory tick

    def _enable(self, now_ns: int) -> None:
        """Power-on's writes, on a trajectory tick: the limits, the period, the
        setpoint where the arm was with its gravity torque, then enable."""
        write = self.board.write
        for j, lim in enumerate(self._felim_counts):
            write("felim", lim, j)
        write("period_us", round(self.traj_period_s * 1e6))
        self._sent = [[None] * self.n, [None] * self.n, [None] * self.n]
        k = self.servo.knots
        self._send(k[3].tolist(), [0.0] * self.n, k[7].tolist())
        write("enable", 1)
        self._pending = False
        self._powered_at = now_ns
        if self._recover is not None:
            c, start, _t0, t = self._recover
            self._recover = (c, start, now_ns, t)
            self._recover_until = now_ns + round(t * 1e9)

    def reflex(self) -> None:
        """The servo off and the motion dropped; a pending enable forgotten."""
        self._pending = False
        super().reflex()

    def _recovering(self, now_ns: int) -> None:
        """The next point of the power-on quintic as the board's setpoint."""
        assert self._recover is not None
        c, start, t0, total = self._recover
        t = min((now_ns - t0) * 1e-9, total)
        if t >= total:
            p, v = start, np.zeros(self.n)
            self._recover = None
        else:
            p = c[0] + t * (c[1] + t * (c[2] + t * (c[3] + t * (c[4] + t * c[5]))))
            v = c[1] + t * (2 * c[2] + t * (3 * c[3] + t * (4 * c[4] + t * 5 * c[5])))
        k = self.servo.knots
        k[3] = p
        k[4] = v
        k[7] = self.chain.gravity_torque(p)
        self._send(k[3].tolist(), k[4].tolist(), k[7].tolist())

    # -- the task ----------------------------------------------------------------------

    def drive_tick(self, now_ns: int) -> None:
        """100 Hz: the board's inputs, its faults and the limits; the next knot."""
        self._now_ns = now_ns
        inputs = self.board.snapshot()
        self._measure(inputs[self._count_slice])
        self._ft_counts = inputs[self._ft_slice]
        self.status = status = inputs[self._status_at]
        ferr = inputs[self._ferr_slice]
        q_prev, self._q_prev = self._q_prev, self.q.copy()
        if not self.powered:
            self._history.append((now_ns, self.q.copy()))
            if (self.evaluator is None and self.station.fault is None and not self._started
                    and len(self._history) >= POWER_ON_READINGS):
                self._started = True
                self.power_on()
            if not self.powered:
                return
        if self._pending:
            self._enable(now_ns)
            return
        servo, cpu = self.servo, self._cpu_list
        for j, e in enumerate(ferr):
            servo.error[j] = e / cpu[j]
        if q_prev is not None:
            servo.velocity[:] = (self.q - q_prev) / self.traj_period_s
        if status & FAULT:
            self._tripped(status, ferr)
            return
        if not status & ENABLED and now_ns - self._powered_at > \
                ENABLE_GRACE * self.traj_period_s * 1e9:
            self.fail(f"the board's power stage is off (status 0x{status:04x})", self.name)
            return
        lo, hi, qs = self._lo_l, self._hi_l, self._qs
        for j in range(self.n):
            if qs[j] < lo[j] or qs[j] > hi[j]:
                self._beyond(j)
                return
        if self._recover is not None:
            self._recovering(now_ns)
        self.trajectory_tick(now_ns)
        if self.state == "settling":
            self._settle(now_ns)

    def _tripped(self, status: int, ferr: Sequence[int]) -> None:
        j = (status >> JOINT_SHIFT) - 1
        if 0 <= j < self.n:
            jt, k, u = self.chain.joints[j], float(self.scales[j]), self.units[j]
            e = ferr[j] / self._cpu_list[j] * k
            self.fail(f"following error: the board tripped on joint {jt.name} "
                      f"({e:+.3f} {u}, limit {FOLLOWING_ERROR_DEG:g} {u}; at "
                      f"{self.q[j] * k:.3f} {u})", self.joints[j].name)
        else:
            self.fail(f"the board faulted (status 0x{status:04x}): a following-error "
                      "limit or its period not set", self.name)

    def _settle(self, now_ns: int) -> None:
        """Ended as :meth:`UrdfArm.settle_on` says, on the error from the last knot (the
        board servos: the host has no servo error of its own)."""
        self.settle_on(self.servo.knots[3] - self.q, now_ns)
