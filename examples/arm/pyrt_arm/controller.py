"""The arm's controller: the root component ``arm`` and its joints ``shoulder`` (q0) and
``elbow`` (q1), on pyrt's arm layer.

Two tasks: ``trajectory`` every :data:`TRAJECTORY_PERIOD` ticks (100 Hz) and
``servo`` every tick.  The arm is a :class:`pyrt.kinematics.Chain`
(:data:`CHAIN`, from its URDF); ``arm to`` and ``arm xy`` queue a joint-mode
:class:`pyrt.motion.MotionSpec` on a :class:`pyrt.motion.Evaluator` (planned
when queued, in the console's thread, not in a loop tick; within
:data:`VMAX_DEG_S` and :data:`AMAX_DEG_S2`; a move queued behind the running one
blends into it by Paul's transition).  The trajectory task hands each knot
(position, velocity, the Coulomb friction as feed-forward) to pyrt's servo
(:class:`pyrt.native.Servo`, C: cubic interpolation to the servo rate, the
arm's PD law and gains, :mod:`pyrt_arm.servo`); the servo task runs it on the
board's counters and writes the DAC counts that changed (the encoders, the
law, the joints' bounds and the counts in one C call,
:class:`pyrt.native.ServoBoard`).  A plug-in motion type (``motion joint_trajectory``)
drives the same servo through :meth:`ArmController.command_joints`.

The amplifiers are on while a move runs and until the arm has settled at its
target (within :data:`AT_TARGET_DEG`, at rest for :data:`SETTLE_S`); then
every drive is 0 and every amplifier off, and the arm lies on its friction
(on a table: no gravity).  A following error beyond 1 deg, a joint outside
its limits or an amplifier without power calls :meth:`pyrt.Component.fail`:
in that tick every joint's reflex writes drive 0 and enable 0.  ``stop``
brakes the servo's reference to rest at the acceleration limits, then
switches the amplifiers off.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from pyrt import (
    Arg,
    CommandError,
    Component,
    JointStates,
    JointTrajectory,
    Limits,
    Signal,
    Task,
    command,
)
from pyrt.boards.registers import bound_writer
from pyrt.component import PREPARE_TRIES, Stale
from pyrt.kinematics import Chain
from pyrt.motion import Evaluator, MotionFault, MotionSpec, RecordError
from pyrt.motion import Limits as MotionLimits
from pyrt.motion.evaluator import Planned, QueueSnapshot, StalePlan
from pyrt.native import ServoBoard

from pyrt_arm.boards import DRIVE_FULL_SCALE
from pyrt_arm.kinematics import GEOMETRY, KinematicsError, elbow_of, fk, ik, urdf
from pyrt_arm.plant import JOINTS
from pyrt_arm.servo import (
    ELBOW,
    FOLLOWING_ERROR_LIMIT_DEG,
    SHOULDER,
    JointServoConfig,
    arm_servo,
    counts_to_deg,
    following_error_fault,
    joint_limit_fault,
)

if TYPE_CHECKING:
    from pyrt_arm.station import ArmStation

__all__ = [
    "AMAX_DEG_S2",
    "AT_TARGET_DEG",
    "CHAIN",
    "MOTION_TYPES",
    "SETTLE_S",
    "TIP_TOLERANCE_MM",
    "TRAJECTORY_PERIOD",
    "VMAX_DEG_S",
    "ArmController",
    "Joint",
]

#: The joints' velocity limits (deg/s): what the servo is tuned and tested for.
VMAX_DEG_S = (90.0, 90.0)
#: The joints' acceleration limits (deg/s^2).
AMAX_DEG_S2 = (360.0, 360.0)
#: The trajectory task's period, in ticks (100 Hz at the 1 ms tick).
TRAJECTORY_PERIOD = 10
#: A move has ended "at target" when every joint's following error is this small (deg) ...
AT_TARGET_DEG = 0.05
#: ... and its measured speed below this (deg/s) ...
SETTLED_SPEED_DEG_S = 2.0
#: ... for this long (s); then the amplifiers are switched off.
SETTLE_S = 0.02
#: The longest the servo waits for the arm to settle after the setpoint has stopped (s).
SETTLE_TIMEOUT_S = 1.0
#: The tip ``status`` gives (from the encoders) lies within this of the true tip (mm)
#: once the arm is at rest: the encoders' quantisation, 1/569 deg per joint.
TIP_TOLERANCE_MM = 0.05
#: Servo ticks in a row with an amplifier reporting no power before that is a fault.
AMP_GRACE_TICKS = 5

#: The arm as a kinematic chain (rad, m), from its URDF.
CHAIN = Chain.from_urdf(urdf())

#: The plug-in motion types the arm runs besides its own moves (``motion NAME ...``):
#: pyrt's joint trajectory, registered by its import here.
MOTION_TYPES = (JointTrajectory.name,)

_REACH = GEOMETRY.r_max_mm
_DEG = 180.0 / math.pi
_TWO31, _TWO32 = 1 << 31, 1 << 32


#: Trajectory periods a move from rest on a running evaluator leaves for its planning.
PLAN_LEAD = 2
#: How far (deg) the arm, amplifiers off, may have drifted from where a move was
#: planned to start before it is planned again (a fifth of the following-error limit:
#: the servo, closing the loop where the arm is, takes the difference).
START_SLIP_DEG = 0.2


@dataclass(frozen=True)
class MoveSnapshot:
    """What planning a move needs, copied in the loop: the evaluator and its
    queue's end; ``rest``: the encoders' angles (deg) when the amplifiers were
    off (the evaluator is then a new one there), else None; the elbow (deg)."""

    evaluator: Evaluator
    queue: QueueSnapshot
    rest: tuple[float, float] | None
    elbow_deg: float


@dataclass(frozen=True)
class MoveWork:
    """A move planned in the caller's thread, and the words of its target."""

    snapshot: MoveSnapshot
    planned: Planned
    to: str


def _joint_limits(config: JointServoConfig) -> Limits:
    low, high = config.limits_deg
    return Limits(low, high, lolo=low, low=low, high=high, hihi=high)


_FERR = Limits(-FOLLOWING_ERROR_LIMIT_DEG, FOLLOWING_ERROR_LIMIT_DEG,
               lolo=-FOLLOWING_ERROR_LIMIT_DEG, low=-0.5 * FOLLOWING_ERROR_LIMIT_DEG,
               high=0.5 * FOLLOWING_ERROR_LIMIT_DEG, hihi=FOLLOWING_ERROR_LIMIT_DEG)
_TIP = Limits(-_REACH, _REACH)


class Joint(Component):
    """One joint: its board registers (``count``, ``amp_ok``, ``drive``, ``enable`` at its
    index), what the servo says of it, and its reflex (drive 0, amplifier disabled)."""

    def __init__(self, arm: ArmController, index: int, config: JointServoConfig) -> None:
        self.name = ("shoulder", "elbow")[index]
        self.arm = arm
        self.index = index
        self.board = arm.board
        self.config = config
        self.limits_deg = config.limits_deg
        #: True while the amplifier is enabled and the servo closes the loop.
        self.engaged = False
        self.no_power = 0

    @property
    def limits_deg(self) -> tuple[float, float]:
        """Where the measured angle may go before that is a fault (deg): the servo's
        bounds of this joint (checked in its C tick)."""
        io, j = self.arm.io, self.index
        return math.degrees(float(io.lo[j])), math.degrees(float(io.hi[j]))

    @limits_deg.setter
    def limits_deg(self, limits: tuple[float, float]) -> None:
        io, j = self.arm.io, self.index
        io.lo[j], io.hi[j] = math.radians(limits[0]), math.radians(limits[1])

    def signals(self) -> list[Signal]:
        s, j = self.arm.servo, self.index
        return [
            Signal(f"q{j}", "deg", self.position, f"{self.name} angle (encoder)", ".4f",
                   limits=_joint_limits(self.config)),
            Signal("setpoint", "deg", lambda: float(s.q_ref[j]) * _DEG, "servo setpoint", ".4f"),
            Signal("error", "deg", lambda: self.error_deg, "following error", ".4f",
                   limits=_FERR),
            Signal("velocity", "deg/s", lambda: float(s.velocity[j]) * _DEG, "measured speed",
                   ".3f"),
            Signal("drive", "DAC counts", lambda: self.drive, "amplifier command", "d"),
            Signal("enabled", "bool", lambda: self.engaged, "amplifier enabled", "d"),
        ]

    @property
    def drive(self) -> int:
        """The drive last written (DAC counts): the servo's count of this joint."""
        return int(self.arm.io.dac[self.index])

    @property
    def error_deg(self) -> float:
        """The servo's following error (deg) while engaged, else 0."""
        return float(self.arm.servo.error[self.index]) * _DEG if self.engaged else 0.0

    def measure(self, count: int) -> float:
        """The joint angle (deg) the counter reading ``count`` gives: the middle of the
        count, as the servo measures it."""
        cpd = self.config.counts_per_deg
        return counts_to_deg(count, self.config.zero_count, cpd) + 0.5 / cpd

    def position(self) -> float:
        """The joint angle the encoder gives (deg)."""
        return self.measure(self.board.read("count", self.index))

    def engage(self) -> None:
        self.no_power = 0
        self.arm.io.dac[self.index] = 0  # the servo's last count: what the board holds
        self.board.write("drive", 0, self.index)
        self.board.write("enable", 1, self.index)
        self.engaged = True

    def reflex(self) -> None:
        """Drive 0 and amplifier disabled, now; the joint's state cleared whatever happens."""
        try:
            self.board.write("drive", 0, self.index)
        finally:
            try:
                self.board.write("enable", 0, self.index)
            finally:
                self.engaged = False
                self.no_power = 0
                self.arm.io.dac[self.index] = 0


class ArmController(Component):
    """The arm (the root component, and the robot ``joint_trajectory`` drives)."""

    name = "arm"
    joint_count = 2
    #: The joints as viewers take them (scope foxglove, pyrt export): the URDF's names.
    joint_states = JointStates(names=("shoulder", "elbow"), position=("q0", "q1"),
                               velocity=("shoulder.velocity", "elbow.velocity"), urdf=urdf())

    def __init__(self, station: ArmStation, board: Any, period_ns: int,
                 configs: Sequence[JointServoConfig] = (SHOULDER, ELBOW)) -> None:
        self.station = station
        self.board = board
        #: pyrt's servo with the arm's gains (``configs``: the shoulder's, the elbow's).
        self.servo = arm_servo(configs, period_ns * 1e-9)
        # the board's side of the servo (one C call a tick: the encoders unwrapped, the
        # law, the joints' bounds, the DAC counts); where count and amp_ok are in the
        # board's snapshot of its inputs; each joint's Coulomb friction (N m)
        layout = [(r.name, i) for r in board.kind.inputs() for i in range(r.count)]
        at = [layout.index(("count", j)) for j in range(len(configs))]
        self._counts_at = slice(at[0], at[-1] + 1)
        assert at == list(range(at[0], at[-1] + 1)), "the counters lie side by side"
        self._ok_at = [layout.index(("amp_ok", j)) for j in range(len(configs))]
        self._no_power = False  # a joint's amplifier has reported no power lately
        # each joint's drive written through a write bound once (a process image's:
        # one call into the image a write)
        self._drive_writers = [bound_writer(board, "drive", j) for j in range(len(configs))]
        self._drive0, self._drive1 = self._drive_writers
        counts = board.snapshot()[self._counts_at]
        self.io = io = ServoBoard(self.servo, [c.counts_per_deg * _DEG for c in configs], counts,
                                  [DRIVE_FULL_SCALE / c.torque_per_drive_nm for c in configs],
                                  DRIVE_FULL_SCALE)
        io.total -= np.array([c.zero_count for c in configs], np.int64)  # 0 at the zero count
        # the servo task's every tick: the board's inputs, the servo's one C call (it
        # answers the joints whose DAC count changed, or -1 when there is more to see)
        self._inputs = board.snapshot
        self._tick = self.servo.board_ticker(io)
        self._dac = io.dac
        self.joints = (Joint(self, 0, configs[0]), Joint(self, 1, configs[1]))  # their bounds
        self._kc = np.array([c.kc_nm for c in configs])
        self._kc_list = self._kc.tolist()
        self._ffb = self.servo.knots[7]  # the feed-forward at knot B (a view: its row)
        self._half_tick = 0.5 * period_ns * 1e-9  # half a servo period (s)
        self.limits = MotionLimits(tuple(math.radians(v) for v in VMAX_DEG_S),
                                   tuple(math.radians(a) for a in AMAX_DEG_S2))
        self.traj_period_s = TRAJECTORY_PERIOD * period_ns * 1e-9
        #: The arm's queued motion while the servo holds it (None: amplifiers off).
        self.evaluator: Evaluator | None = None
        #: How the last move ended ('' before any).
        self.last_stop = ""
        #: What the arm does: idle, moving, settling, braking.
        self.state = "idle"
        self._now_ns = self._settle_from = 0
        self._reason = "at target"
        self._ended = True  # the knots have stopped coming: the servo holds the last one
        self._joined = False  # the servo's segments follow each other in time
        self._seg_end = 0.0  # where the servo's segment ends (s, the loop's clock)
        self._quiet_since: int | None = None

    # -- the component ----------------------------------------------------------------

    def signals(self) -> list[Signal]:
        sh, el = self.joints
        return [
            Signal("q0", "deg", sh.position, "shoulder angle (encoder)", ".4f",
                   limits=_joint_limits(sh.config)),
            Signal("q1", "deg", el.position, "elbow angle (encoder)", ".4f",
                   limits=_joint_limits(el.config)),
            Signal("x", "mm", lambda: self.tip()[0], "tip x (encoders)", ".3f", limits=_TIP),
            Signal("y", "mm", lambda: self.tip()[1], "tip y (encoders)", ".3f", limits=_TIP),
            Signal("ferr0", "deg", lambda: sh.error_deg, "shoulder following error", ".4f",
                   limits=_FERR),
            Signal("ferr1", "deg", lambda: el.error_deg, "elbow following error", ".4f",
                   limits=_FERR),
            Signal("moving", "bool", lambda: self.state != "idle", "a move runs or settles", "d"),
        ]

    def children(self) -> list[Component]:
        return list(self.joints)

    def tasks(self) -> list[Task]:
        return [Task(self.trajectory_tick, period=TRAJECTORY_PERIOD, name="trajectory",
                     timed=True),
                Task(self.servo_tick, period=1, name="servo", timed=True)]

    def reflex(self) -> None:
        """The motion dropped, the move ended (the joints' reflexes cut the drives)."""
        try:
            if self.state != "idle":
                self.last_stop = "stopped: every motor off"
        finally:
            self.state = "idle"
            self.evaluator = None
            self._ended = True
            self._joined = False
            self._quiet_since = None

    # -- where it is --------------------------------------------------------------------

    def angles(self) -> tuple[float, float]:
        """The joint angles the encoders give (deg)."""
        return self.joints[0].position(), self.joints[1].position()

    def tip(self) -> tuple[float, float]:
        return fk(*self.angles())  # the tip the encoders give (mm)

    def where(self, q: Sequence[float] | None = None) -> str:
        """The joints ``q`` (default: the encoders') and the tip, in the operator's words."""
        q0, q1 = self.angles() if q is None else q
        return "q0 {:.3f} deg, q1 {:.3f} deg, tip ({:.2f}, {:.2f}) mm".format(q0, q1, *fk(q0, q1))

    # -- JointRobot: what a plug-in motion type drives -----------------------------------

    def joint_positions(self) -> Sequence[float]:
        """Where the servo's reference is heading (its last knot) while the servo holds the
        arm, else the encoders' angles (deg)."""
        if self.state != "idle":
            q = self.servo.knots[3]
            return float(q[0]) * _DEG, float(q[1]) * _DEG
        return self.angles()

    def joint_limits(self) -> tuple[Sequence[float], Sequence[float]]:
        return VMAX_DEG_S, AMAX_DEG_S2

    def joint_range(self) -> tuple[Sequence[float], Sequence[float]]:
        (l0, h0), (l1, h1) = GEOMETRY.limits_deg
        return (l0, l1), (h0, h1)

    def command_joints(self, q: Sequence[float], qd: Sequence[float]) -> None:
        """A knot (deg, deg/s): the servo's next segment; the first one engages the servo."""
        if self.state == "idle":
            self._engage()
        self.state = "moving"
        self._load(np.radians(q), np.radians(qd), self.traj_period_s)

    def motion_ended(self, reason: str) -> None:
        """The plug-in motion ended: the servo ends at its last knot, or, if the motion
        ended moving, brakes to rest (never extrapolated); the arm settles there."""
        if self.state != "moving":
            return
        if self.servo.knots[4].any():
            self._to_rest()
        else:
            self.evaluator = self._evaluator(self.servo.knots[3])
            self._end_of_knots(self._now_ns)

    # -- the servo ------------------------------------------------------------------------

    def _evaluator(self, q: Any) -> Evaluator:  # the next move starts at q
        start = np.clip(np.asarray(q, dtype=float), CHAIN.lower, CHAIN.upper)
        return Evaluator(CHAIN, self.limits, start, period=self.traj_period_s)

    def _engage(self, evaluator: Evaluator | None = None) -> None:
        """Close the loop where the arm is (the trajectory starts there: ``evaluator``,
        one made there, or a new one), amplifiers on."""
        self.io.encoders(self.board.snapshot()[self._counts_at])
        q = self.servo.q.copy()  # where the servo measures the arm (mid-count)
        self.servo.reset(q, now=self._now_ns * 1e-9)
        self._joined = False
        self.servo.segment(self.traj_period_s, q, np.zeros(2), q, np.zeros(2))
        self._seg_end = self.servo.end
        self.evaluator = evaluator if evaluator is not None else self._evaluator(q)
        for jt in self.joints:
            jt.engage()
        self._ended = True
        self._quiet_since = None

    def _load(self, q: Any, qd: Any, duration: float) -> None:
        """The servo's next segment: the cubic from the last knot to this one (position
        and velocity) in ``duration`` s; the Coulomb friction ``kc sign(qd)`` at each
        knot as its feed-forward, interpolated between them."""
        k = self.servo.knots
        k[0:2] = k[3:5]
        k[3], k[4] = q, qd
        k[6] = k[7]  # the Coulomb friction fed forward, in the motion's direction at B
        (c0, c1), (v0, v1), ff = self._kc_list, qd.tolist(), self._ffb
        ff[0] = c0 if v0 > 0.0 else (-c0 if v0 < 0.0 else 0.0)  # kc sign(qd), on floats
        ff[1] = c1 if v1 > 0.0 else (-c1 if v1 < 0.0 else 0.0)
        # on the loop's clock: where the last segment ended, or now for a motion's first
        servo = self.servo
        start = self._seg_end if self._joined else max(servo.now + servo.period,
                                                        self._now_ns * 1e-9)
        servo.load(duration, quintic=False, start=start)
        self._seg_end = servo.end
        self._ended = False
        self._joined = True

    def _end_of_knots(self, now_ns: int) -> None:  # the servo holds the last one; settle
        self._ended, self._settle_from, self._quiet_since = True, now_ns, None
        if self.state == "moving":
            self.state = "settling"

    def trajectory_tick(self, now_ns: int) -> None:
        """100 Hz: a plug-in motion steps (its knots come by command_joints), or the
        evaluator's knot goes to the servo as its next segment."""
        self._now_ns = now_ns
        executor = self.station.executor
        executor.poll(now_ns)
        ev = self.evaluator
        if executor.busy or ev is None or self.state == "idle":
            return
        self._next_knot(now_ns, ev)

    def _next_knot(self, now_ns: int, ev: Evaluator) -> None:
        """The evaluator's knot for the time that really passed as the servo's next
        segment; the knots a stall of the loop passed over are evaluated on the way."""
        held = now_ns * 1e-9 + self._half_tick  # (the servo's end is _seg_end, kept with it)
        if self._joined and self._seg_end > held:
            return  # the segment running holds now: its knot is made
        try:
            knot = ev.tick()
            while self._joined and self._seg_end + knot.period <= held:
                self._load(knot.q, knot.qd, knot.period)  # a knot the stall passed over
                knot = ev.tick()
        except MotionFault as exc:
            self.fail(f"trajectory: {exc}", self.name)
            return
        # moving, or not where the last knot was (on floats: an array's any() costs more)
        if any(knot.qd.tolist()) or any(knot.qdd.tolist()) \
                or knot.q.tolist() != self.servo.knots[3].tolist():
            self._load(knot.q, knot.qd, knot.period)
        else:
            self._joined = False
            if ev.idle and not self._ended:
                self._end_of_knots(now_ns)

    def servo_tick(self, now_ns: int) -> None:
        """1 kHz: the encoders, pyrt's servo law and the joints' bounds in one C call, the
        drives that changed written; the checks; settling."""
        self._now_ns = now_ns
        if self.state == "idle":
            return
        inputs = self._inputs()  # one read of every input: this tick's
        counts = inputs[self._counts_at]
        now = now_ns * 1e-9
        if self._joined and now > self._seg_end + self._half_tick:
            ev = self.evaluator
            if ev is not None and not self.station.executor.busy:
                self.io.encoders(counts)
                self._next_knot(now_ns, ev)  # the loop stalled past the segment: its knot, now
                if self.state == "idle":
                    return
        changed = self._tick(now, counts)
        if changed < 0 and self._tick_seen():  # tripped or beyond its bounds: failed
            return
        if changed:  # the drives whose counts changed (the two joints')
            d0, d1 = self._dac.tolist()
            if changed & 1:
                self._drive0(d0)
            if changed & 2:
                self._drive1(d1)
        ok0, ok1 = self._ok_at
        if not (inputs[ok0] and inputs[ok1]) or self._no_power:
            self._no_power = False
            for jt, at in zip(self.joints, self._ok_at, strict=True):
                jt.no_power = 0 if inputs[at] else jt.no_power + 1
                self._no_power = self._no_power or jt.no_power > 0
                if jt.no_power >= AMP_GRACE_TICKS:
                    self.fail(f"{JOINTS[jt.index]} amplifier reports no power", jt.name)
                    return
        if self._ended and self.servo.late > 0:
            self._settle(now_ns)

    def _tick_seen(self) -> bool:
        """The servo's tick did more than change drives: a trip (the fault), or a joint
        beyond its bounds (the drives that changed before it written, then the fault),
        or a stall (nothing more to do).  True when the arm failed."""
        servo, c = self.servo, self.io.c
        if servo.tripped:
            trip = servo.trip
            assert trip is not None
            m = float(servo.q[trip.joint]) * _DEG
            self.fail(following_error_fault(trip.name, m + trip.error * _DEG, m,
                                            trip.limit * _DEG) or str(trip),
                      self.joints[trip.joint].name)
            return True
        if c.beyond < 0:
            return False
        changed, writers = c.changed, self._drive_writers
        for j, v in enumerate(self._dac.tolist()):
            if changed >> j & 1:
                writers[j](v)
        jt = self.joints[c.beyond]
        self.fail(str(joint_limit_fault(jt.config.name, float(servo.q[jt.index]) * _DEG,
                                        jt.limits_deg)), jt.name)
        return True

    def _settle(self, now_ns: int) -> None:
        s = self.servo
        quiet = (max(abs(e) for e in s.error.tolist()) * _DEG <= AT_TARGET_DEG
                 and max(abs(v) for v in s.velocity.tolist()) * _DEG <= SETTLED_SPEED_DEG_S)
        if not quiet:
            self._quiet_since = None
        elif self._quiet_since is None:
            self._quiet_since = now_ns
        if self._quiet_since is not None and now_ns - self._quiet_since >= SETTLE_S * 1e9:
            self._finish("at target" if self.state == "settling" else self._reason)
        elif now_ns - self._settle_from >= SETTLE_TIMEOUT_S * 1e9:
            errs = ", ".join(f"{JOINTS[jt.index]} {jt.error_deg:+.4f} deg" for jt in self.joints)
            self._finish(f"did not settle within {SETTLE_TIMEOUT_S:g} s ({errs})")

    def _off(self) -> None:
        """Every drive 0 and amplifier off, the motion dropped."""
        for jt in self.joints:
            jt.reflex()
        self.reflex()

    def _finish(self, why: str) -> None:
        self._off()
        self.last_stop = why

    def _to_rest(self) -> None:
        """The servo's reference from where it is to rest, every joint at once at the
        acceleration limits."""
        s = self.servo
        q, qd = s.q_ref.copy(), s.qd_ref.copy()
        t = float(np.max(np.abs(qd) / np.radians(AMAX_DEG_S2)))
        if t > 1e-6:
            s.segment(t, q, qd, q + 0.5 * qd * t, np.zeros(2), ffa=np.sign(qd) * self._kc)
            self._seg_end = s.end
        self.evaluator = self._evaluator(q + 0.5 * qd * t)
        self._end_of_knots(self._now_ns + round(t * 1e9))

    def brake(self) -> None:
        """The operator's stop: the servo's reference brakes to rest from where it is,
        every joint at once at the acceleration limits (on the path of a joint move);
        queued moves dropped; then the arm settles and is switched off."""
        if self.state == "idle":
            return
        self._to_rest()
        self.state = "braking"
        self._reason = "stopped (stop command)"

    # -- commands -------------------------------------------------------------------------

    def move_snapshot(self) -> MoveSnapshot:
        """What planning a move needs, copied (the loop's side, bounded): the
        queue's end, or, while the amplifiers are off, a new evaluator where the
        arm lies (the hand-over engages the servo there); the elbow as it is."""
        st = self.station
        if self.state == "braking":
            raise CommandError("arm: braking to rest after a stop: wait, then move; "
                               "nothing moved")
        if st.executor.busy or len(st.motion):
            raise CommandError("arm: a motion record runs: wait, then move; nothing moved")
        if self.state == "idle" or self.evaluator is None:
            here = self.angles()
            ev = self._evaluator(np.radians(here))
            return MoveSnapshot(ev, ev.snapshot(), here, here[1])
        return MoveSnapshot(self.evaluator, self.evaluator.snapshot(lead=PLAN_LEAD), None,
                            self.joint_positions()[1])

    def prepare_to(self, snap: MoveSnapshot, q0: float, q1: float) -> MoveWork:
        """``arm to`` in the caller's thread: the move planned against ``snap``."""
        try:
            planned = snap.evaluator.plan(MotionSpec(target=(math.radians(q0),
                                                             math.radians(q1)),
                                                     name="arm to"), snap.queue)
        except RecordError as exc:
            raise CommandError(f"arm: refused: {exc}; nothing moved") from None
        return MoveWork(snap, planned, self.where((q0, q1)))

    def prepare_xy(self, snap: MoveSnapshot, x: float, y: float,
                   elbow: str | None = None) -> MoveWork:
        """``arm xy`` in the caller's thread: the inverse, then the move planned."""
        if elbow is None:
            elbow = elbow_of(snap.elbow_deg)
        try:
            q0, q1 = ik(x, y, "up" if elbow == "up" else "down")
        except KinematicsError as exc:
            raise CommandError(f"arm xy: {exc}; nothing moved") from None
        return self.prepare_to(snap, q0, q1)

    def commit_move(self, work: MoveWork) -> str:
        """Queue a prepared move (the loop's side, bounded); :class:`Stale` (it is
        planned again) if the arm changed since its snapshot."""
        snap = work.snapshot
        if snap.rest is not None:  # planned from rest: still there, amplifiers still off?
            slip = max(abs(a - b) for a, b in zip(self.angles(), snap.rest, strict=True))
            if self.state != "idle" or slip > START_SLIP_DEG:
                raise Stale("arm: the arm moved while the move was planned")
            self._engage(snap.evaluator)
        elif self.evaluator is not snap.evaluator or self.state in ("idle", "braking"):
            raise Stale("arm: the arm changed while the move was planned")
        busy = snap.rest is None
        assert self.evaluator is not None
        try:
            self.evaluator.commit(work.planned)
        except StalePlan as exc:
            if not busy:
                self._off()
            raise Stale(f"arm: {exc}") from None
        self.state = "moving"
        self._ended = False
        if busy:
            return f"queued: {work.to}; it blends into the running move"
        return f"moving to {work.to}"

    def _here(self, prepare: Any, *args: Any) -> str:
        """Snapshot, prepare and commit in the calling thread (the loop's)."""
        for _ in range(PREPARE_TRIES):
            try:
                return self.commit_move(prepare(self.move_snapshot(), *args))
            except Stale:
                continue
        raise CommandError("arm: refused: the motion queue kept changing while the move "
                           "was planned; give it again; nothing moved")

    @command(Arg("Q0", float, lo=SHOULDER.limits_deg[0], hi=SHOULDER.limits_deg[1],
                 units="deg", what="shoulder limits"),
             Arg("Q1", float, lo=ELBOW.limits_deg[0], hi=ELBOW.limits_deg[1], units="deg",
                 what="elbow limits"),
             name="to", moves=True, prepare="prepare_to", snapshot="move_snapshot")
    def commit_to(self, work: MoveWork) -> str:
        """arm to Q0 Q1: move the joints to Q0, Q1 degrees (queued moves blend)."""
        return self.commit_move(work)

    def move_to(self, q0: float, q1: float) -> str:
        """``arm to`` planned in the calling thread."""
        return self._here(self.prepare_to, q0, q1)

    @command(Arg("X", float, lo=-_REACH, hi=_REACH, units="mm", what="reach"),
             Arg("Y", float, lo=-_REACH, hi=_REACH, units="mm", what="reach"),
             Arg("ELBOW", str.lower, optional=True, choices=("up", "down")),
             name="xy", moves=True, prepare="prepare_xy", snapshot="move_snapshot")
    def commit_xy(self, work: MoveWork) -> str:
        """arm xy X Y [up|down]: move the tip to X, Y mm (elbow as it is unless given).

        The joints move on a joint trajectory (the tip's path between is not a
        straight line); queued moves blend."""
        return self.commit_move(work)

    def move_xy(self, x: float, y: float, elbow: str | None = None) -> str:
        """``arm xy`` planned in the calling thread."""
        return self._here(self.prepare_xy, x, y, elbow)

    @command(name="show", reads_only=True)
    def show(self) -> str:
        """arm show: where the arm is, what it does and how the last move ended."""
        last = f"; last move: {self.last_stop}" if self.last_stop else ""
        return f"{self.where()}; {self.state}{last}"
