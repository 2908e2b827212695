"""001's motion record, field by field: each is checked, and honoured (a test of its
effect) or refused by name; the record's termination code, progress and reached event."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from _motion_rig import (
    PUMA,
    PUMA_HOME,
    PUMA_LIMITS,
    TOOL_OFFSET,
    dist_to_segment,
    equation,
    make,
    run,
    tool_pose,
)

from pyrt.frames import PositionEquation, Transform
from pyrt.kinematics import transform
from pyrt.motion import Comply, Limits, MotionSpec, RecordError, Termination


def _line(dp=(0.1, 0.0, -0.05)):
    a = tool_pose(PUMA, PUMA_HOME)
    b = a.copy()
    b[:3, 3] += dp
    return a, b


BAD = [
    ({"mode": "sideways"}, "mode"),
    ({"buffer": "later"}, "buffer"),
    ({"transition": -1.0}, "transition"),
    ({"transition": "soon"}, "transition"),
    ({"segment_time": 0.0}, "segment_time"),
    ({"segment_time": math.inf}, "segment_time"),
    ({"config": ""}, "config"),
    ({"update": 3}, "update"),
    ({"monitor": "watch"}, "monitor"),
    ({"sample_rate": 5.0}, "sample_rate"),
    ({"sample_rate": 5000.0}, "sample_rate"),
    ({"mass": -1.0}, "mass"),
    ({"mass": math.nan}, "mass"),
    ({"force_limits": (1, 2, 3)}, "force_limits"),
    ({"force_limits": (1, 2, 3, 4, 5, 0)}, "force_limits"),
    ({"comply": {"axis": "z", "force": 2.0}}, "comply"),
    ({"max_diff": (0.001,)}, "max_diff"),
    ({"max_diff": (0.001, -0.1)}, "max_diff"),
    ({"distance": (0, 0, 0.1)}, "distance"),
    ({"distance": (0, 0, math.nan, 0, 0, 0)}, "distance"),
    ({"speed": 0.0}, "speed"),
    ({"speed": 1.5}, "speed"),
    ({"tolerance": -0.001}, "tolerance"),
    ({"target": (1.0, math.nan)}, "target"),
    ({"equation": "P"}, "equation"),
    ({"mode": "cart", "target": (0.0,) * 6}, "target"),
    ({"mode": "cart", "config": "lefty-above-flip"}, "config"),
]


@pytest.mark.parametrize("fields,name", BAD)
def test_a_malformed_field_is_refused_by_name(fields, name):
    """A malformed or refused field raises RecordError naming the field."""
    with pytest.raises(RecordError, match=name):
        MotionSpec(**fields)


@pytest.mark.parametrize(("kw", "why"), [
    ({"axes": "w", "force": 2.0}, "axes"),
    ({"axes": "zz", "force": 2.0}, "axes"),
    ({"axes": "", "force": 2.0}, "axes"),
    ({"axes": "rx", "force": 2.0}, "torques are not offered"),
    ({"axes": "z", "force": math.nan}, "force"),
    ({"axes": "xz", "force": (1.0, 2.0, 3.0)}, "force"),
    ({"axes": "z", "force": 5000.0}, "force"),
    ({"axes": "z", "force": 2.0, "gain": 0.0}, "gain"),
    ({"axes": "z", "force": 2.0, "travel": 2.0}, "travel"),
    ({"axes": "z", "force": 2.0, "dwell": -1.0}, "dwell"),
])
def test_a_malformed_comply_specification_is_refused_by_name(kw, why):
    """A comply specification with unknown or repeated axes, a torque axis, a force that is not one finite value per axis within 1000 N, or a gain, travel or dwell out of range: RecordError naming comply and the part."""
    with pytest.raises(RecordError, match=why) as err:
        Comply(**kw)
    assert str(err.value).startswith("comply")


def test_comply_is_a_cartesian_record_s_and_needs_a_force_sensor():
    """comply on a joint-mode record is refused by name; a Cartesian record with comply is made (one force for every axis spread over them), and queued on an evaluator without a force sensor it is refused naming the sensor."""
    c = Comply("XY", 1.5)
    assert c.axes == "xy" and c.force == (1.5, 1.5) and c.index() == [0, 1]
    with pytest.raises(RecordError, match="joint-mode record cannot comply"):
        MotionSpec(mode="joint", target=(0.0,) * 6, comply=c)
    with pytest.raises(RecordError, match="comply: expected a Comply"):
        MotionSpec(mode="cart", comply=("z", 2.0))
    ev = make()
    eq = equation(tool_pose(PUMA, PUMA_HOME))
    with pytest.raises(RecordError, match="no force sensor"):
        ev.queue(MotionSpec(mode="cart", equation=eq, comply=Comply("z", 2.0)))
    assert ev.idle


def test_copy_checks_the_fields_again_and_refuses_unknown_ones():
    """copy() makes a whole checked copy; an unknown field is refused by name."""
    spec = MotionSpec(mode="joint", target=tuple(PUMA_HOME))
    assert spec.copy(speed=0.5).speed == 0.5
    with pytest.raises(RecordError, match="velocity"):
        spec.copy(velocity=2)
    with pytest.raises(RecordError, match="speed"):
        spec.copy(speed=2)


def test_the_record_is_copied_whole_when_queued():
    """The target is the equation's POS when the record is queued: a later change of POS does not move the running motion."""
    _a, b = _line()
    eq = equation(b)
    ev = make()
    ev.queue(MotionSpec(mode="cart", equation=eq))
    other = b.copy()
    other[:3, 3] += [0.0, 0.05, 0.0]
    eq.pos.set(other)
    knots = run(ev)
    assert np.linalg.norm(tool_pose(PUMA, knots[-1].q)[:3, 3] - b[:3, 3]) < 1e-6


def test_code_progress_and_reached_event():
    """A record's handle and its equation report progress 0 -> 1 (rising), then the code reached and the event set."""
    _a, b = _line()
    eq = equation(b)
    ev = make()
    move = ev.queue(MotionSpec(mode="cart", equation=eq))
    assert not move.reached.is_set() and eq.code is None
    progress = [k.progress for k in run(ev) if k.move is move]
    assert progress[0] < 0.05 and max(progress) < 1.0
    assert all(p2 >= p1 for p1, p2 in itertools.pairwise(progress))
    assert move.code == Termination.REACHED and move.progress == 1.0 and move.reached.is_set()
    assert eq.code == "reached" and eq.progress == 1.0 and eq.reached.is_set()


def test_transition_time_is_honoured_and_a_too_short_one_refused():
    """transition: a longer transition lowers the peak acceleration and lengthens the motion; one shorter than the limits need is refused naming both times."""
    _a, b = _line()
    ev = make()
    m1 = ev.queue(MotionSpec(mode="cart", equation=equation(b)))
    k1 = run(ev)
    ev = make()
    m2 = ev.queue(MotionSpec(mode="cart", equation=equation(b), transition=0.6))
    k2 = run(ev)
    assert m1.code == m2.code == Termination.REACHED
    peak1 = max(np.abs(k.qdd).max() for k in k1)
    peak2 = max(np.abs(k.qdd).max() for k in k2)
    assert peak2 < 0.6 * peak1
    assert len(k2) > len(k1)
    assert ev._segs[-1].tau_in == pytest.approx(0.6)
    with pytest.raises(RecordError, match=r"transition: 0\.001 s is shorter than"):
        make().queue(MotionSpec(mode="cart", equation=equation(b), transition=0.001))


def test_segment_time_is_honoured_and_a_too_short_one_refused():
    """segment_time: the line takes that time (the tool's speed mid-line is length / time); one shorter than the limits allow is refused."""
    a, b = _line()
    ev = make()
    ev.queue(MotionSpec(mode="cart", equation=equation(b), segment_time=2.0))
    knots = run(ev)
    length = float(np.linalg.norm(b[:3, 3] - a[:3, 3]))
    mid = knots[len(knots) // 2]
    nxt = knots[len(knots) // 2 + 1]
    speed = np.linalg.norm(tool_pose(PUMA, nxt.q)[:3, 3] - tool_pose(PUMA, mid.q)[:3, 3]) / 0.01
    assert speed == pytest.approx(length / 2.0, rel=1e-3)
    with pytest.raises(RecordError, match="segment_time"):
        make().queue(MotionSpec(mode="cart", equation=equation(b), segment_time=0.01))


def test_a_record_without_an_equation_moves_to_the_last_one():
    """equation None: the last equation queued is used, with its POS value now."""
    _a, b = _line()
    eq = equation(b)
    ev = make()
    ev.queue(MotionSpec(mode="cart", equation=eq))
    run(ev)
    c = b.copy()
    c[:3, 3] += [0.0, 0.05, 0.0]
    eq.pos.set(c)
    ev.queue(MotionSpec(mode="cart"))
    knots = run(ev)
    assert np.linalg.norm(tool_pose(PUMA, knots[-1].q)[:3, 3] - c[:3, 3]) < 1e-6
    with pytest.raises(RecordError, match="equation"):
        make().queue(MotionSpec(mode="cart"))


def test_mode_joint_moves_in_joints_and_mode_cart_on_a_line():
    """mode: the same equation reached by a joint-mode record leaves the line, by a Cartesian one stays on it."""
    a, b = _line((0.15, 0.1, -0.1))
    out = {}
    for mode in ("joint", "cart"):
        ev = make()
        ev.queue(MotionSpec(mode=mode, equation=equation(b)))
        knots = run(ev)
        out[mode] = max(dist_to_segment(tool_pose(PUMA, k.q)[:3, 3], a[:3, 3], b[:3, 3])
                        for k in knots)
        assert np.linalg.norm(tool_pose(PUMA, knots[-1].q)[:3, 3] - b[:3, 3]) < 1e-6
    assert out["cart"] < 1e-6 < 1e-3 < out["joint"]


def test_configuration_change_by_a_joint_record():
    """config: a joint-mode record to the same pose in another configuration ends in it, on the pose."""
    a = tool_pose(PUMA, PUMA_HOME)
    here = PUMA.closed_form.config_of(PUMA_HOME)
    reachable = PUMA.closed_form.solve_all(a @ np.linalg.inv(TOOL_OFFSET) @ TOOL_OFFSET
                                           @ np.linalg.inv(TOOL_OFFSET), PUMA_HOME)
    other = sorted(c for c in reachable if c != here)[0]
    ev = make()
    move = ev.queue(MotionSpec(mode="joint", equation=equation(a), config=other))
    knots = run(ev)
    assert move.code == Termination.REACHED
    assert PUMA.closed_form.config_of(knots[-1].q) == other
    assert np.linalg.norm(tool_pose(PUMA, knots[-1].q)[:3, 3] - a[:3, 3]) < 1e-6
    with pytest.raises(RecordError, match="config"):
        make().queue(MotionSpec(mode="joint", equation=equation(a), config="upside-down"))


def test_monitor_stops_the_motion_on_its_line_with_its_word():
    """monitor: called every tick; the word it returns stops the motion along its line and is the termination code."""
    a, b = _line()
    seen = []

    def watch(knot):
        seen.append(knot.progress)
        return "touch" if knot.progress > 0.5 else None

    ev = make()
    move = ev.queue(MotionSpec(mode="cart", equation=equation(b), monitor=watch))
    knots = run(ev)
    assert move.code == "touch"
    assert len(seen) > 10 and max(seen) < 0.7
    for k in knots:
        assert dist_to_segment(tool_pose(PUMA, k.q)[:3, 3], a[:3, 3], b[:3, 3]) < 1e-6
    assert np.abs(knots[-1].qd).max() < 1e-9


def test_update_term_remembers_where_a_stopped_motion_ended():
    """update: the named varb transform is solved for at the end of the segment, from the T6 reached (the equation then holds there)."""
    _a, b = _line()
    eq = equation(b)
    ev = make()
    move = ev.queue(MotionSpec(mode="cart", equation=eq, update="POS",
                               monitor=lambda k: "touch" if k.progress > 0.4 else None))
    run(ev)
    assert move.code == "touch"
    reached_tool = move.end_t6 @ TOOL_OFFSET
    np.testing.assert_allclose(eq.pos.value, reached_tool, atol=1e-9)
    assert np.linalg.norm(eq.pos.value[:3, 3] - b[:3, 3]) > 0.01
    with pytest.raises(RecordError, match="update"):
        make().queue(MotionSpec(mode="cart", equation=eq, update="TOOL"))  # const
    with pytest.raises(RecordError, match="update"):
        make().queue(MotionSpec(mode="cart", equation=eq, update="NOPE"))


def test_sample_rate_changes_the_trajectory_period():
    """sample_rate: the knots come at the record's rate from its first sample on."""
    _a, b = _line()
    ev = make()
    ev.queue(MotionSpec(mode="cart", equation=equation(b), sample_rate=50.0))
    knots = run(ev)
    assert knots[-1].period == pytest.approx(0.02)
    times = [k.t for k in knots[5:]]
    assert np.allclose(np.diff(times), 0.02)
    assert np.linalg.norm(tool_pose(PUMA, knots[-1].q)[:3, 3] - b[:3, 3]) < 1e-6


def test_mass_gives_the_joint_torques_that_hold_it_and_is_refused_over_the_payload():
    """mass: every knot carries the torques that hold the mass at the flange against gravity (the gradient of its potential energy); a mass over the payload is refused."""
    _a, b = _line()
    ev = make()
    ev.queue(MotionSpec(mode="cart", equation=equation(b), mass=2.0))
    knots = run(ev)
    k = knots[len(knots) // 2]
    assert k.mass == 2.0
    h = 1e-6
    grad = np.zeros(6)
    for j in range(6):
        dq = np.zeros(6)
        dq[j] = h
        grad[j] = 2.0 * 9.81 * (PUMA.fk(k.q + dq)[2, 3] - PUMA.fk(k.q - dq)[2, 3]) / (2 * h)
    np.testing.assert_allclose(k.payload_torque, grad, atol=1e-5)
    small = Limits(vmax=PUMA_LIMITS.vmax, amax=PUMA_LIMITS.amax, payload=2.5)
    ev = make(PUMA, small)
    with pytest.raises(RecordError, match="mass"):
        ev.queue(MotionSpec(mode="cart", equation=equation(b), mass=3.0))


def test_force_limits_make_a_guarded_move_or_are_refused_without_a_sensor():
    """force_limits: refused by name without a force sensor; with one, the move stops along its line with code force when the wrench exceeds a limit."""
    a, b = _line()
    limits = (math.inf, math.inf, 5.0, math.inf, math.inf, math.inf)
    with pytest.raises(RecordError, match="force_limits"):
        make().queue(MotionSpec(mode="cart", equation=equation(b), force_limits=limits))
    ev = make(force_sensor=True)
    move = ev.queue(MotionSpec(mode="cart", equation=equation(b), force_limits=limits))
    contact = a[2, 3] - 0.02  # a surface 20 mm below the start

    def wrench(knot):
        z = tool_pose(PUMA, knot.q)[2, 3]
        return (0.0, 0.0, max(0.0, (contact - z) * 2000.0), 0.0, 0.0, 0.0)

    knots = run(ev, wrench=wrench)
    assert move.code == Termination.FORCE
    stop_at = next(i for i, k in enumerate(knots) if wrench(k)[2] > 5.0)
    assert knots[stop_at + 1].progress < 1.0
    for k in knots:
        assert dist_to_segment(tool_pose(PUMA, k.q)[:3, 3], a[:3, 3], b[:3, 3]) < 1e-6


def test_the_wrench_is_wanted_while_a_force_record_is_queued_or_runs():
    """wants_wrench: False with no record or records without force limits or comply; True
    from the queueing of a guarded move until its pieces are over."""
    _a, b = _line()
    ev = make(force_sensor=True)
    assert not ev.wants_wrench
    ev.queue(MotionSpec(mode="cart", equation=equation(b)))
    assert not ev.wants_wrench
    run(ev)
    assert not ev.wants_wrench
    limits = (math.inf, math.inf, 5.0, math.inf, math.inf, math.inf)
    ev.queue(MotionSpec(mode="cart", equation=equation(_a), force_limits=limits))
    assert ev.wants_wrench
    seen = []
    while not ev.idle:
        ev.tick((0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
        seen.append(ev.wants_wrench)
    assert seen[0] and seen[-2]  # while the guarded move runs


def test_max_diff_bounds_the_tool_motion_per_tick():
    """max_diff: the tool moves at most that far (and turns at most that angle) in one trajectory tick."""
    _a, b = _line()
    ev = make()
    ev.queue(MotionSpec(mode="cart", equation=equation(b), max_diff=(0.0005, 0.01)))
    knots = run(ev)
    p = np.array([tool_pose(PUMA, k.q)[:3, 3] for k in knots])
    assert np.linalg.norm(np.diff(p, axis=0), axis=1).max() <= 0.0005 * 1.001
    assert np.linalg.norm(p[-1] - b[:3, 3]) < 1e-6


def test_distance_modifier_offsets_the_target_in_the_tool_frame():
    """distance: the record ends at the target moved by (dx dy dz rx ry rz) in the tool frame (an approach point)."""
    _a, b = _line()
    ev = make()
    d = (0.0, 0.0, -0.03, 0.0, 0.0, 0.2)
    ev.queue(MotionSpec(mode="cart", equation=equation(b), distance=d))
    knots = run(ev)
    want = b @ transform(d[:3], d[3:])
    got = tool_pose(PUMA, knots[-1].q)
    np.testing.assert_allclose(got, want, atol=1e-6)


def test_speed_scales_the_cartesian_velocity():
    """speed: the tool's speed on the line is at most that fraction of the Cartesian limit."""
    _a, b = _line()
    top = {}
    for speed in (1.0, 0.3):
        ev = make()
        ev.queue(MotionSpec(mode="cart", equation=equation(b), speed=speed))
        knots = run(ev)
        p = np.array([tool_pose(PUMA, k.q)[:3, 3] for k in knots])
        top[speed] = float((np.linalg.norm(np.diff(p, axis=0), axis=1) / 0.01).max())
        assert top[speed] <= speed * PUMA_LIMITS.v_cart * 1.001
    assert top[0.3] < 0.8 * top[1.0]


def test_hold_transform_keeps_its_value_until_the_end_of_the_segment():
    """A hold POS changed during the motion: the motion goes on to the value it started with; the equation takes the new value at the end of the segment."""
    _a, b = _line()
    t6 = Transform.varb("T6")
    tool = Transform.const("TOOL", TOOL_OFFSET)
    pos = Transform.hold("POS", b)
    eq = PositionEquation("H", [t6, tool], [pos])
    ev = make()
    ev.queue(MotionSpec(mode="cart", equation=eq))
    knots = [ev.tick() for _ in range(10)]
    c = b.copy()
    c[:3, 3] += [0.0, 0.04, 0.0]
    pos.set(c)
    assert np.allclose(eq.values(pos)[1], b)  # the equation still moves with the old value
    knots += run(ev)
    assert np.linalg.norm(tool_pose(PUMA, knots[-1].q)[:3, 3] - b[:3, 3]) < 1e-6
    assert np.allclose(eq.values(pos)[1], c)  # taken at the end of the segment
