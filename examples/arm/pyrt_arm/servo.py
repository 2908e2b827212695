"""The servo law: per joint a PD position loop with feed-forward, and its safety checks.

Pure and testable: no I/O, no clock.  Each servo tick (1 kHz, :data:`SERVO_PERIOD_S`)
the station gives a :class:`JointServo` the setpoint (position, velocity and, if the
trajectory has it, acceleration) and the encoder's counter, and gets back the drive
for the amplifier (-1 .. 1 of full scale).  The law in joint torque (N m), with angles
in degrees::

    tau = kp e + kd (qd_sp - qd_meas) + kv qd_sp + ka qdd_sp + kc sign(qd_sp)
    e   = q_sp - q_meas
    drive = clamp(tau / torque_per_drive, -1, 1)

``q_meas`` is the counter's offset from its zero count (differences taken as 32-bit
signed numbers, so a counter that wraps is followed across the wrap); ``qd_meas`` is
its backward difference, low-pass filtered (:attr:`JointServoConfig.velocity_filter_hz`).
``kv``, ``ka`` and ``kc`` feed forward the viscous friction, a nominal inertia and the
Coulomb friction, so the PD loop is left only the coupling between the joints, the
inertia's change with the elbow and the encoder's quantisation.

Two checks run each tick after the update (:meth:`JointServo.fault`); either gives a
reason string naming the joint and the numbers, which the station turns into a trip:

* following error: ``|q_sp - q_meas| > following_error_limit_deg``;
* joint limit: ``q_meas`` outside the joint's limits.

The gains (:data:`SHOULDER`, :data:`ELBOW`) place each joint's closed loop at about
12 Hz with damping 0.9 on its nominal inertia (0.297 kg m^2 for the shoulder, the
elbow at 90 deg; 0.077 kg m^2 for the elbow).  On the simulated arm
(:class:`pyrt_arm.plant.Plant`) with a 1 ms step, a quintic point-to-point move of
both joints at 90 deg/s peak velocity and 360 deg/s^2 peak acceleration keeps the
following error below 0.05 deg (the test bound is :data:`TRACKING_BOUND_DEG`, 0.1 deg),
twenty times inside the limit of 1.0 deg, also with the period jittering between 0.6
and 1.4 ms; a jammed joint trips the check within about 15 ms of a move at that speed.
Settled after a move, the true tip lies within 0.2 mm of the target (what is left is
the Coulomb friction over kp, at most 0.014 deg at the shoulder) and within 0.03 mm
of the tip the encoders give (their quantisation, 0.0018 deg).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from pyrt_arm.kinematics import GEOMETRY
from pyrt_arm.plant import ELBOW_DRIVE, JOINTS, SHOULDER_DRIVE, wrap_int32

__all__ = [
    "ELBOW",
    "FOLLOWING_ERROR_LIMIT_DEG",
    "SERVO_PERIOD_S",
    "SHOULDER",
    "TRACKING_BOUND_DEG",
    "ArmServo",
    "JointServo",
    "JointServoConfig",
    "counts_to_deg",
    "following_error_fault",
    "joint_limit_fault",
]

#: The servo tick (s): 1 kHz.
SERVO_PERIOD_S = 1.0e-3

#: A following error beyond this (deg) is a fault.
FOLLOWING_ERROR_LIMIT_DEG = 1.0

#: The following error (deg) the law keeps below on a 90 deg/s, 360 deg/s^2 quintic move.
TRACKING_BOUND_DEG = 0.1

_RAD_PER_DEG = math.pi / 180.0


def counts_to_deg(count: int, zero_count: int, counts_per_deg: float) -> float:
    """The joint angle (deg) a counter reading gives: ``(count - zero_count)`` taken as a
    32-bit signed difference, over ``counts_per_deg``."""
    return wrap_int32(count - zero_count) / counts_per_deg


def following_error_fault(name: str, setpoint_deg: float, measured_deg: float,
                          limit_deg: float) -> str | None:
    """The fault reason if ``|setpoint - measured| > limit_deg``, else None."""
    error = setpoint_deg - measured_deg
    if abs(error) > limit_deg or not math.isfinite(error):
        return (f"{name} following error {error:+.3f} deg exceeds the limit {limit_deg:.3f} deg "
                f"(setpoint {setpoint_deg:.3f} deg, measured {measured_deg:.3f} deg)")
    return None


def joint_limit_fault(name: str, measured_deg: float,
                      limits_deg: tuple[float, float]) -> str | None:
    """The fault reason if ``measured_deg`` lies outside ``limits_deg`` (inclusive), else
    None."""
    low, high = limits_deg
    if not low <= measured_deg <= high:
        return (f"{name} at {measured_deg:.3f} deg is outside its limits "
                f"[{low:.3f}, {high:.3f}] deg")
    return None


@dataclass(frozen=True)
class JointServoConfig:
    """One joint's servo: gains in joint torque per degree, its encoder scale, its checks."""

    name: str                       #: the joint's name in fault reasons ("q0")
    kp_nm_per_deg: float            #: position gain (N m / deg)
    kd_nm_s_per_deg: float          #: velocity-error gain (N m / (deg/s))
    kv_nm_s_per_deg: float          #: velocity feed-forward, the viscous friction
    ka_nm_s2_per_deg: float         #: acceleration feed-forward, a nominal inertia
    kc_nm: float                    #: Coulomb friction feed-forward (N m)
    torque_per_drive_nm: float      #: joint torque at drive 1.0 (amplifier, motor, gear)
    counts_per_deg: float           #: encoder counts per degree of the joint
    limits_deg: tuple[float, float]  #: the joint limits (deg)
    zero_count: int = 0             #: the counter's value at 0 deg
    velocity_filter_hz: float = 200.0  #: corner of the measured velocity's low-pass
    following_error_limit_deg: float = FOLLOWING_ERROR_LIMIT_DEG

    def __post_init__(self) -> None:
        for name in ("kp_nm_per_deg", "kd_nm_s_per_deg", "kv_nm_s_per_deg",
                     "ka_nm_s2_per_deg", "kc_nm"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"{self.name}: {name} must be a finite number >= 0, "
                                 f"got {value!r}")
        for name in ("torque_per_drive_nm", "counts_per_deg", "velocity_filter_hz",
                     "following_error_limit_deg"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{self.name}: {name} must be a positive finite number, "
                                 f"got {value!r}")
        low, high = self.limits_deg
        if not (math.isfinite(low) and math.isfinite(high) and low < high):
            raise ValueError(f"{self.name}: limits_deg must be (low, high) with low < high, "
                             f"got {self.limits_deg!r}")


def _gains(name: str, inertia_kgm2: float, viscous: float, coulomb: float, hz: float,
           zeta: float, torque_per_drive_nm: float, counts_per_deg: float,
           limits_deg: tuple[float, float]) -> JointServoConfig:
    """A joint's config placing its closed loop at ``hz`` with damping ``zeta`` on
    ``inertia_kgm2``; the feed-forward from the nominal friction and inertia."""
    w = 2.0 * math.pi * hz
    return JointServoConfig(
        name=name,
        kp_nm_per_deg=inertia_kgm2 * w * w * _RAD_PER_DEG,
        kd_nm_s_per_deg=2.0 * zeta * w * inertia_kgm2 * _RAD_PER_DEG,
        kv_nm_s_per_deg=viscous * _RAD_PER_DEG,
        ka_nm_s2_per_deg=inertia_kgm2 * _RAD_PER_DEG,
        kc_nm=coulomb,
        torque_per_drive_nm=torque_per_drive_nm,
        counts_per_deg=counts_per_deg,
        limits_deg=limits_deg,
    )


#: The shoulder's servo: 12 Hz, damping 0.9 on 0.297 kg m^2 (kp 29.5 N m/deg,
#: kd 0.70 N m/(deg/s)).
SHOULDER = _gains("q0", 0.297, SHOULDER_DRIVE.viscous_nm_s_per_rad, SHOULDER_DRIVE.coulomb_nm,
                  12.0, 0.9, SHOULDER_DRIVE.torque_per_drive_nm,
                  SHOULDER_DRIVE.counts_per_deg, GEOMETRY.q0_limits_deg)
#: The elbow's servo: 12 Hz, damping 0.9 on 0.077 kg m^2 (kp 7.6 N m/deg,
#: kd 0.18 N m/(deg/s)).
ELBOW = _gains("q1", 0.077, ELBOW_DRIVE.viscous_nm_s_per_rad, ELBOW_DRIVE.coulomb_nm,
               12.0, 0.9, ELBOW_DRIVE.torque_per_drive_nm,
               ELBOW_DRIVE.counts_per_deg, GEOMETRY.q1_limits_deg)


class JointServo:
    """One joint's servo law with its state (the last count, the filtered velocity).

    Call :meth:`reset` with the counter's value when the loop closes (so the first
    velocity is not a jump), then :meth:`update` once per tick.
    """

    def __init__(self, config: JointServoConfig, period_s: float = SERVO_PERIOD_S) -> None:
        if not (math.isfinite(period_s) and period_s > 0.0):
            raise ValueError(f"period_s must be a positive number of seconds, got {period_s!r}")
        self.config = config
        self.period_s = period_s
        self._last_count: int | None = None
        self._alpha_key = (0.0, 0.0)
        self._alpha = 0.0
        #: the measured angle (deg) and filtered rate (deg/s) of the last update
        self.position_deg = 0.0
        self.velocity_deg_s = 0.0
        #: the setpoint of the last update (deg) and the error then (setpoint - measured)
        self.setpoint_deg = 0.0
        self.error_deg = 0.0
        #: the drive of the last update, and the torque asked for before the clamp (N m)
        self.drive = 0.0
        self.torque_nm = 0.0

    def reset(self, count: int) -> None:
        """Take ``count`` as the present reading, at rest; the setpoint becomes it."""
        self._last_count = count
        self.position_deg = counts_to_deg(count, self.config.zero_count,
                                          self.config.counts_per_deg)
        self.velocity_deg_s = 0.0
        self.setpoint_deg = self.position_deg
        self.error_deg = 0.0
        self.drive = 0.0
        self.torque_nm = 0.0

    def measure(self, count: int) -> float:
        """The joint angle (deg) the counter reading ``count`` gives."""
        return counts_to_deg(count, self.config.zero_count, self.config.counts_per_deg)

    def update(self, q_sp_deg: float, qd_sp_deg_s: float, count: int,
               qdd_sp_deg_s2: float = 0.0, dt_s: float | None = None) -> float:
        """One tick: the drive (-1 .. 1) for setpoint ``q_sp_deg``, ``qd_sp_deg_s``,
        ``qdd_sp_deg_s2`` and the counter reading ``count``; ``dt_s`` is the time since
        the last update (default :attr:`period_s`)."""
        cfg = self.config
        isfinite = math.isfinite
        if not (isfinite(q_sp_deg) and isfinite(qd_sp_deg_s) and isfinite(qdd_sp_deg_s2)):
            for name, value in (("q_sp_deg", q_sp_deg), ("qd_sp_deg_s", qd_sp_deg_s),
                                ("qdd_sp_deg_s2", qdd_sp_deg_s2)):
                if not isfinite(value):
                    raise ValueError(f"{cfg.name}: {name} must be a finite number, "
                                     f"got {value!r}")
        dt = self.period_s if dt_s is None else dt_s
        if not (isfinite(dt) and dt > 0.0):
            raise ValueError(f"{cfg.name}: dt_s must be a positive number of seconds, "
                             f"got {dt_s!r}")
        cpd = cfg.counts_per_deg
        position = wrap_int32(count - cfg.zero_count) / cpd
        last = self._last_count
        if last is None:
            velocity = 0.0
        else:
            raw = wrap_int32(count - last) / cpd / dt
            key = (dt, cfg.velocity_filter_hz)
            if key != self._alpha_key:  # the filter's gain for this period (kept while it holds)
                self._alpha_key = key
                self._alpha = 1.0 - math.exp(-2.0 * math.pi * cfg.velocity_filter_hz * dt)
            velocity = self.velocity_deg_s + self._alpha * (raw - self.velocity_deg_s)
        self._last_count = count
        error = q_sp_deg - position
        sign = 1.0 if qd_sp_deg_s > 0.0 else (-1.0 if qd_sp_deg_s < 0.0 else 0.0)
        torque = (cfg.kp_nm_per_deg * error
                  + cfg.kd_nm_s_per_deg * (qd_sp_deg_s - velocity)
                  + cfg.kv_nm_s_per_deg * qd_sp_deg_s
                  + cfg.ka_nm_s2_per_deg * qdd_sp_deg_s2
                  + cfg.kc_nm * sign)
        drive = max(-1.0, min(1.0, torque / cfg.torque_per_drive_nm))
        self.position_deg = position
        self.velocity_deg_s = velocity
        self.setpoint_deg = q_sp_deg
        self.error_deg = error
        self.torque_nm = torque
        self.drive = drive
        return drive

    def fault(self) -> str | None:
        """The fault reason after the last update (following error first, then the joint
        limit), or None."""
        cfg = self.config
        low, high = cfg.limits_deg
        if (abs(self.error_deg) <= cfg.following_error_limit_deg
                and low <= self.position_deg <= high):
            return None  # the common case, without building the reasons
        return (following_error_fault(cfg.name, self.setpoint_deg, self.position_deg,
                                      cfg.following_error_limit_deg)
                or joint_limit_fault(cfg.name, self.position_deg, cfg.limits_deg))


class ArmServo:
    """Both joints' servo laws; the first fault of either is the arm's (004: an error
    on one joint stops the whole robot)."""

    def __init__(self, configs: Sequence[JointServoConfig] = (SHOULDER, ELBOW),
                 period_s: float = SERVO_PERIOD_S) -> None:
        if len(configs) != len(JOINTS):
            raise ValueError(f"an arm of {len(JOINTS)} joints needs {len(JOINTS)} servo "
                             f"configs, got {len(configs)}")
        self.joints = tuple(JointServo(c, period_s) for c in configs)

    def reset(self, counts: Sequence[int]) -> None:
        """Take ``counts`` as the present readings, at rest."""
        for servo, count in zip(self.joints, counts, strict=True):
            servo.reset(count)

    def update(self, q_sp_deg: Sequence[float], qd_sp_deg_s: Sequence[float],
               counts: Sequence[int], qdd_sp_deg_s2: Sequence[float] = (0.0, 0.0),
               dt_s: float | None = None) -> tuple[float, float]:
        """One tick for both joints: the drives ``(d0, d1)``."""
        d0, d1 = (servo.update(q, qd, c, qdd, dt_s) for servo, q, qd, c, qdd in
                  zip(self.joints, q_sp_deg, qd_sp_deg_s, counts, qdd_sp_deg_s2, strict=True))
        return d0, d1

    def fault(self) -> str | None:
        """The first joint's fault reason after the last update, or None."""
        for servo in self.joints:
            reason = servo.fault()
            if reason is not None:
                return reason
        return None

    @property
    def position_deg(self) -> tuple[float, float]:
        """The measured joint angles (deg) of the last update."""
        return self.joints[0].position_deg, self.joints[1].position_deg
