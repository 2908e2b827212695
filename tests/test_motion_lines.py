"""Straight lines of the tool (Paul's drive transform) on the PUMA and a 7-joint arm,
planned and evaluated tick by tick: on the line, at the target, within the limits."""

from __future__ import annotations

import math

import numpy as np
import pytest
from _motion_rig import (
    ARM7,
    ARM7_HOME,
    ARM7_LIMITS,
    PUMA,
    PUMA_HOME,
    PUMA_LIMITS,
    angle,
    dist_to_segment,
    equation,
    make,
    run,
    tool_pose,
)
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from pyrt.kinematics import rotation
from pyrt.motion import MotionFault, MotionSpec, RecordError, Termination

#: The largest deviation from the line seen by these tests (m), for the record.
SEEN = {"line": 0.0}

ARMS = {"puma": (PUMA, PUMA_HOME, PUMA_LIMITS), "arm7": (ARM7, ARM7_HOME, ARM7_LIMITS)}


def _target(chain, q0, dp, axis, ang):
    a = tool_pose(chain, q0)
    b = a.copy()
    b[:3, 3] += dp
    ax = np.asarray(axis, dtype=float)
    b[:3, :3] = rotation(ax / np.linalg.norm(ax), ang) @ b[:3, :3]
    return a, b


lines = st.tuples(
    st.lists(st.floats(-0.25, 0.25), min_size=7, max_size=7),
    st.lists(st.floats(-0.12, 0.12), min_size=3, max_size=3),
    st.lists(st.floats(-1, 1), min_size=3, max_size=3).filter(lambda v: np.linalg.norm(v) > 0.2),
    st.floats(-0.4, 0.4),
    st.sampled_from([1.0, 0.5]),
)


def _check_line(name, case):
    chain, home, limits = ARMS[name]
    dq, dp, axis, ang, speed = case
    q0 = home + np.array(dq[: chain.n])
    assume(chain.limit_violation(q0) is None)
    assume(np.linalg.svd(chain.jacobian(q0), compute_uv=False)[-1] > 0.05)
    a, b = _target(chain, q0, dp, axis, ang)
    ev = make(chain, limits, q0)
    try:
        move = ev.queue(MotionSpec(mode="cart", equation=equation(b), speed=speed))
    except RecordError as exc:
        # a line out of reach or through a singularity is refused, naming where
        assert "% of the segment" in str(exc) and ("reach" in str(exc) or "singular" in str(exc)
                                                  or "limit" in str(exc))
        assume(False)
    knots = run(ev)
    assert move.code == Termination.REACHED
    worst = 0.0
    for k in knots:
        p = tool_pose(chain, k.q)[:3, 3]
        worst = max(worst, dist_to_segment(p, a[:3, 3], b[:3, 3]))
    SEEN["line"] = max(SEEN["line"], worst)
    assert worst <= 1e-3
    end = tool_pose(chain, knots[-1].q)
    assert np.linalg.norm(end[:3, 3] - b[:3, 3]) <= 0.5e-3
    assert math.degrees(angle(end, b)) <= 0.1
    qd = np.array([k.qd for k in knots])
    qdd = np.array([k.qdd for k in knots])
    assert (np.abs(qd) <= np.array(limits.vmax) * (1 + 1e-6)).all()
    assert (np.abs(qdd) <= np.array(limits.amax) * (1 + 1e-6)).all()
    # the tool's speed along the line within the Cartesian limit
    p = np.array([tool_pose(chain, k.q)[:3, 3] for k in knots])
    v = np.linalg.norm(np.diff(p, axis=0), axis=1) / ev.period
    assert v.max() <= limits.v_cart * speed * 1.01


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.filter_too_much])
@given(lines)
def test_puma_line_stays_within_1mm_and_ends_on_target(case):
    """PUMA: a Cartesian segment keeps the planned tool within 1 mm of the line at every tick, ends within 0.5 mm and 0.1 deg, within every limit."""
    _check_line("puma", case)


@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.filter_too_much])
@given(lines)
def test_arm7_line_stays_within_1mm_and_ends_on_target(case):
    """A 7-joint arm (DH, numerical inverse): the same line properties as the PUMA."""
    _check_line("arm7", case)


def test_puma_line_uses_the_closed_form_with_its_configuration_held():
    """The PUMA's line is solved by Paul's closed form in the start's configuration at every tick."""
    ev = make()
    _a, b = _target(PUMA, PUMA_HOME, [0.1, 0.05, -0.05], [0, 0, 1], 0.3)
    cfg = PUMA.closed_form.config_of(PUMA_HOME)
    ev.queue(MotionSpec(mode="cart", equation=equation(b)))
    knots = run(ev)
    assert {PUMA.closed_form.config_of(k.q) for k in knots} == {cfg}


def test_a_line_through_the_wrist_singularity_is_refused_naming_where():
    """A line whose wrist passes q5 = 0 is refused before it starts, naming the singularity and where."""
    q0 = np.array([0.1, 0.8, -3.0, 0.0, 0.3, 0.0])
    ev = make(q0=q0)
    a = tool_pose(PUMA, q0)
    # the pose of the wrist flipped through zero
    b = tool_pose(PUMA, np.array([0.1, 0.8, -3.0, 0.0, -0.3, 0.0]))
    with pytest.raises(RecordError) as err:
        ev.queue(MotionSpec(mode="cart", equation=equation(b)))
    text = str(err.value)
    assert "singular" in text and "% of the segment" in text
    assert ev.idle
    del a


def test_a_line_out_of_reach_is_refused_naming_where_and_nothing_moves():
    """A line that runs out to the arm's full stretch is refused (the edge of the reach is the elbow's singularity) naming the fraction and the tool position; the arm stays put."""
    ev = make()
    _a, b = _target(PUMA, PUMA_HOME, [0.6, 0.0, 0.4], [0, 0, 1], 0.0)
    with pytest.raises(RecordError) as err:
        ev.queue(MotionSpec(mode="cart", equation=equation(b)))
    text = str(err.value)
    assert ("reach" in text or "singularity" in text) and "% of the segment" in text and "mm" in text
    knots = run(ev, limit=10)
    assert all(np.allclose(k.q, PUMA_HOME) for k in knots)


def test_a_joint_target_beyond_a_limit_is_refused_naming_the_joint():
    """A joint target outside the limits is refused naming the joint."""
    ev = make()
    q = PUMA_HOME.copy()
    q[1] = math.radians(230)
    with pytest.raises(RecordError, match="joint2"):
        ev.queue(MotionSpec(mode="joint", target=q))


def test_a_line_that_crosses_a_joint_limit_is_refused_naming_the_joint():
    """A Cartesian line whose joints would cross a limit is refused, naming the joint and where."""
    q0 = np.array([2.6, 0.8, -3.0, 0.2, 0.8, 0.1])  # joint 1 near its 160 deg limit
    ev = make(q0=q0)
    a = tool_pose(PUMA, q0)
    b = a.copy()
    r = rotation([0, 0, 1], 0.35)
    b[:3, 3] = r @ a[:3, 3]
    b[:3, :3] = r @ a[:3, :3]
    with pytest.raises(RecordError) as err:
        ev.queue(MotionSpec(mode="cart", equation=equation(b)))
    assert "joint1" in str(err.value) or "reach" in str(err.value)


@pytest.mark.parametrize("name", ["puma", "arm7"])
@pytest.mark.parametrize("at", [0.15, 0.5, 0.85])
def test_stop_during_a_line_brakes_on_the_line_within_the_limits(name, at):
    """stop during a Cartesian segment decelerates along the path: the tool stays on its line, the joints within their acceleration limits, and it ends at rest with code stopped."""
    chain, home, limits = ARMS[name]
    dp = [0.1, -0.08, 0.06] if name == "puma" else [-0.1, -0.08, 0.06]
    a, b = _target(chain, home, dp, [0, 1, 0], 0.3)
    ev = make(chain, limits, home)
    move = ev.queue(MotionSpec(mode="cart", equation=equation(b)))
    knots = run(ev, until=lambda k: k.progress >= at)
    ev.stop()
    knots += run(ev)
    assert move.code == Termination.STOPPED
    for k in knots:
        p = tool_pose(chain, k.q)[:3, 3]
        assert dist_to_segment(p, a[:3, 3], b[:3, 3]) <= 1e-3
    assert np.abs(knots[-1].qd).max() < 1e-9
    qdd = np.array([k.qdd for k in knots])
    assert (np.abs(qdd) <= np.array(limits.amax) * (1 + 1e-6)).all()
    # it did stop short of the target
    assert np.linalg.norm(tool_pose(chain, knots[-1].q)[:3, 3] - b[:3, 3]) > 1e-5


def test_a_motion_that_ends_moving_is_brought_to_rest_within_the_limits():
    """A plug-in joint motion that ends at 20 deg/s is braked to rest within the acceleration limits, never extrapolated."""
    ev = make()
    w = math.radians(20)
    ramp = 0.2  # it speeds up gently from rest (within the limits), then ends at full speed

    def fn(t):
        x = w * t * t / (2 * ramp) if t < ramp else w * (t - ramp / 2)
        return PUMA_HOME + np.array([x, 0, 0, 0, 0, 0])

    move = ev.queue_function(fn, 1.0)
    knots = run(ev)
    assert move.code == Termination.REACHED
    assert np.abs(knots[-1].qd).max() < 1e-9
    qdd = np.array([k.qdd for k in knots])
    assert (np.abs(qdd) <= np.array(PUMA_LIMITS.amax) * (1 + 1e-6)).all()
    # it rests a braking distance past the last sample, not 20 deg/s further on
    final = knots[-1].q[0] - PUMA_HOME[0]
    last = w * (1.0 - ramp / 2)
    brake = w * 0.75 * w / PUMA_LIMITS.amax[0] + w * ev.period
    assert last <= final <= last + brake + 1e-9
    for _ in range(50):
        ev.tick()
    assert ev.tick().q[0] == pytest.approx(knots[-1].q[0], abs=1e-12)


def test_a_motion_that_ends_moving_towards_a_limit_faults():
    """A plug-in motion that ends moving with no room to brake before a joint limit raises MotionFault (the documented rule)."""
    q0 = PUMA_HOME.copy()
    q0[0] = math.radians(159.0)
    ev = make(q0=q0)
    w = math.radians(40)
    upper = math.radians(160.0)
    # it runs at 40 deg/s right up to 1e-3 rad short of the limit, and ends there
    t_end = (upper - 1e-3 - q0[0]) / w
    fn = lambda t: q0 + np.array([w * t, 0, 0, 0, 0, 0])  # noqa: E731
    ev.queue_function(fn, t_end)
    with pytest.raises(MotionFault, match="joint1"):
        run(ev)


@settings(max_examples=30, deadline=None)
@given(st.sampled_from(["puma", "arm7"]),
       st.lists(st.floats(-1.5, 1.5), min_size=7, max_size=7),
       st.integers(3, 120), st.floats(0.005, 0.4))
def test_the_singularity_check_decides_each_sample_as_the_decomposition_does(arm, step, m, limit):
    """The planner's smallest singular values (one decomposition in a few, Weyl's bound between them) put each sample of a joint path under or over the limit exactly as a decomposition of every Jacobian does, and never above the true value."""
    from pyrt.motion._checks import smallest_singular

    chain, home, _ = ARMS[arm]
    d = np.array(step[:chain.n])
    # a path through the PUMA's wrist singularity (q5 = 0) half the time
    q0 = home.copy()
    if arm == "puma" and step[6] > 0:
        q0[4], d[4] = -0.6, 1.2
    jacs = np.array([chain.jacobian(q0 + d * (i / m)) for i in range(m)])
    exact = np.linalg.svd(jacs, compute_uv=False)[:, -1]
    got = smallest_singular(jacs, limit)
    assert ((got < limit) == (exact < limit)).all()
    assert (got <= exact + 1e-12).all()
    under = got < limit
    assert np.allclose(got[under], exact[under], rtol=0, atol=1e-12)


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(-2.0, 2.0), min_size=24, max_size=24), st.floats(0.01, 0.5),
       st.booleans())
def test_a_drive_piece_s_poses_at_once_are_its_poses_one_by_one(vals, tau, linear):
    """The planner's checks take a Cartesian piece's poses, and T6 through an equation's frames, all at once: the same as the trajectory tick's one at a time (to rounding), the tiny rotations included."""
    from pyrt.motion._pieces import Frames, FrameTracker, Piece, line_coeffs, transition_coeffs

    v = np.array(vals)
    v[12:15] *= 1e-14 if vals[0] > 1.0 else 1.0  # a start with (almost) no rotation
    c = line_coeffs(v[12:18], v[18:]) if linear else transition_coeffs(
        v[:6], v[6:12], v[12:18], v[18:], tau)
    r_c = rotation(v[:3], 0.4 + abs(v[3]))
    piece = Piece("cart", 0.0, 2 * tau, 0.05, c, None, r_c=r_c, p_c=v[3:6])
    ts = list(np.linspace(0.0, 2 * tau, 17))
    frames = Frames(equation(np.eye(4)), FrameTracker(0.01))
    many = frames.t6_many(piece.poses(ts), [0.0] * len(ts))
    for t, t6 in zip(ts, many, strict=True):
        assert np.allclose(t6, frames.t6(piece.pose(t), 0.0), rtol=0, atol=1e-12)


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(-2.0, 2.0), min_size=24, max_size=24), st.floats(0.01, 0.5),
       st.booleans())
def test_a_joint_piece_s_values_at_once_are_exactly_the_tick_s(vals, tau, linear):
    """The planner's checks take a joint piece's values at all its sample times at once: bit for bit the trajectory tick's, one at a time."""
    from pyrt.motion._pieces import Piece, line_coeffs, transition_coeffs

    v = np.array(vals)
    c = line_coeffs(v[:6], v[6:12]) if linear else transition_coeffs(
        v[:6], v[6:12], v[12:18], v[18:], tau)
    piece = Piece("joint", 0.0, 2 * tau, 0.03, c, None)
    ts = list(np.linspace(0.0, 2 * tau, 23) + 0.001)
    for t, q in zip(ts, piece.values(ts), strict=True):
        assert (q == piece.x(t)).all()
