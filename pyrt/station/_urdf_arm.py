"""The controller of ``pyrt urdf``: the arm (root component), its joints, its two tasks.

:class:`UrdfArm` is the root component, named after the URDF's robot.  It
talks to the arm only through one passive servo board
(:func:`pyrt.boards.armservo.arm_servo_kind`): per joint a DAC (motor
current), an amplifier enable and an encoder counter.  Two tasks on one
ready queue:

* ``trajectory`` (rate group ``trajectory``, :data:`TRAJECTORY_HZ`, 100 Hz):
  one tick of :class:`pyrt.motion.Evaluator` (given the wrist sensor's
  wrench, for guarded moves) gives a knot (joint position, velocity,
  acceleration); the servo is handed the segment from the last knot to this
  one with the chain's inverse dynamics at both ends (gravity, inertia and
  Coriolis feed-forward);
* ``servo`` (rate group ``servo``, :data:`SERVO_HZ`, 1 kHz): the encoders (unwrapped) into
  :class:`pyrt.native.Servo` (quintic interpolation of the segment, PID with
  velocity, acceleration and dynamics feed-forward), its torques as DAC
  counts; a following error beyond the limit trips the servo, and a joint
  beyond its limits trips the station: every joint's reflex writes DAC 0 and
  enable 0 in that tick.

Moves are records of the motion layer, planned when they are queued (in the
command's handler): ``movej`` and ``moveto`` joint-mode records to a joint
target, ``movel`` a Cartesian record in ``T6 . TOOL = COORD . POS``; OPTIONS
set a record's speed, blend tolerance and force limit (the commands:
:mod:`pyrt.station._urdf_moves`).

The arm carries its own weight: after :data:`POWER_ON_TICKS` encoder
readings the servo takes it (the amplifiers enabled; an arm still moving is
braked to rest first, one beyond a limit brought back inside), moves it,
and holds it at the target.  A fault or ``close`` switches every amplifier
off and engages every brake (the board's ``release`` 0: the arm stays where
it was); the next move closes the loop again where the arm lies.  ``stop`` brakes
along the path and holds.

Units at the console: degrees (revolute joints) or millimetres (prismatic
ones), millimetres for the tool position, degrees for its rotations (RX RY
RZ fixed-axis, about the base's x, then y, then z: URDF's ``rpy``).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from pyrt.boards.armservo import DAC_FULL_SCALE, KIND_NAME, ArmServoRegisters
from pyrt.component import Command, Component, Limits, Param, Signal, command, records_of
from pyrt.kinematics import GRAVITY, Chain, rpy_of
from pyrt.kinematics.chain import inertia_bound
from pyrt.motion import Evaluator, MotionFault
from pyrt.motion import Limits as MotionLimits
from pyrt.native import Servo, ServoBoard, gain_ranges, tuned_gains
from pyrt.native._servo import MAX_DT_PERIODS
from pyrt.scheduler import RateGroup, Task
from pyrt.station._urdf_gains import ArmTuning, arm_gain_params, joint_gain_params
from pyrt.station._urdf_moves import ArmMoves

if TYPE_CHECKING:
    from pyrt.station.base import Station
    from pyrt.station.domain import Robot

__all__ = [
    "AT_TARGET_DEG",
    "SERVO_BANDWIDTH_HZ",
    "SERVO_HZ",
    "SERVO_PERIOD_NS",
    "TRAJECTORY_HZ",
    "TRAJECTORY_PERIOD",
    "ArmJoint",
    "Drive",
    "UrdfArm",
    "snapshot_ready",
    "snapshot_restored",
]

#: The servo group's rate (Hz), in time units whatever the loop's tick.
SERVO_HZ = 1000
#: The servo's period (ns): what the servo's gains are tuned for.
SERVO_PERIOD_NS = 1_000_000_000 // SERVO_HZ
#: The trajectory's period, in servo periods (the servo interpolates over them).
TRAJECTORY_PERIOD = 10
#: The trajectory group's rate (Hz): 100 Hz.
TRAJECTORY_HZ = SERVO_HZ // TRAJECTORY_PERIOD
#: Each task's rate group and its rate (Hz): a task runs in the group of its name.
GROUP_HZ = {"servo": SERVO_HZ, "trajectory": TRAJECTORY_HZ}
#: The servo's closed-loop bandwidth (Hz): a triple real pole (pyrt.native.tuned_gains).
SERVO_BANDWIDTH_HZ = 12.0
#: The following-error limit of every joint (deg, or mm for a prismatic joint).
FOLLOWING_ERROR_DEG = 2.0
#: A move has ended "at target" when every joint's following error is this small (deg / mm) ...
AT_TARGET_DEG = 0.005
#: ... and its measured speed below this (deg/s, mm/s) ...
SETTLED_SPEED_DEG_S = 2.0
#: ... for this long (s).
SETTLE_S = 0.03
#: The longest the servo waits for the arm to settle after the trajectory ended (s).
SETTLE_TIMEOUT_S = 3.0
#: How far beyond a joint limit the measured joint may go before that is a fault
#: (deg or mm): the servo's overshoot at a target on the limit stays inside it.
LIMIT_MARGIN_DEG = 1.0
#: The share of each joint's effort the planner may use to accelerate it (the
#: rest holds the arm against gravity and friction).
ACCEL_SHARE = 0.4

#: The servo closes the loop by itself after this many encoder readings (the arm's
#: speed then known: a falling or swinging arm is braked, not held where it was).
POWER_ON_TICKS = 10


@dataclass(frozen=True)
class Drive:
    """One joint's drive as the controller knows it: encoder counts per joint
    radian (or metre), joint torque (N m, or N) per DAC count, and the rotor
    inertia seen at the joint (kg m^2), the acceleration feed-forward."""

    counts_per_unit: float
    nm_per_count: float
    reflected_inertia: float


def _scale(prismatic: bool) -> tuple[float, str]:
    """Operator units per SI unit, and their name."""
    return (1e3, "mm") if prismatic else (180.0 / math.pi, "deg")


class ArmJoint(Component):
    """One joint (named as in the URDF): its registers at its index and its reflex."""

    def __init__(self, arm: UrdfArm, index: int) -> None:
        j = arm.chain.joints[index]
        self.arm = arm
        self.index = index
        self.name = j.name
        self.prismatic = j.kind == "prismatic"
        self.scale, self.units = _scale(self.prismatic)

    def signals(self) -> list[Signal]:
        a, i, k, u = self.arm, self.index, self.scale, self.units
        return [
            Signal("position", u, lambda: float(a.q[i]) * k, f"{self.name} (encoder)", ".4f",
                   limits=a.joint_limits(i)),
            Signal("setpoint", u, lambda: float(a.servo.q_ref[i]) * k, "servo reference",
                   ".4f"),
            Signal("error", u, lambda: float(a.servo.error[i]) * k if a.powered else 0.0,
                   "following error", ".4f"),
            Signal("torque", "N" if self.prismatic else "N m", lambda: float(a.servo.tau[i])
                   if a.powered else 0.0, "commanded joint torque", ".3f"),
            Signal("dac", "DAC counts", lambda: int(a.dac[i]), "amplifier command", "d"),
        ]

    def params(self) -> list[Param]:
        """The servo's gains of this joint (:mod:`pyrt.station._urdf_gains`)."""
        return joint_gain_params(self.arm.servo, self.index, self.prismatic,
                                 self.arm.gain_ranges)

    def reflex(self) -> None:
        """DAC 0, the amplifier disabled and the brake engaged, now."""
        board = self.arm.board
        try:
            board.write("dac", 0, self.index)
        finally:
            try:
                board.write("enable", 0, self.index)
            finally:
                self.arm.dac[self.index] = 0
                board.write("release", 0, self.index)


def task_groups(tasks: list[Task], robot: str) -> list[RateGroup]:
    """``tasks`` in their rate groups (:data:`GROUP_HZ`: a task in the group of its
    name), each in a ready queue of ``robot`` (faults name it), fastest first;
    attach them to the loop and give the station their queues."""
    groups = []
    for task in tasks:
        group = RateGroup(task.name, hz=GROUP_HZ[task.name])
        group.new_queue(robot, [task])
        groups.append(group)
    return sorted(groups, key=lambda g: g.period_ns)


class UrdfArm(ArmMoves, Component):
    """The arm: the root component of ``pyrt urdf`` (see the module text).
    Its moves and their commands are :class:`ArmMoves`, mixed in.

    ``chain`` the arm (its limits and inertials), ``board`` its passive servo
    board, ``drives`` one :class:`Drive` per joint, ``period_ns`` the servo's period
    (:data:`SERVO_PERIOD_NS`: its group's, not the loop's tick).
    """

    def __init__(self, station: Station | Robot, name: str, chain: Chain, board: Any,
                 drives: Sequence[Drive], period_ns: int,
                 wrench: Callable[[Sequence[int]], np.ndarray] | None = None) -> None:
        self.station = station
        self.name = name
        self.chain = chain
        self.board = board
        self.n = n = chain.n
        self.drives = tuple(drives)
        self.period_s = period_ns * 1e-9
        self.traj_period_s = TRAJECTORY_PERIOD * self.period_s
        joints = chain.joints
        self.prismatic = [j.kind == "prismatic" for j in joints]
        self.scales = np.array([_scale(p)[0] for p in self.prismatic])
        self._scales_l = self.scales.tolist()
        self.units = [_scale(p)[1] for p in self.prismatic]
        self.joints = tuple(ArmJoint(self, i) for i in range(n))
        # encoders: where each counter is in the board's snapshot, counts per unit
        layout = [(r.name, i) for r in board.kind.inputs() for i in range(r.count)]
        at = [layout.index(("count", j)) for j in range(n)]
        if at != list(range(at[0], at[0] + n)):  # pragma: no cover - the kind declares them so
            raise ValueError("the board's encoder counters are not one block of its inputs")
        self._count_slice = slice(at[0], at[0] + n)
        #: The wrist sensor: its channels in the snapshot and counts -> wrench (N, N m);
        #: None: no sensor (no force limits).
        self._wrench_of = wrench
        ft = [layout.index(("ft", k)) for k in range(6)] if ("ft", 0) in layout else []
        self._ft_slice = slice(ft[0], ft[0] + 6) if ft else slice(0, 0)
        self._ft_counts: Sequence[int] = [0] * 6
        #: The servo board's registers in blocks (encoders in, DACs out); None on a
        #: board of another kind (hardware (a): its arm reads and writes its own).
        self._regs = ArmServoRegisters(board) if board.kind.name == KIND_NAME else None
        self._cpu_list = [d.counts_per_unit for d in self.drives]
        #: A servo tick this long after the last is a stall (said; csrc/servo.h).
        self._stall_s = MAX_DT_PERIODS * period_ns * 1e-9
        effort = np.array([j.effort if math.isfinite(j.effort) and j.effort > 0
                           else d.nm_per_count * DAC_FULL_SCALE
                           for j, d in zip(joints, self.drives, strict=True)])
        self.effort = effort
        armature = np.array([d.reflected_inertia for d in self.drives])
        inertia = inertia_bound(chain, armature)
        felim = np.array([math.radians(FOLLOWING_ERROR_DEG) if not p
                          else FOLLOWING_ERROR_DEG * 1e-3 for p in self.prismatic])
        gains: dict[str, ArrayLike] = dict(tuned_gains(inertia, effort, self.period_s,
                                                       SERVO_BANDWIDTH_HZ))
        gains["felim"] = felim
        gains["ka"] = armature
        gains["kv"] = np.array([j.damping for j in joints])
        self.servo = Servo(n, self.period_s, names=chain.joint_names, gains=gains)
        k = self.servo.knots
        #: The servo's knots B (q, qd, qdd, ff rows): the trajectory writes them in place.
        self._rows_b = (k[3], k[4], k[5], k[7])
        #: The board's side of the servo: the counters as last read and their unwrapped
        #: totals, the DAC values last written (see servo_tick).
        self._io = ServoBoard(self.servo, self._cpu_list,
                              [int(board.read("count", j)) for j in range(n)],
                              [1.0 / d.nm_per_count for d in self.drives], DAC_FULL_SCALE)
        # the servo task's every tick, bound once: the encoders in, the one C call,
        # this tick's DAC counts out (a passive board's; hardware (a) has none)
        self._tick_io = self.servo.board_ticker(self._io)
        #: The servo's following errors and velocity estimate (views of its state).
        self._error, self._velocity = self.servo.error, self.servo.velocity
        self._dac_list = self._io.dac.tolist
        regs = self._regs
        self._counts_in = regs.counts_reader() if regs is not None else None
        self._write_dac = regs.dac_writer() if regs is not None else None
        #: The measured joints (rad, m), from the encoders (unwrapped): the servo's input.
        self.q = self.servo.q
        self._qs = self.q.tolist()
        #: The DAC values last written (the servo's board keeps them: see servo_tick).
        self.dac: np.ndarray | list[int] = self._io.dac
        #: Each gain's safe range per joint: get/set take the gains within them.
        self.gain_ranges = gain_ranges(inertia, effort, self.period_s)
        self.servo.ranges = self.gain_ranges
        self.tuning = ArmTuning(self.servo, inertia, effort, SERVO_BANDWIDTH_HZ)
        # the planner's limits: the URDF's velocities, accelerations from the efforts
        vmax = np.array([j.velocity if math.isfinite(j.velocity) and j.velocity > 0
                         else (0.25 if p else 1.0) for j, p in zip(joints, self.prismatic,
                                                                    strict=True)])
        amax = ACCEL_SHARE * effort / inertia
        self.limits = MotionLimits(tuple(vmax), tuple(amax))
        self.evaluator: Evaluator | None = None
        #: True while the amplifiers are enabled and the servo holds or moves the arm.
        self.powered = False
        #: What the arm does: idle, moving, settling.
        self.state = "idle"
        #: How the last move ended ('' before any).
        self.last_stop = ""
        self._quiet_since: int | None = None
        self._settle_from = 0
        self._now_ns = 0
        self._records: list[Command] | None = None
        self._margin = np.where(self.prismatic, LIMIT_MARGIN_DEG * 1e-3,
                                math.radians(LIMIT_MARGIN_DEG))
        #: Where the measured joints may go before that is a fault (the limits and a
        #: margin; from where the arm lay, while it is brought back inside them).
        self._lo_l: list[float] = []
        self._hi_l: list[float] = []
        self._bound(chain.lower - self._margin, chain.upper + self._margin)
        self._recover_until: int | None = None
        #: The fault's bounds are widened to where the arm lay beyond a limit.
        self._wide = False
        #: The last readings while unpowered (time, joints): the speed at power-on.
        self._history: deque[tuple[int, np.ndarray]] = deque(maxlen=20)
        #: The servo closes the loop by itself once, after POWER_ON_TICKS readings.
        self._started = False
        self._heading: np.ndarray | None = None
        #: TOOL: the tool's frame on the chain's tool (``NAME tool``); COORD: the frame
        #: moveto and movel targets are given in (``NAME coord``); identity at start.
        self.tool_frame = np.eye(4)
        self.coord_frame = np.eye(4)
        #: The conveyor COORD rides on (``NAME conveyor``), or None; a trajectory
        #: tick's loop time and the sample it hands out (a sample's time for it).
        self.conveyor = None
        self._anchor = (0.0, 0)
        self._latest = None
        #: The servo's segments join in time (a motion's knots follow each other), and
        #: where the next one starts on the loop's clock (s).
        self._joined = False
        self._start = 0.0
        #: Where the segment the servo runs ends (s, the loop's clock; servo.end).
        self._end = 0.0

    # -- set-up ---------------------------------------------------------------------

    def joint_limits(self, i: int) -> Limits:
        """Joint ``i``'s limits in operator units, as a display range and major alarms."""
        j, k = self.chain.joints[i], float(self.scales[i])
        lo = j.lower * k if math.isfinite(j.lower) else -360.0
        hi = j.upper * k if math.isfinite(j.upper) else 360.0
        return Limits(lo, hi, lolo=lo, low=lo, high=hi, hihi=hi)

    # -- the component ----------------------------------------------------------------

    def signals(self) -> list[Signal]:
        out = []
        for i in range(self.n):
            out.append(Signal(f"q{i + 1}", self.units[i], self._joint_reader(i),
                              f"joint {self.chain.joints[i].name} (encoder)", ".4f",
                              limits=self.joint_limits(i)))
        for c, axis in enumerate("xyz"):
            out.append(Signal(axis, "mm", self._tool_reader(c), f"tool {axis} (encoders)",
                              ".3f"))
        for c, axis in enumerate(("rx", "ry", "rz")):
            out.append(Signal(axis, "deg", self._tool_reader(3 + c),
                              f"tool rotation about the base's {axis[1]} (encoders; URDF rpy)",
                              ".3f"))
        out.append(Signal("moving", "bool", lambda: self.state != "idle",
                          "a move runs or settles", "d"))
        out.append(Signal("powered", "bool", lambda: self.powered,
                          "the amplifiers are enabled (the servo holds the arm)", "d"))
        return out

    def _joint_reader(self, i: int) -> Callable[[], float]:
        k = float(self.scales[i])
        return lambda: float(self.q[i]) * k

    def _tool_reader(self, c: int) -> Callable[[], float]:
        """Tool x y z (mm) for c = 0 1 2, rx ry rz (deg) for c = 3 4 5."""
        if c < 3:
            return lambda: float(self.tool()[c, 3]) * 1e3
        return lambda: math.degrees(rpy_of(self.tool())[c - 3])

    def children(self) -> list[Component]:
        return list(self.joints)

    def params(self) -> list[Param]:
        """The servo's bandwidth and dynamics feed-forward for every joint at once
        (:mod:`pyrt.station._urdf_gains`)."""
        w = float(self.gain_ranges["kd"][1][0]) / (3.0 * float(self.tuning.inertia[0]))
        return arm_gain_params(self.name, self.tuning, w / (2.0 * math.pi))

    def tasks(self) -> list[Task]:
        """Each runs at every release of its rate group (:meth:`rate_groups`)."""
        return [Task(self.trajectory_tick, period=1, name="trajectory", timed=True),
                Task(self.servo_tick, period=1, name="servo", timed=True)]

    def rate_groups(self, robot: str) -> list[RateGroup]:
        """The arm's tasks in their rate groups (:func:`task_groups`)."""
        return task_groups(self.tasks(), robot)

    def commands(self) -> list[Command]:
        if self._records is None:
            own = [replace(r, help=r.help.replace("NAME ", f"{self.name} "))
                   for r in records_of(self, self.name)]
            self._records = [self._movej_record(), *own]
        return self._records

    def reflex(self) -> None:
        """The servo off and the motion dropped (the joints' reflexes cut the currents)."""
        try:
            if self.state != "idle":
                self.last_stop = "stopped: every joint off"
        finally:
            self.powered = False
            self.state = "idle"
            self.evaluator = None
            self._quiet_since = None
            self._joined = False

    # -- where it is ------------------------------------------------------------------

    def _measure(self, counts: Sequence[int]) -> None:
        """The joints from this tick's ``counts``: each counter's step since the last
        read taken modulo 2^32 (a 32-bit counter wraps), the middle of the count."""
        self._io.encoders(counts)
        self._qs = self.q.tolist()

    def wrench(self) -> np.ndarray:
        """The wrist sensor's wrench (fx fy fz N, tx ty tz N m; tool frame), or zeros
        without a sensor."""
        if self._wrench_of is None:
            return np.zeros(6)
        if self._regs is not None:  # read when it is needed (hardware (a): each tick)
            self._ft_counts = self._regs.ft()
        return self._wrench_of(self._ft_counts)

    def tool(self) -> np.ndarray:
        """The tool pose the encoders give (4, 4; m, in the base's frame): the chain's
        tool with :attr:`tool_frame` (``NAME tool``) on it."""
        return self.chain.fk(self.q) @ self.tool_frame

    def config(self, q: np.ndarray | None = None) -> str:
        """The arm's configuration (the closed form's name), or '' without one."""
        closed = self.chain.closed_form
        if closed is None:
            return ""
        return str(closed.config_of(self.q if q is None else q))

    def joints_text(self, q: np.ndarray) -> str:
        return " ".join(f"{float(v) * k:.3f}" for v, k in zip(q, self.scales, strict=True))

    def pose_text(self, t: np.ndarray) -> str:
        x, y, z = (t[:3, 3] * 1e3).tolist()
        rx, ry, rz = (math.degrees(a) for a in rpy_of(t))
        return f"({x:.2f}, {y:.2f}, {z:.2f}) mm, rpy ({rx:.3f}, {ry:.3f}, {rz:.3f}) deg"

    def where(self) -> str:
        """The joints, the tool pose and the configuration, in the operator's words."""
        units = "deg" if not any(self.prismatic) else "deg/mm"
        cfg = self.config()
        return (f"joints {self.joints_text(self.q)} {units}; tool {self.pose_text(self.tool())}"
                + (f"; {cfg}" if cfg else ""))

    # -- the servo ---------------------------------------------------------------------

    def power_on(self) -> None:
        """Close the loop where the arm is (gravity held), amplifiers on; the
        trajectory starts there.  An arm that is still moving (falling, swinging)
        is first braked to rest, and one lying beyond a limit (sunk onto an end
        stop while the amplifiers were off) brought back inside: a quintic at half
        the acceleration limits before the trajectory's knots begin."""
        q = self.q.copy()
        v = np.zeros(self.n)
        if self._history:  # the speed over the last readings, by their times
            t_old, q_old = self._history[0]
            if self._now_ns > t_old:
                v = (q - q_old) / ((self._now_ns - t_old) * 1e-9)
        ff = self.chain.gravity_torque(q)
        self.servo.reset(q, ff, now=self._now_ns * 1e-9)
        self._joined = False
        k = self.servo.knots
        k[...] = 0.0
        k[3] = q
        k[7] = ff
        amax = 0.5 * np.array(self.limits.amax)
        t = float(np.max(np.abs(v) / amax))  # the time to brake every joint to rest
        start = np.clip(q + 0.5 * v * t, self.chain.lower, self.chain.upper)
        self.evaluator = Evaluator(self.chain, self.limits, start, period=self.traj_period_s,
                                   force_sensor=self._wrench_of is not None)
        self._anchor = (self._now_ns * 1e-9 + self.traj_period_s, 0)
        margin = self._margin
        self._history.clear()
        self._bound(np.minimum(self.chain.lower, q) - margin,
                    np.maximum(self.chain.upper, q) + margin)
        self._wide = bool(((q < self.chain.lower) | (q > self.chain.upper)).any())
        self._recover_until = None
        out = np.abs(start - q)
        if out.any() or t > 0.0:
            t = max(0.2, t, float(np.max(np.sqrt(5.77 * out / amax))))
            t = math.ceil(t / self.traj_period_s) * self.traj_period_s
            zero = np.zeros(self.n)
            self.servo.segment(t, q, v, start, zero, zero, zero, ff,
                               self.chain.gravity_torque(start))
            # it starts at the servo's next tick: the trajectory takes over at its end
            self._recover_until = self._now_ns + round((self.period_s + t) * 1e9)
        self._io.dac[:] = 0
        regs = self._regs
        assert regs is not None  # a passive board's arm (hardware (a) has its own)
        regs.write_all("dac", 0)
        regs.write_all("enable", 1)
        regs.write_all("release", 1)
        self.powered = True
        self.state = "idle"

    def servo_tick(self, now_ns: int) -> None:
        """1 kHz: the encoders, the servo law, the DACs; the checks; settling."""
        self._now_ns = now_ns
        counts = self._counts_in()  # type: ignore[misc]  # the encoders as one block
        if not self.powered:  # the readings kept: an arm moving is braked at power-on
            self._measure(counts)
            self._history.append((now_ns, self.q.copy()))
            if (self.evaluator is None and self.station.fault is None and not self._started
                    and len(self._history) >= POWER_ON_TICKS):
                self._started = True
                self.power_on()
            return
        now = now_ns * 1e-9
        if self._joined and now > self._end + 0.5 * self.period_s:
            # the loop stalled past the segment's end before the trajectory's turn: its
            # knot for now is made here, so the reference keeps to the time that passed
            self._io.encoders(counts)
            self.trajectory_tick(now_ns)
            if not self.powered:
                return
        # the encoders, the law, the bounds and the DAC counts: one C call (servo.q is
        # self.q); what it gives: the DACs whose counts changed, or -1 to look closer
        changed = self._tick_io(now, counts)
        if changed:
            if changed < 0:
                if _servo_said(self):
                    return
            else:  # within +-full scale: clamped in C
                self._write_dac(self._dac_list(), changed)  # type: ignore[misc]
        if self.state == "settling":
            self._settle(now_ns)

    def _beyond(self, j: int) -> None:
        """Joint ``j`` lies beyond its limit and margin: the fault."""
        jt = self.chain.joints[j]
        k, u = float(self.scales[j]), self.units[j]
        self.fail(f"joint {jt.name} at {self.q[j] * k:.3f} {u} is beyond its limits "
                  f"{jt.lower * k:.3f} .. {jt.upper * k:.3f} {u}", self.joints[j].name)

    def _bound(self, lo: np.ndarray, hi: np.ndarray) -> None:
        """Where the measured joints may go before that is a fault (plain floats)."""
        self._lo_l = [float(v) for v in lo]
        self._hi_l = [float(v) for v in hi]
        self._io.lo[:] = lo
        self._io.hi[:] = hi

    def _settle(self, now_ns: int) -> None:
        if self.servo.late:  # else the last segment still runs
            self.settle_on(self._error, now_ns)

    def settle_on(self, err: np.ndarray, now_ns: int) -> None:
        """The move ends when every joint's error ``err`` (rad or m) is within
        :data:`AT_TARGET_DEG` and slower than :data:`SETTLED_SPEED_DEG_S` for
        :data:`SETTLE_S`, or says it did not settle after :data:`SETTLE_TIMEOUT_S`."""
        k = self.scales
        ks = self._scales_l  # plain floats: six joints' tests quicker than numpy's
        quiet = (all(abs(e) * s <= AT_TARGET_DEG
                     for e, s in zip(err.tolist(), ks))  # noqa: B905 - n each
                 and all(abs(v) * s <= SETTLED_SPEED_DEG_S
                         for v, s in zip(self._velocity.tolist(), ks)))  # noqa: B905
        if not quiet:
            self._quiet_since = None
        elif self._quiet_since is None:
            self._quiet_since = now_ns
        if self._quiet_since is not None and now_ns - self._quiet_since >= SETTLE_S * 1e9:
            self.state = "idle"
            self._quiet_since = None
            if not self.last_stop:
                self.last_stop = "at target"
        elif now_ns - self._settle_from >= SETTLE_TIMEOUT_S * 1e9:
            errs = ", ".join(f"{jt.name} {float(e) * kk:+.4f}" for jt, e, kk in
                             zip(self.chain.joints, err, k, strict=True))
            self.state = "idle"
            self.last_stop = f"did not settle within {SETTLE_TIMEOUT_S:g} s ({errs})"

    # -- the trajectory ----------------------------------------------------------------

    def trajectory_tick(self, now_ns: int) -> None:
        """100 Hz: the evaluator's knot for the time that really passed, handed to the
        servo as its next segment.

        The segments join in time as in space: the next one starts where the last
        ended, on the loop's clock.  A tick that comes after the running segment's end
        has passed by a trajectory period or more (the loop stalled) evaluates the
        knots it missed and hands the servo the segment of the last two, the one that
        holds now: the trajectory keeps to the loop's time, never to a count of ticks.
        A tick that finds the running segment reaching beyond now has nothing to make.
        """
        ev = self.evaluator
        if not self.powered or ev is None:
            return
        if self._recover_until is not None:
            if now_ns < self._recover_until:
                return
            self._recover_until = None
        now = now_ns * 1e-9
        half = 0.5 * self.period_s
        if self._joined:
            start = self._end
            if start > now + half:  # the segment running holds now: its knot is made
                return
        else:  # a motion's first segment starts now (the servo held its start until now),
            start = now  # its knots on the trajectory group's ticks from there
        if self._wide:  # back inside the limits: the fault's bounds are the limits' again
            lo, hi = self.chain.lower - self._margin, self.chain.upper + self._margin
            if bool(((self.q >= lo) & (self.q <= hi)).all()):
                self._bound(lo, hi)
                self._wide = False
        # the wrist's wrench when a record may use it (a force limit or comply)
        wrench = self.wrench() if self._wrench_of is not None and ev.wants_wrench else None
        k = self.servo.knots
        missed = None
        while True:
            self._anchor = (start + ev.period, ev.sample)
            try:
                knot = ev.tick(wrench)
            except MotionFault as exc:
                self.fail(f"trajectory: {exc}", self.name)
                return
            _knot_events(self, knot, wrench, ev)
            if not self._joined or start + knot.period > now + half:
                break
            missed, start = knot, start + knot.period  # a knot the stall passed over
        if missed is not None:  # the segment of the last two knots: the one that holds now
            _knot_b(self, missed)
        moving = missed is not None or any(knot.qd.tolist()) or any(knot.qdd.tolist()) \
            or bool((knot.q != k[3]).any())  # (plain floats: the quicker test of six)
        if moving:
            k[0:3] = k[3:6]
            k[6] = k[7]
            _knot_b(self, knot)
            self._start = start
            self.follow(knot.period)
            if knot.move is not None and knot.move.done and knot.move is self._latest:
                # the last record queued has reached its point on a moving frame
                if self.state != "tracking":
                    self.state = "tracking"
                    self.last_stop = (f"tracking: the tool follows its point on the moving "
                                      f"conveyor at {self.pose_text(self.tool())}")
            elif self.state != "moving":
                self.state = "moving"
        else:
            self._joined = False
            if self.state == "moving" and ev.idle:
                self.state = "settling"
                self._settle_from = now_ns
                self._quiet_since = None

    def follow(self, period: float) -> None:
        """Hand the servo the segment to the knot just made (the servo's knots B),
        starting where the last one ended on the loop's clock (or now, the first of a
        motion); a hardware (a) arm writes it to its board instead."""
        self.servo.load(period, quintic=True, start=self._start)
        self._end = self._start + period  # the servo's end, as it computes it
        self._joined = True

    # -- commands (the moves: ArmMoves) ----------------------------------------------

    @command(name="where", reads_only=True)
    def where_cmd(self) -> str:
        """NAME where: the joints, the tool pose (from the encoders), the configuration."""
        last = f"; last move: {self.last_stop}" if self.last_stop else ""
        power = "" if self.powered else "; amplifiers off"
        return f"{self.where()}; {self.state}{power}{last}"

    # -- the station's questions -------------------------------------------------------

    def busy(self) -> bool:
        """A move runs, the arm settles, or the servo brings it to rest after power-on
        (the tool tracking a conveyor has reached its point: not busy)."""
        return self.state not in ("idle", "tracking") or self._recover_until is not None

    def _time_now(self) -> float:
        """The loop's time (s), for the conveyor."""
        return self._now_ns * 1e-9

    def _sample_time(self, sample: int) -> float:
        """The loop time (s) the servo reaches trajectory sample ``sample`` at."""
        t0, n0 = self._anchor
        return t0 + (sample - n0) * self.traj_period_s

    def stop(self) -> str:
        """Brake along the path to rest and hold there (the servo stays on)."""
        ev = self.evaluator
        if ev is None or not self.powered or self.state == "idle":
            return ""
        ev.stop()
        self.last_stop = "stopped (stop command)"
        self.state = "moving"  # tracking a conveyor too: braking is a move
        return f"{self.name}: stopping: braking along the path to rest, then holding"


def _servo_said(arm: UrdfArm) -> bool:
    """A servo tick that did more than change DACs (:meth:`Servo.board_ticker`): a
    stall said; a trip or a joint beyond its bounds is the fault (True), the DACs
    that changed before it written first."""
    servo, io = arm.servo, arm._io
    if servo.dt > arm._stall_s:
        arm.say(f"servo: {servo.dt * 1e3:.1f} ms passed since its last tick (the loop "
                f"stalled): the integral took {arm._stall_s * 1e3:g} ms of it", "warning")
    trip = servo.trip
    if trip is not None:
        arm.fail(f"{trip} (joint {trip.name} at "
                 f"{arm.q[trip.joint] * arm.scales[trip.joint]:.3f} "
                 f"{arm.units[trip.joint]})", arm.joints[trip.joint].name)
        return True
    changed = io.changed
    if changed:  # the DACs whose counts changed (those before a joint beyond its bounds)
        arm._write_dac(arm._dac_list(), changed)  # type: ignore[misc]
    if io.beyond >= 0:
        arm._beyond(io.beyond)
        return True
    return False


def snapshot_ready(arm: UrdfArm, state: Any) -> None:
    """Before a black box's snapshot ``state`` of ``arm`` is put back
    (:mod:`pyrt.station.snapshot`): the objects it restores in place that a station
    just built has not made yet (the evaluator, made at power-on) are made, so that
    what they hold that is not state (the chain, locks) is the station's own."""
    fields = state.get("$o") if isinstance(state, dict) else None
    if not isinstance(fields, dict) or fields.get("evaluator") is None \
            or arm.evaluator is not None:
        return
    q = np.clip(np.nan_to_num(arm.q), arm.chain.lower, arm.chain.upper)
    arm.evaluator = Evaluator(arm.chain, arm.limits, q, period=arm.traj_period_s,
                              force_sensor=arm._wrench_of is not None)


def snapshot_restored(arm: UrdfArm) -> None:
    """After a snapshot was put back into ``arm``: the planning caches outside the
    loop's thread (a chain of their own, made when first used) are dropped; a plan
    is the same whichever chain makes it."""
    arm._prep_chain = None
    ev = arm.evaluator
    if ev is not None:
        ev._side = None


def _knot_b(arm: UrdfArm, knot: Any) -> None:
    """``knot`` into the arm's servo's knots B with its dynamics feed-forward (inverse
    dynamics, computed in place, and the payload held)."""
    q, qd, qdd, ff = arm._rows_b
    q[:] = knot.q
    qd[:] = knot.qd
    qdd[:] = knot.qdd
    arm.chain.rnea(q, qd, qdd, GRAVITY, out=ff)
    if knot.payload_torque is not None:
        ff += knot.payload_torque


def _knot_events(arm: UrdfArm, knot: Any, wrench: np.ndarray | None, ev: Evaluator) -> None:
    """What a knot's events say of how the arm's motion ended (its ``last_stop``)."""
    for word, move in knot.events:
        c = move.spec.comply
        if word == "reached" and c is not None:
            f = ev.comply_force
            said = ", ".join(f"{float(f['xyz'.index(a)]):.2f} N along {a} (set {v:g} N)"
                             for a, v in zip(c.axes, c.forces, strict=True))
            arm.last_stop = f"at target, complying: the tool presses {said}"
        if word in ("reached", "aborted"):  # the end of the whole motion is reported
            continue
        if word == "force" and wrench is not None:
            arm.last_stop = (f"force limit: the wrist felt |F| "
                             f"{float(np.linalg.norm(wrench[:3])):.2f} N (fx fy fz "
                             f"{' '.join(f'{v:.2f}' for v in wrench[:3])} N) at "
                             f"{arm.pose_text(arm.tool())}; braked to rest")
        else:
            arm.last_stop = "stopped (stop command)" if word == "stopped" else word
