"""The ``arm`` station: registered as ``arm`` in the entry-point group ``pyrt.stations``.

Built only from pyrt's public API.  The boards are one servo board of kind
:data:`pyrt_arm.boards.SERVO` (``sim:``: in this process, with the simulated
arm behind it; ``tcp://HOST:PORT``: ``pyrt board-sim arm`` in another
process).  The component tree::

    arm          the controller (root): q0 q1 x y, following errors; arm to / xy / show
      shoulder   joint q0: its servo law, its registers, its reflex
      elbow      joint q1
    sim          the simulated arm's truth and fault injection (sim show, sim fault ...)

One general ready queue runs two tasks: ``servo`` every tick (1 kHz at the
default 1 ms tick) and ``trajectory`` every 10th (100 Hz).  The trajectory
task steps the motion executor: a ``joint_trajectory`` motion (pyrt's
:mod:`pyrt.robots.trajectory`) writes a setpoint knot ``(q, qd)`` every
10 ms through :meth:`ArmController.command_joints`, and a joint_trajectory
record queued behind the running one is appended to it, so that queued
moves blend.  The servo task interpolates the knots (cubic Hermite, one
trajectory period behind) into a 1 kHz setpoint with velocity and
acceleration, runs each joint's PD law with feed-forward
(:mod:`pyrt_arm.servo`) on its encoder counter and writes its drive.

The amplifiers are enabled while a move runs and until the arm has settled
at its target (within :data:`AT_TARGET_DEG` on every joint, at rest for
:data:`SETTLE_S`); then every drive is 0 and every amplifier disabled, and
the arm lies still on its friction (it lies on a table: no gravity).

Faults: a following error beyond 1 deg, a joint outside its limits, or an
amplifier that reports no power calls :meth:`pyrt.Component.fail`, and the
station trips: in the same tick every joint's reflex writes drive 0 and
enable 0 (and clears its state in a ``finally``), the motion ends and queued
moves are dropped.  The operator's ``stop`` brakes the setpoint to rest at
the arm's acceleration limits, then switches the amplifiers off.
"""

from __future__ import annotations

import argparse
import contextlib
import itertools
import math
from collections.abc import Sequence
from typing import Any

from pyrt import (
    Arg,
    BoardKind,
    Boards,
    CommandError,
    Component,
    ConfigError,
    JointStates,
    Limits,
    Loop,
    MotionExecutor,
    MotionType,
    PyrtError,
    ReadyQueue,
    ShellProfile,
    Signal,
    Station,
    StationFactory,
    Task,
    World,
    command,
    install,
    open_boards,
)
from pyrt.robots.trajectory import JointTrajectory, joint_trajectory_record
from pyrt.station.base import BoardWorld

from pyrt_arm.boards import (
    ARM_BOARDS,
    DEFAULT_START_DEG,
    WORLD_STEP_S,
    ArmPhysics,
    arm_world,
    drive_counts,
)
from pyrt_arm.kinematics import GEOMETRY, KinematicsError, elbow_of, fk, ik, urdf
from pyrt_arm.plant import JOINTS, Plant
from pyrt_arm.servo import ELBOW, FOLLOWING_ERROR_LIMIT_DEG, SHOULDER, JointServo, JointServoConfig

__all__ = [
    "AMAX_DEG_S2",
    "ARM",
    "AT_TARGET_DEG",
    "SETTLE_S",
    "TIP_TOLERANCE_MM",
    "TRAJECTORY_PERIOD",
    "VMAX_DEG_S",
    "ArmController",
    "ArmFactory",
    "ArmSim",
    "ArmStation",
    "Joint",
    "build_arm",
]

#: The joints' velocity limits (deg/s): what the servo is tuned and tested for.
VMAX_DEG_S = (90.0, 90.0)
#: The joints' acceleration limits (deg/s^2).
AMAX_DEG_S2 = (360.0, 360.0)
#: The trajectory task's period, in ticks (100 Hz at the 1 ms tick).
TRAJECTORY_PERIOD = 10
#: A move has ended "at target" when every joint's measured angle is this close (deg).
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

_REACH = GEOMETRY.r_max_mm


def _joint_limits(config: JointServoConfig) -> Limits:
    low, high = config.limits_deg
    return Limits(low, high, lolo=low, low=low, high=high, hihi=high)


_FERR = Limits(-FOLLOWING_ERROR_LIMIT_DEG, FOLLOWING_ERROR_LIMIT_DEG,
               lolo=-FOLLOWING_ERROR_LIMIT_DEG, low=-0.5 * FOLLOWING_ERROR_LIMIT_DEG,
               high=0.5 * FOLLOWING_ERROR_LIMIT_DEG, hihi=FOLLOWING_ERROR_LIMIT_DEG)
_TIP = Limits(-_REACH, _REACH)


# -- a joint ----------------------------------------------------------------------------------


class Joint(Component):
    """One joint: its servo law, its board registers (``count``, ``amp_ok``, ``drive``,
    ``enable`` at its index) and its reflex (drive 0, amplifier disabled)."""

    def __init__(self, name: str, index: int, board: Any, config: JointServoConfig) -> None:
        self.name = name
        self.index = index
        self.board = board
        self.servo = JointServo(config)
        #: True while the amplifier is enabled and the servo closes the loop.
        self.engaged = False
        #: The drive last written (DAC counts).
        self.drive = 0
        self._no_power = 0

    def signals(self) -> list[Signal]:
        s = self.servo
        return [
            Signal(f"q{self.index}", "deg", self.position, f"{self.name} angle (encoder)",
                   ".4f", limits=_joint_limits(s.config)),
            Signal("setpoint", "deg", lambda: s.setpoint_deg, "servo setpoint", ".4f"),
            Signal("error", "deg", lambda: s.error_deg, "following error", ".4f", limits=_FERR),
            Signal("velocity", "deg/s", lambda: s.velocity_deg_s, "measured speed", ".3f"),
            Signal("drive", "DAC counts", lambda: self.drive, "amplifier command", "d"),
            Signal("enabled", "bool", lambda: self.engaged, "amplifier enabled", "d"),
        ]

    def count(self) -> int:
        """The encoder counter."""
        value: int = self.board.read("count", self.index)
        return value

    def position(self) -> float:
        """The joint angle the encoder gives (deg)."""
        return self.servo.measure(self.count())

    def engage(self) -> None:
        """Close the loop at the present angle and enable the amplifier."""
        self.servo.reset(self.count())
        self.drive = 0
        self._no_power = 0
        self.board.write("drive", 0, self.index)
        self.board.write("enable", 1, self.index)
        self.engaged = True

    def update(self, q: float, qd: float, qdd: float, dt_s: float, count: int,
               amp_ok: int) -> str | None:
        """One servo tick on this tick's ``count`` and ``amp_ok`` inputs: write the drive;
        the fault reason, or None."""
        drive = drive_counts(self.servo.update(q, qd, count, qdd, dt_s))
        if drive != self.drive:
            self.board.write("drive", drive, self.index)
            self.drive = drive
        if amp_ok:
            self._no_power = 0
        else:
            self._no_power += 1
            if self._no_power >= AMP_GRACE_TICKS:
                return f"{JOINTS[self.index]} amplifier reports no power"
        return self.servo.fault()

    def release(self) -> None:
        """Drive 0 and the amplifier disabled: the joint is left to its friction."""
        self.reflex()

    def reflex(self) -> None:
        """Drive 0 and amplifier disabled, now; the joint's state cleared whatever happens."""
        try:
            self.board.write("drive", 0, self.index)
        finally:
            try:
                self.board.write("enable", 0, self.index)
            finally:
                self.engaged = False
                self.drive = 0
                self._no_power = 0


# -- the controller -----------------------------------------------------------------------------


Knot = tuple[int, tuple[float, float], tuple[float, float]]


def _cubic(a: Knot, b: Knot) -> tuple[int, tuple[tuple[float, float, float, float], ...]]:
    """The cubic Hermite from knot ``a`` to knot ``b``: its start time and, per joint, the
    coefficients of ``q(u) = c0 + c1 u + c2 u**2 + c3 u**3`` (``u`` seconds from ``a``)."""
    h = (b[0] - a[0]) * 1e-9
    out = []
    for j in (0, 1):
        p0, m0, p1, m1 = a[1][j], a[2][j], b[1][j], b[2][j]
        d = (p1 - p0) / h
        out.append((p0, m0, (3.0 * d - 2.0 * m0 - m1) / h, (m0 + m1 - 2.0 * d) / (h * h)))
    return a[0], tuple(out)


class ArmController(Component):
    """The arm (the root component, and the robot ``joint_trajectory`` drives)."""

    name = "arm"
    joint_count = 2
    #: The joints as viewers take them (scope foxglove, pyrt export): the URDF's names.
    joint_states = JointStates(names=("shoulder", "elbow"), position=("q0", "q1"),
                               velocity=("shoulder.velocity", "elbow.velocity"), urdf=urdf())

    def __init__(self, station: ArmStation, board: Any, period_ns: int) -> None:
        self.station = station
        self.board = board
        self.joints = (Joint("shoulder", 0, board, SHOULDER), Joint("elbow", 1, board, ELBOW))
        self.period_ns = period_ns
        # where each joint's count and amp_ok are in the board's snapshot of its inputs
        layout = [(r.name, i) for r in board.kind.inputs() for i in range(r.count)]
        self._inputs = [(layout.index(("count", j)), layout.index(("amp_ok", j)))
                        for j in (0, 1)]
        #: The servo runs this far behind the trajectory's knots (one trajectory period).
        self.delay_ns = TRAJECTORY_PERIOD * period_ns
        #: How the last move ended ('' before any).
        self.last_stop = ""
        #: What the arm does: idle, moving, settling, braking.
        self.state = "idle"
        self.target: tuple[float, float] | None = None
        self._knots: list[Knot] = []
        #: the knots' segment the servo is on: (start, end, per joint cubic coefficients)
        self._segment: tuple[int, int, tuple[tuple[float, float, float, float], ...]] | None = None
        self._now_ns = 0
        self._last_servo_ns: int | None = None
        self._sp_q = [0.0, 0.0]
        self._sp_qd = [0.0, 0.0]
        self._settled_ns = 0
        self._quiet_since: int | None = None
        self._stop_reason = "endpoint"

    # -- the component ----------------------------------------------------------------

    def signals(self) -> list[Signal]:
        sh, el = self.joints
        return [
            Signal("q0", "deg", sh.position, "shoulder angle (encoder)", ".4f",
                   limits=_joint_limits(sh.servo.config)),
            Signal("q1", "deg", el.position, "elbow angle (encoder)", ".4f",
                   limits=_joint_limits(el.servo.config)),
            Signal("x", "mm", lambda: self.tip()[0], "tip x (encoders)", ".3f", limits=_TIP),
            Signal("y", "mm", lambda: self.tip()[1], "tip y (encoders)", ".3f", limits=_TIP),
            Signal("ferr0", "deg", lambda: sh.servo.error_deg if sh.engaged else 0.0,
                   "shoulder following error", ".4f", limits=_FERR),
            Signal("ferr1", "deg", lambda: el.servo.error_deg if el.engaged else 0.0,
                   "elbow following error", ".4f", limits=_FERR),
            Signal("moving", "bool", lambda: self.state != "idle", "a move runs or settles", "d"),
        ]

    def children(self) -> list[Component]:
        return list(self.joints)

    def tasks(self) -> list[Task]:
        return [Task(self.servo_tick, period=1, name="servo", timed=True),
                Task(self.trajectory_tick, period=TRAJECTORY_PERIOD, name="trajectory",
                     timed=True)]

    def reflex(self) -> None:
        """Every setpoint dropped, the move ended (the joints' reflexes cut the drives)."""
        try:
            if self.state != "idle":
                self.last_stop = "stopped: every motor off"
        finally:
            self._knots = []
            self._segment = None
            self.state = "idle"
            self._last_servo_ns = None
            self._quiet_since = None

    # -- where it is --------------------------------------------------------------------

    def angles(self) -> tuple[float, float]:
        """The joint angles the encoders give (deg)."""
        return self.joints[0].position(), self.joints[1].position()

    def tip(self) -> tuple[float, float]:
        """The tip the encoders give (mm)."""
        q0, q1 = self.angles()
        return fk(q0, q1)

    def where(self) -> str:
        """The joints and the tip, in the operator's words."""
        q0, q1 = self.angles()
        x, y = fk(q0, q1)
        return f"q0 {q0:.3f} deg, q1 {q1:.3f} deg, tip ({x:.2f}, {y:.2f}) mm"

    # -- JointRobot: what joint_trajectory drives -----------------------------------------

    def joint_positions(self) -> Sequence[float]:
        """Where the servo's setpoint is heading (its last knot) while the servo holds the
        arm, else the encoders' angles."""
        if self.state != "idle" and self._knots:
            return self._knots[-1][1]
        return self.angles()

    def joint_limits(self) -> tuple[Sequence[float], Sequence[float]]:
        return VMAX_DEG_S, AMAX_DEG_S2

    def joint_range(self) -> tuple[Sequence[float], Sequence[float]]:
        (l0, h0), (l1, h1) = GEOMETRY.limits_deg
        return (l0, l1), (h0, h1)

    def command_joints(self, q: Sequence[float], qd: Sequence[float]) -> None:
        """A setpoint knot at the trajectory task's time; the first one engages the servo."""
        if self.state == "idle":
            self._engage(self._now_ns)
        self.state = "moving"
        knot = (self._now_ns, (float(q[0]), float(q[1])), (float(qd[0]), float(qd[1])))
        if self._knots and self._knots[-1][0] >= knot[0]:
            self._knots[-1] = knot
            self._segment = None
        else:
            self._knots.append(knot)
        del self._knots[:-4]

    def _engage(self, now_ns: int) -> None:
        for jt in self.joints:
            jt.engage()
        q = [jt.servo.position_deg for jt in self.joints]
        self._sp_q, self._sp_qd = list(q), [0.0, 0.0]
        self._knots = [(now_ns - self.delay_ns, (q[0], q[1]), (0.0, 0.0))]
        self._segment = None
        self._last_servo_ns = None
        self._quiet_since = None

    # -- the tasks ------------------------------------------------------------------------

    def trajectory_tick(self, now_ns: int) -> None:
        """100 Hz: step the motion executor; queued joint moves blend into the running one."""
        self._now_ns = now_ns
        st = self.station
        st.executor.poll(now_ns)
        current = st.executor.current
        while isinstance(current, JointTrajectory) and not current.done:
            record = st.motion.peek()
            if record is None or record.type != JointTrajectory.name:
                break
            st.motion.get()
            try:
                current.append(record.params)
            except CommandError as exc:
                self.say(f"move refused: {exc}", "warning")

    def servo_tick(self, now_ns: int) -> None:
        """1 kHz: setpoint from the knots, each joint's servo law, the checks, settling."""
        if self.state == "idle":
            return
        last, self._last_servo_ns = self._last_servo_ns, now_ns
        dt = (now_ns - last) * 1e-9 if last is not None and now_ns > last else self.period_ns * 1e-9
        tau = now_ns - self.delay_ns
        q, qd, qdd = self._setpoint(tau)
        self._sp_q, self._sp_qd = q, qd
        inputs = self.board.snapshot()  # one read of every input: this tick's
        for j, jt in enumerate(self.joints):
            at_count, at_ok = self._inputs[j]
            reason = jt.update(q[j], qd[j], qdd[j], dt, inputs[at_count], inputs[at_ok])
            if reason is not None:
                self.fail(reason, jt.name)
                return
        if self.state != "moving" and tau >= self._knots[-1][0]:
            self._settle(now_ns)

    def _setpoint(self, tau: int) -> tuple[list[float], list[float], list[float]]:
        knots = self._knots
        first, final = knots[0], knots[-1]
        if tau <= first[0]:
            return list(first[1]), [0.0, 0.0], [0.0, 0.0]
        if tau >= final[0]:
            if final[2] == (0.0, 0.0):
                return list(final[1]), [0.0, 0.0], [0.0, 0.0]
            dt = (tau - final[0]) * 1e-9
            return ([final[1][j] + final[2][j] * dt for j in (0, 1)], list(final[2]),
                    [0.0, 0.0])
        seg = self._segment
        if seg is None or not seg[0] < tau <= seg[1]:
            for a, b in itertools.pairwise(knots):
                if a[0] < tau <= b[0]:
                    seg = self._segment = (a[0], b[0], _cubic(a, b)[1])
                    break
            else:  # pragma: no cover - the knots cover (first, final]
                return list(final[1]), [0.0, 0.0], [0.0, 0.0]
        u = (tau - seg[0]) * 1e-9
        (a0, a1, a2, a3), (b0, b1, b2, b3) = seg[2]
        return ([a0 + u * (a1 + u * (a2 + u * a3)), b0 + u * (b1 + u * (b2 + u * b3))],
                [a1 + u * (2.0 * a2 + 3.0 * u * a3), b1 + u * (2.0 * b2 + 3.0 * u * b3)],
                [2.0 * a2 + 6.0 * u * a3, 2.0 * b2 + 6.0 * u * b3])

    def motion_ended(self, reason: str) -> None:
        """The executor's motion ended (``reason``): the servo settles at the last knot."""
        if self.state == "moving":
            self.state = "settling"
            self._stop_reason = reason
            self._quiet_since = None
            self._settled_ns = self._now_ns

    def _settle(self, now_ns: int) -> None:
        quiet = all(abs(jt.servo.error_deg) <= AT_TARGET_DEG
                    and abs(jt.servo.velocity_deg_s) <= SETTLED_SPEED_DEG_S
                    for jt in self.joints)
        if not quiet:
            self._quiet_since = None
        elif self._quiet_since is None:
            self._quiet_since = now_ns
        if self._quiet_since is not None and now_ns - self._quiet_since >= SETTLE_S * 1e9:
            self._finish("at target" if self.state == "settling" else self._stop_reason)
        elif now_ns - self._settled_ns >= SETTLE_TIMEOUT_S * 1e9 + self.delay_ns:
            errs = ", ".join(f"{JOINTS[j]} {jt.servo.error_deg:+.4f} deg"
                             for j, jt in enumerate(self.joints))
            self._finish(f"did not settle within {SETTLE_TIMEOUT_S:g} s ({errs})")

    def _finish(self, why: str) -> None:
        for jt in self.joints:
            jt.release()
        self.last_stop = why
        self.state = "idle"
        self._knots = []
        self._segment = None
        self._quiet_since = None

    def brake(self) -> None:
        """The operator's stop: the setpoint decelerates to rest from where it is, every
        joint at once at the acceleration limits; then the arm settles and is switched off."""
        if self.state == "idle":
            return
        tau = self._now_ns - self.delay_ns
        if self._last_servo_ns is not None:
            tau = self._last_servo_ns - self.delay_ns
        q, qd = self._sp_q, self._sp_qd
        t_stop = max(abs(qd[j]) / AMAX_DEG_S2[j] for j in (0, 1))
        stop_ns = int(t_stop * 1e9)
        if stop_ns < 1000:
            self._knots = [(tau, (q[0], q[1]), (0.0, 0.0))]
        else:
            end = (q[0] + 0.5 * qd[0] * t_stop, q[1] + 0.5 * qd[1] * t_stop)
            self._knots = [(tau, (q[0], q[1]), (qd[0], qd[1])),
                           (tau + stop_ns, end, (0.0, 0.0))]
        self._segment = None
        self.state = "braking"
        self._stop_reason = "stopped (stop command)"
        self._quiet_since = None
        self._settled_ns = tau + self.delay_ns + stop_ns

    # -- commands -------------------------------------------------------------------------

    def _move(self, q0: float, q1: float) -> str:
        x, y = fk(q0, q1)
        if self.state == "braking":
            raise CommandError("arm: braking to rest after a stop: wait, then move; "
                               "nothing moved")
        _n, waiting = self.station.submit_motion(joint_trajectory_record((q0, q1)))
        to = f"q0 {q0:.3f} deg, q1 {q1:.3f} deg, tip ({x:.2f}, {y:.2f}) mm"
        self.target = (q0, q1)
        if waiting:
            return f"queued: {to}; it blends into the running move"
        return f"moving to {to}"

    @command(Arg("Q0", float, lo=SHOULDER.limits_deg[0], hi=SHOULDER.limits_deg[1],
                 units="deg", what="shoulder limits"),
             Arg("Q1", float, lo=ELBOW.limits_deg[0], hi=ELBOW.limits_deg[1], units="deg",
                 what="elbow limits"),
             name="to", moves=True)
    def move_to(self, q0: float, q1: float) -> str:
        """arm to Q0 Q1: move the joints to Q0, Q1 degrees (queued moves blend)."""
        return self._move(q0, q1)

    @command(Arg("X", float, lo=-_REACH, hi=_REACH, units="mm", what="reach"),
             Arg("Y", float, lo=-_REACH, hi=_REACH, units="mm", what="reach"),
             Arg("ELBOW", str.lower, optional=True, choices=("up", "down")),
             name="xy", moves=True)
    def move_xy(self, x: float, y: float, elbow: str | None = None) -> str:
        """arm xy X Y [up|down]: move the tip to X, Y mm (elbow as it is unless given).

        The joints move on a joint trajectory (the tip's path between is not a
        straight line); queued moves blend."""
        if elbow is None:
            elbow = elbow_of(self.joint_positions()[1])
        try:
            q0, q1 = ik(x, y, "up" if elbow == "up" else "down")
        except KinematicsError as exc:
            raise CommandError(f"arm xy: {exc}; nothing moved") from None
        return self._move(q0, q1)

    @command(name="show", reads_only=True)
    def show(self) -> str:
        """arm show: where the arm is, what it does and how the last move ended."""
        last = f"; last move: {self.last_stop}" if self.last_stop else ""
        return f"{self.where()}; {self.state}{last}"


# -- the simulated world as a component -------------------------------------------------------


class ArmSim(Component):
    """The simulated arm in this process: its truth and its faults (``sim``)."""

    name = "sim"

    def __init__(self, plant: Plant) -> None:
        self.plant = plant

    def signals(self) -> list[Signal]:
        p = self.plant
        return [
            Signal("q0", "deg", lambda: p.q_deg[0], "true shoulder angle", ".4f"),
            Signal("q1", "deg", lambda: p.q_deg[1], "true elbow angle", ".4f"),
            Signal("qd0", "deg/s", lambda: p.qd_deg_s[0], "true shoulder speed", ".3f"),
            Signal("qd1", "deg/s", lambda: p.qd_deg_s[1], "true elbow speed", ".3f"),
            Signal("x", "mm", lambda: p.tip_mm[0], "true tip x", ".3f"),
            Signal("y", "mm", lambda: p.tip_mm[1], "true tip y", ".3f"),
        ]

    @command(name="show", reads_only=True)
    def show(self) -> str:
        """sim show: the simulated arm's truth (true joints, speeds and tip, faults)."""
        p = self.plant
        (q0, q1), (v0, v1), (x, y) = p.q_deg, p.qd_deg_s, p.tip_mm
        faults = ", ".join(p.active_faults()) or "none"
        return (f"true q0 {q0:.4f} deg, q1 {q1:.4f} deg; speed {v0:.3f}, {v1:.3f} deg/s; "
                f"tip ({x:.3f}, {y:.3f}) mm; faults: {faults}")

    @command(Arg("KIND", str.lower, choices=("jam", "encoder", "motor", "none")),
             Arg("JOINT", str.lower, optional=True, choices=JOINTS), name="fault")
    def fault(self, kind: str, joint: str | None = None) -> str:
        """sim fault jam|encoder|motor q0|q1, or sim fault none: inject a fault.

        jam (the joint is braked where it is), encoder (its counter freezes),
        motor (its power is cut); none clears them all."""
        p = self.plant
        if kind == "none":
            if joint is not None:
                raise CommandError("sim fault none takes no joint")
            p.clear_faults()
            return "sim: every fault cleared"
        if joint is None:
            raise CommandError(f"sim fault {kind}: which joint? q0 or q1")
        j = JOINTS.index(joint)
        {"jam": p.jam, "encoder": p.disconnect_encoder, "motor": p.motor_off}[kind](j)
        return f"sim: {', '.join(p.active_faults())}"


# -- the station ----------------------------------------------------------------------------------


class ArmStation(Station):
    """Everything ``pyrt arm`` runs (see the module text), built by :func:`build_arm`.

    ``boards``: the arm's (owned and closed by the station); ``world``: the
    simulated arm behind in-process boards, or None over ``tcp://``.
    """

    name = "arm"

    def __init__(self, loop: Loop, boards: Boards, world: World | None) -> None:
        super().__init__(loop)
        self.attach_boards(boards)
        self.world = world
        self.board = boards["servo"]
        if world is not None:
            physics = world.plant
            assert isinstance(physics, ArmPhysics)
            self.plant = physics.plant
            self.attach_world(world.step, "physics")
        self.controller = ctl = ArmController(self, self.board, loop.period_ns)
        self.queue = ReadyQueue.general(name="arm")
        install(self.queue, ctl.tasks())
        loop.attach(self.queue, name="queue:arm")

        def done(motion: MotionType) -> None:
            reason = motion.stop_reason or "ended"
            if reason.startswith("refused"):
                ctl.say(f"move {reason}", "warning")
            ctl.motion_ended(reason)

        def error(cause: str, motion: MotionType) -> None:
            self.trip(cause, source="trajectory")

        self.executor = MotionExecutor(ctl, self.motion.get, done, error)
        extras: list[Component] = []
        if world is not None:
            extras.append(ArmSim(self.plant))
        elif boards.has_info:
            extras.append(BoardWorld(boards))
        self.adopt(ctl, queues=[self.queue], executors=[self.executor], extras=extras,
                   where=ctl.where, ended=self._ended, status=self._status)
        self.profile = ShellProfile(idle="nothing to wait for: arm idle at {where}")

    # -- what the operator reads (given to adopt) --------------------------------------

    def busy(self) -> bool:
        """A move runs, waits, or the arm settles or brakes."""
        return super().busy() or self.controller.state != "idle"

    def _ended(self) -> tuple[str, list[str]]:
        """How the move ended: at target, stopped, did not settle, or the fault."""
        if self.fault is not None:
            why = f"fault: {self.fault.cause}"
            return why, [f"FAULT: {self.fault.cause}; {self.where()}"]
        why = self.controller.last_stop or "ended"
        if why == "at target":
            return why, [f"at target (every joint within {AT_TARGET_DEG:g} deg): "
                         f"{self.where()}; the true tip is within {TIP_TOLERANCE_MM:g} mm of it"]
        return why, [f"{why}: {self.where()}"]

    def _status(self) -> str:
        """One line: joints, tip, state, following errors."""
        ctl = self.controller
        errs = (", following error " + ", ".join(f"{jt.servo.error_deg:+.4f}"
                                                  for jt in ctl.joints) + " deg"
                if ctl.state != "idle" else ", amplifiers off")
        return f"{self.where()} (±{TIP_TOLERANCE_MM:g} mm at rest), {ctl.state}{errs}"

    def check_motion(self, record: Any) -> None:
        """Refuse a move while the arm brakes after a stop."""
        if self.controller.state == "braking":
            raise CommandError("arm: braking to rest after a stop: wait, then move; "
                               "nothing queued")

    def stop(self) -> str:
        """The operator's stop: the move ended, queued moves dropped, the arm braked to rest
        at its acceleration limits and then switched off (idle: every motor off now)."""
        ctl = self.controller
        for ex in self.executors:
            ex.abort("stop command")
        self.motion.clear()
        if ctl.state == "idle":
            return super().stop()
        ctl.brake()
        return f"arm: stopping: braking to rest, then every motor off; {self.where()}"

    def close(self) -> None:
        """Every motor off (not braked: the loop stops), then pyrt's close."""
        runner = self.runner
        if runner is not None and runner.running:
            with contextlib.suppress(PyrtError):
                runner.call(self.reflex, "shutdown", take_fault=False, name="shutdown")
        super().close()


def build_arm(loop: Loop, *, boards: str | None = None,
              start: Sequence[float] | None = None,
              world_step_s: float = WORLD_STEP_S) -> ArmStation:
    """The arm on ``loop``, not yet started (call ``station.start()``).

    ``boards``: the board URL (default ``sim:``: the servo board in this
    process with the simulated arm behind it, starting at ``start`` degrees;
    ``tcp://HOST:PORT``: ``pyrt board-sim arm``, whose options set the arm).
    ``world_step_s`` is the simulated arm's longest internal integration step.
    ConfigError for bad settings; BoardError if the boards cannot be reached.
    """
    b = open_boards(boards, "arm", ARM_BOARDS)
    try:
        world = None
        if b.in_process:
            try:
                world = arm_world(b.simulated or b, DEFAULT_START_DEG if start is None else start,
                                  max_step_s=world_step_s)
            except ValueError as exc:
                raise ConfigError(str(exc)) from None
        elif start is not None:
            raise ConfigError(f"board URL {b.url!r}: the arm's start position is an option "
                              "of 'pyrt board-sim arm' (the world runs there)")
        return ArmStation(loop, b, world)
    except BaseException:
        b.close()
        raise


# -- the factory: pyrt arm ----------------------------------------------------------------------


def _start(text: str) -> tuple[float, float]:
    parts = text.split(",")
    try:
        q = tuple(float(p) for p in parts)
    except ValueError:
        q = ()
    if len(q) != 2 or not all(math.isfinite(v) for v in q):
        raise argparse.ArgumentTypeError(f"expected Q0,Q1 in degrees, got {text!r}")
    return q[0], q[1]


class ArmFactory(StationFactory):
    """pyrt arm: a two-joint planar arm (004's MRC II in miniature) on pyrt's public API.

Two DC motors with encoders behind one register-level servo board; a 1 kHz
servo task and a 100 Hz trajectory task on one ready queue.  Commands:
arm to Q0 Q1 (degrees), arm xy X Y [up|down] (mm), arm show; queued moves
blend.  wait says how a move ended, stop brakes the arm to rest, status
gives the joints and the tip.  A following error above 1 deg, a joint
beyond its limits or an amplifier without power trips the station: every
drive 0 and every amplifier disabled in the same tick; ack clears it.  The
simulated arm's truth and faults: sim show, sim fault jam|encoder|motor
q0|q1, sim fault none.

With --boards tcp://HOST:PORT the controller drives the servo board of a
'pyrt board-sim arm' in another process, at real time.
"""

    name = "arm"
    summary = "run a two-joint planar arm (servo board, 1 kHz servo, blended joint moves)"
    description = __doc__ or ""
    default_tick_us = 1000
    max_tick_us = 1000
    max_tick_why = "the servo task runs every tick and is tuned for 1 kHz"

    def board_kinds(self) -> dict[str, BoardKind]:
        return dict(ARM_BOARDS)

    def add_world_arguments(self, parser: argparse.ArgumentParser) -> None:
        g = parser.add_argument_group("simulation (sim: boards only; board-sim takes the same)")
        g.add_argument("--start", type=_start, metavar="Q0,Q1", default=None,
                       help="the simulated arm's joint angles at start, degrees "
                            f"(default {DEFAULT_START_DEG[0]:g},{DEFAULT_START_DEG[1]:g})")

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        self.add_world_arguments(parser)

    def world(self, boards: Boards, args: argparse.Namespace) -> World:
        start = getattr(args, "start", None)
        try:
            return arm_world(boards, DEFAULT_START_DEG if start is None else start)
        except ValueError as exc:
            raise ConfigError(str(exc)) from None

    def build(self, loop: Loop, args: argparse.Namespace) -> ArmStation:
        return build_arm(loop, boards=args.boards, start=args.start)


#: ``pyrt arm`` (the entry point ``pyrt_arm.station:ARM`` in ``pyrt.stations``).
ARM = ArmFactory()
