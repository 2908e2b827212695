"""Motion records that name joint sets: the planner moves only the named sets'
joints and holds the others exactly; unknown sets and malformed records are
refused when queued, and nothing moves."""

from __future__ import annotations

import numpy as np
import pytest
from _motion_rig import PUMA, PUMA_HOME, equation, make, run, tool_pose
from hypothesis import given, settings
from hypothesis import strategies as st

from pyrt.kinematics import JointSets
from pyrt.motion import MotionSpec, RecordError

SETS = JointSets.split(PUMA, {"arm": [0, 1, 2], "wrist": [3, 4, 5]})


def test_a_wrist_record_leaves_the_arm_joints_exactly_still():
    """A record for `wrist` moves joints 4-6 to its target; joints 1-3 stay exactly at their values for the whole segment."""
    ev = make(sets=SETS)
    target = (0.9, -0.4, 1.2)
    move = ev.queue(MotionSpec(target=target, sets="wrist"))
    knots = run(ev)
    assert move.done and move.code == "reached"
    for k in knots:
        np.testing.assert_array_equal(k.q[:3], PUMA_HOME[:3])
        np.testing.assert_array_equal(k.qd[:3], 0.0)
    np.testing.assert_allclose(knots[-1].q[3:], target, rtol=0, atol=1e-12)
    # the wrist did move, and through intermediate values
    assert max(abs(k.q[4] - PUMA_HOME[4]) for k in knots) > 1.0
    assert len({round(float(k.q[3]), 6) for k in knots}) > 10


@settings(max_examples=15, deadline=None)
@given(st.lists(st.floats(0.1, 0.5), min_size=6, max_size=6),
       st.lists(st.sampled_from([-1.0, 1.0]), min_size=6, max_size=6), st.booleans())
def test_records_for_one_set_after_another_hold_the_other_set(sizes, signs, blend):
    """An arm record then a wrist record: the wrist held exactly during the arm's (blended: until the blend); the arm's joints held exactly where the arm record left them (buffered: the whole wrist segment; blended: once the blend is done); the end is both targets."""
    ev = make(sets=SETS)
    deltas = np.array(sizes) * np.array(signs)
    arm_t = tuple(PUMA_HOME[:3] + np.array(deltas[:3]))
    wrist_t = tuple(PUMA_HOME[3:] + np.array(deltas[3:]))
    first = ev.queue(MotionSpec(target=arm_t, sets=("arm",)))
    second = ev.queue(MotionSpec(target=wrist_t, sets=["wrist"],
                                 buffer="blending" if blend else "buffered"))
    knots = run(ev)
    during = [bool(np.array_equal(k.q[3:], PUMA_HOME[3:])) for k in knots if k.move is first]
    # buffered: the wrist holds for the whole arm segment; blended: until the blend begins
    assert during and all(during if not blend else during[:len(during) // 2])
    assert during == sorted(during, reverse=True)  # once the wrist moves, it moves on
    after = [k for k in knots if k.move is second]
    assert after
    held = knots[-1].q[:3]
    np.testing.assert_allclose(held, arm_t, rtol=0, atol=1e-12)
    still = [bool(np.array_equal(k.q[:3], held)) for k in after]
    if not blend:
        assert all(still)
    else:
        # the arm's joints come to rest in the blend, then hold to the end
        first_held = still.index(True)
        assert all(still[first_held:]) and first_held < len(after) // 2
    np.testing.assert_allclose(knots[-1].q, arm_t + wrist_t, rtol=0, atol=1e-12)


def test_a_record_without_sets_moves_every_joint_and_sets_covering_all_is_the_same():
    """sets defaults to all: a record without it, and one naming both sets, reach the same full target."""
    target = tuple(PUMA_HOME + 0.2)
    ends = []
    for spec in (MotionSpec(target=target), MotionSpec(target=target, sets=("wrist", "arm"))):
        ev = make(sets=SETS)
        ev.queue(spec)
        ends.append(run(ev)[-1].q)
    np.testing.assert_array_equal(ends[0], ends[1])
    np.testing.assert_allclose(ends[0], target, rtol=0, atol=1e-12)


REFUSED = [
    ({"target": (0.1, 0.2, 0.3), "sets": ("hand",)}, r"sets: .*no joint set 'hand' \(its sets: "
                                                     r"arm, wrist\)"),
    ({"target": (0.1, 0.2, 0.3, 0.4), "sets": ("wrist",)},
     r"target: 4 joint values; joint set\(s\) wrist have 3"),
    ({"target": tuple(PUMA_HOME), "sets": ("wrist",)}, "target: 6 joint values"),
    ({"target": (0.1, 0.2, 9.0), "sets": ("wrist",)}, "outside the joint limits"),
]


@pytest.mark.parametrize("fields, message", REFUSED)
def test_bad_set_records_are_refused_when_queued_and_nothing_moves(fields, message):
    """An unknown set, a target of the wrong length or beyond a limit: refused at queue, the arm stays."""
    ev = make(sets=SETS)
    with pytest.raises(RecordError, match=message):
        ev.queue(MotionSpec(**fields))
    assert ev.idle
    knots = run(ev, limit=20)
    for k in knots:
        np.testing.assert_array_equal(k.q, PUMA_HOME)


def test_an_equation_target_cannot_name_sets():
    """A record naming sets moves to a joint target; one with only a position equation is refused."""
    ev = make(sets=SETS)
    eq = equation(tool_pose(PUMA, PUMA_HOME))
    with pytest.raises(RecordError, match="sets: a record naming joint sets moves to a joint "
                                          "target"):
        ev.queue(MotionSpec(equation=eq, sets=("wrist",)))
    assert ev.idle


def test_an_arm_without_sets_refuses_a_record_naming_one():
    """An evaluator made without joint sets refuses a record that names one, saying so."""
    ev = make()
    with pytest.raises(RecordError, match="declares no joint sets"):
        ev.queue(MotionSpec(target=(0.1, 0.2, 0.3), sets="wrist"))
    assert ev.idle


BAD_FIELD = [
    ({"sets": ()}, "sets: expected one or more"),
    ({"sets": ("wrist", "wrist")}, "named twice"),
    ({"sets": (3,)}, "sets: expected one or more"),
    ({"sets": 5}, "sets: expected joint set names"),
    ({"mode": "cart", "sets": ("wrist",)}, "sets: a Cartesian record"),
]


@pytest.mark.parametrize("fields, message", BAD_FIELD)
def test_the_sets_field_is_checked_when_the_record_is_made(fields, message):
    """sets: empty, repeated, not names, or on a Cartesian record: RecordError naming the field."""
    with pytest.raises(RecordError, match=message):
        MotionSpec(**fields)


def test_the_sets_field_is_normalised_and_copied():
    """One name becomes a tuple; copy() keeps it."""
    spec = MotionSpec(target=(0.0,) * 3, sets="wrist")
    assert spec.sets == ("wrist",)
    assert spec.copy(name="w").sets == ("wrist",)
    assert MotionSpec().sets is None


def test_sets_must_be_the_chains_joints():
    """An evaluator given joint sets of another arm is refused when made."""
    other = JointSets.from_urdf('<robot name="r"><link name="a"/><link name="b"/>'
                                '<joint name="j" type="continuous"><parent link="a"/>'
                                '<child link="b"/></joint></robot>')
    with pytest.raises(ValueError, match="are not chain 'puma560'"):
        make(sets=other)


@settings(max_examples=10, deadline=None)
@given(st.integers(10, 60), st.sampled_from([-1.0, 1.0]))
def test_an_aborting_set_record_brakes_the_other_joints_to_rest_and_holds_them(ticks, sign):
    """A wrist record aborting a running arm move: joints 1-3 brake to rest without coming back (monotonic), then hold exactly; the wrist reaches its target."""
    ev = make(sets=SETS)
    ev.queue(MotionSpec(target=tuple(PUMA_HOME[:3] + sign * 0.5), sets="arm"))
    for _ in range(ticks):
        ev.tick()
    wrist_t = tuple(PUMA_HOME[3:] + 0.3)
    move = ev.queue(MotionSpec(target=wrist_t, sets="wrist", buffer="aborting"))
    knots = run(ev)
    assert move.code == "reached"
    arm = np.array([k.q[:3] for k in knots])
    steps = np.diff(arm, axis=0) * sign
    assert (steps >= -1e-15).all(), "an arm joint came back"
    rest = arm[-1]
    held = [bool(np.array_equal(a, rest)) for a in arm]
    first = held.index(True)
    assert all(held[first:]) and first < len(knots) // 2
    np.testing.assert_allclose(knots[-1].q[3:], wrist_t, rtol=0, atol=1e-12)
