"""The simulated arm: two-link planar dynamics, DC motors through gears, encoders.

The plant knows nothing of pyrt.  A controller (in the station: its register-level
boards) writes the inputs and reads the outputs, and the loop calls :meth:`Plant.step`
with the time since the last call:

inputs (plain lists, one entry per joint)
    ``drive[j]``       the amplifier's command, -1 .. 1 of full scale (a DAC's range)
    ``amp_enable[j]``  the amplifier's enable; a disabled amplifier gives no current
outputs
    :meth:`Plant.count` / :meth:`Plant.counts`  the incremental encoders' counters
    :meth:`Plant.motor_powered`  the amplifiers' status: False while a motor's power is cut
true state (for tests, the console's ``sim`` commands and truth checks)
    :attr:`Plant.q_deg`, :attr:`Plant.qd_deg_s`, :attr:`Plant.tip_mm`,
    :attr:`Plant.current_a`, :attr:`Plant.torque_nm`, :meth:`Plant.kinetic_energy_j`
fault injection
    :meth:`Plant.jam` (a brake: the joint stops and stays), :meth:`Plant.disconnect_encoder`
    (its counter freezes), :meth:`Plant.motor_off` (no current whatever the drive)

Dynamics (gravity off: the arm lies on a table), per joint ``j``::

    M(q) qdd + c(q, qd) = tau - b qd - f_c

with links as uniform rods and a point payload at the tip, the motors' rotor inertia
reflected through the gear onto the diagonal of ``M``, viscous friction ``b`` and
Coulomb friction ``f_c`` (with sticking: a joint at rest stays at rest while the
torque it needs to stay is within ``f_c``).  Each motor is driven by a current
amplifier: ``i = drive * amp_gain`` (drive clamped to -1 .. 1), saturated at the
current limit, ``tau = Kt * i * gear``.  The torque limit is ``Kt * i_limit * gear``.

Integration is semi-implicit Euler (velocity first, implicit in the viscous and the
Coulomb friction, then position) over equal internal steps of at most
:data:`MAX_STEP_S` (0.2 ms; ``max_step_s`` sets another) covering whatever ``dt_s`` it is
given.  At rest with no current (amplifiers off or no drive) nothing moves, and a step
costs next to nothing.  Mechanical end
stops a little beyond the software limits (:attr:`PlantParams.hard_stops_deg`) stop
a joint dead.

Encoders count ``4096`` per motor turn (1024 lines, quadrature) times the gear: 204,800
counts per joint turn, 568.9 per degree.  The counter starts at ``floor(q * counts
per degree)`` (referenced at zero degrees) and wraps as a 32-bit signed counter.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

from pyrt_arm.kinematics import GEOMETRY, Geometry, fk

__all__ = [
    "ELBOW_DRIVE",
    "JOINTS",
    "MAX_STEP_S",
    "SHOULDER_DRIVE",
    "MotorParams",
    "Plant",
    "PlantParams",
    "wrap_int32",
]

#: The joints' names, by index.
JOINTS = ("q0", "q1")

#: The longest internal integration step (s).
MAX_STEP_S = 0.2e-3

_DEG = math.pi / 180.0
_TWO32 = 1 << 32
_TWO31 = 1 << 31


def wrap_int32(value: int) -> int:
    """``value`` as a 32-bit signed counter holds it (wrapped into -2**31 .. 2**31 - 1)."""
    return ((value + _TWO31) % _TWO32) - _TWO31


@dataclass(frozen=True)
class MotorParams:
    """One joint's drive train: DC motor, current amplifier, gear, encoder, friction.

    Friction and inertia are in joint terms (after the gear).
    """

    kt_nm_per_a: float          #: motor torque constant (N m / A)
    gear: float                 #: gear ratio (motor turns per joint turn)
    rotor_inertia_kgm2: float   #: rotor inertia on the motor side (kg m^2)
    amp_gain_a: float           #: amplifier current at drive 1.0 (A)
    current_limit_a: float      #: amplifier current limit (A); sets the torque limit
    viscous_nm_s_per_rad: float  #: viscous friction at the joint (N m s / rad)
    coulomb_nm: float           #: Coulomb friction at the joint (N m)
    counts_per_motor_rev: int = 4096  #: encoder counts per motor turn (quadrature)

    def __post_init__(self) -> None:
        for name in ("kt_nm_per_a", "gear", "amp_gain_a", "current_limit_a"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be a positive finite number, got {value!r}")
        for name in ("rotor_inertia_kgm2", "viscous_nm_s_per_rad", "coulomb_nm"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
        if self.counts_per_motor_rev <= 0:
            raise ValueError(f"counts_per_motor_rev must be positive, got "
                             f"{self.counts_per_motor_rev!r}")

    @property
    def torque_limit_nm(self) -> float:
        """The largest joint torque the drive gives: ``Kt * i_limit * gear``."""
        return self.kt_nm_per_a * self.current_limit_a * self.gear

    @property
    def torque_per_drive_nm(self) -> float:
        """Joint torque per unit drive below the current limit: ``Kt * amp_gain * gear``."""
        return self.kt_nm_per_a * self.amp_gain_a * self.gear

    @property
    def counts_per_deg(self) -> float:
        """Encoder counts per degree of the joint."""
        return self.counts_per_motor_rev * self.gear / 360.0

    @property
    def reflected_inertia_kgm2(self) -> float:
        """The rotor's inertia seen at the joint: ``J_rotor * gear**2``."""
        return self.rotor_inertia_kgm2 * self.gear * self.gear


#: Shoulder: a 0.06 N m/A motor, 50:1, 5 A amplifier limited to 4 A: 12 N m.
SHOULDER_DRIVE = MotorParams(kt_nm_per_a=0.06, gear=50.0, rotor_inertia_kgm2=2.0e-5,
                       amp_gain_a=5.0, current_limit_a=4.0,
                       viscous_nm_s_per_rad=0.5, coulomb_nm=0.4)
#: Elbow: a 0.04 N m/A motor, 50:1, 4 A amplifier limited to 3 A: 6 N m.
ELBOW_DRIVE = MotorParams(kt_nm_per_a=0.04, gear=50.0, rotor_inertia_kgm2=1.0e-5,
                    amp_gain_a=4.0, current_limit_a=3.0,
                    viscous_nm_s_per_rad=0.3, coulomb_nm=0.25)


@dataclass(frozen=True)
class PlantParams:
    """The arm's masses, drive trains and end stops; lengths come from ``geometry``.

    Links are uniform rods; the payload is a point mass at the tip.
    """

    geometry: Geometry = GEOMETRY
    m1_kg: float = 2.0          #: link 1 (shoulder to elbow, with the elbow motor)
    m2_kg: float = 1.0          #: link 2 (elbow to tip)
    payload_kg: float = 0.5     #: a point mass at the tip
    motors: tuple[MotorParams, MotorParams] = (SHOULDER_DRIVE, ELBOW_DRIVE)
    #: mechanical end stops (deg), a little beyond the software limits
    hard_stops_deg: tuple[tuple[float, float], tuple[float, float]] = (
        (-178.0, 178.0), (-160.0, 160.0))

    def __post_init__(self) -> None:
        for name in ("m1_kg", "m2_kg"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be a positive mass in kg, got {value!r}")
        if not (math.isfinite(self.payload_kg) and self.payload_kg >= 0.0):
            raise ValueError(f"payload_kg must be a mass >= 0 kg, got {self.payload_kg!r}")
        if len(self.motors) != 2 or len(self.hard_stops_deg) != 2:
            raise ValueError("an arm of two joints needs two motors and two pairs of end stops")
        for j, (low, high) in enumerate(self.hard_stops_deg):
            if not (math.isfinite(low) and math.isfinite(high) and low < high):
                raise ValueError(f"hard_stops_deg[{j}] must be (low, high) with low < high, "
                                 f"got {(low, high)!r}")

    def inertia_terms(self) -> tuple[float, float, float]:
        """``(alpha, beta, delta)`` of ``M = [[alpha + 2 beta cos q1, delta + beta cos q1],
        [delta + beta cos q1, delta]]`` (kg m^2), the rotors excluded."""
        l1 = self.geometry.l1_mm / 1000.0
        l2 = self.geometry.l2_mm / 1000.0
        j1 = self.m1_kg * l1 * l1 / 3.0                       # link 1 about the shoulder
        j2 = self.m2_kg * l2 * l2 / 3.0 + self.payload_kg * l2 * l2  # link 2 about the elbow
        s2 = self.m2_kg * l2 / 2.0 + self.payload_kg * l2     # link 2's first moment
        m2 = self.m2_kg + self.payload_kg
        return j1 + j2 + m2 * l1 * l1, l1 * s2, j2

    def mass_matrix(self, q1_deg: float) -> tuple[tuple[float, float], tuple[float, float]]:
        """``M(q)`` (kg m^2, joint terms), the rotors' reflected inertia included."""
        alpha, beta, delta = self.inertia_terms()
        c = math.cos(q1_deg * _DEG)
        m00 = alpha + 2.0 * beta * c + self.motors[0].reflected_inertia_kgm2
        m01 = delta + beta * c
        m11 = delta + self.motors[1].reflected_inertia_kgm2
        return ((m00, m01), (m01, m11))


def _check_joint(joint: int) -> int:
    if isinstance(joint, bool) or not isinstance(joint, int) or joint not in (0, 1):
        raise ValueError(f"joint must be 0 (q0) or 1 (q1), got {joint!r}")
    return joint


@dataclass
class _Faults:
    jammed: list[bool] = field(default_factory=lambda: [False, False])
    encoder_off: list[bool] = field(default_factory=lambda: [False, False])
    motor_off: list[bool] = field(default_factory=lambda: [False, False])


class Plant:
    """The simulated arm (see the module docstring).

    ``q_deg`` and ``qd_deg_s`` give the starting position (within the end stops) and
    velocity.  ``drive`` and ``amp_enable`` are the inputs, read at each :meth:`step`
    and held over it (a zero-order hold, as a DAC holds its value between servo ticks);
    the amplifiers start enabled with zero drive.
    """

    def __init__(self, params: PlantParams | None = None,
                 q_deg: Sequence[float] = (0.0, 0.0),
                 qd_deg_s: Sequence[float] = (0.0, 0.0),
                 max_step_s: float = MAX_STEP_S) -> None:
        self.params = params if params is not None else PlantParams()
        if not (isinstance(max_step_s, (int, float)) and math.isfinite(max_step_s)
                and 0.0 < max_step_s <= 0.01):
            raise ValueError(f"max_step_s must be a step of 0 .. 10 ms, got {max_step_s!r}")
        #: The longest internal integration step (s).
        self.max_step_s = float(max_step_s)
        q = _pair("q_deg", q_deg)
        qd = _pair("qd_deg_s", qd_deg_s)
        for j in (0, 1):
            low, high = self.params.hard_stops_deg[j]
            if not low <= q[j] <= high:
                raise ValueError(f"{JOINTS[j]} = {q[j]!r} deg lies beyond its end stops "
                                 f"[{low}, {high}] deg")
        #: the amplifiers' commands, -1 .. 1 of full scale (clamped), one per joint
        self.drive: list[float] = [0.0, 0.0]
        #: the amplifiers' enables, one per joint
        self.amp_enable: list[bool] = [True, True]
        self.time_s = 0.0
        self._q = [q[0] * _DEG, q[1] * _DEG]
        self._qd = [qd[0] * _DEG, qd[1] * _DEG]
        self._faults = _Faults()
        self._cpd = [m.counts_per_deg for m in self.params.motors]
        self._count_offset = [0, 0]      # counter = floor(q * cpd) + offset (wrapped)
        self._frozen = [0, 0]            # the counter's value while disconnected
        alpha, beta, delta = self.params.inertia_terms()
        self._alpha = alpha + self.params.motors[0].reflected_inertia_kgm2
        self._beta = beta
        self._delta = delta
        self._m11 = delta + self.params.motors[1].reflected_inertia_kgm2
        self._b = [m.viscous_nm_s_per_rad for m in self.params.motors]
        self._fc = [m.coulomb_nm for m in self.params.motors]
        self._stops = [(lo * _DEG, hi * _DEG) for lo, hi in self.params.hard_stops_deg]
        self._current = [0.0, 0.0]

    # -- inputs ------------------------------------------------------------------------

    def _currents(self) -> list[float]:
        out = [0.0, 0.0]
        for j, motor in enumerate(self.params.motors):
            if not self.amp_enable[j] or self._faults.motor_off[j]:
                continue
            d = max(-1.0, min(1.0, self.drive[j]))
            i = d * motor.amp_gain_a
            out[j] = max(-motor.current_limit_a, min(motor.current_limit_a, i))
        return out

    # -- integration -------------------------------------------------------------------

    def step(self, dt_s: float) -> None:
        """Advance the plant by ``dt_s`` seconds (>= 0) in equal internal steps of at most
        :attr:`max_step_s`.  A drive that is not a finite number is refused (ValueError)
        and nothing changes."""
        if not isinstance(dt_s, (int, float)) or not math.isfinite(dt_s) or dt_s < 0.0:
            raise ValueError(f"dt_s must be a finite number of seconds >= 0, got {dt_s!r}")
        if len(self.drive) != 2 or len(self.amp_enable) != 2:
            raise ValueError("drive and amp_enable must hold one entry per joint (2)")
        for j, d in enumerate(self.drive):
            if isinstance(d, bool) or not isinstance(d, (int, float)) or not math.isfinite(d):
                raise ValueError(f"drive[{j}] must be a finite number, got {d!r}")
        if dt_s == 0.0:
            return
        current = self._currents()
        self._current = current
        v0, v1 = self._qd
        if v0 == 0.0 and v1 == 0.0 and current[0] == 0.0 and current[1] == 0.0:
            self.time_s += dt_s  # at rest, no torque: friction holds it (no gravity)
            return
        n = max(1, math.ceil(dt_s / self.max_step_s - 1e-9))
        h = dt_s / n
        m0, m1 = self.params.motors
        t0 = current[0] * m0.kt_nm_per_a * m0.gear
        t1 = current[1] * m1.kt_nm_per_a * m1.gear
        alpha, beta, delta, m11 = self._alpha, self._beta, self._delta, self._m11
        b0, b1 = self._b
        fc0, fc1 = self._fc
        (lo0, hi0), (lo1, hi1) = self._stops
        free = not (self._faults.jammed[0] or self._faults.jammed[1])
        a11 = m11 + h * b1
        q0, q1 = self._q
        v0, v1 = self._qd
        cos, sin = math.cos, math.sin
        for _ in range(n):
            c = cos(q1)
            hh = beta * sin(q1)
            m00 = alpha + 2.0 * beta * c
            m01 = delta + beta * c
            a00 = m00 + h * b0
            # (M + h B) v+ = M v + h (tau - c(q, v)) + h f, with the Coriolis and
            # centrifugal torques c explicit and f the Coulomb torques
            r0 = m00 * v0 + m01 * v1 + h * (t0 + hh * (2.0 * v0 * v1 + v1 * v1))
            r1 = m01 * v0 + m11 * v1 + h * (t1 - hh * v0 * v0)
            n0 = n1 = 0.0
            solved = False
            if free and v0 != 0.0 and v1 != 0.0:
                # both sliding on: the common case, solved here
                s0 = 1.0 if v0 > 0.0 else -1.0
                s1 = 1.0 if v1 > 0.0 else -1.0
                e0 = r0 - h * fc0 * s0
                e1 = r1 - h * fc1 * s1
                det = a00 * a11 - m01 * m01
                n0 = (a11 * e0 - m01 * e1) / det
                n1 = (a00 * e1 - m01 * e0) / det
                solved = n0 * s0 >= 0.0 and n1 * s1 >= 0.0
            if not solved:
                n0, n1 = self._solve_friction(h, a00, m01, a11, r0, r1, v0, v1)
            q0 += h * n0
            q1 += h * n1
            if q0 <= lo0 or q0 >= hi0:
                q0 = min(max(q0, lo0), hi0)
                n0 = 0.0
            if q1 <= lo1 or q1 >= hi1:
                q1 = min(max(q1, lo1), hi1)
                n1 = 0.0
            v0, v1 = n0, n1
        self._q = [q0, q1]
        self._qd = [v0, v1]
        self.time_s += dt_s

    def _solve_friction(self, h: float, a00: float, a01: float, a11: float,
                        r0: float, r1: float, v0: float, v1: float) -> tuple[float, float]:
        """The new velocities with each joint either sliding (Coulomb torque opposing its
        new velocity) or stuck (velocity zero, the needed torque within the Coulomb
        bound, or unbounded for a jammed joint).  A mode is guessed from the present
        velocities and corrected until it is consistent; the 3 x 3 modes are tried in
        turn if that does not settle."""
        jam = self._faults.jammed
        # mode per joint: 0 stuck, +1 / -1 sliding in that direction
        modes = [0 if (jam[j] or v == 0.0) else (1 if v > 0.0 else -1)
                 for j, v in enumerate((v0, v1))]
        for _ in range(4):
            result = self._try_modes(h, a00, a01, a11, r0, r1, modes)
            if result is None:
                break
            vel, change = result
            if change is None:
                return vel
            modes = change
        for m0 in (0, 1, -1):
            for m1 in (0, 1, -1):
                result = self._try_modes(h, a00, a01, a11, r0, r1, [m0, m1])
                if result is not None and result[1] is None:
                    return result[0]
        # not reached for a positive definite M; stop both joints rather than diverge
        return 0.0, 0.0  # pragma: no cover

    def _try_modes(self, h: float, a00: float, a01: float, a11: float, r0: float, r1: float,
                   modes: list[int]) -> tuple[tuple[float, float], list[int] | None] | None:
        """Solve for one mode; returns the velocities and None if the mode holds, or the
        corrected modes; None if the mode is impossible (a jammed joint set sliding)."""
        jam = self._faults.jammed
        fc = self._fc
        if (jam[0] and modes[0]) or (jam[1] and modes[1]):
            return None
        m0, m1 = modes
        if m0 and m1:
            b0 = r0 - h * fc[0] * m0
            b1 = r1 - h * fc[1] * m1
            det = a00 * a11 - a01 * a01
            v0 = (a11 * b0 - a01 * b1) / det
            v1 = (a00 * b1 - a01 * b0) / det
            f = (-fc[0] * m0, -fc[1] * m1)
        elif m0:
            b0 = r0 - h * fc[0] * m0
            v1 = 0.0
            v0 = b0 / a00
            f = (-fc[0] * m0, (a01 * v0 - r1) / h)
        elif m1:
            b1 = r1 - h * fc[1] * m1
            v0 = 0.0
            v1 = b1 / a11
            f = ((a01 * v1 - r0) / h, -fc[1] * m1)
        else:
            v0 = v1 = 0.0
            f = (-r0 / h, -r1 / h)
        new = list(modes)
        for j, (v, fj) in enumerate(((v0, f[0]), (v1, f[1]))):
            if modes[j]:
                if v * modes[j] < 0.0:
                    new[j] = 0           # would reverse within the step: it sticks
            elif not jam[j] and abs(fj) > fc[j]:
                new[j] = -1 if fj > 0.0 else 1   # friction cannot hold it: it slides
        if new == modes:
            return (v0, v1), None
        return (v0, v1), new

    # -- encoders ----------------------------------------------------------------------

    def _raw_count(self, j: int) -> int:
        return math.floor(self._q[j] / _DEG * self._cpd[j]) + self._count_offset[j]

    def count(self, joint: int) -> int:
        """The encoder counter of ``joint`` (0 or 1): 32-bit signed, wrapping."""
        j = _check_joint(joint)
        if self._faults.encoder_off[j]:
            return self._frozen[j]
        return wrap_int32(self._raw_count(j))

    def counts(self) -> tuple[int, int]:
        """Both encoder counters, ``(count(0), count(1))``."""
        return self.count(0), self.count(1)

    def counts_per_deg(self, joint: int) -> float:
        """Encoder counts per degree of ``joint``."""
        return self._cpd[_check_joint(joint)]

    def preset_encoder(self, joint: int, value: int) -> None:
        """Load the counter of ``joint`` with ``value`` (a 32-bit signed number): it counts
        on from there."""
        j = _check_joint(joint)
        if isinstance(value, bool) or not isinstance(value, int) or not (
                -_TWO31 <= value < _TWO31):
            raise ValueError(f"an encoder preset must be a 32-bit signed integer, got {value!r}")
        if self._faults.encoder_off[j]:
            self._frozen[j] = value
        else:
            self._count_offset[j] += value - self._raw_count(j)

    # -- faults ------------------------------------------------------------------------

    def jam(self, joint: int, on: bool = True) -> None:
        """Jam ``joint`` (a brake): it stops at once and stays put until released."""
        j = _check_joint(joint)
        self._faults.jammed[j] = bool(on)
        if on:
            self._qd[j] = 0.0

    def disconnect_encoder(self, joint: int, on: bool = True) -> None:
        """Disconnect the encoder of ``joint``: its counter freezes; reconnected, it counts
        on from the frozen value (the motion in between is lost)."""
        j = _check_joint(joint)
        if on and not self._faults.encoder_off[j]:
            self._frozen[j] = self.count(j)
        elif not on and self._faults.encoder_off[j]:
            self._count_offset[j] += self._frozen[j] - self._raw_count(j)
        self._faults.encoder_off[j] = bool(on)

    def motor_off(self, joint: int, on: bool = True) -> None:
        """Cut the power of ``joint``'s motor: no current whatever the drive and enable."""
        j = _check_joint(joint)
        self._faults.motor_off[j] = bool(on)
        if on:
            self._current[j] = 0.0

    def motor_powered(self, joint: int) -> bool:
        """False while the power of ``joint``'s motor is cut (:meth:`motor_off`): what an
        amplifier's status line reports, so a controller can see a joint lose power."""
        return not self._faults.motor_off[_check_joint(joint)]

    def clear_faults(self) -> None:
        """Release every injected fault (a disconnected encoder counts on from its frozen
        value)."""
        for j in (0, 1):
            self.jam(j, False)
            self.disconnect_encoder(j, False)
            self.motor_off(j, False)

    def active_faults(self) -> list[str]:
        """The injected faults in force, e.g. ``["q0 jammed", "q1 encoder disconnected"]``."""
        out = []
        for j, name in enumerate(JOINTS):
            if self._faults.jammed[j]:
                out.append(f"{name} jammed")
            if self._faults.encoder_off[j]:
                out.append(f"{name} encoder disconnected")
            if self._faults.motor_off[j]:
                out.append(f"{name} motor off")
        return out

    # -- true state --------------------------------------------------------------------

    @property
    def q_deg(self) -> tuple[float, float]:
        """The true joint angles (deg)."""
        return self._q[0] / _DEG, self._q[1] / _DEG

    @property
    def qd_deg_s(self) -> tuple[float, float]:
        """The true joint rates (deg/s)."""
        return self._qd[0] / _DEG, self._qd[1] / _DEG

    @property
    def tip_mm(self) -> tuple[float, float]:
        """The true tip position ``(x, y)`` (mm)."""
        q0, q1 = self.q_deg
        return fk(q0, q1, self.params.geometry)

    @property
    def current_a(self) -> tuple[float, float]:
        """The motor currents (A) applied over the last step."""
        return self._current[0], self._current[1]

    @property
    def torque_nm(self) -> tuple[float, float]:
        """The motor torques at the joints (N m) applied over the last step."""
        m = self.params.motors
        return (self._current[0] * m[0].kt_nm_per_a * m[0].gear,
                self._current[1] * m[1].kt_nm_per_a * m[1].gear)

    def kinetic_energy_j(self) -> float:
        """The arm's kinetic energy ``qd' M(q) qd / 2`` (J), rotors included."""
        (m00, m01), (_, m11) = self.params.mass_matrix(self._q[1] / _DEG)
        v0, v1 = self._qd
        return 0.5 * (m00 * v0 * v0 + 2.0 * m01 * v0 * v1 + m11 * v1 * v1)


def _pair(name: str, values: Sequence[float]) -> tuple[float, float]:
    if len(values) != 2:
        raise ValueError(f"{name} must hold two values (q0, q1), got {values!r}")
    out = (float(values[0]), float(values[1]))
    if not all(math.isfinite(v) for v in out):
        raise ValueError(f"{name} must be finite numbers, got {values!r}")
    return out
