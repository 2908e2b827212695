"""A pure-Python reference of csrc/armworld.c: the simulated arm's step as
pyrt.sim.arm computed it in Python (numpy over the kinematics kernels), one
internal step at a time; its sensor noise is drawn from :class:`NoiseSource`,
the C kernel's generator written plainly (splitmix64, Box-Muller)."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import replace as _replace

import numpy as np
from numpy.typing import ArrayLike

from pyrt.boards.armservo import arm_servo_kind
from pyrt.boards.registers import RegisterBoard
from pyrt.errors import ConfigError
from pyrt.kinematics import GRAVITY, Chain, Inertial
from pyrt.sim.arm import ArmTruth, FTCalibration, Motor, _vec, default_motors

#: An engaged brake's creep speed per unit of torque over its rating (csrc/armworld.h's
#: PYRT_ARM_BRAKE_VS).
BRAKE_VS = 1e-4

_solve: Callable[..., np.ndarray] = np.linalg.solve
try:  # numpy's solver without the checks of np.linalg.solve (3x faster for 6 x 6)
    from numpy.linalg._umath_linalg import solve1 as _solve1

    _solve = _solve1
except ImportError:  # pragma: no cover - another numpy
    pass

_INT32 = (-(1 << 31), (1 << 31) - 1)
_TWO32 = 1 << 32
_TWO31 = 1 << 31
_MASK = (1 << 64) - 1


class NoiseSource:
    """splitmix64 over a 64-bit state, uniform (z >> 11) 2**-53, normals by
    Box-Muller pairs (csrc/armworld.h)."""

    def __init__(self, seed: int):
        self.state = seed & _MASK

    def next64(self) -> int:
        self.state = (self.state + 0x9E3779B97F4A7C15) & _MASK
        z = self.state
        z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & _MASK
        z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & _MASK
        return z ^ (z >> 31)

    def uniform(self) -> float:
        return (self.next64() >> 11) * 2.0 ** -53

    def normals6(self) -> list[float]:
        out = []
        for _ in range(3):
            u1 = self.uniform()
            u2 = self.uniform()
            r = math.sqrt(-2.0 * math.log(1.0 - u1))
            out += [r * math.cos(2.0 * math.pi * u2), r * math.sin(2.0 * math.pi * u2)]
        return out


class RefArmWorld:
    """pyrt.sim.arm.ArmWorld's step as it was computed in Python, one
    internal step at a time (the same constructor, calls and registers); the
    F/T noise from :class:`NoiseSource`."""

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
                 brake: ArrayLike | None = None):
        n = chain.n
        #: The brakes' holding torques and whether each is released (the board's register).
        self.brake = _vec("brake", brake, n, 0.0)
        self.release = [1] * n
        self.n = n
        self.chain = chain
        self.motors = tuple(motors) if motors is not None else default_motors(chain)
        if len(self.motors) != n or not all(isinstance(m, Motor) for m in self.motors):
            raise ConfigError(f"motors: expected {n} Motor, got {len(self.motors)}")
        self.kind = arm_servo_kind(n)
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
        self.friction_velocity = float(friction_velocity)
        self.max_step = float(max_step)
        self.tip = _vec("tip", tip, 3, 0.0)
        self._tip_any = bool(self.tip.any())
        self.table_stiffness = float(table_stiffness)
        self.table_damping = float(table_damping)
        self.table_friction = float(table_friction)
        self.table_z: float | None = None
        self.ft = ft if ft is not None else FTCalibration()
        self.ft_noise = (float(ft_noise[0]), float(ft_noise[1]))
        self._rng = NoiseSource(seed)
        sn, st = self.ft_noise
        self._noise = np.array([sn, sn, sn, st, st, st])
        self._ft_scale = self.ft.scale
        self._ft_offsets = np.array(self.ft.offsets, dtype=float)
        self._counts: list[int | None] = [None] * n
        self._dac_in: list[int] = []
        self._on_in: list[int] = []
        self._armature = np.array([m.reflected_inertia for m in self.motors])
        self._nm_per_count = np.array([m.nm_per_count for m in self.motors])
        # a motor stronger than the joint's effort is limited to it (URDF's <limit effort>)
        self._effort = np.array([min(m.torque_limit, j.effort if j.effort > 0 else math.inf)
                                 for m, j in zip(self.motors, chain.joints, strict=True)])
        self._amps_per_count = np.array([m.amps_per_count for m in self.motors])
        self._cpr = np.array([m.counts_per_joint_rev for m in self.motors]) / (2.0 * math.pi)
        margin = float(stop_margin)
        self.stop_lower = chain.lower - margin
        self.stop_upper = chain.upper + margin
        self._has_stops = bool(np.isfinite(self.stop_lower).any()
                               or np.isfinite(self.stop_upper).any())
        effort = np.array([m.torque_limit for m in self.motors])
        self.stop_stiffness = _vec("stop_stiffness", stop_stiffness, n,
                                   effort / math.radians(0.5))
        self.payload = 0.0
        self._dyn = chain
        self.set_payload(float(payload))
        self.time = 0.0
        self._q = _vec("q0", q0, n, 0.0)
        if ((self._q < self.stop_lower) | (self._q > self.stop_upper)).any():
            raise ConfigError(f"q0 {self._q.tolist()} lies beyond the end stops")
        self._qd = np.zeros(n)
        m_diag = np.diag(chain.mass_matrix(self._q)) + self._armature
        self._stop_damping = 2.0 * 0.7 * np.sqrt(self.stop_stiffness * m_diag)
        # preallocated buffers of the step
        self._mass = np.empty((n, n))
        self._mass_diag = self._mass.reshape(-1)[:: n + 1]  # a view of the diagonal
        self._gravity = tuple(float(x) for x in self.gravity)  # the kernels cache a tuple
        self._has_friction = bool(self.friction.any())
        self._inv_vs = 1.0 / self.friction_velocity
        self._fc_vs = self.friction / self.friction_velocity
        self._bias = np.empty(n)
        self._jac = np.empty((6, n))
        self._pose = np.empty((4, 4))
        self._torque = np.zeros(n)
        self._current = np.zeros(n)
        self._contact = np.zeros(3)
        self._wrench = np.zeros(6)
        if table_z is not None:
            self.set_table(table_z)
        self._publish()

    # ------------------------------------------------------------ the operator's world

    def set_table(self, z: float | None) -> None:
        """Place the table at height ``z`` (m, world frame), or take it away (None)."""
        if z is not None and not (isinstance(z, (int, float)) and math.isfinite(z)):
            raise ConfigError(f"table height: expected metres, got {z!r}")
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
            self._dyn = chain.replace(joints=joints)
        else:
            self._dyn = chain
        self.payload = float(mass)

    def set_state(self, q: ArrayLike, qd: ArrayLike | None = None) -> None:
        """Put the arm at ``q`` moving at ``qd`` (default at rest); the encoders follow."""
        qv = _vec("q", q, self.n, 0.0)
        self._q[:] = qv
        self._qd[:] = _vec("qd", qd, self.n, 0.0)
        self._contact_force(self._dyn, with_jacobian=False)
        self._publish()

    # ------------------------------------------------------------ time

    def step(self, dt: float) -> None:
        """Advance by ``dt`` seconds (>= 0) in equal internal steps of at
        most :attr:`max_step`, the board's outputs held over it (a DAC holds
        its value between servo ticks); then set the board's inputs."""
        if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt >= 0):
            raise ValueError(f"dt: expected seconds >= 0, got {dt!r}")
        if dt == 0:
            return
        b = self.board
        self.release = b.values("release")
        dac, on = b.values("dac"), b.values("enable")
        if dac != self._dac_in or on != self._on_in:  # the amplifiers' new currents
            self._dac_in, self._on_in = dac, on
            d = np.array(dac, dtype=float) * np.array(on, dtype=bool)
            self._current = d * self._amps_per_count
            np.clip(d * self._nm_per_count, -self._effort, self._effort, out=self._torque)
        k = max(1, math.ceil(dt / self.max_step - 1e-9))
        h = dt / k
        for _ in range(k):
            self._substep(h)
        self.time += dt
        self._publish()

    def _substep(self, h: float) -> None:
        q, qd, dyn = self._q, self._qd, self._dyn
        mass = dyn.mass_matrix(q, out=self._mass)
        diag = self._mass_diag
        diag += self._armature
        mv = mass @ qd
        bias = dyn.rnea(q, qd, None, self._gravity, out=self._bias)
        # force: every generalised force plus the h D qd term of the linearly
        # implicit step (the viscous damping's cancels); the joint-wise damping
        # and stiffness go onto the diagonal, the contact's into the matrix
        force = self._torque - bias
        diag += h * self.damping
        if self._has_friction:
            th = np.tanh(qd * self._inv_vs)
            dfr = self._fc_vs * (1.0 - th * th)
            force += dfr * qd - self.friction * th
            diag += h * dfr
        for j in range(self.n):  # an engaged brake: a viscous lock of BRAKE / BRAKE_VS
            if not self.release[j]:
                diag[j] += h * self.brake[j] / BRAKE_VS
        if self._has_stops and ((q < self.stop_lower) | (q > self.stop_upper)).any():
            ks, cs = self.stop_stiffness, self._stop_damping
            d_lo = self.stop_lower - q
            d_hi = q - self.stop_upper
            push_lo = (d_lo > 0) & (ks * d_lo - cs * qd > 0)
            push_hi = (d_hi > 0) & (ks * d_hi + cs * qd > 0)
            act = push_lo | push_hi
            # k d - c qd + c qd: the spring's force (the damper's cancels with h D qd)
            force += np.where(push_lo, ks * d_lo, 0.0) - np.where(push_hi, ks * d_hi, 0.0)
            diag += np.where(act, h * cs + h * h * ks, 0.0)
        if self.table_z is not None:
            contact = self._contact_force(dyn, with_jacobian=True)
            if contact is not None:
                jt, cn, kn, ct = contact
                jz = jt[2]
                force += jt.T @ self._contact + cn * jz * (jz @ qd)
                mass += (h * cn + h * h * kn) * np.outer(jz, jz)
                if ct > 0:
                    jxy = jt[:2]
                    mass += h * ct * (jxy.T @ jxy)
                    force += ct * (jxy.T @ (jxy @ qd))
        qd[:] = _solve(mass, mv + h * force)
        q += h * qd

    def _contact_force(self, dyn: Chain, with_jacobian: bool
                       ) -> tuple[np.ndarray, float, float, float] | None:
        """The table's force on the tip (stored in self._contact, world
        frame) and the wrist's wrench; with_jacobian: also the tip's linear
        Jacobian (3, n), the normal damping and stiffness and the
        tangential damping coefficient in effect, or None out of contact."""
        pose = self.chain.fk(self._q, out=self._pose)
        r = pose[:3, :3] @ self.tip
        p = pose[:3, 3] + r
        self._contact[:] = 0.0
        z = self.table_z
        result = None
        if z is not None and p[2] < z:
            jac = self.chain.jacobian(self._q, out=self._jac)
            jv, jw = jac[:3], jac[3:]
            if self._tip_any:
                # v_tip = v + w x r = v - r x w: subtract [r]x Jw
                rx, ry, rz = r
                jt = jv.copy()
                jt[0] -= ry * jw[2] - rz * jw[1]
                jt[1] -= rz * jw[0] - rx * jw[2]
                jt[2] -= rx * jw[1] - ry * jw[0]
            else:
                jt = jv.copy()
            vel = jt @ self._qd
            depth = z - p[2]
            fn = self.table_stiffness * depth - self.table_damping * vel[2]
            if fn > 0:
                vt = math.hypot(vel[0], vel[1])
                vs = 1e-3
                ct = self.table_friction * fn * (math.tanh(vt / vs) / vt if vt > 1e-12
                                                 else 1.0 / vs)
                self._contact[0] = -ct * vel[0]
                self._contact[1] = -ct * vel[1]
                self._contact[2] = fn
                result = (jt, self.table_damping, self.table_stiffness, ct)
        # the wrist's wrench: contact and the payload's weight, at the tip, in the tool frame
        f_world = self._contact + self.payload * self.gravity
        fx, fy, fz = pose[:3, :3].T @ f_world
        tx, ty, tz = self.tip
        w = self._wrench
        w[0], w[1], w[2] = fx, fy, fz
        w[3], w[4], w[5] = ty * fz - tz * fy, tz * fx - tx * fz, tx * fy - ty * fx
        return result if with_jacobian else None

    def _publish(self) -> None:
        """Set the board's inputs: encoder counters and the wrist sensor."""
        b = self.board
        last = self._counts
        for j, c in enumerate(np.floor(self._q * self._cpr).tolist()):
            c = ((int(c) + _TWO31) % _TWO32) - _TWO31
            if c != last[j]:
                b.set_input("count", c, j)
                last[j] = c
        if self.table_z is not None or self.payload > 0:
            self._contact_force(self._dyn, with_jacobian=False)
        else:
            self._contact[:] = 0.0
            self._wrench[:] = 0.0
        noise = np.array(self._rng.normals6()) * self._noise
        counts = np.rint((self._wrench + noise) * self._ft_scale) + self._ft_offsets
        lo, hi = _INT32
        for k, c in enumerate(counts.tolist()):
            b.set_input("ft", int(min(max(c, lo), hi)), k)

    # ------------------------------------------------------------ truth

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
        joints in degrees, the tip in mm, the contact force in N."""
        t = self.truth()
        out: dict[str, object] = {f"q{j + 1}": f"{math.degrees(v):.4f}"
                                  for j, v in enumerate(t.q)}
        for axis, v in zip("xyz", t.tip, strict=True):
            out[axis] = f"{v * 1e3:.3f}"
        out["fz"] = f"{t.contact[2]:.3f}"
        out["table"] = "none" if self.table_z is None else f"{self.table_z * 1e3:.1f}"
        out["payload"] = f"{self.payload:g}"
        return out
