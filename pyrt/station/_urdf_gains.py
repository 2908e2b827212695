"""The servo's gains of ``pyrt urdf`` as run-time parameters (``get``/``set``, EPICS ``_SP``).

Per joint (``JOINT.kp`` ...): the PID gains ``kp`` ``ki`` ``kd``, the
integrator's limit ``ilim``, and the feed-forwards: ``kv`` (velocity:
viscous friction), ``ka`` (acceleration: rotor inertia) and ``kff`` (the
share 0 .. 1 of the chain's inverse dynamics: gravity, inertia, Coriolis).
Per arm (``NAME.bandwidth``, ``NAME.kff``): every joint's ``kp ki kd``
placed at a triple real pole at the bandwidth (:func:`pyrt.native.tuned_gains`,
for each joint's largest inertia), and every joint's dynamics feed-forward
at once.

Each range is the joint's safe range (:func:`pyrt.native.gain_ranges`: the
stiffest loop keeps its margin at the servo rate, feed-forwards within what
the effort gives); a value outside it is refused with the range and nothing
changes.  A gain may change while a move runs (the law takes its gains
between ticks; the integrator holds torque, so a new ``ki`` is bumpless):
tuning watches the step response on the scope.  Gains are not written back.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from pyrt.component import Param
from pyrt.errors import CommandError
from pyrt.native import NativeInputError, Servo, tuned_gains

__all__ = ["BANDWIDTH_RANGE_HZ", "GAIN_DOCS", "arm_gain_params", "joint_gain_params"]

#: The per-joint gains served as parameters, and what each is.
GAIN_DOCS: dict[str, str] = {
    "kp": "proportional gain",
    "ki": "integral gain",
    "kd": "derivative gain (on the velocity error)",
    "ilim": "the integrator's limit",
    "kv": "velocity feed-forward (viscous friction)",
    "ka": "acceleration feed-forward (rotor inertia)",
    "kff": "share of the dynamics feed-forward (gravity, inertia, Coriolis; 0 off, 1 all)",
}

#: The lowest arm bandwidth ``NAME.bandwidth`` takes (Hz); the highest is the
#: safe ranges' (1/20 of the servo rate).
BANDWIDTH_RANGE_HZ = 1.0


def _units(name: str, prismatic: bool) -> str:
    """A gain's units for a revolute (N m, rad) or a prismatic (N, m) joint."""
    if prismatic:
        return {"kp": "N/m", "ki": "N/(m s)", "kd": "N s/m", "kv": "N s/m", "ka": "kg",
                "kff": "", "ilim": "N"}[name]
    return {"kp": "N m/rad", "ki": "N m/(rad s)", "kd": "N m s/rad", "kv": "N m s/rad",
            "ka": "kg m^2", "kff": "", "ilim": "N m"}[name]


def _set(servo: Servo, name: str, joint: int, value: float, who: str) -> None:
    try:
        servo.set_gain(name, joint, float(value))
    except NativeInputError as exc:
        raise CommandError(f"{who}: {exc}; nothing changed") from None


def joint_gain_params(servo: Servo, joint: int, prismatic: bool,
                      ranges: dict[str, tuple[np.ndarray, np.ndarray]]) -> list[Param]:
    """Joint ``joint``'s gains as parameters, each ranged by ``ranges`` (its safe range)."""
    out = []
    for name, doc in GAIN_DOCS.items():
        lo, hi = (float(ranges[name][0][joint]), float(ranges[name][1][joint]))

        def write(v: float, name: str = name) -> None:
            _set(servo, name, joint, v, f"set {servo.names[joint]}.{name}")

        def read(name: str = name) -> float:
            return float(getattr(servo, name)[joint])

        out.append(Param(name, _units(name, prismatic), read, write, lo, hi,
                         f"servo: {doc}", safe_while_moving=True))
    return out


class ArmTuning:
    """The arm's bandwidth as last set (the per-joint gains may differ since)."""

    def __init__(self, servo: Servo, inertia: np.ndarray, effort: np.ndarray,
                 bandwidth_hz: float) -> None:
        self.servo = servo
        self.inertia = np.asarray(inertia, dtype=float)
        self.effort = np.asarray(effort, dtype=float)
        self.bandwidth_hz = float(bandwidth_hz)

    def set_bandwidth(self, hz: float, who: str) -> str:
        """Every joint's kp ki kd at a triple pole at ``hz``; refused together."""
        g = tuned_gains(self.inertia, self.effort, self.servo.period, float(hz))
        try:
            self.servo.set_gains({k: g[k] for k in ("kp", "ki", "kd")})
        except NativeInputError as exc:
            raise CommandError(f"{who}: {exc}; nothing changed") from None
        self.bandwidth_hz = float(hz)
        return "kp ki kd of every joint at a triple pole there"

    def set_kff(self, share: float, who: str) -> None:
        try:
            self.servo.set_gains({"kff": np.full(self.servo.n, float(share))})
        except NativeInputError as exc:
            raise CommandError(f"{who}: {exc}; nothing changed") from None


def arm_gain_params(name: str, tuning: ArmTuning, max_hz: float) -> list[Param]:
    """The arm's own gain parameters: ``bandwidth`` (Hz, up to ``max_hz``) and ``kff``."""
    servo = tuning.servo

    def kff() -> float:
        v = servo.kff
        return float(v[0]) if bool(np.all(v == v[0])) else math.nan

    def bw(v: Any) -> str:
        return tuning.set_bandwidth(v, f"set {name}.bandwidth")

    return [
        Param("bandwidth", "Hz", lambda: tuning.bandwidth_hz, bw, BANDWIDTH_RANGE_HZ, max_hz,
              "servo: every joint's kp ki kd tuned to a triple real pole at this closed-loop "
              "bandwidth (the value last set; JOINT.kp etc. may differ since)",
              safe_while_moving=True),
        Param("kff", "", kff, lambda v: tuning.set_kff(v, f"set {name}.kff"), 0.0, 1.0,
              "servo: every joint's share of the dynamics feed-forward (nan: they differ)",
              safe_while_moving=True),
    ]
