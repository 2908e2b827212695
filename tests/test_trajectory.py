"""Joint trajectories: Paul's transitions (001) between straight joint-space lines, and the motion type."""

from __future__ import annotations

import math

import numpy as np
import pytest
from _ref_trajectory import RefPlan
from hypothesis import given, settings
from hypothesis import strategies as st

from pyrt.commands._motion import parse_motion
from pyrt.errors import CommandError
from pyrt.robots.trajectory import (
    TAU_MIN,
    JointRobot,
    JointTargets,
    JointTrajectory,
    RangedJointRobot,
    Trajectory,
    acceleration_time,
    joint_targets,
    joint_trajectory_record,
    plan,
)
from pyrt.scheduler.motion import MotionExecutor, MotionRecord, get_motion_type

# -- strategies ---------------------------------------------------------------------------------

coordinate = st.floats(-10.0, 10.0, allow_nan=False)


@st.composite
def plans(draw, max_joints=4, max_vias=5):
    """(start, vias, vmax, amax, durations, speeds) of a random plan."""
    n = draw(st.integers(1, max_joints))
    m = draw(st.integers(1, max_vias))
    point = st.lists(coordinate, min_size=n, max_size=n)
    start = draw(point)
    vias = [draw(point) for _ in range(m)]
    if m > 1 and draw(st.booleans()):
        vias[1] = list(vias[0])  # a via repeated: a segment of zero length
    vmax = draw(st.lists(st.floats(0.1, 10.0), min_size=n, max_size=n))
    amax = draw(st.lists(st.floats(0.1, 100.0), min_size=n, max_size=n))
    option = st.one_of(st.none(), st.floats(0.05, 1.0))
    speeds = draw(st.one_of(st.none(), st.lists(option, min_size=m, max_size=m)))
    durations = draw(st.one_of(st.none(), st.lists(st.one_of(st.none(), st.floats(0.01, 30.0)),
                                                    min_size=m, max_size=m)))
    return start, vias, vmax, amax, durations, speeds


def _plan(args) -> Trajectory:
    start, vias, vmax, amax, durations, speeds = args
    return plan(start, vias, vmax, amax, durations=durations, speeds=speeds)


def _jerk_bound(tr: Trajectory) -> np.ndarray:
    """Per joint, the largest jerk of any transition quartic: 3 |dv| / (2 tau**2)."""
    dv = np.abs(tr.v_out - tr.v_in)
    with np.errstate(divide="ignore", invalid="ignore"):
        jerk = np.where(tr.taus[:, None] > 0, 1.5 * dv / tr.taus[:, None] ** 2, 0.0)
    return jerk.max(axis=0)


def _dense(tr: Trajectory, count: int = 1500) -> np.ndarray:
    """Sample times: a uniform grid plus each join and transition centre, and just around them."""
    extra = [tr.joins, tr.point_times, tr.joins - 1e-9, tr.joins + 1e-9]
    return np.concatenate([np.linspace(0.0, tr.duration, count), *extra])


# -- the planner against the reference ----------------------------------------------------------


@settings(max_examples=150, deadline=None)
@given(plans(), st.lists(st.floats(0.0, 1.0), min_size=40, max_size=40))
def test_samples_agree_with_the_pure_python_reference(args, fractions):
    """On random plans, q, qd and qdd agree with the plain-float reference (Paul's u-form) to 1e-9."""
    start, vias, vmax, amax, durations, speeds = args
    tr = _plan(args)
    ref = RefPlan(start, vias, vmax, amax, durations, speeds)
    assert tr.duration == pytest.approx(ref.duration, rel=1e-12, abs=1e-12)
    times = [f * ref.duration for f in fractions] + [0.0, ref.duration, -1.0, ref.duration + 1]
    for t in times:
        got = tr.sample(t)
        want = ref.sample(t)
        for g, w in zip(got, want, strict=True):
            np.testing.assert_allclose(g, w, rtol=0, atol=1e-9)


def test_a_worked_two_joint_plan_has_the_stated_times():
    """Segment times are the slowest joint's at its limit (at least 2 tau_a); each tau is 3|dv|/(4 amax)."""
    tr = plan([0, 0], [[1, 0.5], [2, -1]], vmax=[1, 2], amax=[4, 8])
    tau_a = max(1.5 * 1 / 4, 1.5 * 2 / 8)
    assert acceleration_time([1, 2], [4, 8]) == tau_a == 0.375
    seg = np.diff(tr.point_times)
    assert seg.tolist() == [max(1.0, 0.25, 2 * tau_a), max(1.0, 0.75, 2 * tau_a)]
    assert tr.v_out[0].tolist() == [1.0, 0.5] and tr.v_out[1].tolist() == [1.0, -1.5]
    assert tr.taus.tolist() == [0.75 * 1 / 4, 0.75 * 2 / 8, max(0.75 * 1 / 4, 0.75 * 1.5 / 8)]
    assert tr.duration == tr.point_times[-1] + tr.taus[-1]
    # the joins are the ends of each transition: [t - tau, t + tau] around every point
    expected = [tr.point_times[0] + tr.taus[0]]
    for t, tau in zip(tr.point_times[1:-1], tr.taus[1:-1], strict=True):
        expected += [t - tau, t + tau]
    expected.append(tr.point_times[-1] - tr.taus[-1])
    np.testing.assert_allclose(tr.joins, expected)


# -- continuity, limits, ends, via points -------------------------------------------------------


@settings(max_examples=300, deadline=None)
@given(plans())
def test_position_velocity_and_acceleration_are_continuous_at_every_join(args):
    """At each line/quartic join, q, qd and qdd at t +- eps differ by no more than eps times the next derivative's bound."""
    tr = _plan(args)
    _, _, vmax, amax, _, _ = args
    vmax, amax = np.array(vmax), np.array(amax)
    jerk = _jerk_bound(tr)
    for tj in tr.joins:
        for eps in (1e-5, 1e-7):
            q0, qd0, qdd0 = tr.sample(tj - eps)
            q1, qd1, qdd1 = tr.sample(tj + eps)
            noise = 1e-9
            assert np.all(np.abs(q1 - q0) <= 2 * eps * vmax * (1 + 1e-9) + noise)
            assert np.all(np.abs(qd1 - qd0) <= 2 * eps * amax * (1 + 1e-9) + noise)
            assert np.all(np.abs(qdd1 - qdd0) <= 2 * eps * jerk * (1 + 1e-9) + noise)


def test_the_continuity_check_sees_a_jump():
    """A joint whose line velocity changes with no transition (tau forced to 0) fails the same bound: the check can fail."""
    good = plan([0.0], [[1.0], [3.0]], [1.0], [1.0])
    broken = Trajectory(good.points, good.point_times, [good.taus[0], 0.0, good.taus[2]],
                        good.v_in, good.v_out)
    tj = good.point_times[1]
    eps = 1e-7
    jump = broken.sample(tj + eps)[1] - broken.sample(tj - eps)[1]
    assert abs(jump[0]) > 2 * eps * 1.0 + 1e-9
    smooth = good.sample(tj + eps)[1] - good.sample(tj - eps)[1]
    assert abs(smooth[0]) <= 2 * eps * 1.0 + 1e-9


@settings(max_examples=150, deadline=None)
@given(plans())
def test_no_joint_exceeds_its_velocity_or_acceleration_limit(args):
    """Over a dense sample (and at every join), |qd_j| <= vmax_j and |qdd_j| <= amax_j."""
    tr = _plan(args)
    _, _, vmax, amax, _, _ = args
    vmax, amax = np.array(vmax), np.array(amax)
    for t in _dense(tr):
        _, qd, qdd = tr.sample(float(t))
        assert np.all(np.abs(qd) <= vmax * (1 + 1e-9) + 1e-12)
        assert np.all(np.abs(qdd) <= amax * (1 + 1e-9) + 1e-12)


def test_the_limits_are_reached_on_a_long_move():
    """A long move runs its slowest joint at its velocity limit and its transitions at the acceleration limit."""
    tr = plan([0.0, 0.0], [[10.0, 2.0]], vmax=[1.0, 1.0], amax=[2.0, 2.0])
    _, qd, _ = tr.sample(tr.duration / 2)
    assert qd.tolist() == [1.0, 0.2]
    _, _, qdd = tr.sample(tr.point_times[0])  # the middle of the start transition
    assert qdd[0] == pytest.approx(2.0, rel=1e-12)
    half = plan([0.0, 0.0], [[10.0, 2.0]], vmax=[1.0, 1.0], amax=[2.0, 2.0], speeds=0.5)
    assert half.sample(half.duration / 2)[1].tolist() == [0.5, 0.1]


@settings(max_examples=150, deadline=None)
@given(plans())
def test_starts_and_ends_at_rest_at_the_given_points(args):
    """sample(0) is the start and sample(duration) the last via, exactly, with zero velocity and acceleration."""
    start, vias, *_ = args
    tr = _plan(args)
    for t, where in ((0.0, start), (tr.duration, vias[-1])):
        q, qd, qdd = tr.sample(t)
        assert q.tolist() == [float(x) for x in where]
        assert not qd.any() and not qdd.any()
    near = tr.sample(1e-9)
    np.testing.assert_allclose(near[0], start, atol=1e-9)
    np.testing.assert_allclose(near[1], 0.0, atol=1e-6)


@settings(max_examples=150, deadline=None)
@given(plans())
def test_passes_each_via_point_within_the_stated_deviation(args):
    """At each point's time the path is 3|dv|tau/16 from it per joint, never more than 3 vmax tau_a / 8."""
    _, _, vmax, amax, *_ = args
    tr = _plan(args)
    tau_a = acceleration_time(vmax, amax)
    bound = 3.0 / 8.0 * np.array(vmax) * tau_a
    for point, t, dev in zip(tr.points, tr.point_times, tr.deviations, strict=True):
        q, _, _ = tr.sample(float(t))
        np.testing.assert_allclose(np.abs(q - point), dev, atol=1e-9)
        assert np.all(dev <= bound * (1 + 1e-12))


@settings(max_examples=100, deadline=None)
@given(plans())
def test_each_joint_stays_between_its_smallest_and_largest_point(args):
    """The quartics cut corners inward: no joint overshoots the range its points span."""
    tr = _plan(args)
    low, high = tr.points.min(axis=0), tr.points.max(axis=0)
    for t in _dense(tr, 600):
        q, _, _ = tr.sample(float(t))
        assert np.all(q >= low - 1e-9) and np.all(q <= high + 1e-9)


def test_a_duration_is_kept_or_stretched_never_shortened():
    """A longer duration is kept; a shorter one than the limits allow is stretched to what they need."""
    slow = plan([0.0], [[1.0]], [1.0], [10.0], durations=5.0)
    assert slow.point_times[1] - slow.point_times[0] == pytest.approx(5.0, abs=1e-12)
    fast = plan([0.0], [[1.0]], [1.0], [10.0], durations=0.1)
    assert fast.point_times[1] - fast.point_times[0] == pytest.approx(1.0, abs=1e-12)


def test_a_straight_line_through_a_via_at_the_same_velocity_has_no_transition():
    """Collinear vias passed at one velocity need no quartic there (tau 0) and the path hits them exactly."""
    tr = plan([0.0, 0.0], [[2.0, 1.0], [4.0, 2.0]], [1.0, 1.0], [1.0, 1.0])
    assert tr.taus[1] == 0.0
    q, qd, _ = tr.sample(float(tr.point_times[1]))
    assert q.tolist() == [2.0, 1.0]
    np.testing.assert_allclose(qd, [2 / 3, 1 / 3], rtol=1e-15)


def test_planner_refuses_malformed_input():
    """Wrong lengths, non-finite values, non-positive limits, no vias, bad speed: ValueError."""
    with pytest.raises(ValueError, match="at least one via"):
        plan([0.0], [], [1.0], [1.0])
    with pytest.raises(ValueError, match="via 1 must be 2 numbers"):
        plan([0.0, 0.0], [[1.0]], [1.0, 1.0], [1.0, 1.0])
    with pytest.raises(ValueError, match="finite"):
        plan([0.0], [[math.nan]], [1.0], [1.0])
    with pytest.raises(ValueError, match="> 0"):
        plan([0.0], [[1.0]], [0.0], [1.0])
    with pytest.raises(ValueError, match="speeds"):
        plan([0.0], [[1.0]], [1.0], [1.0], speeds=1.5)
    with pytest.raises(ValueError, match="durations: 2 values for 1 segments"):
        plan([0.0], [[1.0]], [1.0], [1.0], durations=[1.0, 2.0])


def test_then_rests_between_two_trajectories():
    """then() joins two plans with a rest at the meeting point; refuses one that starts elsewhere."""
    a = plan([0.0], [[1.0]], [1.0], [4.0])
    b = plan([1.0], [[-1.0]], [1.0], [4.0])
    ab = a.then(b)
    assert ab.duration == pytest.approx(a.duration + b.duration, abs=1e-12)
    q, qd, qdd = ab.sample(a.duration)
    assert q.tolist() == [1.0] and not qd.any() and not qdd.any()
    for t in (0.1, 0.3, 0.6):
        for got, want in zip(ab.sample(a.duration + t), b.sample(t), strict=True):
            np.testing.assert_allclose(got, want, atol=1e-12)
    with pytest.raises(ValueError, match="start where"):
        a.then(a)
    assert TAU_MIN > 0


# -- record parameters --------------------------------------------------------------------------


def test_record_parameters_in_every_form():
    """q as a vector, q as several vias, q0..qN as numbers or comma lists, and strings all give the same targets."""
    one = JointTargets(((1.0, 2.0),))
    two = JointTargets(((1.0, 2.0), (3.0, 4.0)), duration=2.0, speed=0.5)
    assert joint_targets({"q": [1, 2]}, 2) == one
    assert joint_targets({"q": "1,2"}, 2) == one
    assert joint_targets({"q0": 1, "q1": 2.0}, 2) == one
    assert joint_targets({"q": np.array([1.0, 2.0])}, 2) == one
    opts = {"duration": 2, "speed": 0.5}
    assert joint_targets({"q": [[1, 2], [3, 4]], **opts}, 2) == two
    assert joint_targets({"q": "1,2;3,4", **opts}, 2) == two
    assert joint_targets({"q0": "1,3", "q1": "2,4", **opts}, 2) == two
    assert joint_targets({"q0": [1, 3], "q1": (2, 4), **opts}, 2) == two
    assert joint_targets(joint_trajectory_record([1, 2], [3, 4], duration=2, speed=0.5).params,
                         2) == two
    record = parse_motion("joint_trajectory q0=1,3 q1=2,4 duration=2 speed=0.5")
    assert record is not None and record.type == "joint_trajectory"
    assert joint_targets(record.params, 2) == two
    assert get_motion_type("JOINT_TRAJECTORY") is JointTrajectory


@pytest.mark.parametrize("params, message", [
    ({}, "target missing"),
    ({"q": [1, 2, 3]}, "has 3 joint values; the robot has 2 joints"),
    ({"q": [[1, 2], [3]]}, "via point 2 has 1 joint values"),
    ({"q0": 1}, "q1 missing"),
    ({"q0": "1,2", "q1": 3}, "different numbers of via points"),
    ({"q": [1, 2], "q0": 1}, "not both"),
    ({"q": [1, math.inf]}, "must be finite"),
    ({"q": [1, math.nan]}, "must be finite"),
    ({"q": [1, "x"]}, "must be a number"),
    ({"q": [True, 1]}, "must be a number"),
    ({"q": []}, "is empty"),
    ({"q": [1, 2], "speed": 0}, "speed must be a fraction"),
    ({"q": [1, 2], "speed": 1.5}, "speed must be a fraction"),
    ({"q": [1, 2], "duration": -1}, "duration must be > 0"),
    ({"q": [1, 2], "accel": 3}, "unknown parameter"),
    ({"q": [1, 2.5]}, r"q1 = 2.5 is outside the joint's range -2 .. 2; nothing moved"),
    ({"q": [[0, 0], [0, -3]]}, r"q1 = -3 \(via point 2\) is outside"),
])
def test_check_refuses_bad_parameters_before_anything_moves(params, message):
    """check() (and start) refuse a bad record with CommandError naming the problem; the robot is not commanded."""
    arm = ToyArm()
    with pytest.raises(CommandError, match=message):
        JointTrajectory.check(arm, params)
    done = []
    executor = MotionExecutor(arm, [MotionRecord("joint_trajectory", params)].pop, done.append)
    executor.poll(0)
    assert done[0].stop_reason.startswith("refused: joint_trajectory: ")
    assert arm.commands == []


def test_check_refuses_a_robot_without_joints():
    """A robot that does not implement JointRobot is refused by name."""
    with pytest.raises(CommandError, match="dict is not a robot with joints"):
        JointTrajectory.check({}, {"q": [1]})


# -- the motion type on a toy robot -------------------------------------------------------------


class ToyArm:
    """Two joints following the setpoint exactly; records every command."""

    joint_count = 2

    def __init__(self, q=(0.0, 0.0)):
        self.q = list(q)
        self.commands: list[tuple[np.ndarray, np.ndarray]] = []

    def joint_positions(self):
        return list(self.q)

    def joint_limits(self):
        return [1.0, 2.0], [4.0, 8.0]

    def joint_range(self):
        return [-2.0, -2.0], [2.0, 2.0]

    def command_joints(self, q, qd):
        self.q = q.tolist()
        self.commands.append((q.copy(), qd.copy()))


DT_NS = 1_000_000  # 1 kHz


def _run(motion: JointTrajectory, t_ns: int, until_ns: int, dt_ns: int = DT_NS) -> int:
    while not motion.done and t_ns <= until_ns:
        motion.step(t_ns)
        t_ns += dt_ns
    return t_ns


def _max_velocity_step(commands) -> np.ndarray:
    qd = np.array([c[1] for c in commands])
    return np.abs(np.diff(qd, axis=0)).max(axis=0)


def test_toy_arm_satisfies_the_protocols():
    """The in-test arm is a JointRobot and a RangedJointRobot."""
    assert isinstance(ToyArm(), JointRobot) and isinstance(ToyArm(), RangedJointRobot)


def test_motion_runs_to_the_target_and_ends_at_rest():
    """Stepped at 1 kHz on a fake clock, the arm reaches the target at rest and the motion ends at 'endpoint'."""
    arm = ToyArm((0.5, -0.5))
    motion = JointTrajectory()
    motion.start(arm, joint_trajectory_record([1.0, 1.0]), 7_000)
    assert motion.trajectory is not None
    assert motion.trajectory.start.tolist() == [0.5, -0.5]
    _run(motion, 7_000, 7_000 + 10 * 10**9)
    assert motion.done and motion.stop_reason == "endpoint"
    assert arm.q == [1.0, 1.0]
    assert not arm.commands[-1][1].any()
    assert motion.setpoint is not None and not motion.setpoint[2].any()
    assert np.all(_max_velocity_step(arm.commands) <= np.array([4.0, 8.0]) * 1e-3 * (1 + 1e-9))
    assert motion.remaining == 0.0


def test_a_queued_second_target_blends_without_a_velocity_jump():
    """A target appended while the first segment runs joins by Paul's transition: no velocity step beyond amax*dt, no stop at the first target."""
    arm = ToyArm()
    motion = JointTrajectory()
    motion.start(arm, joint_trajectory_record([1.5, 0.0]), 0)
    t = _run(motion, 0, 400 * DT_NS)
    first = motion.trajectory
    assert first is not None
    assert motion.append({"q0": -1.0, "q1": 1.0}) is True
    second = motion.trajectory
    assert second is not None and second.duration > first.duration
    _run(motion, t, 20 * 10**9)
    assert motion.stop_reason == "endpoint" and arm.q == [-1.0, 1.0]
    qd = np.array([c[1] for c in arm.commands])
    assert np.all(_max_velocity_step(arm.commands) <= np.array([4.0, 8.0]) * 1e-3 * (1 + 1e-9))
    # the speed never drops to zero in the middle: it turned the corner without stopping
    middle = np.linalg.norm(qd[200:-200], axis=1)
    assert middle.min() > 0.1
    # the commanded path equals the single plan through both points
    whole = plan([0.0, 0.0], [[1.5, 0.0], [-1.0, 1.0]], [1.0, 2.0], [4.0, 8.0])
    assert second.duration == whole.duration
    for k in range(0, len(arm.commands), 97):
        np.testing.assert_array_equal(arm.commands[k][0], whole.sample(k * DT_NS * 1e-9)[0])


def test_an_append_after_the_final_deceleration_began_rests_then_goes_on():
    """Appended during the final transition, the move comes to rest at the first target and then continues, still without a jump."""
    arm = ToyArm()
    motion = JointTrajectory()
    motion.start(arm, joint_trajectory_record([1.0, 0.0]), 0)
    first = motion.trajectory
    assert first is not None
    late = int((first.duration - first.taus[-1] / 2) * 1e9)
    t = _run(motion, 0, late)
    assert motion.append({"q": [0.0, 1.0], "speed": 0.5}) is False
    _run(motion, t, 20 * 10**9)
    assert motion.stop_reason == "endpoint" and arm.q == [0.0, 1.0]
    q = np.array([c[0] for c in arm.commands])
    qd = np.array([c[1] for c in arm.commands])
    assert np.all(_max_velocity_step(arm.commands) <= np.array([4.0, 8.0]) * 1e-3 * (1 + 1e-9))
    rest = round(first.duration * 1e3)
    np.testing.assert_allclose(q[rest], [1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(qd[rest], [0.0, 0.0], atol=1e-12)
    assert np.abs(qd[:, 1]).max() <= 0.5 * 2.0 + 1e-12  # speed=0.5 of joint 1's 2.0


def test_append_refuses_bad_params_and_a_finished_motion():
    """append() checks like check(), changes nothing when it refuses, and refuses once the motion has ended."""
    arm = ToyArm()
    motion = JointTrajectory()
    motion.start(arm, joint_trajectory_record([1.0, 0.0]), 0)
    before = motion.trajectory
    with pytest.raises(CommandError, match="outside the joint's range"):
        motion.append({"q": [3.0, 0.0]})
    assert motion.trajectory is before
    motion.stop("stop")
    with pytest.raises(CommandError, match="not running"):
        motion.append({"q": [0.0, 0.0]})


def test_stop_ends_the_motion_through_the_executor():
    """Under the executor, abort() (a stop or a reflex) ends the move at once; no command is written after it."""
    arm = ToyArm()
    records = [joint_trajectory_record([1.0, 1.0], [0.0, 0.0])]
    finished = []
    executor = MotionExecutor(arm, lambda: records.pop() if records else None, finished.append)
    t = 0
    for _ in range(300):
        executor.poll(t)
        t += DT_NS
    assert executor.busy and len(arm.commands) == 300
    moving = arm.commands[-1][1]
    assert np.linalg.norm(moving) > 0.1
    executor.abort("stop command")
    executor.poll(t)
    assert not executor.busy and len(arm.commands) == 300
    assert finished[0].stop_reason == "stop command" and finished[0].done


def test_start_refuses_a_robot_with_bad_limits():
    """A robot whose limits are not positive is refused at start, before any command."""

    class Broken(ToyArm):
        def joint_limits(self):
            return [1.0, 0.0], [4.0, 8.0]

    arm = Broken()
    with pytest.raises(CommandError, match="the robot's velocity and acceleration limits"):
        JointTrajectory().start(arm, joint_trajectory_record([0.5, 0.5]), 0)
    assert arm.commands == []


target = st.lists(st.floats(-2.0, 2.0), min_size=2, max_size=2)


@settings(max_examples=40, deadline=None)
@given(st.lists(target, min_size=1, max_size=3), st.lists(target, min_size=1, max_size=2),
       st.floats(0.0, 1.2), st.one_of(st.none(), st.floats(0.2, 1.0)))
def test_appending_at_any_time_keeps_the_executed_path_and_its_continuity(first, more, when, speed):
    """Whenever a target is appended, every setpoint written is a sample of the final trajectory, and no step jumps more than the limits allow."""
    arm = ToyArm()
    motion = JointTrajectory()
    motion.start(arm, joint_trajectory_record(*first), 0)
    planned = motion.trajectory
    assert planned is not None
    dt = 4 * DT_NS  # 250 Hz keeps the example quick; the bounds scale with dt
    t = _run(motion, 0, int(when * planned.duration * 1e9), dt)
    if motion.done:
        return
    params = {"q": more} if speed is None else {"q": more, "speed": speed}
    blended = motion.append(params)
    t = _run(motion, t, 60 * 10**9, dt)
    final = motion.trajectory
    assert final is not None and motion.stop_reason == "endpoint"
    assert arm.q == [float(x) for x in more[-1]]
    if blended:  # one plan through every point, as if given at once
        assert final.duration == plan([0.0, 0.0], first + more, [1.0, 2.0], [4.0, 8.0],
                                      durations=None,
                                      speeds=[None] * len(first) + [speed] * len(more)).duration
    else:  # a rest at the last first target
        assert len(final.points) == len(first) + len(more) + 2
    for k, (q, qd) in enumerate(arm.commands):
        want = final.sample(k * dt * 1e-9)
        np.testing.assert_array_equal(q, want[0])
        np.testing.assert_array_equal(qd, want[1])
    assert np.all(_max_velocity_step(arm.commands) <= np.array([4.0, 8.0]) * dt * 1e-9 * (1 + 1e-9))
    q = np.array([c[0] for c in arm.commands])
    assert np.all(np.abs(np.diff(q, axis=0)) <= np.array([1.0, 2.0]) * dt * 1e-9 * (1 + 1e-9))
    assert np.all(q >= -2.0) and np.all(q <= 2.0)
