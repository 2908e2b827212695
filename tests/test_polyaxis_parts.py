"""Parts of the PolyAxis: the hare's path and profile, the stop conditions, the neck-ring contact."""

from __future__ import annotations

import itertools
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pyrt.native import StaticsSolver
from pyrt.robots._neck import ring_contact
from pyrt.robots.paths import Hare, Segment, paul_blend, paul_g, plan_segments
from pyrt.robots.stops import StopCheck, StopReason

POLL = 0.05


def _run(hare, dt=POLL, settled=None, max_steps=100_000):
    trace = []
    for _ in range(max_steps):
        p = hare.advance(dt, settled)
        trace.append((hare.v, hare.s, hare.index, p))
        if hare.finished:
            break
    return trace


def test_hare_reaches_top_speed_after_the_ramp():
    """The hare's speed rises linearly in time and reaches 2.0 cm/s at 20 cm."""
    hare = Hare([Segment((0.0, 0.0, 0.0), (100.0, 0.0, 0.0))], 2.0, 20.0)
    trace = _run(hare)
    speeds = [v for v, *_ in trace]
    assert max(speeds) == pytest.approx(2.0)
    first_top = next(s for v, s, *_ in trace if v >= 2.0 - 1e-9)
    assert first_top == pytest.approx(20.0, abs=0.2)
    # linear in time while ramping: constant increments of a * dt = 0.1 * 0.05
    incs = [b - a for a, b in itertools.pairwise(speeds[:21])]
    assert all(i == pytest.approx(0.005) for i in incs)
    assert trace[-1][3] == (100.0, 0.0, 0.0)


def test_hare_slows_over_the_last_ramp():
    """The speed falls over the last 20 cm and the hare ends exactly at the endpoint."""
    hare = Hare([Segment((0.0, 0.0, 0.0), (0.0, 0.0, 60.0))], 2.0, 20.0)
    trace = _run(hare)
    late = [(v, s) for v, s, *_ in trace if s > 45.0 and s < 60.0]
    assert all(v < 2.0 * math.sqrt((60.0 - s + 0.2) / 20.0) + 1e-6 for v, s in late)
    assert hare.finished and hare.position == (0.0, 0.0, 60.0)
    # the move takes about L / v + v / a seconds (trapezoid)
    assert len(trace) * POLL == pytest.approx(60.0 / 2.0 + 2.0 / 0.1, rel=0.05)


def test_short_segment_never_reaches_top_speed():
    """A 10 cm move peaks below 2 cm/s (triangular profile) and ends on the point."""
    hare = Hare([Segment((0.0, 0.0, 0.0), (10.0, 0.0, 0.0))], 2.0, 20.0)
    trace = _run(hare)
    assert max(v for v, *_ in trace) < 1.5
    assert hare.position == (10.0, 0.0, 0.0)


def test_neck_turn_waits_for_the_source():
    """At the turn the hare stops until the source has come to rest there."""
    segs = [Segment((0.0, 0.0, 0.0), (0.0, 0.0, 30.0)), Segment((0.0, 0.0, 30.0), (0.0, 0.0, 40.0))]
    hare = Hare(segs, 2.0, 20.0)
    ready = [False]
    trace = _run(hare, settled=lambda: ready[0], max_steps=2000)
    assert not hare.finished and hare.at_turn and hare.position == (0.0, 0.0, 30.0)
    assert trace[-1][0] == 0.0
    ready[0] = True
    _run(hare, settled=lambda: True)
    assert hare.finished and hare.position == (0.0, 0.0, 40.0)


def test_plan_segments_turns_only_between_vessel_and_neck():
    """One segment within the vessel or the neck, two (through the turn point) between them."""
    def in_neck(p):
        return p[2] > 100.0

    via = (0.0, 0.0, 95.0)
    assert len(plan_segments((0, 0, 0), (50, 0, 50), in_neck, via)) == 1
    assert len(plan_segments((0, 0, 110), (0, 0, 130), in_neck, via)) == 1
    two = plan_segments((50, 0, 0), (0, 0, 130), in_neck, via)
    assert [s.end for s in two] == [via, (0, 0, 130)]


def test_paul_quartic_boundary_conditions():
    """g(0)=g'(0)=g''(0)=0, g(1)=1/2, g'(1)=1, g''(1)=0 (Paul's transition)."""
    h = 1e-5
    assert paul_g(0.0) == 0.0 and paul_g(1.0) == 0.5
    d1 = (paul_g(1.0) - paul_g(1.0 - h)) / h
    assert d1 == pytest.approx(1.0, abs=1e-4)
    d2_end = (paul_g(1.0) - 2 * paul_g(1.0 - h) + paul_g(1.0 - 2 * h)) / h**2
    assert d2_end == pytest.approx(0.0, abs=1e-3)
    assert (paul_g(h) - paul_g(0.0)) / h == pytest.approx(0.0, abs=1e-6)


def test_blend_is_continuous_and_smooth():
    """The blended corner joins both segments with continuous position and direction."""
    corner = (0.0, 0.0, 100.0)
    d1, d2 = (0.0, 0.0, 1.0), (1.0, 0.0, 0.0)
    half = 10.0
    assert paul_blend(corner, d1, d2, half, -half) == pytest.approx((0.0, 0.0, 90.0))
    assert paul_blend(corner, d1, d2, half, half) == pytest.approx((10.0, 0.0, 100.0))
    h = 1e-4
    a = paul_blend(corner, d1, d2, half, half - h)
    b = paul_blend(corner, d1, d2, half, half)
    assert [(y - x) / h for x, y in zip(a, b, strict=True)] == pytest.approx(list(d2), abs=1e-3)
    segs = [Segment((0.0, 0.0, 50.0), corner), Segment(corner, (50.0, 0.0, 100.0))]
    hare = Hare(segs, 2.0, 20.0, blend=True)
    trace = _run(hare)
    assert hare.finished and not any(t[2] for t in trace)
    steps = [math.dist(p, q) for (*_, p), (*_, q) in itertools.pairwise(trace)]
    assert max(steps) <= 2.0 * POLL + 1e-9  # never jumps, keeps moving through the turn
    assert min(v for v, s, *_ in trace if 40.0 < s < 60.0) > 1.9


def _check(**kw):
    base = dict(end_error=1.0, find_tolerance=0.1, stuck_time=10.0, low_tension=2.0,
                max_tension=200.0, net_force_limit=25.0)
    base.update(kw)
    return StopCheck((0.0, 0.0, 0.0), (100.0, 0.0, 0.0), **base)


NAMES = ["axis0", "axis1", "axis2"]
OK_T = [30.0, 10.0, 20.0]


@pytest.mark.parametrize(("dist_err", "distance", "stops"), [
    (0.05, 0.09, True), (0.05, 0.11, False),   # never tighter than 0.1 cm
    (0.5, 0.45, True), (0.5, 0.55, False),     # distErr when it is the lesser
    (0.99, 0.95, True), (0.99, 1.05, False),   # END_ERROR ... (here distErr) the lesser
    (3.0, 0.95, False), (1.01, 0.05, False),   # distErr beyond END_ERROR: never an endpoint
])
def test_endpoint_condition(dist_err, distance, stops):
    """ENDPOINT_STOP within the lesser of END_ERROR and distErr, never under 0.1 cm, and only
    with distErr within END_ERROR (the station's tolerance)."""
    c = _check()
    hit = c.check(0.0, (100.0 - distance, 0.0, 0.0), dist_err, OK_T, 1.0, NAMES)
    assert (hit is not None and hit[0] is StopReason.ENDPOINT_STOP) == stops


def test_stuck_only_past_half_way():
    """STUCK_STOP: more than half way and no closer for 10 s; not before half way."""
    c = _check()
    for t in range(0, 30):
        assert c.check(float(t), (40.0, 0.0, 0.0), 0.05, OK_T, 1.0, NAMES) is None
    c = _check()
    hits = [c.check(float(t), (60.0, 0.0, 0.0), 0.05, OK_T, 1.0, NAMES) for t in range(0, 12)]
    assert hits[9] is None and hits[10][0] is StopReason.STUCK_STOP


def test_progress_resets_the_stuck_clock():
    """Getting closer restarts the 10 s."""
    c = _check()
    for t in range(0, 30):
        assert c.check(float(t), (60.0 + t * 0.5, 0.0, 0.0), 0.05, OK_T, 1.0, NAMES) is None


@pytest.mark.parametrize(("tensions", "force", "reason"), [
    ([30.0, 1.9, 20.0], 1.0, StopReason.LOW_TENSION_STOP),
    ([30.0, 201.0, 20.0], 1.0, StopReason.HIGH_TENSION_STOP),
    (OK_T, 25.5, StopReason.NET_FORCE_STOP),
])
def test_safety_stops(tensions, force, reason):
    """LOW_TENSION, HIGH_TENSION and NET_FORCE stops, checked before the endpoint."""
    hit = _check().check(0.0, (100.0, 0.0, 0.0), 0.05, tensions, force, NAMES)
    assert hit[0] is reason


def test_tension_stops_can_be_switched_off():
    """With tension stops off, tensions out of bounds do not stop; the net force still does."""
    c = _check(tension_stops=False)
    assert c.check(0.0, (50.0, 0.0, 0.0), 0.05, [0.0, 500.0, 1.0], 1.0, NAMES) is None
    assert c.check(0.0, (50.0, 0.0, 0.0), 0.05, OK_T, 30.0, NAMES)[0] is StopReason.NET_FORCE_STOP


RING = ((5.7, 0.0, 364.0), (0.0, 0.0, 1.0), 42.0)


@settings(max_examples=60, deadline=None)
@given(x=st.floats(-250, 250), y=st.floats(-20, 20), z=st.floats(-100, 330),
       tx=st.sampled_from([-50.0, 50.0, 0.0]))
def test_ring_contact_matches_the_physics(x, y, z, tx):
    """The rope length over the contact point equals the statics kernel's wrapped length."""
    top = (tx, 0.0, 391.0)
    q = (x, y, z)
    solver = StaticsSolver([top], [None], None, [10.0], [1e-5], [1000.0], ring=RING)
    g, _, wrapped = solver.evaluate(q)
    c = ring_contact(RING, top, q)
    assert (c is not None) == wrapped[0]
    length = math.dist(top, q) if c is None else math.dist(top, c) + math.dist(c, q)
    assert length == pytest.approx(g[0], abs=1e-6)
