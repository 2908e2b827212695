"""Sequences of joint and Cartesian segments joined by Paul's transitions (001's
four), PLCopen's buffer modes, and moving frames: continuity at every join,
accelerations within the limits, blends within their stated tolerance."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from _motion_rig import (
    PUMA,
    PUMA_HOME,
    PUMA_LIMITS,
    conveyor,
    dist_to_segment,
    equation,
    make,
    run,
    tool_pose,
)
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pyrt.kinematics import rotation
from pyrt.motion import MotionSpec, RecordError, Termination

#: The largest blend error (m) seen by these tests, for the record.
SEEN = {"blend": 0.0, "blend_tol": 0.0}

AMAX = np.array(PUMA_LIMITS.amax)
VMAX = np.array(PUMA_LIMITS.vmax)


def _unblended(kind, start_q, end_q, start_pose, end_pose, k=80):
    """Tool points of a segment as planned without blends: a line, or the
    tool's path along the joint line."""
    if kind == "cart":
        return [(start_pose[:3, 3], end_pose[:3, 3])]
    pts = [tool_pose(PUMA, start_q + (end_q - start_q) * i / k)[:3, 3] for i in range(k + 1)]
    return list(itertools.pairwise(pts))


def _check_continuity(knots, *, cart_only=False):
    """Joint position, velocity continuous (accelerations within the limits),
    the tool's position and velocity continuous."""
    q = np.array([k.q for k in knots])
    qd = np.array([k.qd for k in knots])
    qdd = np.array([k.qdd for k in knots])
    dt = knots[0].period
    assert (np.abs(qdd) <= AMAX * (1 + 1e-6)).all(), np.abs(qdd).max(axis=0)
    assert (np.abs(qd) <= VMAX * (1 + 1e-6)).all()
    assert (np.abs(np.diff(q, axis=0)) <= VMAX * dt * (1 + 1e-6)).all()
    assert (np.abs(np.diff(qd, axis=0)) <= AMAX * dt * (1 + 1e-6)).all()
    p = np.array([tool_pose(PUMA, x)[:3, 3] for x in q])
    v = np.diff(p, axis=0) / dt
    assert np.linalg.norm(np.diff(v, axis=0), axis=1).max() <= 0.1  # no jump of the tool's velocity
    if cart_only:
        a = np.linalg.norm(np.diff(v, axis=0), axis=1) / dt
        assert a.max() <= 1.05 * PUMA_LIMITS.a_cart + 0.5  # translation within the Cartesian limit


segments = st.lists(
    st.one_of(
        st.tuples(st.just("joint"), st.lists(st.floats(-0.25, 0.25), min_size=6, max_size=6)),
        st.tuples(st.just("cart"), st.lists(st.floats(-0.08, 0.08), min_size=4, max_size=4)),
    ),
    min_size=2, max_size=5,
)


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(segments, st.sampled_from([None, 0.002, 0.01, 0.03]), st.sampled_from([1.0, 0.6]))
def test_random_sequences_are_continuous_within_limits_and_tolerance(seq, tol, speed):
    """A random sequence of joint and Cartesian segments, blended: joint and tool position and velocity continuous at every join, joint accelerations within the limits, every knot within the stated tolerance of the unblended path."""
    ev = make()
    q_end = PUMA_HOME.copy()
    path = []
    moves = []
    # the first record names the equation (the tool) every later joint record moves
    seq = [("cart", [0.01, 0.0, 0.0, 0.0]), *seq]
    for kind, vals in seq:
        start_q, start_pose = q_end.copy(), tool_pose(PUMA, q_end)
        if kind == "joint":
            spec = MotionSpec(mode="joint", target=q_end + np.array(vals), tolerance=tol,
                              speed=speed)
        else:
            pose = start_pose.copy()
            pose[:3, 3] += vals[:3]
            pose[:3, :3] = rotation([0, 0, 1], vals[3] * 3) @ pose[:3, :3]
            spec = MotionSpec(mode="cart", equation=equation(pose), tolerance=tol, speed=speed)
        try:
            move = ev.queue(spec)
        except RecordError as exc:
            assert "refused" in str(exc) or "outside" in str(exc)
            continue
        moves.append(move)
        # where it ends, as planned
        seg = ev._segs[-1]
        q_end = seg.q_end.copy()
        path += _unblended(kind, start_q, q_end, start_pose, tool_pose(PUMA, q_end))
    knots = run(ev, limit=20000)
    assert all(m.code == Termination.REACHED for m in moves)
    _check_continuity(knots)
    if tol is not None and path:
        worst = 0.0
        for k in knots:
            p = tool_pose(PUMA, k.q)[:3, 3]
            worst = max(worst, min(dist_to_segment(p, a, b) for a, b in path))
        SEEN["blend"] = max(SEEN["blend"], worst)
        SEEN["blend_tol"] = max(SEEN["blend_tol"], worst / tol)
        assert worst <= tol
    for m in moves:
        if tol is not None:
            assert m.blend_error <= tol
    assert np.abs(knots[-1].qd).max() < 1e-9


@pytest.mark.parametrize("step", [0.002, 0.005, 0.01])
def test_short_cartesian_segments_keep_every_acceleration_within_the_limits(step):
    """Many short Cartesian segments (2 to 10 mm) at full speed, blended: joint accelerations and the tool's stay within the limits (the anchors' complaint)."""
    ev = make()
    pose = tool_pose(PUMA, PUMA_HOME)
    for i in range(12):
        pose = pose.copy()
        pose[:3, 3] += step * np.array([1.0, (-1) ** i, 0.3])
        ev.queue(MotionSpec(mode="cart", equation=equation(pose), tolerance=0.001))
    knots = run(ev)
    _check_continuity(knots, cart_only=True)


@pytest.mark.parametrize("step", [0.005, 0.02])
def test_short_joint_segments_keep_every_acceleration_within_the_limits(step):
    """Many short joint segments at full speed, blended: accelerations within the limits."""
    ev = make()
    q = PUMA_HOME.copy()
    for i in range(12):
        q = q + step * np.array([1.0, (-1) ** i, 0.5, -1.0, 1.0, (-1) ** (i // 2)])
        ev.queue(MotionSpec(mode="joint", target=q))
    knots = run(ev)
    _check_continuity(knots)


@settings(max_examples=15, deadline=None)
@given(st.lists(st.floats(-0.8, 0.8), min_size=6, max_size=6).filter(
    lambda d: max(abs(x) for x in d) >= 0.5))
def test_a_joint_move_from_rest_accelerates_at_its_limit_not_below(delta):
    """A joint move from rest is planned at its limits the first time: the leading joint's sampled acceleration peaks within 3 % under its limit (not slowed a tenth below it), and no knot is over a limit."""
    ev = make()
    target = PUMA_HOME + np.array(delta)
    ev.queue(MotionSpec(mode="joint", target=target))
    knots = run(ev)
    _check_continuity(knots)
    lead = int(np.argmax(np.abs(delta) / VMAX))
    peak = max(abs(float(k.qdd[lead])) for k in knots)
    assert 0.97 * AMAX[lead] <= peak <= AMAX[lead]
    assert np.allclose(knots[-1].q, target, atol=1e-9)


def test_a_sharp_corner_with_a_small_tolerance_is_never_cut_more():
    """A 90 degree corner at full speed with 1 mm tolerance: the blend is made within it (slower) or the arm stops exactly at the corner; the path never leaves the tolerance (the anchors' complaint)."""
    ev = make()
    a = tool_pose(PUMA, PUMA_HOME)
    b = a.copy()
    b[:3, 3] += [0.12, 0.0, 0.0]
    c = b.copy()
    c[:3, 3] += [0.0, 0.12, 0.0]
    ev.queue(MotionSpec(mode="cart", equation=equation(b), tolerance=0.001))
    m2 = ev.queue(MotionSpec(mode="cart", equation=equation(c), tolerance=0.001))
    assert m2.buffer in ("blending", "buffered")
    if m2.buffer == "buffered":
        assert "tolerance" in m2.note or "room" in m2.note
    knots = run(ev)
    worst = max(min(dist_to_segment(tool_pose(PUMA, k.q)[:3, 3], a[:3, 3], b[:3, 3]),
                    dist_to_segment(tool_pose(PUMA, k.q)[:3, 3], b[:3, 3], c[:3, 3]))
                for k in knots)
    assert worst <= 0.001
    _check_continuity(knots)


def test_a_gentle_corner_is_blended_within_its_tolerance():
    """A 20 degree corner with 5 mm tolerance is blended (no stop) and cut by less than 5 mm."""
    ev = make()
    a = tool_pose(PUMA, PUMA_HOME)
    b = a.copy()
    b[:3, 3] += [0.12, 0.0, 0.0]
    c = b.copy()
    c[:3, 3] += 0.1 * np.array([math.cos(0.35), math.sin(0.35), 0.0])
    ev.queue(MotionSpec(mode="cart", equation=equation(b), tolerance=0.005))
    m2 = ev.queue(MotionSpec(mode="cart", equation=equation(c), tolerance=0.005))
    assert m2.buffer == "blending"
    knots = run(ev)
    speeds = [np.linalg.norm(tool_pose(PUMA, k2.q)[:3, 3] - tool_pose(PUMA, k1.q)[:3, 3])
              for k1, k2 in itertools.pairwise(knots[20:-20])]
    assert min(speeds) > 1e-4  # it never stops at the corner
    cut = min(np.linalg.norm(tool_pose(PUMA, k.q)[:3, 3] - b[:3, 3]) for k in knots)
    worst = max(min(dist_to_segment(tool_pose(PUMA, k.q)[:3, 3], a[:3, 3], b[:3, 3]),
                    dist_to_segment(tool_pose(PUMA, k.q)[:3, 3], b[:3, 3], c[:3, 3]))
                for k in knots)
    assert 0 < worst <= 0.005 and cut > 0
    SEEN["blend"] = max(SEEN["blend"], worst)


@pytest.mark.parametrize("first,second", [("joint", "joint"), ("cart", "cart"),
                                          ("cart", "joint"), ("joint", "cart")])
def test_each_of_the_four_transitions_is_continuous(first, second):
    """joint->joint, cart->cart, cart->joint, joint->cart (001): continuous joint and tool position and velocity, accelerations within the limits, both records reached at their targets."""
    ev = make()
    a = tool_pose(PUMA, PUMA_HOME)
    mid_q = PUMA_HOME + np.array([0.15, 0.1, -0.1, 0.2, 0.1, -0.2])
    b = tool_pose(PUMA, mid_q)
    if first == "joint":
        m1 = ev.queue(MotionSpec(mode="joint", target=mid_q))
    else:
        m1 = ev.queue(MotionSpec(mode="cart", equation=equation(b)))
    end_q = mid_q + np.array([0.1, -0.15, 0.1, -0.1, 0.2, 0.1])
    c = tool_pose(PUMA, end_q)
    if second == "joint":
        m2 = ev.queue(MotionSpec(mode="joint", target=end_q))
    else:
        m2 = ev.queue(MotionSpec(mode="cart", equation=equation(c)))
    assert m2.buffer == "blending"
    knots = run(ev)
    assert m1.code == m2.code == Termination.REACHED
    _check_continuity(knots)
    end = tool_pose(PUMA, knots[-1].q)
    assert np.linalg.norm(end[:3, 3] - c[:3, 3]) < 1e-6
    del a


def test_buffered_stops_at_the_corner_then_goes_on():
    """buffered: the arm comes to rest exactly at the first target before the second segment starts."""
    ev = make()
    a = tool_pose(PUMA, PUMA_HOME)
    b = a.copy()
    b[:3, 3] += [0.1, 0.0, 0.0]
    c = b.copy()
    c[:3, 3] += [0.0, 0.1, 0.0]
    ev.queue(MotionSpec(mode="cart", equation=equation(b)))
    m2 = ev.queue(MotionSpec(mode="cart", equation=equation(c), buffer="buffered"))
    assert m2.buffer == "buffered"
    knots = run(ev)
    d = [np.linalg.norm(tool_pose(PUMA, k.q)[:3, 3] - b[:3, 3]) for k in knots]
    assert min(d) < 1e-6  # it comes to rest at the corner itself
    _check_continuity(knots)


def test_aborting_replaces_the_running_segment_braking_into_the_new_one():
    """aborting: the running line is replaced at once; joints continuous and within their limits while braking into the new segment, which ends on its target; the old record's code is aborted."""
    ev = make()
    a = tool_pose(PUMA, PUMA_HOME)
    b = a.copy()
    b[:3, 3] += [0.12, 0.0, 0.0]
    c = a.copy()
    c[:3, 3] += [-0.05, 0.1, -0.05]
    m1 = ev.queue(MotionSpec(mode="cart", equation=equation(b)))
    knots = run(ev, until=lambda k: k.progress > 0.5)
    m2 = ev.queue(MotionSpec(mode="cart", equation=equation(c), buffer="aborting"))
    knots += run(ev)
    assert m1.code == Termination.ABORTED and m2.code == Termination.REACHED
    _check_continuity(knots)
    assert np.linalg.norm(tool_pose(PUMA, knots[-1].q)[:3, 3] - c[:3, 3]) < 1e-6
    # it turned away without stopping at the first target
    for k1, k2 in itertools.pairwise(knots):
        p1, p2 = tool_pose(PUMA, k1.q)[:3, 3], tool_pose(PUMA, k2.q)[:3, 3]
        if np.linalg.norm(p1 - b[:3, 3]) < 0.002:
            assert np.linalg.norm(p2 - p1) > 1e-4


def test_aborting_a_joint_segment_with_a_joint_segment():
    """aborting a joint move mid-way with a joint move back: continuous, within the limits."""
    ev = make()
    m1 = ev.queue(MotionSpec(mode="joint", target=PUMA_HOME + 0.4))
    knots = run(ev, until=lambda k: k.progress > 0.4)
    m2 = ev.queue(MotionSpec(mode="joint", target=PUMA_HOME - 0.1, buffer="aborting"))
    knots += run(ev)
    assert m1.code == Termination.ABORTED and m2.code == Termination.REACHED
    _check_continuity(knots)
    assert np.allclose(knots[-1].q, PUMA_HOME - 0.1, atol=1e-9)


# -- moving frames ----------------------------------------------------------------------------


def _conveyor_case(first):
    ev = make()
    a = tool_pose(PUMA, PUMA_HOME)
    conv = conveyor(speed=0.05, period=ev.period)
    pos = a.copy()
    pos[:3, 3] += [0.05, -0.1, -0.08]  # a point on the belt, in the belt's frame
    eqc = equation(pos, name="C", coord=conv)
    b = a.copy()
    b[:3, 3] += [-0.15, 0.05, 0.0]
    if first == "joint":
        m1 = ev.queue(MotionSpec(mode="joint", target=PUMA_HOME + np.array([0.1, 0.05, 0.05, 0, 0, 0])))
    else:
        m1 = ev.queue(MotionSpec(mode="cart", equation=equation(b)))
    m2 = ev.queue(MotionSpec(mode="cart", equation=eqc))
    return ev, conv, pos, m1, m2


@pytest.mark.parametrize("first", ["joint", "cart"])
def test_a_conveyor_at_50_mm_s_is_tracked_within_2_mm_after_the_transition(first):
    """A conveyor COORD translating at 50 mm/s (a functional transform): after the transition the commanded tool stays within 2 mm of the moving target point, for joint->cart and cart->cart; continuous and within the limits."""
    ev, conv, pos, _m1, m2 = _conveyor_case(first)
    assert m2.buffer == "blending"
    knots = run(ev, limit=400)
    reached = [k.t for k in knots if any(w == "reached" and m is m2 for w, m in k.events)]
    assert reached, "the conveyor record never reached its point"
    after = [k for k in knots if k.t >= reached[0]]
    assert len(after) > 100
    for k in after:
        belt = np.eye(4)
        belt[1, 3] = 0.05 * k.sample * ev.period
        target = (belt @ pos)[:3, 3]
        assert np.linalg.norm(tool_pose(PUMA, k.q)[:3, 3] - target) <= 0.002
    _check_continuity(knots)
    # the functional transform was evaluated once per sample, no more
    assert conv.evaluations <= knots[-1].sample + 3


@pytest.mark.parametrize("second", ["cart", "joint"])
def test_leaving_a_conveyor_is_continuous(second):
    """From following the conveyor to a static Cartesian line or a joint move (cart->cart and cart->joint with moving frames): continuous and within the limits."""
    ev, _conv, _pos, _m1, _m2 = _conveyor_case("cart")
    knots = run(ev, limit=250)
    a = tool_pose(PUMA, PUMA_HOME)
    if second == "cart":
        m3 = ev.queue(MotionSpec(mode="cart", equation=equation(a)))
    else:
        m3 = ev.queue(MotionSpec(mode="joint", target=PUMA_HOME))
    knots += run(ev)
    assert m3.code == Termination.REACHED
    _check_continuity(knots)
    assert np.linalg.norm(tool_pose(PUMA, knots[-1].q)[:3, 3] - a[:3, 3]) < 1e-6


def test_joint_to_joint_with_a_moving_frame_arrives_where_the_frame_will_be():
    """A joint-mode record to a point on the moving conveyor ends where that point is when the segment ends (001's estimate)."""
    ev = make()
    a = tool_pose(PUMA, PUMA_HOME)
    conv = conveyor(speed=0.05, period=ev.period)
    pos = a.copy()
    pos[:3, 3] += [0.05, -0.1, -0.08]
    m = ev.queue(MotionSpec(mode="joint", equation=equation(pos, name="C", coord=conv)))
    knots = run(ev)
    assert m.code == Termination.REACHED
    k = knots[-1]
    belt = np.eye(4)
    # the point on the belt at the time the record was reached
    t_r = next(kk for kk in knots if any(w == "reached" for w, _ in kk.events))
    belt[1, 3] = 0.05 * t_r.sample * ev.period
    assert np.linalg.norm(tool_pose(PUMA, k.q)[:3, 3] - (belt @ pos)[:3, 3]) < 0.002
    _check_continuity(knots)


@pytest.mark.parametrize("at", [0.2, 0.6, 0.95])
def test_stop_during_a_joint_segment_and_its_blend_brakes_within_the_limits(at):
    """stop during a joint segment or in the blend into a Cartesian one: the joints stay on the path (joint line, then the planned transition) and within their limits; every queued record ends stopped."""
    ev = make()
    q1 = PUMA_HOME + np.array([0.2, 0.1, -0.1, 0.2, 0.1, -0.2])
    m1 = ev.queue(MotionSpec(mode="joint", target=q1))
    a = tool_pose(PUMA, q1)
    b = a.copy()
    b[:3, 3] += [0.05, 0.05, 0.0]
    m2 = ev.queue(MotionSpec(mode="cart", equation=equation(b)))
    knots = run(ev, until=lambda k: k.move is m1 and k.progress >= at)
    ev.stop()
    knots += run(ev)
    assert m1.code == m2.code == Termination.STOPPED
    assert np.abs(knots[-1].qd).max() < 1e-9
    _check_continuity(knots)
    if at < 0.5:  # still on the joint line: every joint on the segment from start to q1
        for k in knots:
            s = (k.q - PUMA_HOME) / (q1 - PUMA_HOME)
            assert np.allclose(s, s[0], atol=1e-9)


def test_a_long_run_keeps_the_tick_bounded():
    """Forty records one after another: the evaluator keeps only the pieces and records still to come (the tick does not grow with the run), and the handles keep distinct numbers."""
    ev = make()
    moves = []
    for i in range(40):
        q = PUMA_HOME + 0.05 * np.array([(-1) ** i, 0.5, 0.0, 0.0, 0.0, 0.0])
        moves.append(ev.queue(MotionSpec(mode="joint", target=q, buffer="buffered")))
        run(ev)
        assert len(ev._pieces) <= 8 and len(ev._segs) <= 3
    assert all(m.code == Termination.REACHED for m in moves)
    assert len({m.index for m in moves}) == 40
