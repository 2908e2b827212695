"""The arm's servo tuning on pyrt's generic servo, and the words of its faults.

The servo law is pyrt's (:class:`pyrt.native.Servo`, C: interpolation of the
trajectory's knots to the servo rate, PID with velocity, acceleration and
dynamics feed-forward, a following-error trip).  What is the arm's own is
the tuning, one :class:`JointServoConfig` per joint in the units an engineer
of this arm thinks in (N m per degree), and :func:`arm_servo` that turns it
into the generic servo's gains (per radian).  The law, per joint::

    tau   = kp e + kd (qd_ref - v) + kv qd_ref + ka qdd_ref + ff   (the generic servo)
    ff    = kc sign(qd), given at each knot and interpolated between knots
    drive = clamp(tau / torque_per_drive, -1, 1)

The Coulomb term rides on the generic servo's feed-forward: the controller gives
``kc sign(qd)`` at each 100 Hz knot and the servo interpolates it between them,
so it eases in over a move's first knot interval and out over its last, where
the PD loop takes the friction (at rest it holds the arm within ``kc / kp``:
0.014 deg for the shoulder, 0.033 deg for the elbow, inside the 0.05 deg of
"at target").  :func:`coulomb` is the same term taken on the reference's
velocity tick by tick.

``v`` is the measured angle's backward difference, low-pass filtered at
:attr:`JointServoConfig.velocity_filter_hz`.  ``kv``, ``ka`` and ``kc`` feed
forward the viscous friction, a nominal inertia and the Coulomb friction, so
the PD loop is left only the coupling between the joints, the inertia's
change with the elbow and the encoder's quantisation.

The gains (:data:`SHOULDER`, :data:`ELBOW`) place each joint's closed loop
at about 12 Hz with damping 0.9 on its nominal inertia (0.297 kg m^2 for
the shoulder, the elbow at 90 deg; 0.077 kg m^2 for the elbow).  On the
simulated arm (:class:`pyrt_arm.plant.Plant`) a quintic move of both joints
at 90 deg/s and 360 deg/s^2 keeps the following error below
:data:`TRACKING_BOUND_DEG` (0.1 deg), ten times inside the limit of 1.0 deg;
a jammed joint trips the check within about 15 ms of a move at that speed.

Two checks, each with a reason that names the joint and the numbers: the
following error (the generic servo's trip, :func:`following_error_fault`)
and the joint limits (:func:`joint_limit_fault`, checked by the servo's C tick
on the measured angle: the bounds of :class:`pyrt.native.ServoBoard`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from pyrt.native import Servo

from pyrt_arm.kinematics import GEOMETRY
from pyrt_arm.plant import CHAIN, MOTORS, wrap_int32

__all__ = [
    "ELBOW",
    "FOLLOWING_ERROR_LIMIT_DEG",
    "SERVO_PERIOD_S",
    "SHOULDER",
    "TRACKING_BOUND_DEG",
    "JointServoConfig",
    "arm_servo",
    "coulomb",
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

_PER_RAD = 180.0 / math.pi


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
        kp_nm_per_deg=inertia_kgm2 * w * w / _PER_RAD,
        kd_nm_s_per_deg=2.0 * zeta * w * inertia_kgm2 / _PER_RAD,
        kv_nm_s_per_deg=viscous / _PER_RAD,
        ka_nm_s2_per_deg=inertia_kgm2 / _PER_RAD,
        kc_nm=coulomb,
        torque_per_drive_nm=torque_per_drive_nm,
        counts_per_deg=counts_per_deg,
        limits_deg=limits_deg,
    )


def _joint(j: int, name: str, inertia_kgm2: float) -> JointServoConfig:
    """Joint ``j``'s config at 12 Hz, damping 0.9: its friction from the arm's URDF,
    its drive from :data:`pyrt_arm.plant.MOTORS`."""
    joint, motor = CHAIN.joints[j], MOTORS[j]
    return _gains(name, inertia_kgm2, joint.damping, joint.friction, 12.0, 0.9,
                  motor.torque_limit, motor.counts_per_joint_rev / 360.0,
                  GEOMETRY.limits_deg[j])


#: The shoulder's servo: 12 Hz, damping 0.9 on 0.297 kg m^2 (kp 29.5 N m/deg,
#: kd 0.70 N m/(deg/s)).
SHOULDER = _joint(0, "q0", 0.297)
#: The elbow's servo: 12 Hz, damping 0.9 on 0.077 kg m^2 (kp 7.6 N m/deg,
#: kd 0.18 N m/(deg/s)).
ELBOW = _joint(1, "q1", 0.077)


def coulomb(config: JointServoConfig, qd_ref: float) -> float:
    """The Coulomb friction fed forward (N m): ``kc sign(qd_ref)``."""
    return config.kc_nm if qd_ref > 0.0 else (-config.kc_nm if qd_ref < 0.0 else 0.0)


def arm_servo(configs: Sequence[JointServoConfig] = (SHOULDER, ELBOW),
              period_s: float = SERVO_PERIOD_S) -> Servo:
    """pyrt's generic servo for these joints at ``period_s``: the configs' gains per
    radian, no integrator, the output clamped at full drive (``torque_per_drive``),
    the following-error limit and the velocity filter as configured."""
    def row(f: str, scale: float = _PER_RAD) -> np.ndarray:
        return np.array([getattr(c, f) * scale for c in configs])

    return Servo(len(configs), period_s, names=[c.name for c in configs], gains={
        "kp": row("kp_nm_per_deg"), "kd": row("kd_nm_s_per_deg"),
        "kv": row("kv_nm_s_per_deg"), "ka": row("ka_nm_s2_per_deg"),
        "tmax": row("torque_per_drive_nm", 1.0),
        "felim": row("following_error_limit_deg", 1.0 / _PER_RAD),
        "velhz": row("velocity_filter_hz", 1.0)})
