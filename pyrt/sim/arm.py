"""The simulated arm: any :class:`~pyrt.kinematics.Chain` with inertials,
behind one board of either of 004's two kinds of hardware.

The control code sees only the board's registers:

* (b) the passive servo board (:func:`pyrt.boards.armservo.arm_servo_kind`,
  the default): per joint a DAC (``+-32767`` counts is ``+-Motor.max_current``
  A), an amplifier enable, a brake release and an encoder counter
  (``Motor.counts_per_joint_rev`` per joint turn, 0 at joint value 0), and
  the wrist sensor's six channels (counts of :class:`FTCalibration`); the
  controller's servo writes the DACs at the servo rate;
* (a) the motion-control board (:func:`pyrt.boards.armdrive.arm_drive_kind`,
  ``drive=`` a :class:`DriveTuning`): setpoints at the trajectory rate, the
  board's own servo (csrc/drive.c) interpolating and closing the loop at
  :attr:`DriveTuning.period` on the same encoders and amplifiers, inside the
  world's step (:meth:`ArmWorld.step` runs it between the controller's ticks);
  the board engages each joint's brake while its amplifier is off, so the arm
  stays where it was after a fault.

Physics, per internal step ``h`` (:attr:`ArmWorld.max_step`, default 1 ms;
:meth:`ArmWorld.step` covers any ``dt`` in equal steps of at most that)::

    (M(q) + Ja) qdd = tau_motor - rnea(q, qd, 0, g) - B qd - Fc tanh(qd / vs)
                      + tau_stops + J_tip^T F_contact

* ``M`` the chain's mass matrix (the payload, a point mass at the tool tip,
  folded into the last link), ``Ja = diag(J_rotor G^2)`` the motors' rotor
  inertia seen through the gears (a URDF has no place for it; it dominates
  a geared wrist);
* a DC motor per joint behind a current amplifier: ``i = dac / 32767 *
  max_current`` while enabled, ``tau = Kt G i``; ``max_current`` is the
  effort over ``Kt G``, so the URDF's ``effort`` is the torque limit;
* the URDF's ``damping`` ``B`` and Coulomb ``friction`` ``Fc``, smoothed
  below ``friction_velocity`` ``vs``;
* end stops: beyond each limit by ``stop_margin`` a one-sided spring-damper
  (``stop_stiffness``, default the effort over 0.5 degree; damping ratio
  0.7), so driving into a stop is physical;
* the table: a plane at height ``z`` (world frame) that the tool tip
  (``tip``, a point in the tool frame) may press into: a one-sided
  spring-damper normal force (``table_stiffness`` N/m, ``table_damping``
  N s/m) and Coulomb friction (``table_friction``, smoothed);
* the wrist force/torque sensor in the tool frame reads the wrench that the
  contact and the payload's weight put on the tool, with seeded noise.

Integration is linearly implicit (semi-implicit) Euler: the velocity from
``(M + h D + h^2 K) qd+ = M qd + h f + h D qd`` with ``D`` and ``K`` the
damping and stiffness of the viscous, friction, stop and contact terms
(the stiff ones), the rigid-body terms explicit, then ``q += h qd+``:
stable for the stiff stops and contact at a 1 ms step, and with no
damping or friction it is the symplectic Euler step (energy bounded, not
drifting).

The whole of one :meth:`ArmWorld.step` -- every internal step, then the
encoder counts, the contact and the wrist's counts -- is one call of the C
kernel (csrc/armworld.c through :class:`pyrt.native.ArmKernel`); Python
only carries the board's registers in and out.  The sensor's noise comes
from the kernel's own generator (splitmix64 and Box-Muller from ``seed``,
one draw per step), so a run is reproducible from its seed anywhere; the
same step in Python is kept as the tests' reference (tests/_ref_armworld.py).

The truth (:meth:`ArmWorld.truth`: joints, tool pose, contact force) is for
tests and the operator's ``sim`` words, never for control code.
"""

from __future__ import annotations

import math
from array import array
from collections.abc import Sequence
from dataclasses import dataclass, field
from dataclasses import replace as _replace

import numpy as np
from numpy.typing import ArrayLike

from pyrt.boards.armdrive import arm_drive_kind
from pyrt.boards.armservo import (
    DAC_FULL_SCALE,
    FT_CHANNELS,
    arm_servo_kind,
    input_cells,
    register_cells,
)
from pyrt.boards.registers import RegisterBoard
from pyrt.errors import ConfigError, NativeError
from pyrt.kinematics import GRAVITY, Chain, Inertial
from pyrt.kinematics.chain import inertia_bound
from pyrt.native import ArmKernel, ChainKernels, DriveKernel, tuned_gains

__all__ = [
    "DAC_FULL_SCALE",
    "FT_CHANNELS",
    "PUMA560_MOTORS",
    "ArmPlant",
    "ArmTruth",
    "ArmWorld",
    "DriveTuning",
    "FTCalibration",
    "Motor",
    "default_motors",
    "inertia_bound",
]

@dataclass(frozen=True)
class DriveTuning:
    """A hardware (a) board's servo as it was commissioned: its tick
    ``period`` (s) and each joint's closed loop at a triple real pole at
    ``bandwidth_hz`` (:func:`pyrt.native.tuned_gains` on the joint's largest
    inertia, the rotor's included; the rotor's inertia and the URDF's damping
    as acceleration and velocity feed-forward)."""

    period: float = 1e-3
    bandwidth_hz: float = 12.0
    #: Each joint has a brake (holding the motor's torque limit) that the board engages
    #: while the joint's amplifier is off (a fault, enable 0, a lost link) and releases
    #: while it is on, as a servo drive's brake output does.
    brakes: bool = True

    def __post_init__(self) -> None:
        for name in ("period", "bandwidth_hz"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ConfigError(f"drive {name}: expected a number > 0, got {v!r}")
        if self.bandwidth_hz * self.period > 0.05:
            raise ConfigError(f"drive bandwidth {self.bandwidth_hz} Hz: at most a twentieth "
                              f"of the board's rate ({0.05 / self.period:g} Hz)")


@dataclass(frozen=True)
class Motor:
    """One joint's drive: a DC motor (torque constant ``kt`` N m/A, rotor
    inertia ``rotor_inertia`` kg m^2 on the motor side) through a gear of
    ``gear`` motor turns per joint turn, a current amplifier of full scale
    ``max_current`` A, and an incremental encoder of ``counts_per_rev``
    counts per motor turn (quadrature)."""

    kt: float
    gear: float
    rotor_inertia: float
    max_current: float
    counts_per_rev: int = 4000

    def __post_init__(self) -> None:
        for name in ("kt", "gear", "max_current"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ConfigError(f"motor {name}: expected a number > 0, got {v!r}")
        if not (math.isfinite(self.rotor_inertia) and self.rotor_inertia >= 0):
            raise ConfigError(f"motor rotor_inertia: expected >= 0 kg m^2, "
                              f"got {self.rotor_inertia!r}")
        if isinstance(self.counts_per_rev, bool) or not isinstance(self.counts_per_rev, int) \
                or self.counts_per_rev < 1:
            raise ConfigError(f"motor counts_per_rev: expected an integer >= 1, "
                              f"got {self.counts_per_rev!r}")

    @property
    def torque_limit(self) -> float:
        """The joint torque at full-scale current, ``kt gear max_current`` (N m)."""
        return self.kt * self.gear * self.max_current

    @property
    def reflected_inertia(self) -> float:
        """The rotor's inertia seen at the joint, ``rotor_inertia gear^2`` (kg m^2)."""
        return self.rotor_inertia * self.gear * self.gear

    @property
    def counts_per_joint_rev(self) -> float:
        """Encoder counts per joint turn (or per metre / 2 pi for a prismatic joint)."""
        return self.counts_per_rev * self.gear

    @property
    def amps_per_count(self) -> float:
        """Amplifier current per DAC count (A)."""
        return self.max_current / DAC_FULL_SCALE

    @property
    def nm_per_count(self) -> float:
        """Joint torque per DAC count (N m)."""
        return self.torque_limit / DAC_FULL_SCALE


def _sized(effort: float, kt: float, gear: float, rotor: float, counts: int = 4000) -> Motor:
    return Motor(kt=kt, gear=gear, rotor_inertia=rotor, max_current=effort / (kt * gear),
                 counts_per_rev=counts)


def default_motors(chain: Chain, gear: float = 100.0, kt: float = 0.1) -> tuple[Motor, ...]:
    """A motor per joint sized from its ``effort``: ``gear`` 100, ``kt`` 0.1
    N m/A, full-scale current the effort over ``kt gear``, and a rotor of
    1e-4 kg m^2 per N m of motor torque (a typical servo motor's ratio), so
    the reflected inertia is ``1e-4 effort gear`` (0.2 kg m^2 for 20 N m).
    ConfigError for a joint without an effort limit."""
    out = []
    for j in chain.joints:
        if not (math.isfinite(j.effort) and j.effort > 0):
            raise ConfigError(f"joint {j.name!r} has no effort limit: the simulated arm "
                              f"sizes its motor from it")
        out.append(_sized(j.effort, kt, gear, 1e-4 * j.effort / gear))
    return tuple(out)


#: The PUMA 560's drives (Corke and Armstrong-Helouvry: rotor inertia Jm and
#: gear ratio G per joint, G's sign left out; torque constants of the arm's
#: two motor sizes), full scale at the packaged URDF's effort.
PUMA560_MOTORS: tuple[Motor, ...] = tuple(
    _sized(effort, kt, gear, jm) for effort, kt, gear, jm in (
        (97.6, 0.2611, 62.6111, 200e-6), (186.4, 0.2611, 107.815, 200e-6),
        (89.4, 0.2611, 53.7063, 200e-6), (24.2, 0.0988, 76.0364, 33e-6),
        (20.1, 0.0988, 71.923, 33e-6), (21.3, 0.0988, 76.686, 33e-6)))


@dataclass(frozen=True)
class FTCalibration:
    """The wrist sensor's counts: ``counts_per_n`` for forces,
    ``counts_per_nm`` for torques, ``offsets`` (6 counts) at zero load."""

    counts_per_n: float = 1000.0
    counts_per_nm: float = 10000.0
    offsets: tuple[int, ...] = (0, 0, 0, 0, 0, 0)
    _scale: np.ndarray = field(init=False, repr=False, compare=False)
    _offsets: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        for name in ("counts_per_n", "counts_per_nm"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ConfigError(f"F/T {name}: expected a number > 0, got {v!r}")
        if len(self.offsets) != 6 or not all(isinstance(o, int) for o in self.offsets):
            raise ConfigError(f"F/T offsets: expected 6 integers, got {self.offsets!r}")
        # made once: the controller converts the sensor's counts every trajectory tick
        object.__setattr__(self, "_scale", self.scale)
        object.__setattr__(self, "_offsets", np.asarray(self.offsets, dtype=float))

    @property
    def scale(self) -> np.ndarray:
        """Counts per unit, per channel (6,)."""
        return np.array([self.counts_per_n] * 3 + [self.counts_per_nm] * 3)

    def wrench(self, counts: ArrayLike) -> np.ndarray:
        """The wrench (N, N m; 6,) that register counts give."""
        return (np.array(counts, dtype=float) - self._offsets) / self._scale


@dataclass(frozen=True)
class ArmTruth:
    """The simulated arm's true state: ``time`` (s), joints ``q`` and ``qd``,
    the ``tool`` pose (4, 4) and the ``tip`` point (3,) in the world (m),
    the table's ``contact`` force on the tip (3,, world, N), the noise-free
    ``wrench`` the wrist sensor feels (6,, sensor frame), the motors'
    ``torque`` at the joints (N m) and ``current`` (A)."""

    time: float
    q: np.ndarray
    qd: np.ndarray
    tool: np.ndarray
    tip: np.ndarray
    contact: np.ndarray
    wrench: np.ndarray
    torque: np.ndarray
    current: np.ndarray = field(repr=False)


def _vec(name: str, value: ArrayLike | None, n: int, default: float | np.ndarray) -> np.ndarray:
    if value is None:
        return np.array(np.broadcast_to(default, (n,)), dtype=float)
    v = np.array(value, dtype=float)
    if v.shape == ():
        v = np.full(n, float(v))
    if v.shape != (n,) or not np.isfinite(v).all():
        raise ConfigError(f"{name}: expected {n} finite numbers, got {value!r}")
    return v


class ArmWorld:
    """The simulated arm (see the module text) behind ``board`` (a
    :class:`~pyrt.boards.RegisterBoard` of :func:`~pyrt.boards.armservo.arm_servo_kind`,
    or of :func:`~pyrt.boards.armdrive.arm_drive_kind` with ``drive``; a new
    one if not given).

    ``chain`` the arm (its inertials, limits, ``effort``, ``damping`` and
    ``friction`` are used; ``damping`` and ``friction`` given here override
    the URDF's, per joint or one number for all); ``motors`` one
    :class:`Motor` per joint (default :func:`default_motors`); ``q0`` where
    it starts (default zero, at rest); ``table_z`` the table's height in m
    (None: no table); ``payload`` kg at the tool tip; ``seed`` the F/T
    noise's (an integer 0 .. 2**64 - 1); ``drive`` the hardware (a) board's
    tuning (None: the passive board, hardware (b)); ``brake`` each joint's
    brake's rated holding torque (N m or N; None: none, or the motor's torque
    limit when ``drive`` has brakes; csrc/armworld.h models it as a stiff
    viscous lock): engaged where the passive board's ``release`` register is
    0, or with a drive while the joint's amplifier is off.  ConfigError for
    anything refused.
    """

    def __init__(self, chain: Chain, *, motors: Sequence[Motor] | None = None,
                 board: RegisterBoard | None = None, q0: ArrayLike | None = None,
                 gravity: ArrayLike = GRAVITY, damping: ArrayLike | None = None,
                 friction: ArrayLike | None = None, friction_velocity: float = 0.005,
                 max_step: float = 1e-3, stop_margin: float = math.radians(2.0),
                 stop_stiffness: ArrayLike | None = None, tip: ArrayLike = (0.0, 0.0, 0.0),
                 table_z: float | None = None, table_stiffness: float = 5e4,
                 table_damping: float = 500.0, table_friction: float = 0.3,
                 payload: float = 0.0, ft: FTCalibration | None = None,
                 ft_noise: tuple[float, float] = (0.05, 0.002), seed: int = 0,
                 drive: DriveTuning | None = None, brake: ArrayLike | None = None):
        n = chain.n
        self.n = n
        self.chain = chain
        self.motors = tuple(motors) if motors is not None else default_motors(chain)
        if len(self.motors) != n or not all(isinstance(m, Motor) for m in self.motors):
            raise ConfigError(f"motors: expected {n} Motor, got {len(self.motors)}")
        self.drive = drive
        self.kind = arm_drive_kind(n) if drive is not None else arm_servo_kind(n)
        if board is None:
            board = RegisterBoard(self.kind)
        for reg in self.kind.registers:
            if reg.name not in board.kind or board.kind.register(reg.name).count != reg.count:
                raise ConfigError(f"board {board!r} lacks register {reg.describe()}")
        self.board = board
        self.gravity = _vec("gravity", gravity, 3, 0.0)
        self.damping = _vec("damping", damping, n, np.array([j.damping for j in chain.joints]))
        self.friction = _vec("friction", friction, n,
                             np.array([j.friction for j in chain.joints]))
        if (self.damping < 0).any() or (self.friction < 0).any():
            raise ConfigError("damping and friction must be >= 0")
        for name, v in (("friction_velocity", friction_velocity), ("max_step", max_step),
                        ("table_stiffness", table_stiffness)):
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ConfigError(f"{name}: expected a number > 0, got {v!r}")
        for name, v in (("stop_margin", stop_margin), ("table_damping", table_damping),
                        ("table_friction", table_friction), ("payload", payload)):
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ConfigError(f"{name}: expected a number >= 0, got {v!r}")
        if max_step > 0.01:
            raise ConfigError(f"max_step: at most 10 ms, got {max_step!r}")
        if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 1 << 64:
            raise ConfigError(f"seed: expected an integer 0 .. 2**64 - 1, got {seed!r}")
        self.friction_velocity = float(friction_velocity)
        self.max_step = float(max_step)
        self.tip = _vec("tip", tip, 3, 0.0)
        self.table_stiffness = float(table_stiffness)
        self.table_damping = float(table_damping)
        self.table_friction = float(table_friction)
        self.table_z: float | None = None
        self.ft = ft if ft is not None else FTCalibration()
        sn, st = (float(ft_noise[0]), float(ft_noise[1]))
        if not all(math.isfinite(v) and v >= 0 for v in (sn, st)):
            raise ConfigError(f"ft_noise: expected two numbers >= 0 (N, N m), got {ft_noise!r}")
        self.ft_noise = (sn, st)
        self._armature = np.array([m.reflected_inertia for m in self.motors])
        # a motor stronger than the joint's effort is limited to it (URDF's <limit effort>)
        effort = np.array([min(m.torque_limit, j.effort if j.effort > 0 else math.inf)
                           for m, j in zip(self.motors, chain.joints, strict=True)])
        margin = float(stop_margin)
        self.stop_lower = chain.lower - margin
        self.stop_upper = chain.upper + margin
        self.stop_stiffness = _vec("stop_stiffness", stop_stiffness, n,
                                   np.array([m.torque_limit for m in self.motors])
                                   / math.radians(0.5))
        if (self.stop_stiffness < 0).any():
            raise ConfigError("stop_stiffness must be >= 0")
        q_start = _vec("q0", q0, n, 0.0)
        if ((q_start < self.stop_lower) | (q_start > self.stop_upper)).any():
            raise ConfigError(f"q0 {q_start.tolist()} lies beyond the end stops")
        m_diag = np.diag(chain.mass_matrix(q_start)) + self._armature
        stop_damping = 2.0 * 0.7 * np.sqrt(self.stop_stiffness * m_diag)
        params = {
            "armature": self._armature, "damping": self.damping, "friction": self.friction,
            "stop_lo": self.stop_lower, "stop_hi": self.stop_upper,
            "stop_k": self.stop_stiffness, "stop_c": stop_damping,
            "nm_per_count": [m.nm_per_count for m in self.motors],
            "amps_per_count": [m.amps_per_count for m in self.motors],
            "effort": effort,
            "counts": [m.counts_per_joint_rev / (2.0 * math.pi) for m in self.motors],
        }
        if brake is None and drive is not None and drive.brakes:
            brake = [m.torque_limit for m in self.motors]
        #: Each joint's brake's holding torque (zeros: no brakes).
        self.brake = _vec("brake", brake, n, 0.0)
        if (self.brake < 0).any():
            raise ConfigError("brake: holding torques must be >= 0")
        params["brake"] = self.brake
        try:
            self._k = ArmKernel(
                _kernels(chain), params, max_step=self.max_step,
                friction_velocity=self.friction_velocity, gravity=self.gravity, tip=self.tip,
                table_stiffness=self.table_stiffness, table_damping=self.table_damping,
                table_friction=self.table_friction, ft_scale=self.ft.scale,
                ft_offsets=[float(o) for o in self.ft.offsets],
                ft_sigma=[sn, sn, sn, st, st, st], seed=seed)
        except NativeError as exc:
            raise ConfigError(f"simulated arm {chain.name!r}: {exc}") from None
        k = self._k
        # the brakes: the drive's amplifier enables release them (hardware (a)), or the
        # passive board's release register (hardware (b)); none fitted: zero torques
        k.use_brakes(k.enable if drive is not None else None)
        self._release_in: list[int] = []
        self._drive: DriveKernel | None = None
        if drive is not None:
            gains: dict[str, ArrayLike] = dict(tuned_gains(
                inertia_bound(chain, self._armature), effort, drive.period, drive.bandwidth_hz))
            gains["ka"] = self._armature
            gains["kv"] = self.damping
            try:
                self._drive = DriveKernel(
                    n, drive.period, counts=params["counts"],
                    nm_per_count=params["nm_per_count"], gains=gains, arm=k)
            except NativeError as exc:
                raise ConfigError(f"simulated arm {chain.name!r}: its drive: {exc}") from None
        self._regs: dict[str, list[int]] = {}
        self._status_last: int | None = None
        self._ferr_last: Sequence[int | None] = [None] * n
        # the kernel's own arrays: the state and the truth
        self._q, self._qd = k.q, k.qd
        self._torque, self._current = k.torque, k.current
        self._contact, self._wrench = k.contact, k.wrench
        self._q[:] = q_start
        self._counts: Sequence[int | None] = [None] * n
        self._ft_last: Sequence[int | None] = [None] * 6
        self._dac_in: list[int] = []
        self._on_in: list[int] = []
        self._set_input = board.set_input
        self._values = board.values
        # the fast path: the in-process register file's own storage, read and written in
        # place (None: through set_input and values); the kernel's counts are 32-bit and
        # its sensor's clamped to 32 bits, as the registers declare them
        self._cells = {name: register_cells(board, name) for name in ("dac", "enable", "release")}
        self._in_cells = {name: input_cells(board, name) for name in ("count", "ft")}
        #: The passive board's five registers in place (dac enable release count ft; ft None:
        #: a wired board without the wrist sensor), or None.
        self._direct: tuple[list[int], list[int], list[int], memoryview,
                            memoryview | None] | None = None
        self._pair = n == 2
        #: A wired board's (see :meth:`rewire`): its enables changed on the direct path.
        self._enabled = getattr(board, "amplifiers_enabled", None) if drive is None else None
        self.rewire()
        self.payload = 0.0
        self._dyn = chain
        self.set_payload(float(payload))
        self.time = 0.0
        #: The loop time (ns) :meth:`advance_to` last advanced to (None before the first).
        self._last_ns: int | None = None
        # the kernel's own registers: its counts and sensor out, as lists (numpy's
        # tolist: the quickest way out of C memory)
        self._k_count, self._k_ft = k.count, k.ft
        self._k_step = k.step
        self._k_step_dac = k.step_dac
        if table_z is not None:
            self.set_table(table_z)
        self._publish()

    def rewire(self) -> None:
        """Look up again where the passive board's registers are kept.

        The in-process register file's storage is read and written in place (the
        servo rate's path).  A board wired onto another board's registers (a
        :class:`~pyrt.boards.RegisterBoard` subclass between the world and a
        board of another kind) offers ``world_cells()``: its five registers in
        place, ``(dac, enable, release, count, ft)`` (lists for the outputs,
        writable memoryviews of 64-bit integers for the inputs; ``ft`` None
        where it has no wrist sensor), or None
        while it must be served register by register (``values`` and
        ``set_input``); and may offer ``amplifiers_enabled(enable)``, called on
        that path whenever the enables the kernel takes change.  Such a board
        calls this whenever its answer changes (an injected fault)."""
        self._direct = None
        self._counts, self._ft_last = [None] * self.n, [None] * 6  # the next sets set all
        if self.drive is not None:
            return
        wired = getattr(self.board, "world_cells", None)
        if wired is not None:
            self._direct = wired()
            return
        cells, ins = self._cells, self._in_cells
        dac, on, rel = cells["dac"], cells["enable"], cells["release"]
        count_in, ft_in = ins["count"], ins["ft"]
        if dac is not None and on is not None and rel is not None \
                and count_in is not None and ft_in is not None:
            self._direct = (dac, on, rel, count_in, ft_in)

    # ------------------------------------------------------------ the operator's world

    def set_table(self, z: float | None) -> None:
        """Place the table at height ``z`` (m, world frame), or take it away (None)."""
        if z is not None and not (isinstance(z, (int, float)) and math.isfinite(z)):
            raise ConfigError(f"table height: expected metres, got {z!r}")
        self._k.set_table(None if z is None else float(z))
        self.table_z = None if z is None else float(z)

    def set_payload(self, mass: float) -> None:
        """Grasp a payload of ``mass`` kg at the tool tip (0: none)."""
        if not (isinstance(mass, (int, float)) and math.isfinite(mass) and mass >= 0):
            raise ConfigError(f"payload: expected a mass >= 0 kg, got {mass!r}")
        chain = self.chain
        if mass > 0:
            last = chain.joints[-1]
            at = (chain.tool @ np.array([*self.tip, 1.0]))[:3]
            body = last.inertial + Inertial(mass, at, np.zeros((3, 3)))
            joints = (*chain.joints[:-1], _replace(last, inertial=body))
            dyn = chain.replace(joints=joints)
        else:
            dyn = chain
        self._k.set_payload(float(mass), _kernels(dyn))
        self._dyn = dyn
        self.payload = float(mass)

    def set_state(self, q: ArrayLike, qd: ArrayLike | None = None) -> None:
        """Put the arm at ``q`` moving at ``qd`` (default at rest); the encoders follow."""
        qv = _vec("q", q, self.n, 0.0)
        qdv = _vec("qd", qd, self.n, 0.0)
        self._q[:] = qv
        self._qd[:] = qdv
        self._publish()

    # ------------------------------------------------------------ time

    def advance_to(self, now_ns: int) -> None:
        """Advance to the loop's time ``now_ns`` (ns): by the time since the last
        call (none on the first; a time not later than the last does nothing),
        as :meth:`step`.  The world's step where a station steps it in process."""
        last, self._last_ns = self._last_ns, now_ns
        if last is None or now_ns <= last:
            return
        dt = (now_ns - last) * 1e-9
        if self._direct is not None:
            self._step_direct(dt)
        else:
            self.step(dt)

    def step(self, dt: float) -> None:
        """Advance by ``dt`` seconds (>= 0) in equal internal steps of at
        most :attr:`max_step`, the board's outputs held over it (a DAC holds
        its value between servo ticks); then set the board's inputs.  The
        whole step is one call of the C kernel (csrc/armworld.c)."""
        if dt.__class__ is not float or not 0.0 <= dt < math.inf:
            if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt >= 0):
                raise ValueError(f"dt: expected seconds >= 0, got {dt!r}")
            dt = float(dt)
        if dt == 0:
            return
        if self._direct is not None:  # the register file in place: the servo rate's path
            self._step_direct(dt)
            return
        k = self._k
        if self._drive is not None:
            self._step_driven(dt)
            return
        cells = self._cells
        dac = cells["dac"] or self._values("dac")
        if dac != self._dac_in:  # the amplifiers' new currents
            k.set_dac(dac)
            self._dac_in = dac[:]
        on = cells["enable"] or self._values("enable")
        if on != self._on_in:
            k.set_enable(on)
            self._on_in = on[:]
        release = cells["release"] or self._values("release")
        if release != self._release_in:
            k.release[:] = release
            self._release_in = release[:]
        k.step(dt)
        self.time += dt
        self._set_inputs()

    def _step_direct(self, dt: float) -> None:
        """The passive board's register file in place: the outputs into the kernel
        (those that changed), its step of ``dt`` > 0 s, the inputs out."""
        dac, on, release, count, ft = self._direct  # type: ignore[misc]
        if on != self._on_in:
            self._k.set_enable(on)
            self._on_in = on[:]
            if self._enabled is not None:
                self._enabled(self._on_in)
        if release != self._release_in:
            self._k.release[:] = release
            self._release_in = release[:]
        if dac != self._dac_in:  # the amplifiers' new currents, with the step
            self._k_step_dac(dt, dac)
            self._dac_in = dac[:]
        else:
            self._k_step(dt)
        self.time += dt
        if self._pair:  # two joints: two stores (an array's slice assignment costs more)
            count[0], count[1] = self._k_count.tolist()
        else:
            count[:] = array("q", self._k_count.tolist())
        if ft is not None:
            ft[:] = array("q", self._k_ft.tolist())

    def _step_driven(self, dt: float) -> None:
        """Hardware (a): the board's output registers into its servo, the arm
        advanced with the servo ticking at the board's rate (one C call), then
        the inputs: encoders, wrist, status, following errors."""
        d = self._drive
        assert d is not None
        values, regs = self._values, self._regs
        for name in ("setpoint", "velocity", "torque", "felim"):
            v = values(name)
            if v != regs.get(name):
                getattr(d, name)[:] = v
                regs[name] = v
        scalars = values("enable") + values("sync") + values("period_us")
        if scalars != regs.get("scalars"):
            d.set_registers(enable=scalars[0], sync=scalars[1], period_us=scalars[2])
            regs["scalars"] = scalars
        d.run(dt)
        self.time += dt
        self._set_inputs()
        status = d.status
        if status != self._status_last:
            self._set_input("status", status)
            self._status_last = status
        ferr: list[int] = d.ferr.tolist()
        last = self._ferr_last
        if ferr != last:
            for j, e in enumerate(ferr):
                if e != last[j]:
                    self._set_input("ferr", e, j)
            self._ferr_last = ferr

    def _publish(self) -> None:
        """Compute the inputs at the present state (one draw of the sensor's
        noise) and set them on the board."""
        self._k.publish()
        self._set_inputs()

    def _set_inputs(self) -> None:
        """Set the board's inputs the kernel published: encoder counters and
        the wrist sensor (those that changed)."""
        k = self._k
        count, ft_cells = self._in_cells["count"], self._in_cells["ft"]
        direct = self._direct
        if direct is not None:
            direct[3][:] = array("q", k.count.tolist())
            if direct[4] is not None:
                direct[4][:] = array("q", k.ft.tolist())
            return
        if count is not None and ft_cells is not None:
            count[:] = array("q", k.count.tolist())
            ft_cells[:] = array("q", k.ft.tolist())
            return
        set_input = self._set_input
        counts = k.counts()
        last = self._counts
        if counts != last:
            for j, c in enumerate(counts):
                if c != last[j]:
                    set_input("count", c, j)
            self._counts = counts
        ft = k.ft_counts()
        last = self._ft_last
        if ft != last:
            for j, c in enumerate(ft):
                if c != last[j]:
                    set_input("ft", c, j)
            self._ft_last = ft

    # ------------------------------------------------------------ truth

    def encoder_counts(self) -> list[int]:
        """The encoders' own counters as the last step left them (32-bit signed,
        register order): what a board's ``count`` shows unless something between
        (a wired board's injected fault) changes it."""
        return self._k.counts()

    def truth(self) -> ArmTruth:
        """The true state (copies): for tests and the operator, never for control code."""
        pose = self.chain.fk(self._q)
        tip = (pose @ np.array([*self.tip, 1.0]))[:3]
        return ArmTruth(self.time, self._q.copy(), self._qd.copy(), pose, tip,
                        self._contact.copy(), self._wrench.copy(), self._torque.copy(),
                        self._current.copy())

    def energy(self) -> float:
        """Kinetic (rotors included) plus potential energy (J), zero height at the world's z = 0."""
        dyn, q, qd = self._dyn, self._q, self._qd
        kinetic = 0.5 * float(qd @ (dyn.mass_matrix(q) @ qd) + self._armature @ (qd * qd))
        frames = dyn.frames(q)
        potential = 0.0
        for i, joint in enumerate(dyn.joints):
            f = frames[i + 1]
            com = f[:3, :3] @ joint.inertial.com + f[:3, 3]
            potential -= joint.inertial.mass * float(self.gravity @ com)
        return kinetic + potential

    def info(self) -> dict[str, object]:
        """The truth in words (board-sim's INFO, the operator's ``sim show``):
        joints in degrees, the tip in mm, the contact force in N (and a
        hardware (a) board's status word)."""
        t = self.truth()
        out: dict[str, object] = {f"q{j + 1}": f"{math.degrees(v):.4f}"
                                  for j, v in enumerate(t.q)}
        for axis, v in zip("xyz", t.tip, strict=True):
            out[axis] = f"{v * 1e3:.3f}"
        out["fz"] = f"{t.contact[2]:.3f}"
        out["table"] = "none" if self.table_z is None else f"{self.table_z * 1e3:.1f}"
        out["payload"] = f"{self.payload:g}"
        if self._drive is not None:  # hardware (a): the board's status word
            out["drive"] = f"0x{self._drive.status:04x}"
        return out


def _kernels(chain: Chain) -> ChainKernels:
    """The C kernels of ``chain``'s description, with a workspace of their own
    (the arm's step shares it with no other caller)."""
    joints = chain.joints
    return ChainKernels(
        [j.kind for j in joints], np.array([j.origin for j in joints]),
        np.array([j.axis for j in joints]), chain.offsets, chain.base, chain.tool,
        chain.lower, chain.upper, np.array([j.inertial.mass for j in joints]),
        np.array([j.inertial.com for j in joints]),
        np.array([j.inertial.inertia for j in joints]))


class ArmPlant:
    """An :class:`ArmWorld` as a :class:`pyrt.sim.world.World`'s plant:
    ``step(now_ns)`` advances it by the time since the last call (none on
    the first), ``info()`` is its truth in words."""

    def __init__(self, world: ArmWorld):
        self.world = world

    def step(self, now_ns: int) -> None:
        """Advance the arm to ``now_ns`` (dt = now - last; :meth:`ArmWorld.advance_to`)."""
        self.world.advance_to(now_ns)

    def info(self) -> dict[str, object]:
        """The world's truth for ``sim show`` and board-sim's INFO."""
        return self.world.info()
