"""Joint trajectories for any robot with joints: straight lines in joint space
joined by Paul's transition polynomials (001, "Trajectory Generation"), and
the motion type that runs them.

**The planner** (:func:`plan`, pure: no robot, no clock).  A trajectory runs
from a start point through via points ``P1 .. Pm`` (joint vectors, in the
robot's units: rad or deg, and per second).  Between two points the path is
a straight line in joint space run at constant velocity ``v_i = (P_i -
P_i-1) / T_i``.  Around each point, from ``tau`` before the time the lines
pass through it to ``tau`` after, the corner is replaced by Paul's quartic
(R. Paul, "Manipulator Cartesian Path Control", 1979), in local time
``0 <= s <= 2 tau``::

    q(s) = P - v_in tau + v_in s + dv s**3 / (4 tau**2) - dv s**4 / (16 tau**3),   dv = v_out - v_in

It meets the incoming line's position, velocity and (zero) acceleration at
``s = 0`` and the outgoing line's at ``s = 2 tau``: position, velocity and
acceleration are continuous at every join.  The start is the same transition
from rest (``v_in = 0``) and the end one to rest (``v_out = 0``), so a
trajectory starts and ends at rest, exactly at its first and last points.

The numbers, per joint ``j``:

* **segment time** ``T_i = max(max_j |P_ij - P_i-1,j| / (speed_i vmax_j),
  2 tau_a, duration_i)``: the slowest joint sets it and every joint arrives
  together; ``duration`` (seconds) and ``speed`` (a fraction of the limits,
  0 < speed <= 1) are optional per segment, and a duration the limits cannot
  meet is stretched.  ``tau_a = max_j 1.5 vmax_j / amax_j`` is the robot's
  acceleration time (:func:`acceleration_time`): the longest half-transition
  any velocity change needs (``|dv_j| <= 2 vmax_j``), so two transitions
  never overlap.
* **transition half-time** at each point ``tau = max_j 3 |dv_j| / (4
  amax_j)`` (0 where no joint changes velocity): the quartic's acceleration
  ``3 dv s (2 tau - s) / (4 tau**3)`` keeps one sign and peaks at ``3 |dv| /
  (4 tau)``, so ``|qdd_j| <= amax_j``.
* **velocity**: on a line ``|v_ij| <= speed_i vmax_j``; over a transition the
  velocity moves monotonically from ``v_in`` to ``v_out``: ``|qd_j| <=
  vmax_j`` everywhere.
* **position**: each joint stays between the smallest and the largest value
  its points take (the quartic is convex or concave between two tangents).
* **deviation** (the path cuts each corner): at the time the lines pass
  through a via point the trajectory is ``3 |dv_j| tau / 16`` from it in joint
  ``j`` (:attr:`Trajectory.deviations`), never more than ``3 vmax_j tau_a /
  8``; the start and the end are met exactly.

:meth:`Trajectory.sample` costs one bisection and a Horner evaluation of
coefficients computed at plan time.

**The motion type** :class:`JointTrajectory` (``joint_trajectory``) drives a
:class:`JointRobot`: ``start`` reads the robot's joints and limits and plans,
``step`` writes the setpoint at the poll's time, ``done`` when the end is
reached (stop reason ``endpoint``).  :meth:`JointTrajectory.append` queues
more via points while it runs; they blend with the same transition when they
come before the final deceleration has begun, else the robot comes to rest
at the last point and goes on from there.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np
import numpy.typing as npt

from pyrt.errors import CommandError
from pyrt.scheduler.motion import MotionRecord, MotionType, register_motion_type

__all__ = [
    "TAU_MIN",
    "JointRobot",
    "JointTargets",
    "JointTrajectory",
    "RangedJointRobot",
    "Trajectory",
    "acceleration_time",
    "joint_targets",
    "joint_trajectory_record",
    "plan",
]

Vector = npt.NDArray[np.float64]

#: The shortest transition half-time (s): a velocity change so small that its
#: own ``tau`` would be shorter still gets this one (0 stays 0).
TAU_MIN = 1e-6


# -- the planner ------------------------------------------------------------------------------


def _vector(values: Any, n: int | None, what: str) -> Vector:
    try:
        v = np.array(values, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{what} must be a vector of numbers, got {values!r}") from exc
    if v.ndim != 1 or (n is not None and v.shape[0] != n) or v.shape[0] == 0:
        want = f"{n} numbers" if n is not None else "a non-empty vector"
        raise ValueError(f"{what} must be {want}, got shape {v.shape}")
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{what} must be finite, got {values!r}")
    return v


def _limits(vmax: npt.ArrayLike, amax: npt.ArrayLike, n: int | None) -> tuple[Vector, Vector]:
    v = _vector(vmax, n, "vmax")
    a = _vector(amax, v.shape[0], "amax")
    if np.any(v <= 0) or np.any(a <= 0):
        raise ValueError(f"velocity and acceleration limits must be > 0, got {v!r}, {a!r}")
    return v, a


def acceleration_time(vmax: npt.ArrayLike, amax: npt.ArrayLike) -> float:
    """The robot's acceleration time ``tau_a = max_j 1.5 vmax_j / amax_j`` (s), at
    least :data:`TAU_MIN`: the longest half-transition any velocity change needs."""
    v, a = _limits(vmax, amax, None)
    return max(float(np.max(1.5 * v / a)), TAU_MIN)


def _per_segment(value: Any, m: int, what: str, ok: Any) -> list[float | None]:
    items = [value] * m if value is None or isinstance(value, int | float) else list(value)
    if len(items) != m:
        raise ValueError(f"{what}: {len(items)} values for {m} segments")
    out: list[float | None] = []
    for x in items:
        if x is None:
            out.append(None)
            continue
        if isinstance(x, bool) or not isinstance(x, int | float) or not ok(float(x)):
            raise ValueError(f"{what}: {x!r} is out of range")
        out.append(float(x))
    return out


def _transition_tau(dv: Vector, amax: Vector) -> float:
    tau = float(np.max(0.75 * np.abs(dv) / amax))
    return 0.0 if tau == 0.0 else max(tau, TAU_MIN)


def plan(
    start: npt.ArrayLike,
    vias: Sequence[npt.ArrayLike] | npt.NDArray[Any],
    vmax: npt.ArrayLike,
    amax: npt.ArrayLike,
    *,
    durations: float | Sequence[float | None] | None = None,
    speeds: float | Sequence[float | None] | None = None,
) -> Trajectory:
    """The trajectory from ``start`` at rest through every point of ``vias`` to
    rest at the last one (the module's docstring gives the rules).

    ``vmax`` and ``amax`` are the per-joint limits (> 0); ``durations``
    (seconds, > 0) and ``speeds`` (fractions, 0 < speed <= 1) are one value
    for every segment or one per segment (None: not given).  ValueError for
    malformed input."""
    p0 = _vector(start, None, "start")
    n = p0.shape[0]
    v_lim, a_lim = _limits(vmax, amax, n)
    if len(vias) == 0:
        raise ValueError("plan: at least one via point is needed")
    points = np.vstack([p0] + [_vector(p, n, f"via {i + 1}") for i, p in enumerate(vias)])
    m = points.shape[0] - 1
    dur = _per_segment(durations, m, "durations", lambda x: math.isfinite(x) and x > 0)
    spd = _per_segment(speeds, m, "speeds", lambda x: 0 < x <= 1)
    tau_a = acceleration_time(v_lim, a_lim)
    seg_v = np.zeros((m + 2, n))  # the lines' velocities, with rest before and after
    seg_t = np.zeros(m)
    for i in range(m):
        delta = points[i + 1] - points[i]
        t = max(float(np.max(np.abs(delta) / ((spd[i] or 1.0) * v_lim))), 2.0 * tau_a)
        t = max(t, dur[i] or 0.0)
        seg_t[i] = t
        seg_v[i + 1] = delta / t
    taus = np.array([_transition_tau(seg_v[i + 1] - seg_v[i], a_lim) for i in range(m + 1)])
    times = np.empty(m + 1)
    times[0] = taus[0]
    for i in range(m):
        times[i + 1] = times[i] + seg_t[i]
    return Trajectory(points, times, taus, seg_v[:-1], seg_v[1:])


def _frozen(a: npt.ArrayLike) -> Vector:
    out = np.array(a, dtype=np.float64)
    out.flags.writeable = False
    return out


class _Piece:
    """One polynomial of the trajectory, in local time ``s = t - start``:
    position, velocity and acceleration coefficients, highest power first."""

    __slots__ = ("acc", "linear", "pos", "start", "vel")

    def __init__(self, start: float, coeffs: Sequence[Vector]) -> None:
        self.start = start
        c = [np.array(x, dtype=np.float64) for x in coeffs]  # c0 .. c4
        self.linear = not any(np.any(x) for x in c[2:])
        self.pos = tuple(reversed(c))
        self.vel = tuple(reversed([k * c[k] for k in range(1, len(c))]))
        self.acc = tuple(reversed([k * (k - 1) * c[k] for k in range(2, len(c))]))


def _horner(coeffs: tuple[Vector, ...], s: float) -> Vector:
    out: Vector = coeffs[0] * s + coeffs[1]
    for c in coeffs[2:]:
        out = out * s + c
    return out


class Trajectory:
    """A planned joint trajectory (made by :func:`plan` and :meth:`then`).

    Times are seconds from its start.  Per point (the start, every via
    point, the end; a rest in the middle, after :meth:`then`, lists its point
    twice): ``points`` (k, n), ``point_times`` (k,) when the straight lines
    pass through it, ``taus`` (k,) its transition's half-time, ``v_in`` and
    ``v_out`` (k, n) the lines' velocities before and after it, and
    ``deviations`` (k, n) how far the trajectory passes from it, per joint,
    at ``point_times``.  ``joins`` are the times where a straight line and a
    transition polynomial meet.  Arrays are read-only.
    """

    def __init__(
        self,
        points: npt.ArrayLike,
        point_times: npt.ArrayLike,
        taus: npt.ArrayLike,
        v_in: npt.ArrayLike,
        v_out: npt.ArrayLike,
    ) -> None:
        self.points = _frozen(points)
        self.point_times = _frozen(point_times)
        self.taus = _frozen(taus)
        self.v_in = _frozen(v_in)
        self.v_out = _frozen(v_out)
        k, n = self.points.shape
        if not (self.point_times.shape == self.taus.shape == (k,)
                and self.v_in.shape == self.v_out.shape == (k, n)):
            raise ValueError("Trajectory: points, times, taus and velocities do not agree")
        self.joint_count = n
        #: The length of the trajectory (s).
        self.duration = float(self.point_times[-1] + self.taus[-1])
        dv = self.v_out - self.v_in
        self.deviations = _frozen(3.0 / 16.0 * np.abs(dv) * self.taus[:, None])
        pieces: list[_Piece] = []
        joins: list[float] = []
        for i in range(k):
            p, tau, t = self.points[i], float(self.taus[i]), float(self.point_times[i])
            if tau > 0.0:
                a, b = self.v_in[i], self.v_out[i]
                d = b - a
                pieces.append(_Piece(t - tau, [p - a * tau, a, np.zeros(n),
                                               d / (4.0 * tau * tau),
                                               -d / (16.0 * tau * tau * tau)]))
            if i + 1 < k:
                begin, end = t + tau, float(self.point_times[i + 1] - self.taus[i + 1])
                if end > begin:
                    v = self.v_out[i]
                    if tau > 0.0:
                        joins.append(begin)
                    pieces.append(_Piece(begin, [p + v * tau, v]))
                    if self.taus[i + 1] > 0.0:
                        joins.append(end)
        self.joins = _frozen(joins)
        self._pieces = pieces
        self._starts = [pc.start for pc in pieces]
        self._first: Vector = self.points[0]
        self._last: Vector = self.points[-1]

    @property
    def start(self) -> Vector:
        """Where the trajectory begins, at rest."""
        return self._first

    @property
    def end(self) -> Vector:
        """Where the trajectory ends, at rest."""
        return self._last

    def sample(self, t: float) -> tuple[Vector, Vector, Vector]:
        """``(q, qd, qdd)`` at ``t`` seconds (new arrays); at rest at the start
        before 0 and at the end after :attr:`duration`."""
        if t >= self.duration or not self._pieces:
            return self._last.copy(), np.zeros(self.joint_count), np.zeros(self.joint_count)
        if t <= 0.0:
            return self._first.copy(), np.zeros(self.joint_count), np.zeros(self.joint_count)
        i = max(bisect_right(self._starts, t) - 1, 0)
        piece = self._pieces[i]
        s = t - piece.start
        if piece.linear:
            c1, c0 = piece.pos[-2:]
            return c1 * s + c0, c1.copy(), np.zeros(self.joint_count)
        return _horner(piece.pos, s), _horner(piece.vel, s), _horner(piece.acc, s)

    def then(self, other: Trajectory) -> Trajectory:
        """This trajectory followed by ``other`` (which starts where this one
        ends): a rest at the meeting point, no velocity or acceleration jump."""
        if other.joint_count != self.joint_count or not np.array_equal(other.start, self.end):
            raise ValueError("Trajectory.then: the second trajectory must start where the "
                             "first ends")
        return Trajectory(
            np.vstack([self.points, other.points]),
            np.concatenate([self.point_times, other.point_times + self.duration]),
            np.concatenate([self.taus, other.taus]),
            np.vstack([self.v_in, other.v_in]),
            np.vstack([self.v_out, other.v_out]))


# -- the robot side ---------------------------------------------------------------------------


@runtime_checkable
class JointRobot(Protocol):
    """What :class:`JointTrajectory` drives: any robot with joints.  Positions,
    limits and setpoints share the robot's units (e.g. rad, rad/s, rad/s2)."""

    @property
    def joint_count(self) -> int:
        """How many joints (n)."""
        ...

    def joint_positions(self) -> Sequence[float]:
        """The joints' present positions (n values)."""
        ...

    def joint_limits(self) -> tuple[Sequence[float], Sequence[float]]:
        """``(vmax, amax)``: each joint's velocity and acceleration limit (> 0)."""
        ...

    def command_joints(self, q: Vector, qd: Vector) -> None:
        """Take the setpoint: position and velocity of every joint."""
        ...


@runtime_checkable
class RangedJointRobot(JointRobot, Protocol):
    """A :class:`JointRobot` whose joints have position limits: a target
    outside them is refused before anything moves."""

    def joint_range(self) -> tuple[Sequence[float], Sequence[float]]:
        """``(low, high)``: each joint's allowed positions, inclusive."""
        ...


# -- motion records ---------------------------------------------------------------------------


@dataclass(frozen=True)
class JointTargets:
    """A ``joint_trajectory`` record's parameters, checked: the via points in
    order, and the optional segment duration (s) and speed fraction."""

    vias: tuple[tuple[float, ...], ...]
    duration: float | None = None
    speed: float | None = None


_NAME = "joint_trajectory"


def _number(value: Any, what: str) -> float:
    if isinstance(value, str):
        try:
            value = float(value.strip())
        except ValueError:
            raise CommandError(f"{_NAME}: {what} must be a number, got {value[:40]!r}") from None
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise CommandError(f"{_NAME}: {what} must be a number, got {str(value)[:40]!r}")
    v = float(value)
    if not math.isfinite(v):
        raise CommandError(f"{_NAME}: {what} must be finite, got {v}")
    return v


def _numbers(value: Any, what: str) -> list[float]:
    """A number, a comma-separated string of numbers, or a sequence of numbers."""
    if isinstance(value, str):
        items: list[Any] = value.split(",")
    elif isinstance(value, Sequence | np.ndarray):
        items = list(value)
    else:
        items = [value]
    if not items:
        raise CommandError(f"{_NAME}: {what} is empty")
    return [_number(x, what) for x in items]


def _vias_of_q(value: Any, n: int) -> list[list[float]]:
    if isinstance(value, str):
        rows: list[Any] = [r for r in value.split(";")]
    elif isinstance(value, Sequence | np.ndarray) and len(value) > 0 and all(
            isinstance(r, str | Sequence | np.ndarray) for r in value):
        rows = list(value)
    else:
        rows = [value]
    vias = [_numbers(r, "q") for r in rows]
    for i, via in enumerate(vias):
        if len(via) != n:
            where = f"via point {i + 1}" if len(vias) > 1 else "q"
            raise CommandError(f"{_NAME}: {where} has {len(via)} joint values; the robot "
                               f"has {n} joints")
    return vias


def joint_targets(params: Mapping[str, Any], joint_count: int) -> JointTargets:
    """The checked parameters of a ``joint_trajectory`` record for a robot of
    ``joint_count`` joints, or CommandError saying what is wrong.

    The via points come either as ``q``: one point (n numbers, or the string
    ``"a,b"``) or several (a sequence of points, or ``"a,b;c,d"``), or as
    ``q0 .. q{n-1}``: each a number (one point) or several numbers (a
    sequence, or ``"a,c"``), the same count for every joint.  Optional:
    ``duration`` (s, > 0) and ``speed`` (0 < speed <= 1), for each segment."""
    n = joint_count
    per_joint = [f"q{j}" for j in range(n)]
    allowed = {"q", "duration", "speed", *per_joint}
    unknown = sorted(set(params) - allowed)
    if unknown:
        shown = ", ".join(repr(k)[:40] for k in unknown)
        raise CommandError(f"{_NAME}: unknown parameter(s) {shown}; takes q or "
                           f"q0..q{n - 1}, and duration, speed")
    given = [k for k in per_joint if k in params]
    if "q" in params and given:
        raise CommandError(f"{_NAME}: give q or q0..q{n - 1}, not both")
    if "q" in params:
        vias = _vias_of_q(params["q"], n)
    elif given:
        missing = [k for k in per_joint if k not in params]
        if missing:
            raise CommandError(f"{_NAME}: {', '.join(missing)} missing (every joint's target "
                               "is needed)")
        columns = [_numbers(params[k], k) for k in per_joint]
        counts = {len(c) for c in columns}
        if len(counts) != 1:
            raise CommandError(f"{_NAME}: q0..q{n - 1} give different numbers of via points "
                               f"({', '.join(str(len(c)) for c in columns)})")
        vias = [list(row) for row in zip(*columns, strict=True)]
    else:
        raise CommandError(f"{_NAME}: target missing: give q=[...] or q0..q{n - 1}")
    duration = speed = None
    if params.get("duration") is not None:
        duration = _number(params["duration"], "duration")
        if duration <= 0:
            raise CommandError(f"{_NAME}: duration must be > 0 s, got {duration}")
    if params.get("speed") is not None:
        speed = _number(params["speed"], "speed")
        if not 0 < speed <= 1:
            raise CommandError(f"{_NAME}: speed must be a fraction 0 < speed <= 1, got {speed}")
    return JointTargets(tuple(tuple(v) for v in vias), duration, speed)


def joint_trajectory_record(
    *vias: Sequence[float], duration: float | None = None, speed: float | None = None
) -> MotionRecord:
    """The motion record that moves through ``vias`` (one or more joint
    vectors) in order, optionally with a duration (s) or speed fraction per segment."""
    params: dict[str, Any] = {"q": tuple(tuple(float(x) for x in v) for v in vias)}
    if duration is not None:
        params["duration"] = float(duration)
    if speed is not None:
        params["speed"] = float(speed)
    return MotionRecord(_NAME, params)


def _robot(robot: Any) -> JointRobot:
    if not isinstance(robot, JointRobot):
        raise CommandError(f"{_NAME}: {type(robot).__name__} is not a robot with joints "
                           "(joint_count, joint_positions, joint_limits, command_joints)")
    n = robot.joint_count
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise CommandError(f"{_NAME}: the robot's joint_count must be a positive whole "
                           f"number, got {n!r}")
    return robot


def _check_range(robot: JointRobot, vias: Sequence[Sequence[float]]) -> None:
    if not isinstance(robot, RangedJointRobot):
        return
    low, high = robot.joint_range()
    n = robot.joint_count
    if len(low) != n or len(high) != n:
        raise CommandError(f"{_NAME}: the robot's joint_range gives {len(low)} and "
                           f"{len(high)} limits for {n} joints")
    for i, via in enumerate(vias):
        for j, x in enumerate(via):
            if not low[j] <= x <= high[j]:
                where = f" (via point {i + 1})" if len(vias) > 1 else ""
                raise CommandError(f"{_NAME}: q{j} = {x:g}{where} is outside the joint's "
                                   f"range {low[j]:g} .. {high[j]:g}; nothing moved")


@dataclass
class _Group:
    """Via points blended into one rest-to-rest plan, and where it starts."""

    start: Vector
    vias: list[tuple[float, ...]]
    durations: list[float | None]
    speeds: list[float | None]
    offset: float = 0.0
    trajectory: Trajectory | None = None


class JointTrajectory(MotionType):
    """Joint moves through via points, blended (001): q0=.. q1=.. [duration=S] [speed=F]

    ``motion joint_trajectory q0=A q1=B`` moves to one point, ``q0=A,C
    q1=B,D`` through two (:func:`joint_targets` gives every form).  Drives a
    :class:`JointRobot`.  ``start`` reads the robot's joints and limits and
    plans (:func:`plan`); each ``step(now_ns)`` writes the setpoint at that
    time with ``command_joints(q, qd)`` (``setpoint`` holds ``(q, qd, qdd)``
    for a feed-forward); the motion is done at the end (stop reason
    ``endpoint``).  :meth:`append` queues more via points while it runs.
    ``stop`` ends it at once and writes nothing: the robot holds or its
    reflex acts.
    """

    @classmethod
    def accepts(cls, robot: Any) -> bool:
        """Any robot with joints (a :class:`JointRobot`) is driven by this type."""
        return isinstance(robot, JointRobot)

    name = _NAME

    def __init__(self) -> None:
        super().__init__()
        self.robot: JointRobot | None = None
        #: The whole trajectory planned so far (time 0 at ``start``).
        self.trajectory: Trajectory | None = None
        #: The last setpoint written: ``(q, qd, qdd)``.
        self.setpoint: tuple[Vector, Vector, Vector] | None = None
        self._groups: list[_Group] = []
        self._vmax: Vector = np.zeros(0)
        self._amax: Vector = np.zeros(0)
        self._t0_ns = 0
        self._now_ns = 0

    @classmethod
    def check(cls, robot: Any, params: Mapping[str, Any]) -> None:
        """Refuse now (CommandError) a record that could never start: not a
        robot with joints, wrong joint count, a value that is not a finite
        number, a target outside the joints' range, a bad duration or speed."""
        r = _robot(robot)
        _check_range(r, joint_targets(params, r.joint_count).vias)

    def start(self, robot: Any, record: MotionRecord, now_ns: int) -> None:
        r = _robot(robot)
        n = r.joint_count
        targets = joint_targets(record.params, n)
        _check_range(r, targets.vias)
        vmax, amax = r.joint_limits()
        try:
            self._vmax, self._amax = _limits(vmax, amax, n)
            here = _vector(r.joint_positions(), n, "joint positions")
        except ValueError as exc:
            raise CommandError(f"{_NAME}: the robot's {exc}") from None
        self.robot = r
        m = len(targets.vias)
        self._groups = [_Group(here, list(targets.vias), [targets.duration] * m,
                               [targets.speed] * m)]
        self._replan()
        self._t0_ns = self._now_ns = now_ns

    def step(self, now_ns: int) -> None:
        robot, trajectory = self.robot, self.trajectory
        if robot is None or trajectory is None:
            raise CommandError(f"{_NAME}: step before start")
        self._now_ns = now_ns
        t = (now_ns - self._t0_ns) * 1e-9
        q, qd, qdd = trajectory.sample(t)
        self.setpoint = (q, qd, qdd)
        robot.command_joints(q, qd)
        if t >= trajectory.duration:
            self.stop("endpoint")

    @property
    def elapsed(self) -> float:
        """Seconds from the start to the last step."""
        return (self._now_ns - self._t0_ns) * 1e-9

    @property
    def remaining(self) -> float:
        """Seconds from the last step to the end of everything queued."""
        if self.trajectory is None:
            return 0.0
        return max(self.trajectory.duration - self.elapsed, 0.0)

    def append(self, params: Mapping[str, Any]) -> bool:
        """Queue the via points of ``params`` (a ``joint_trajectory`` record's
        parameters) after those already planned.  True when they blend with
        Paul's transition (the final deceleration has not begun at the last
        step), False when the robot comes to rest at the present last point
        and starts again from there.  CommandError if the parameters are bad
        or the motion is not running; then nothing changes.  Call it in the
        loop thread (a mailbox command), like ``step``."""
        robot = self.robot
        if robot is None or self.done or self.trajectory is None:
            raise CommandError(f"{_NAME}: not running; queue a new motion record instead")
        targets = joint_targets(params, robot.joint_count)
        _check_range(robot, targets.vias)
        m = len(targets.vias)
        last = self._groups[-1]
        old = last.trajectory
        assert old is not None
        joined = _Group(last.start, last.vias + list(targets.vias),
                        last.durations + [targets.duration] * m,
                        last.speeds + [targets.speed] * m, last.offset)
        new = self._plan(joined)
        k = len(last.vias)
        split = last.offset + float(new.point_times[k] - max(new.taus[k], old.taus[k]))
        blended = self.elapsed <= split
        if blended:
            joined.trajectory = new
            self._groups[-1] = joined
        else:
            self._groups.append(_Group(old.end.copy(), list(targets.vias),
                                       [targets.duration] * m, [targets.speed] * m))
        self._replan()
        return blended

    def _plan(self, group: _Group) -> Trajectory:
        return plan(group.start, group.vias, self._vmax, self._amax,
                    durations=group.durations, speeds=group.speeds)

    def _replan(self) -> None:
        whole: Trajectory | None = None
        for g in self._groups:
            if g.trajectory is None:
                g.trajectory = self._plan(g)
            g.offset = 0.0 if whole is None else whole.duration
            whole = g.trajectory if whole is None else whole.then(g.trajectory)
        self.trajectory = whole


register_motion_type(JointTrajectory.name, JointTrajectory)
