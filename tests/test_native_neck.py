"""The one neck-ring model (csrc/neck.c): against the reference, and shared by the world
(statics) and the controller (polyctl) with each one's segments as a parameter."""

from __future__ import annotations

import math

import _ref_polyctl as ref
import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

import pyrt.native as nat
from pyrt.native._errors import NoConvergenceError

NAN = math.nan
SNO_RING = ((0.0, 0.0, 595.8), (0.0, 0.0, 1.0), 72.5)
SNO_TOPS = [(0.0, 0.0, 1299.0), (60.0, 0.0, 1299.0), (-60.0, 0.0, 1299.0), (0.0, 60.0, 1299.0),
            (0.0, -60.0, 1299.0)]
SNO_BOTTOMS = [None, (545.44, 0.0, -250.0), (-545.44, 0.0, -250.0), (0.0, 545.44, -250.0),
               (0.0, -545.44, -250.0)]
SNO_OFFSETS = [(0.0, 0.0, 0.0), (5.0, 0.0, 0.0), (-5.0, 0.0, 0.0), (0.0, 5.0, 0.0),
               (0.0, -5.0, 0.0)]


def _frame(ring: nat.NeckRing) -> tuple[float, ...]:
    return (*ring.centre, *ring.axis, *ring.e1, *ring.e2, ring.radius)


@st.composite
def _rings(draw):
    centre = tuple(draw(st.floats(-100.0, 100.0)) for _ in range(3))
    axis = tuple(draw(st.floats(-1.0, 1.0)) for _ in range(3))
    assume(math.hypot(*axis) > 0.1)
    return nat.NeckRing(centre, axis, draw(st.floats(5.0, 100.0)))


def _at(ring: nat.NeckRing, a: float, b: float, c: float) -> tuple[float, float, float]:
    """The point a along the axis, b along e1, c along e2 from the centre."""
    return tuple(ring.centre[k] + a * ring.axis[k] + b * ring.e1[k] + c * ring.e2[k]
                 for k in range(3))  # type: ignore[return-value]


_along = st.floats(-500.0, 500.0)
_across = st.floats(-300.0, 300.0)


@settings(max_examples=300, deadline=None)
@given(ring=_rings(), data=st.data())
def test_contact_equals_reference(ring, data):
    """Any ring, any segment (either end above), with or without a hint: the rim point and
    angle, or no contact, or a degenerate piece, as the reference finds them."""
    far = _at(ring, data.draw(_along), data.draw(_across), data.draw(_across))
    q = _at(ring, data.draw(_along), data.draw(_across), data.draw(_across))
    hint = data.draw(st.none() | st.floats(-4.0, 4.0))
    try:
        want = ref.contact(_frame(ring), far, q, hint)
        if want is None and math.dist(far, q) < ref.MIN_SEGMENT:
            raise ref.Degenerate("a straight segment of no length")
    except ref.Degenerate:
        with pytest.raises(nat.DegenerateGeometryError):
            ring.contact(far, q, hint)
        return
    got = ring.contact(far, q, hint)
    assert (got is None) == (want is None)
    if got is not None:
        np.testing.assert_allclose(got[0], want[0], rtol=0, atol=1e-9)
        assert got[1] == pytest.approx(want[1], abs=1e-9)


@settings(max_examples=300, deadline=None)
@given(ring=_rings(), segments=st.integers(0, 3), central=st.booleans(), data=st.data())
def test_rope_path_equals_reference(ring, segments, central, data):
    """A whole rope with any mask of segments allowed to bear: its length as the reference's."""
    top = _at(ring, data.draw(st.floats(1.0, 500.0)), data.draw(_across), data.draw(_across))
    bottom = None if central else _at(ring, data.draw(st.floats(-500.0, -1.0)),
                                      data.draw(_across), data.draw(_across))
    q = _at(ring, data.draw(_along), data.draw(_across), data.draw(_across))
    try:
        want = ref.rope_length(_frame(ring), top, bottom, (0.0, 0.0, 0.0), q, segments)
    except ref.Degenerate:
        with pytest.raises(nat.DegenerateGeometryError):
            ring.rope_path(top, bottom, q, segments)
        return
    got = ring.rope_path(top, bottom, q, segments)
    assert got.length == pytest.approx(want, rel=1e-12, abs=1e-9)
    assert got.upper is None or segments & nat.NECK_UPPER
    assert got.lower is None or (segments & nat.NECK_LOWER and bottom is not None)


def test_hint_does_not_change_the_answer():
    """From last time's rim angle Newton lands on the same rim point as from the crossing."""
    ring = nat.NeckRing(*SNO_RING)
    top = SNO_TOPS[1]
    first = ring.contact(top, (400.0, 30.0, 100.0))
    assert first is not None
    again = ring.contact(top, (401.0, 29.0, 101.0), first[1])
    fresh = ring.contact(top, (401.0, 29.0, 101.0))
    np.testing.assert_allclose(again[0], fresh[0], rtol=0, atol=1e-12)


def test_frame_and_refusals():
    """The ring's frame is orthonormal and right-handed; no radius means no contact; a zero
    axis, a non-finite number or the carriage on the rim is refused as a NativeError."""
    ring = nat.NeckRing((1.0, 2.0, 3.0), (0.0, 3.0, 4.0), 10.0)
    a, e1, e2 = (np.array(v) for v in (ring.axis, ring.e1, ring.e2))
    np.testing.assert_allclose([a @ a, e1 @ e1, e2 @ e2, a @ e1, a @ e2, e1 @ e2],
                               [1, 1, 1, 0, 0, 0], atol=1e-15)
    np.testing.assert_allclose(np.cross(a, e1), e2, atol=1e-15)
    flat = nat.NeckRing(*SNO_RING[:2], 0.0)
    assert flat.contact(SNO_TOPS[1], (400.0, 0.0, 100.0)) is None
    assert nat.ring_contact((*SNO_RING[:2], 0.0), SNO_TOPS[1], (400.0, 0.0, 100.0)) is None
    assert nat.ring_contact(None, SNO_TOPS[1], (400.0, 0.0, 100.0)) is None
    with pytest.raises(nat.NativeInputError):
        nat.NeckRing((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 1.0)
    with pytest.raises(nat.NonFiniteError):
        nat.NeckRing((0.0, NAN, 0.0), (0.0, 0.0, 1.0), 1.0)
    with pytest.raises(nat.NativeInputError):
        nat.NeckRing((0.0, 0.0), (0.0, 0.0, 1.0), 1.0)
    with pytest.raises(nat.DegenerateGeometryError):
        nat.NeckRing(*SNO_RING).contact(SNO_TOPS[1], (72.50001, 0.0, 595.79999))
    with pytest.raises(nat.DegenerateGeometryError):
        nat.NeckRing(*SNO_RING).rope_path(SNO_TOPS[1], SNO_BOTTOMS[1], SNO_TOPS[1], 3)


def test_ring_contact_forms_agree():
    """ring_contact with (centre, axis, radius) or a NeckRing is NeckRing.contact's point."""
    ring = nat.NeckRing(*SNO_RING)
    q = (400.0, 30.0, 100.0)
    want = ring.contact(SNO_TOPS[1], q)[0]
    assert nat.ring_contact(SNO_RING, SNO_TOPS[1], q) == want
    assert nat.ring_contact(ring, SNO_TOPS[1], q) == want


def _world(ring):
    n = len(SNO_TOPS)
    return nat.StaticsSolver(SNO_TOPS, SNO_BOTTOMS, SNO_OFFSETS, [50.0] * n, [2e-5] * n,
                             [3000.0] * n, ring=ring)


@pytest.mark.parametrize("x", [(400.0, 0.0, 100.0), (0.0, 300.0, -200.0), (5.0, 3.0, 700.0),
                               (60.0, -20.0, 650.0), (0.0, 0.0, 100.0)])
def test_world_uses_the_one_model(x):
    """The statics kernel's rope lengths and contacts are the model's, with the world's
    segments (StaticsSolver.RING_SEGMENTS)."""
    ring = nat.NeckRing(*SNO_RING)
    g, _, wrapped = _world(ring).evaluate(x)
    for i, (top, bottom, o) in enumerate(zip(SNO_TOPS, SNO_BOTTOMS, SNO_OFFSETS, strict=True)):
        q = (x[0] + o[0], x[1] + o[1], x[2] + o[2])
        path = ring.rope_path(top, bottom, q, nat.StaticsSolver.RING_SEGMENTS)
        assert g[i] == path.length
        assert wrapped[i] == (path.upper is not None or path.lower is not None)


@pytest.mark.parametrize("hare", [(400.0, 0.0, 100.0), (0.0, 300.0, -200.0), (5.0, 3.0, 700.0),
                                  (60.0, -20.0, 650.0), (0.0, 0.0, 100.0)])
def test_controller_uses_the_one_model(hare):
    """The poll kernel's rope lengths at the hare are the model's, with the controller's
    segments (PolyControl.RING_SEGMENTS)."""
    ring = nat.NeckRing(*SNO_RING)
    n = len(SNO_TOPS)
    bott = np.array([(NAN,) * 3 if b is None else b for b in SNO_BOTTOMS])
    finder = nat.PositionFinder(np.array(SNO_TOPS), bott, np.array(SNO_OFFSETS))
    batch = nat.FuzzyBatch(nat.FuzzyParams(), n)
    batch.inputs[:, nat.FuzzyInput.TENSION_HIGH] = 200.0
    x = (10.0, 0.0, 100.0)
    ctl = nat.PolyControl(finder, batch, tops=SNO_TOPS, bottoms=SNO_BOTTOMS, offsets=SNO_OFFSETS,
                          stretch=[0.0] * n, dead=[0.0] * n, ring=ring, axis_point=(0.0, 0.0),
                          weight_air=50.0, weight_liquid=40.0, liquid_level=None,
                          offside_tension=10.0, near_end_cm=10.0, position=x)
    g, _, _ = _world(ring).evaluate(x)
    lengths = [0.0] * n
    ctl.measure([20.0] * n, g, lengths)
    el = [0.0] * n
    ctl.drive(hare, [0.0] * n, 20.0, el, [0.0] * n, [0.0] * n, [1.0] * n)
    for i, (top, bottom, o) in enumerate(zip(SNO_TOPS, SNO_BOTTOMS, SNO_OFFSETS, strict=True)):
        q = (hare[0] + o[0], hare[1] + o[1], hare[2] + o[2])
        want = lengths[i] - finder.residuals[i] - el[i]
        path = ring.rope_path(top, bottom, q, nat.PolyControl.RING_SEGMENTS)
        assert want == pytest.approx(path.length, rel=1e-12, abs=1e-9)


def test_segments_are_a_parameter_of_the_one_model():
    """With the source up in the neck a side rope's lower segment bears on the ring only
    when the mask lets it; the upper segment far out in the vessel likewise."""
    ring = nat.NeckRing(*SNO_RING)
    top, bottom = SNO_TOPS[1], SNO_BOTTOMS[1]
    up_in_neck, far_out = (60.0, 0.0, 650.0), (400.0, 0.0, 100.0)
    lengths = {}
    for mask in range(4):
        neck = ring.rope_path(top, bottom, up_in_neck, mask)
        out = ring.rope_path(top, bottom, far_out, mask)
        assert (neck.lower is not None) == bool(mask & nat.NECK_LOWER)
        assert (out.upper is not None) == bool(mask & nat.NECK_UPPER)
        lengths[mask] = (neck.length, out.length)
    straight = math.dist(top, up_in_neck) + math.dist(up_in_neck, bottom)
    assert lengths[0][0] == pytest.approx(straight, rel=1e-15)
    assert lengths[nat.NECK_LOWER][0] > straight


@pytest.mark.parametrize("x", [(0.0, 0.0, 1250.0), (20.0, 0.0, 1200.0), (-30.0, 25.0, 900.0)])
def test_controller_finds_the_source_where_lower_segments_bear(x):
    """Up in the neck, with world lengths (lower segments on the ring), the controller's
    measure finds the source there with distErr ~0; one told to let only the upper
    segments bear (ring_segments, the named place it knows less) does not."""
    ring = nat.NeckRing(*SNO_RING)
    n = len(SNO_TOPS)
    g, _, wrapped = _world(ring).evaluate(x)
    assert any(wrapped)
    found = {}
    for segs in (nat.PolyControl.RING_SEGMENTS, nat.NECK_UPPER):
        bott = np.array([(NAN,) * 3 if b is None else b for b in SNO_BOTTOMS])
        finder = nat.PositionFinder(np.array(SNO_TOPS), bott, np.array(SNO_OFFSETS), tol=1e-6)
        batch = nat.FuzzyBatch(nat.FuzzyParams(), n)
        ctl = nat.PolyControl(finder, batch, tops=SNO_TOPS, bottoms=SNO_BOTTOMS,
                              offsets=SNO_OFFSETS, stretch=[0.0] * n, dead=[0.0] * n,
                              ring=ring, axis_point=(0.0, 0.0), weight_air=50.0,
                              weight_liquid=40.0, liquid_level=None, offside_tension=10.0,
                              near_end_cm=10.0, position=(x[0] + 2.0, x[1] - 1.0, x[2] + 3.0),
                              ring_segments=segs)
        try:
            for _ in range(4):  # the contacts follow the estimate poll by poll
                out = ctl.measure([20.0] * n, list(g), [0.0] * n)
        except NoConvergenceError:  # the lengths fix no position in its model
            out = [math.inf] * 4
        found[segs] = (math.dist(out[:3], x), out[3], ctl.lower_rim_angles)
    dist, dist_err, lower = found[nat.PolyControl.RING_SEGMENTS]
    assert dist < 1e-3 and dist_err < 1e-3 and any(a is not None for a in lower)
    dist, dist_err, lower = found[nat.NECK_UPPER]
    assert dist > 1.0 and dist_err > 1.0 and all(a is None for a in lower)
    with pytest.raises(nat.NativeInputError, match="ring_segments"):
        nat.PolyControl(finder, batch, tops=SNO_TOPS, bottoms=SNO_BOTTOMS, offsets=SNO_OFFSETS,
                        stretch=[0.0] * n, dead=[0.0] * n, ring=ring, axis_point=(0.0, 0.0),
                        weight_air=50.0, weight_liquid=40.0, liquid_level=None,
                        offside_tension=10.0, near_end_cm=10.0, position=x, ring_segments=4)


def test_a_tie_between_two_contacts_is_not_decided_by_rounding():
    """A rope from a point on the ring's axis, started at the symmetric rim point: both the C
    kernel and the reference step the same way (+), whatever the rounding of the slope."""
    ring = nat.NeckRing((0.0, 0.0, 0.0), (0.0, 0.6246950475544243, 0.7808688094430304), 5.0)
    far, q = _at(ring, 6.0, 0.0, 0.0), _at(ring, -1.0, -6.0, 0.0)
    got = ring.contact(far, q, 0.0)
    want = ref.contact(_frame(ring), far, q, 0.0)
    assert got is not None and want is not None
    np.testing.assert_allclose(got[0], want[0], rtol=0, atol=1e-9)
    assert got[1] == pytest.approx(want[1], abs=1e-9) and got[1] > 0
