"""Evaluator.snapshot / plan / commit: a record planned outside the loop, handed over only
while the snapshot it was planned from still holds."""

from __future__ import annotations

import threading

import numpy as np
import pytest
from _motion_rig import PUMA, PUMA_HOME, PUMA_LIMITS, run

from pyrt.motion import Evaluator, MotionSpec
from pyrt.motion.evaluator import StalePlan

TARGET = tuple(float(v) for v in PUMA_HOME + np.array([0.3, -0.2, 0.25, 0.1, -0.3, 0.2]))
OTHER = tuple(float(v) for v in PUMA_HOME + np.array([-0.2, 0.1, -0.1, 0.0, 0.2, -0.1]))


def _ev() -> Evaluator:
    return Evaluator(PUMA, PUMA_LIMITS, PUMA_HOME)


def test_a_plan_made_in_another_thread_runs_as_the_same_record_queued_in_the_loop():
    """plan() in a worker thread, commit() here: the knots equal those of queue() on a twin evaluator, sample for sample."""
    ev, twin = _ev(), _ev()
    snap = ev.snapshot()
    out = {}
    worker = threading.Thread(target=lambda: out.setdefault("p", ev.plan(MotionSpec(
        target=TARGET), snap)))
    worker.start()
    worker.join(30.0)
    assert not worker.is_alive()
    ev.commit(out["p"])
    twin.queue(MotionSpec(target=TARGET))
    a, b = run(ev), run(twin)
    assert len(a) == len(b)
    assert all(np.array_equal(x.q, y.q) for x, y in zip(a, b, strict=True))
    assert np.allclose(a[-1].q, TARGET, atol=1e-9)


def test_a_plan_the_trajectory_has_overtaken_is_stale_one_with_a_lead_is_not():
    """From rest: a plan with no lead is stale once a trajectory tick has passed (nothing queued); one made with a lead of two periods still holds after one tick, the arm holding still until it begins, and ends on its target."""
    ev = _ev()
    planned = ev.plan(MotionSpec(target=TARGET), ev.snapshot())
    ev.tick()
    with pytest.raises(StalePlan, match="passed the plan's start"):
        ev.commit(planned)
    assert ev.idle
    planned = ev.plan(MotionSpec(target=TARGET), ev.snapshot(lead=2))
    ev.tick()
    ev.commit(planned)
    knots = run(ev)
    assert np.array_equal(knots[0].q, PUMA_HOME)  # held until the plan begins
    assert np.allclose(knots[-1].q, TARGET, atol=1e-9)
    qd = np.array([k.qd for k in knots])
    assert np.max(np.abs(np.diff(qd, axis=0))) < 0.1  # no jump into the move


@pytest.mark.parametrize("between", ["queue", "stop"])
def test_a_plan_is_stale_when_anything_was_queued_or_stopped_since_its_snapshot(between):
    """A record queued, or a stop, between a plan's snapshot and its hand-over: the hand-over is refused (StalePlan) and the queue is as that other action left it."""
    ev = _ev()
    ev.queue(MotionSpec(target=OTHER))
    run(ev, limit=5)
    snap = ev.snapshot()
    planned = ev.plan(MotionSpec(target=TARGET), snap)
    if between == "queue":
        ev.queue(MotionSpec(target=OTHER))
    else:
        ev.stop()
    with pytest.raises(StalePlan):
        ev.commit(planned)
    knots = run(ev)
    assert not np.allclose(knots[-1].q, TARGET, atol=1e-3)
    if between == "queue":
        assert np.allclose(knots[-1].q, OTHER, atol=1e-9)


def test_a_plan_from_a_snapshot_of_a_running_move_blends_from_its_queued_end():
    """A snapshot taken while a move runs: the record planned from it blends at that move's end (PLCopen blending), joint velocity continuous, ending on its own target."""
    ev = _ev()
    ev.queue(MotionSpec(target=OTHER))
    run(ev, limit=10)
    move = ev.commit(ev.plan(MotionSpec(target=TARGET), ev.snapshot()))
    assert move.buffer == "blending"
    knots = run(ev)
    qd = np.array([k.qd for k in knots])
    assert np.max(np.abs(np.diff(qd, axis=0))) < 0.1
    assert np.allclose(knots[-1].q, TARGET, atol=1e-9)


def test_a_cartesian_plan_and_its_ticks_are_the_same_to_the_bit_in_any_thread():
    """A planner's prepared inverse (the thread that made it) and the closed form's plain call
    (any other thread) give the same plan and the same ticks, to the last bit."""
    from _motion_rig import equation, tool_pose

    a = tool_pose(PUMA, PUMA_HOME)
    b = a.copy()
    b[:3, 3] += [0.08, -0.05, 0.04]
    spec = MotionSpec(mode="cart", equation=equation(b))

    def planned_and_run(ev):
        ev.queue(spec)
        seg = ev._segs[-1]
        return [p.c.copy() for p in seg.pieces], seg.q_end.copy(), [k.q for k in run(ev)]

    own = planned_and_run(Evaluator(PUMA, PUMA_LIMITS, PUMA_HOME))
    ev = Evaluator(PUMA, PUMA_LIMITS, PUMA_HOME)
    out = []
    t = threading.Thread(target=lambda: out.append(planned_and_run(ev)))
    t.start()
    t.join()
    other = out[0]
    assert all(np.array_equal(x, y) for x, y in zip(own[0], other[0], strict=True))
    assert np.array_equal(own[1], other[1])
    assert len(own[2]) == len(other[2]) > 10
    assert all(np.array_equal(x, y) for x, y in zip(own[2], other[2], strict=True))
