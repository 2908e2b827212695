"""The simulated arm: pyrt's rigid-body world (:class:`pyrt.sim.arm.ArmWorld`, its
step in C) of the arm's URDF, behind the example's servo board.

The arm is described once, in ``arm.urdf`` beside this module (:data:`URDF`:
links, masses, inertias, joint limits, torque limits, viscous and Coulomb
friction); its drive trains are :data:`MOTORS` (a URDF has no place for
them) and it carries :data:`PAYLOAD_KG` at the tip.  :class:`Plant` puts
the world behind a board of the example's kind (:data:`pyrt_arm.boards.SERVO`:
``count``, ``amp_ok``, ``drive``, ``enable`` per joint) and the controller
sees nothing else: the world's own passive servo board is wired onto it
(:class:`_Wiring`): its DACs are the board's ``drive``, its amplifier
enables the board's ``enable`` (cut while a motor's power is off, which the
board's ``amp_ok`` shows), its brakes the jams, and its encoder counters
go to the board's ``count`` through the encoders' faults (a disconnected
encoder's counter freezes; a preset shifts it).  The world reads and writes
through that wiring inside its one call per step: no copy in between.

Physics (the world's; :mod:`pyrt.sim.arm` says it all), per joint::

    (M(q) + J_rotor G^2) qdd + c(q, qd) = tau - b qd - f_c tanh(qd / vs) + tau_stops

with gravity off (the arm lies on a table), each motor behind a current
amplifier (``i = dac / 32767 * amp_gain``, the torque ``Kt G i`` limited to
the URDF's ``effort``, ``Kt i_limit G``), integrated semi-implicitly in
internal steps of at most :data:`MAX_STEP_S`.  Two things differ from a
perfectly rigid, perfectly sticking arm, by choice of the world's model:
Coulomb friction is smoothed below 0.005 rad/s (a joint held by less
torque than its friction creeps, at most a few hundredths of a degree a
second; at rest with no torque nothing moves), and the end stops,
:data:`STOP_MARGIN_DEG` beyond the software limits, are stiff
spring-dampers (the drive's full torque pushes about half a degree into
one) rather than dead stops.  A jam is a brake of :data:`JAM_NM`: the
joint stops at once and stays within a fraction of an encoder count.

Encoders count ``4096`` per motor turn (1024 lines, quadrature) times the gear: 204,800
counts per joint turn, 568.9 per degree.  The counter is ``floor(q * counts per
degree)`` (referenced at zero degrees) and wraps as a 32-bit signed counter.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from pyrt import RegisterBoard
from pyrt.boards.armservo import arm_servo_kind, input_cells, register_cells
from pyrt.kinematics import Chain
from pyrt.sim.arm import ArmWorld, Motor

from pyrt_arm.kinematics import urdf

__all__ = [
    "CHAIN",
    "JAM_NM",
    "JOINTS",
    "MAX_STEP_S",
    "MOTORS",
    "PAYLOAD_KG",
    "STOP_MARGIN_DEG",
    "URDF",
    "Plant",
    "wrap_int32",
]

#: The joints' names, by index.
JOINTS = ("q0", "q1")

#: The arm's URDF (its text; the file ``arm.urdf`` of this package).
URDF = urdf()

#: The arm as a kinematic chain with its inertials (rad, m, kg), from :data:`URDF`.
CHAIN = Chain.from_urdf(URDF)

#: The drive trains: a DC motor (torque constant, rotor inertia on the motor side)
#: through a 50:1 gear, a current amplifier whose full scale (``max_current``, A at
#: drive 1.0) is limited by the URDF's ``effort`` (the shoulder's 5 A amplifier to
#: 4 A: 12 N m; the elbow's 4 A to 3 A: 6 N m), and an encoder of 4096 counts per
#: motor turn.
MOTORS = (Motor(kt=0.06, gear=50.0, rotor_inertia=2.0e-5, max_current=5.0, counts_per_rev=4096),
          Motor(kt=0.04, gear=50.0, rotor_inertia=1.0e-5, max_current=4.0, counts_per_rev=4096))

#: The point mass at the tip (kg).
PAYLOAD_KG = 0.5

#: The mechanical end stops lie this far beyond the software limits (deg): the
#: shoulder's at +-178 deg, the elbow's at +-158 deg (one margin for both joints:
#: the elbow's stops were 160 deg before the arm was described as a URDF).
STOP_MARGIN_DEG = 8.0

#: A jam's brake: its holding torque (N m), far beyond what either motor gives.
JAM_NM = 1000.0

#: The longest internal integration step (s): one servo period.
MAX_STEP_S = 1.0e-3

_TWO32 = 1 << 32
_TWO31 = 1 << 31


def wrap_int32(value: int) -> int:
    """``value`` as a 32-bit signed counter holds it (wrapped into -2**31 .. 2**31 - 1)."""
    return ((value + _TWO31) % _TWO32) - _TWO31


def _check_joint(joint: int) -> int:
    if isinstance(joint, bool) or not isinstance(joint, int) or joint not in (0, 1):
        raise ValueError(f"joint must be 0 (q0) or 1 (q1), got {joint!r}")
    return joint


def _pair(name: str, values: Sequence[float]) -> tuple[float, float]:
    if len(values) != 2:
        raise ValueError(f"{name} must hold two values (q0, q1), got {values!r}")
    out = (float(values[0]), float(values[1]))
    if not all(math.isfinite(v) for v in out):
        raise ValueError(f"{name} must be finite numbers, got {values!r}")
    return out


class _Wiring(RegisterBoard):
    """The world's passive servo board (pyrt's ``arm-servo`` kind), wired onto
    ``board`` (the example's): what the world reads of its outputs and writes
    to its inputs goes to and from ``board`` at once (see the module text).

    On the example's in-process register file (``sim:``) the world reads the
    board's ``drive`` and ``enable`` and writes its ``count`` in place
    (:meth:`world_cells`; the world's ``amp_ok`` follows the enables, through
    :meth:`amplifiers_enabled`) while every motor has power and no encoder is
    shifted or frozen; otherwise, and on any other board, register by register
    through ``values`` and ``set_input``, which apply the faults."""

    def __init__(self, board: RegisterBoard) -> None:
        super().__init__(arm_servo_kind(2))
        self._values_of = board.values
        self._set = board.set_input
        #: the board's own storage of drive, enable and count (None: not in place)
        self._drive = register_cells(board, "drive")
        self._enable = register_cells(board, "enable")
        self._count = input_cells(board, "count")
        #: the world behind it (set once the world is made): its counters, its rewiring
        self.world: ArmWorld | None = None
        #: per joint: the motor has power / the brake is released (no jam; changed in
        #: place)
        self.powered = [True, True]
        self.release = [1, 1]
        #: per joint: the counter's shift (a preset, a reconnection), and its value
        #: while the encoder is disconnected (None: connected)
        self.offset = [0, 0]
        self.frozen: list[int | None] = [None, None]
        self.changed = True          # the power changed: enables and amp_ok again
        self._plain = True           # no encoder offset and none frozen: counts as they come
        self._on_in: list[int] = []
        self._on = [0, 0]
        self._ok = [-1, -1]

    def world_cells(self) -> tuple[list[int], list[int], list[int], memoryview, None] | None:
        """The world's registers in place on the board (dac: ``drive``, enable, the
        jams' brake releases, count; no wrist sensor), while every motor has power and
        the counts go on as they come; else None."""
        drive, enable, count = self._drive, self._enable, self._count
        if drive is None or enable is None or count is None or not self._plain \
                or not all(self.powered):
            return None
        return drive, enable, self.release, count, None

    def amplifiers_enabled(self, enable: list[int]) -> None:
        """The world took new enables (in place, every motor powered): ``amp_ok`` follows."""
        for j, e in enumerate(enable):
            ok = 1 if e else 0
            if ok != self._ok[j]:
                self._set("amp_ok", ok, j)
                self._ok[j] = ok

    def values(self, name: str) -> list[int]:
        if name == "dac":  # the world copies what it keeps: the board's own list will do
            drive = self._drive
            return drive if drive is not None else self._values_of("drive")
        if name == "enable":
            on = self._enable
            if on is None:
                on = self._values_of("enable")
            if on != self._on_in or self.changed:
                self._on_in, self.changed = on[:], False
                self._on = [e if p else 0 for e, p in zip(on, self.powered, strict=True)]
                self.amplifiers_enabled(self._on)
            return self._on
        if name == "release":
            return self.release
        return super().values(name)

    def set_input(self, name: str, value: int, index: int = 0) -> None:
        if name == "count":
            count = self._count
            if self._plain and count is not None:
                count[index] = value
            elif self.frozen[index] is None:
                if self.offset[index]:
                    value = wrap_int32(value + self.offset[index])
                self._set("count", value, index)
            return
        super().set_input(name, value, index)

    def raw(self, j: int) -> int:
        """Joint ``j``'s counter as the world's encoder has it (before any fault)."""
        assert self.world is not None
        return self.world.encoder_counts()[j]

    def rewired(self) -> None:
        """An encoder's offset or freeze, or a motor's power, changed: whether counts
        go on as they come, and the world's path (in place or register by register)."""
        self._plain = not any(self.offset) and all(f is None for f in self.frozen)
        if self.world is not None:
            self.world.rewire()

    def publish(self, j: int) -> None:
        """Joint ``j``'s counter onto the board: frozen, or the encoder's shifted."""
        self.rewired()
        frozen = self.frozen[j]
        self._set("count", frozen if frozen is not None
                  else wrap_int32(self.raw(j) + self.offset[j]), j)


class Plant:
    """The simulated arm behind ``board`` (a :class:`pyrt.RegisterBoard` of the
    example's servo kind, :data:`pyrt_arm.boards.SERVO`): see the module text.

    ``q_deg`` and ``qd_deg_s`` give the starting position (within the end stops) and
    velocity; ``max_step_s`` the longest internal integration step.  The inputs
    are the board's outputs, held over each :meth:`step` (a zero-order hold, as a DAC
    holds its value between servo ticks); its inputs are set at each step.
    ValueError for a start beyond the end stops or a step out of 0 .. 10 ms.
    """

    def __init__(self, board: RegisterBoard, q_deg: Sequence[float] = (0.0, 0.0),
                 qd_deg_s: Sequence[float] = (0.0, 0.0),
                 max_step_s: float = MAX_STEP_S) -> None:
        if not (isinstance(max_step_s, (int, float)) and math.isfinite(max_step_s)
                and 0.0 < max_step_s <= 0.01):
            raise ValueError(f"max_step_s must be a step of 0 .. 10 ms, got {max_step_s!r}")
        q = _pair("q_deg", q_deg)
        qd = _pair("qd_deg_s", qd_deg_s)
        for j, (low, high) in enumerate(self.end_stops_deg):
            if not low <= q[j] <= high:
                raise ValueError(f"{JOINTS[j]} = {q[j]!r} deg lies beyond its end stops "
                                 f"[{low}, {high}] deg")
        self.board = board
        self._wiring = w = _Wiring(board)
        #: The rigid-body world (its truth for tests and the operator: ``world.truth()``).
        self.world = ArmWorld(CHAIN, motors=MOTORS, board=w, q0=np.radians(q),
                              gravity=(0.0, 0.0, 0.0), max_step=float(max_step_s),
                              stop_margin=math.radians(STOP_MARGIN_DEG), payload=PAYLOAD_KG,
                              ft_noise=(0.0, 0.0), brake=[JAM_NM, JAM_NM])
        w.world = self.world
        if qd != (0.0, 0.0):
            self.world.set_state(np.radians(q), np.radians(qd))
        self._cpd = [m.counts_per_joint_rev / 360.0 for m in MOTORS]
        self._kt_gear = [m.kt * m.gear for m in MOTORS]

    @property
    def end_stops_deg(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """The mechanical end stops (deg), :data:`STOP_MARGIN_DEG` beyond the limits."""
        lo, hi = np.degrees(CHAIN.lower), np.degrees(CHAIN.upper)
        m = STOP_MARGIN_DEG
        return ((float(lo[0]) - m, float(hi[0]) + m), (float(lo[1]) - m, float(hi[1]) + m))

    @property
    def time_s(self) -> float:
        """The simulated time (s) the arm has been advanced by."""
        return self.world.time

    def step(self, dt_s: float) -> None:
        """Advance the arm by ``dt_s`` seconds (>= 0; ValueError otherwise, nothing
        changed) with the board's outputs held, then set the board's inputs."""
        self.world.step(dt_s)

    # -- encoders ----------------------------------------------------------------------

    def count(self, joint: int) -> int:
        """The encoder counter of ``joint`` (0 or 1) as the board shows it: 32-bit
        signed, wrapping."""
        return self.board.read("count", _check_joint(joint))

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
        w = self._wiring
        if w.frozen[j] is not None:
            w.frozen[j] = value
        else:
            w.offset[j] = value - w.raw(j)
        w.publish(j)

    # -- faults ------------------------------------------------------------------------

    def jam(self, joint: int, on: bool = True) -> None:
        """Jam ``joint`` (a brake): it stops at once and stays put until released."""
        j = _check_joint(joint)
        self._wiring.release[j] = 0 if on else 1  # in place: the world compares it each step
        if on:
            t = self.world.truth()
            qd = t.qd.copy()
            qd[j] = 0.0
            self.world.set_state(t.q, qd)

    def disconnect_encoder(self, joint: int, on: bool = True) -> None:
        """Disconnect the encoder of ``joint``: its counter freezes; reconnected, it counts
        on from the frozen value (the motion in between is lost)."""
        j = _check_joint(joint)
        w = self._wiring
        frozen = w.frozen[j]
        if on and frozen is None:
            w.frozen[j] = self.count(j)
            w.rewired()
        elif not on and frozen is not None:
            w.offset[j] = frozen - w.raw(j)
            w.frozen[j] = None
            w.publish(j)

    def motor_off(self, joint: int, on: bool = True) -> None:
        """Cut the power of ``joint``'s motor: no current whatever the drive and enable
        (from the next step; the board's ``amp_ok`` then shows it)."""
        j = _check_joint(joint)
        self._wiring.powered[j] = not on
        self._wiring.changed = True
        self._wiring.rewired()

    def motor_powered(self, joint: int) -> bool:
        """False while the power of ``joint``'s motor is cut (:meth:`motor_off`): what an
        amplifier's status line reports, so a controller can see a joint lose power."""
        return self._wiring.powered[_check_joint(joint)]

    def clear_faults(self) -> None:
        """Release every injected fault (a disconnected encoder counts on from its frozen
        value)."""
        for j in (0, 1):
            self.jam(j, False)
            self.disconnect_encoder(j, False)
            self.motor_off(j, False)

    def active_faults(self) -> list[str]:
        """The injected faults in force, e.g. ``["q0 jammed", "q1 encoder disconnected"]``."""
        w = self._wiring
        out = []
        for j, name in enumerate(JOINTS):
            if not w.release[j]:
                out.append(f"{name} jammed")
            if w.frozen[j] is not None:
                out.append(f"{name} encoder disconnected")
            if not w.powered[j]:
                out.append(f"{name} motor off")
        return out

    # -- true state --------------------------------------------------------------------

    @property
    def q_deg(self) -> tuple[float, float]:
        """The true joint angles (deg)."""
        q = self.world.truth().q
        return math.degrees(q[0]), math.degrees(q[1])

    @property
    def qd_deg_s(self) -> tuple[float, float]:
        """The true joint rates (deg/s)."""
        qd = self.world.truth().qd
        return math.degrees(qd[0]), math.degrees(qd[1])

    @property
    def tip_mm(self) -> tuple[float, float]:
        """The true tip position ``(x, y)`` (mm)."""
        tip = self.world.truth().tip
        return float(tip[0]) * 1e3, float(tip[1]) * 1e3

    @property
    def torque_nm(self) -> tuple[float, float]:
        """The motor torques at the joints (N m) applied over the last step."""
        tau = self.world.truth().torque
        return float(tau[0]), float(tau[1])

    @property
    def current_a(self) -> tuple[float, float]:
        """The motor currents (A) applied over the last step (within the limits)."""
        t0, t1 = self.torque_nm
        return t0 / self._kt_gear[0], t1 / self._kt_gear[1]

    def kinetic_energy_j(self) -> float:
        """The arm's kinetic energy ``qd' M(q) qd / 2`` (J), rotors included."""
        return self.world.energy()  # no gravity: no potential energy
