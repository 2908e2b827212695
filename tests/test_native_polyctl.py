"""The control poll kernels (csrc/polyctl.c) against the pure-Python reference, and their input checks."""

from __future__ import annotations

import math

import numpy as np
import pytest
from _ref_polyctl import MIN_SEGMENT, Degenerate, RefPolyControl, contact, rope_length
from hypothesis import given, settings
from hypothesis import strategies as st

import pyrt.native as nat
from pyrt.errors import NativeError

NAN = math.nan


def _frame(centre, axis, radius):
    r = nat.NeckRing(centre, axis, radius)
    return (*r.centre, *r.axis, *r.e1, *r.e2, r.radius)


#: (tops, bottoms, offsets, ring, vessel radius, planar) of the two packaged stations.
GEOMETRY = {
    "prototype": (
        [(0.0, 5.0, 389.0), (50.0, 0.0, 391.0), (-50.0, 0.0, 391.0)],
        [None, (317.0, 0.0, 89.53), (-317.0, 0.0, 89.53)],
        [(0.0, 0.0, 0.0)] * 3,
        _frame((5.7, 0.0, 364.0), (0.0, 0.0, 1.0), 42.0), 320.0, True),
    "sno": (
        [(0.0, 0.0, 1299.0), (60.0, 0.0, 1299.0), (-60.0, 0.0, 1299.0), (0.0, 60.0, 1299.0),
         (0.0, -60.0, 1299.0)],
        [None, (545.44, 0.0, -250.0), (-545.44, 0.0, -250.0), (0.0, 545.44, -250.0),
         (0.0, -545.44, -250.0)],
        [(0.0, 0.0, 0.0), (5.0, 0.0, 0.0), (-5.0, 0.0, 0.0), (0.0, 5.0, 0.0), (0.0, -5.0, 0.0)],
        _frame((0.0, 0.0, 595.8), (0.0, 0.0, 1.0), 72.5), 600.5, False),
}
STRETCH, DEAD, TOL = 2e-5, 50.0, 0.1
T_LOW, T_HIGH = 2.0, 200.0


def _pair(name, start, *, liquid_level=None):
    tops, bottoms, offsets, ring, _, _ = GEOMETRY[name]
    n = len(tops)
    bott = np.array([(NAN, NAN, NAN) if b is None else b for b in bottoms])
    finder = nat.PositionFinder(np.array(tops), bott, np.array(offsets), tol=TOL)
    params = nat.FuzzyParams().for_poll_period(0.05)
    batch = nat.FuzzyBatch(params, n)
    batch.inputs[:, nat.FuzzyInput.TENSION_LOW] = T_LOW
    batch.inputs[:, nat.FuzzyInput.TENSION_HIGH] = T_HIGH
    kw = dict(tops=tops, bottoms=bottoms, offsets=offsets, stretch=[STRETCH] * n,
              dead=[DEAD] * n, ring=ring, axis_point=(0.0, 0.0), weight_air=52.3,
              weight_liquid=41.5, liquid_level=liquid_level, offside_tension=10.0,
              near_end_cm=10.0, position=start)
    ctl = nat.PolyControl(finder, batch, **kw)
    ref = RefPolyControl([(params, T_LOW, T_HIGH)] * n, tol=TOL, **kw)
    return ctl, ref, batch


def _encoder_lengths(name, x, tensions):
    tops, bottoms, offsets, ring, _, _ = GEOMETRY[name]
    return [(rope_length(ring, t, b, o, x) + DEAD) / (1.0 + STRETCH * max(tn, 0.0))
            for t, b, o, tn in zip(tops, bottoms, offsets, tensions, strict=True)]


@st.composite
def _scenes(draw):
    name = draw(st.sampled_from(sorted(GEOMETRY)))
    _, _, _, _, radius, planar = GEOMETRY[name]
    c = st.floats(-0.8 * radius, 0.8 * radius)
    x = (draw(c), 0.0 if planar else draw(c), draw(c))
    start = tuple(v + draw(st.floats(-3.0, 3.0)) * (0.0 if planar and k == 1 else 1.0)
                  for k, v in enumerate(x))
    n = len(GEOMETRY[name][0])
    polls = []
    for _ in range(3):
        tens = draw(st.lists(st.floats(-5.0, 150.0), min_size=n, max_size=n))
        noise = draw(st.lists(st.floats(-0.2, 0.2), min_size=n, max_size=n))
        hare = tuple(v + draw(st.floats(-20.0, 20.0)) for v in x)
        vel = draw(st.lists(st.floats(-7.0, 7.0), min_size=n, max_size=n))
        polls.append((tens, noise, hare, vel))
    endpoint = draw(st.none() | st.just(tuple(v + 5.0 for v in x)))
    signal_all = draw(st.booleans())
    desired = draw(st.lists(st.floats(0.0, 80.0), min_size=n, max_size=n))
    level = draw(st.none() | st.floats(-radius, radius))
    return name, x, start, polls, endpoint, signal_all, desired, level


@settings(max_examples=150, deadline=None)
@given(_scenes())
def test_poll_equals_reference(scene):
    """Three polls of measure and drive: C and the Python reference agree (position, distErr,
    net force, lengths, error signals, velocity changes, fuzzy rules)."""
    name, x, start, polls, endpoint, signal_all, desired0, level = scene
    ctl, ref, batch = _pair(name, start, liquid_level=level)
    for obj in (ctl, ref):
        obj.set_endpoint(endpoint)
        obj.reset_rates()
    n = ref.n
    for tens, noise, hare, vel in polls:
        enc = [e + d for e, d in zip(_encoder_lengths(name, x, tens), noise, strict=True)]
        lc, lr = [0.0] * n, [0.0] * n
        try:
            rr = ref.measure(tens, enc, lr)
        except (RuntimeError, np.linalg.LinAlgError):
            with pytest.raises(NativeError):
                ctl.measure(tens, enc, lc)
            return
        rc = ctl.measure(tens, enc, lc)
        np.testing.assert_allclose(lc, lr, rtol=0, atol=1e-9)
        np.testing.assert_allclose(rc, rr, rtol=1e-9, atol=1e-8)
        # the drive from the very same estimate: the off side is a sign test
        # that rounding-level differences of the two solvers could flip
        ref.position = tuple(rc[:3])
        outs = []
        for obj in (ctl, ref):
            el, et = [0.0] * n, [0.0] * n
            want = list(desired0) if signal_all else [0.0] * n
            free = [0.0] * n if signal_all else [1.0] * n
            dv = obj.drive(hare, vel, 20.0, el, et, want, free, signal_all=signal_all)
            outs.append((el, et, want, free, dv))
        for a, b in zip(*outs, strict=True):
            np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-8)
        np.testing.assert_allclose(batch.rules, ref.rules, rtol=1e-9, atol=1e-9)


@settings(max_examples=300, deadline=None)
@given(name=st.sampled_from(sorted(GEOMETRY)), data=st.data())
def test_ring_contact_equals_reference(name, data):
    """The rim point and angle (or no contact) agree with the reference, with and without a hint."""
    tops, _, _, ring, radius, _ = GEOMETRY[name]
    top = data.draw(st.sampled_from(tops))
    c = st.floats(-radius, radius)
    q = (data.draw(c), data.draw(c), data.draw(c))
    hint = data.draw(st.none() | st.floats(-4.0, 4.0))
    neck = nat.NeckRing(ring[0:3], ring[3:6], ring[12])
    assert (*neck.e1, *neck.e2) == tuple(ring[6:12])
    try:
        want = contact(ring, top, q, hint)
        if want is None and math.dist(top, q) < MIN_SEGMENT:
            raise Degenerate("a straight segment of no length")
    except Degenerate:
        with pytest.raises(nat.DegenerateGeometryError):
            neck.contact(top, q, hint)
        return
    got = neck.contact(top, q, hint)
    assert (got is None) == (want is None)
    if got is not None:
        np.testing.assert_allclose(got[0], want[0], rtol=0, atol=1e-9)
        assert got[1] == pytest.approx(want[1], abs=1e-9)


def test_contacts_are_used():
    """Far out in the sno vessel every rope bears on the ring and is still found; on the axis none does."""
    tens = [30.0, 10.0, 40.0, 20.0, 20.0]
    for x, bears in [((400.0, 0.0, 100.0), True), ((0.0, 0.0, 100.0), False)]:
        ctl, _, _ = _pair("sno", x)
        out = ctl.measure(tens, _encoder_lengths("sno", x, tens), [0.0] * 5)
        assert math.dist(out[:3], x) < 0.05 and out[3] < 0.01
        assert all((a is not None) == bears for a in ctl.rim_angles)


def test_bad_input_is_refused():
    """Wrong sizes, non-finite numbers and a ring that is not an orthonormal frame raise
    NativeError at construction; a NaN tension from the devices is refused by C."""
    ctl, _, _ = _pair("prototype", (0.0, 0.0, 100.0))
    tops, bottoms, offsets, ring, _, _ = GEOMETRY["prototype"]
    finder = nat.PositionFinder(np.array(tops), np.array([(NAN,) * 3, bottoms[1], bottoms[2]]))
    batch = nat.FuzzyBatch(nat.FuzzyParams(), 3)
    good = dict(tops=tops, bottoms=bottoms, offsets=offsets, stretch=[STRETCH] * 3,
                dead=[DEAD] * 3, ring=ring, axis_point=(0.0, 0.0), weight_air=1.0,
                weight_liquid=1.0, liquid_level=None, offside_tension=10.0, near_end_cm=10.0,
                position=(0.0, 0.0, 100.0))
    skew = (*ring[:9], *ring[6:9], ring[12])   # e2 = e1: not a frame
    assert nat.PolyControl(finder, batch, **dict(good, ring=None)).n == 3
    for key, bad in [("tops", tops[:2]), ("stretch", [NAN] * 3), ("ring", ring[:5]),
                     ("ring", (*ring[:3], 0.0, 0.0, 2.0, *ring[6:])), ("ring", skew),
                     ("position", (0.0, NAN, 1.0)), ("near_end_cm", 0.0),
                     ("offsets", [(0.0, 0.0)] * 3), ("weight_air", math.inf)]:
        with pytest.raises(NativeError):
            nat.PolyControl(finder, batch, **dict(good, **{key: bad}))
    with pytest.raises(NativeError):
        nat.PolyControl(finder, nat.FuzzyBatch(nat.FuzzyParams(), 2), **good)
    lengths = [1.0, 2.0, 3.0]
    with pytest.raises(NativeError, match="NaN or infinity"):
        ctl.measure([10.0, NAN, 10.0], [500.0, 500.0, 500.0], lengths)
    with pytest.raises(NativeError):
        ctl.drive((0.0, 0.0, NAN), [0.0] * 3, 20.0, [0.0] * 3, [0.0] * 3, [0.0] * 3, [0.0] * 3)
