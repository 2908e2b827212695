"""The position finder and rope geometry (csrc/findpos.c through pyrt.native)."""

from __future__ import annotations

import math

import _ref_findpos as ref
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import pyrt.native as nat
from pyrt.errors import NativeError, PyrtError

NAN = math.nan
GEOMETRIES = {
    "prototype": (ref.PROTO_TOPS, ref.PROTO_BOTTOMS, True),
    "five": (ref.FIVE_TOPS, ref.FIVE_BOTTOMS, False),
}


def _inside(planar: bool):
    """Points inside the prototype vessel (radius 320 cm; in the y = 0 plane if planar)."""
    coord = st.floats(-319.0, 319.0)
    ys = st.just(0.0) if planar else coord
    return st.tuples(coord, ys, coord).map(np.array).filter(
        lambda x: np.linalg.norm(x) < ref.VESSEL_RADIUS
    )


def _offset(planar: bool):
    """A start offset of at most 20 cm (in plane if planar: y is frozen there)."""
    unit = st.floats(-1.0, 1.0)
    return st.tuples(unit, st.just(0.0) if planar else unit, unit, st.floats(0.0, 20.0)).map(
        lambda t: np.array(t[:3]) / max(np.linalg.norm(t[:3]), 1e-9) * t[3]
    )


def test_table3_lengths():
    """The Table 3 database position gives the central and side rope lengths of Eq. 1."""
    x = np.array([-0.199943, 0.0, 95.569618419])
    lengths = nat.rope_lengths(x, ref.PROTO_TOPS, ref.PROTO_BOTTOMS)
    central = math.dist((0.0, 5.0, 389.0), x)
    side = math.dist((50.0, 0.0, 391.0), x) + math.dist((317.0, 0.0, 89.53), x)
    assert lengths[0] == pytest.approx(central, abs=1e-12)
    assert lengths[1] == pytest.approx(side, abs=1e-12)
    assert lengths[0] == pytest.approx(293.47, abs=0.01)


def test_segments_are_unit_directions():
    """rope_segments gives unit pull directions, zero bottom for the central rope, and sums."""
    x = np.array([40.0, 0.0, 120.0])
    seg = nat.rope_segments(x, ref.PROTO_TOPS, ref.PROTO_BOTTOMS)
    np.testing.assert_allclose(np.linalg.norm(seg.top_dir, axis=1), 1.0)
    np.testing.assert_allclose(np.linalg.norm(seg.bottom_dir[1:], axis=1), 1.0)
    assert seg.bottom_len[0] == 0.0 and not seg.bottom_dir[0].any()
    np.testing.assert_allclose(seg.total, seg.top_len + seg.bottom_len)
    np.testing.assert_allclose(x + seg.top_dir * seg.top_len[:, None], ref.PROTO_TOPS)


def test_offsets_shift_the_carriage_pulley():
    """A carriage pulley offset moves the rope's end point by that offset (Delta of Eq. 1)."""
    off = np.array([[0.0, 0.0, 0.0], [5.0, 0.0, 2.0], [-5.0, 0.0, 2.0]])
    x = np.array([10.0, 0.0, 100.0])
    with_off = nat.rope_lengths(x, ref.PROTO_TOPS, ref.PROTO_BOTTOMS, off)
    moved = [nat.rope_lengths(x + off[i], ref.PROTO_TOPS, ref.PROTO_BOTTOMS)[i] for i in range(3)]
    np.testing.assert_allclose(with_off, moved, rtol=0, atol=1e-12)


@settings(max_examples=60, deadline=None)
@given(x=_inside(False), geometry=st.sampled_from(sorted(GEOMETRIES)))
def test_rope_lengths_equal_reference(x, geometry):
    """C rope lengths equal the numpy reference to 1e-9 cm."""
    tops, bottoms, _ = GEOMETRIES[geometry]
    np.testing.assert_allclose(
        nat.rope_lengths(x, tops, bottoms), ref.rope_lengths(x, tops, bottoms), rtol=0, atol=1e-9
    )


def test_freeze_mask_rule():
    """The freeze vector holds y for the in-plane prototype and nothing for five ropes."""
    assert nat.freeze_mask(ref.PROTO_BOTTOMS) == (0, 1, 0)
    assert nat.freeze_mask(ref.FIVE_BOTTOMS) == (0, 0, 0)
    near = np.array([[NAN, NAN, NAN], [300.0, 0.4, 80.0], [-300.0, 0.5, 80.0]])
    assert nat.freeze_mask(near) == (0, 1, 0)
    assert nat.freeze_mask(near + np.array([0.0, 0.2, 0.0])) == (0, 0, 0)


@settings(max_examples=150, deadline=None)
@given(data=st.data(), geometry=st.sampled_from(sorted(GEOMETRIES)))
def test_noise_free_solution_within_0_01_cm(data, geometry):
    """From exact lengths and a start up to 20 cm off, the solution is within 0.01 cm."""
    tops, bottoms, planar = GEOMETRIES[geometry]
    truth = data.draw(_inside(planar))
    start = truth + data.draw(_offset(planar))
    lengths = nat.rope_lengths(truth, tops, bottoms)
    result = nat.find_position(tops, bottoms, lengths, start)
    assert np.linalg.norm(result.position - truth) < 0.01
    assert result.rms < 0.01
    assert result.status is nat.Status.OK


@settings(max_examples=100, deadline=None)
@given(
    data=st.data(),
    geometry=st.sampled_from(sorted(GEOMETRIES)),
    seed=st.integers(0, 2**32 - 1),
    with_offsets=st.booleans(),
)
def test_equals_reference(data, geometry, seed, with_offsets):
    """C and the numpy reference agree on position, residuals and iterations (noise, offsets)."""
    tops, bottoms, planar = GEOMETRIES[geometry]
    truth = data.draw(_inside(planar))
    start = truth + data.draw(_offset(planar))
    rng = np.random.default_rng(seed)
    offsets = None
    if with_offsets:
        offsets = rng.uniform(-8.0, 8.0, (len(tops), 3))
        offsets[0] = 0.0                      # the central rope has no carriage pulley offset
        if planar:
            offsets[:, 1] = 0.0
    lengths = nat.rope_lengths(truth, tops, bottoms, offsets) + rng.normal(0.0, 0.1, len(tops))
    c = nat.find_position(tops, bottoms, lengths, start, offsets=offsets)
    x, rms, res, it = ref.find_position(tops, bottoms, lengths, start, offsets=offsets)
    np.testing.assert_allclose(c.position, x, rtol=0, atol=1e-9)
    np.testing.assert_allclose(c.residuals, res, rtol=0, atol=1e-9)
    assert c.rms == pytest.approx(rms, abs=1e-9)
    assert c.iterations == it
    np.testing.assert_allclose(nat.rope_lengths(truth, tops, bottoms, offsets),
                               ref.rope_lengths(truth, tops, bottoms, offsets), rtol=0, atol=1e-9)


@pytest.mark.parametrize("geometry", sorted(GEOMETRIES))
def test_noise_error_comparable_to_noise(geometry):
    """With 0.1 cm Gaussian length noise the position error stays comparable to the noise."""
    tops, bottoms, planar = GEOMETRIES[geometry]
    rng = np.random.default_rng(1996)
    errors = []
    while len(errors) < 400:
        truth = rng.uniform(-320.0, 320.0, 3)
        if planar:
            truth[1] = 0.0
        if np.linalg.norm(truth) >= ref.VESSEL_RADIUS:
            continue
        off = rng.normal(size=3) * [1.0, 0.0 if planar else 1.0, 1.0]
        start = truth + off / np.linalg.norm(off) * rng.uniform(0.0, 20.0)
        lengths = nat.rope_lengths(truth, tops, bottoms) + rng.normal(0.0, 0.1, len(tops))
        errors.append(np.linalg.norm(nat.find_position(tops, bottoms, lengths, start).position
                                     - truth))
    errors = np.array(errors)
    assert np.sqrt(np.mean(errors**2)) < 0.25
    assert errors.max() < 1.0


def test_residual_sign_is_measured_minus_predicted():
    """Residuals are measured - predicted at the solution, and rms is their RMS."""
    truth = np.array([25.0, 0.0, 140.0])
    lengths = nat.rope_lengths(truth, ref.PROTO_TOPS, ref.PROTO_BOTTOMS) + np.array([0.3, -0.2, 0.4])
    r = nat.find_position(ref.PROTO_TOPS, ref.PROTO_BOTTOMS, lengths, truth)
    predicted = nat.rope_lengths(r.position, ref.PROTO_TOPS, ref.PROTO_BOTTOMS)
    np.testing.assert_allclose(r.residuals, lengths - predicted, rtol=0, atol=1e-12)
    assert r.rms == pytest.approx(np.sqrt(np.mean(r.residuals**2)), rel=1e-12)
    assert r.residuals.sum() != 0.0


def test_single_central_rope_fixes_z():
    """One central rope with x and y frozen: the z solution leaves no residual."""
    tops = [[0.0, 0.0, 400.0]]
    bottoms = [[NAN, NAN, NAN]]
    r = nat.find_position(tops, bottoms, [300.0], [0.0, 0.0, 90.0], freeze=(1, 1, 0))
    assert r.position == pytest.approx([0.0, 0.0, 100.0], abs=1e-9)
    assert r.residuals[0] == pytest.approx(0.0, abs=1e-9)


def test_freeze_holds_start_value():
    """A frozen direction keeps its start value even when the lengths pull it away."""
    truth = np.array([30.0, 4.0, 150.0])
    lengths = nat.rope_lengths(truth, ref.PROTO_TOPS, ref.PROTO_BOTTOMS)
    r = nat.find_position(ref.PROTO_TOPS, ref.PROTO_BOTTOMS, lengths, [20.0, 0.0, 140.0])
    assert r.position[1] == 0.0
    free = nat.find_position(ref.FIVE_TOPS, ref.FIVE_BOTTOMS,
                             nat.rope_lengths(truth, ref.FIVE_TOPS, ref.FIVE_BOTTOMS),
                             [20.0, 0.0, 140.0], freeze=(0, 0, 0))
    assert free.position == pytest.approx(truth, abs=0.01)


def test_tolerance_and_iterations():
    """A looser tolerance stops sooner; the tolerance bounds the last step."""
    truth = np.array([-80.0, 0.0, 60.0])
    lengths = nat.rope_lengths(truth, ref.PROTO_TOPS, ref.PROTO_BOTTOMS)
    start = truth + np.array([15.0, 0.0, -12.0])
    tight = nat.find_position(ref.PROTO_TOPS, ref.PROTO_BOTTOMS, lengths, start, tol=1e-6)
    loose = nat.find_position(ref.PROTO_TOPS, ref.PROTO_BOTTOMS, lengths, start, tol=5.0)
    assert loose.iterations < tight.iterations
    assert np.linalg.norm(tight.position - truth) < 1e-8


# --------------------------------------------------------------- prepared form


def _finder(**kw):
    return nat.PositionFinder(ref.FIVE_TOPS, ref.FIVE_BOTTOMS, **kw)


def test_prepared_equals_one_shot():
    """PositionFinder.solve gives exactly what find_position gives."""
    truth = np.array([50.0, -40.0, 100.0])
    lengths = nat.rope_lengths(truth, ref.FIVE_TOPS, ref.FIVE_BOTTOMS) + 0.05
    start = truth + np.array([10.0, 5.0, -10.0])
    f = _finder()
    pos = f.solve(lengths, start)
    one = nat.find_position(ref.FIVE_TOPS, ref.FIVE_BOTTOMS, lengths, start)
    np.testing.assert_array_equal(pos, one.position)
    np.testing.assert_array_equal(f.residuals, one.residuals)
    assert f.rms == one.rms and f.iterations == one.iterations
    assert f.freeze == (0, 0, 0) and f.n == 5


def test_prepared_continues_from_last_solution():
    """Without a start the previous solution is the start, as in a control poll."""
    f = _finder()
    a = np.array([0.0, 0.0, 100.0])
    f.solve(nat.rope_lengths(a, ref.FIVE_TOPS, ref.FIVE_BOTTOMS), a)
    for k in range(1, 20):
        x = a + np.array([0.5 * k, -0.3 * k, 0.2 * k])
        pos = f.solve(nat.rope_lengths(x, ref.FIVE_TOPS, ref.FIVE_BOTTOMS))
        assert np.linalg.norm(pos - x) < 0.01
        assert f.iterations <= 3


def test_prepared_in_place_lengths_and_tops():
    """Lengths written into .lengths and tops moved in place are used by the next solve."""
    f = _finder()
    x = np.array([-30.0, 20.0, 200.0])
    moved_top = np.array([3.0, 48.0, 370.0])
    f.set_top(3, moved_top)
    f.tops[4] = [0.0, -45.0, 380.0]
    tops = ref.FIVE_TOPS.copy()
    tops[3], tops[4] = moved_top, [0.0, -45.0, 380.0]
    f.lengths[:] = nat.rope_lengths(x, tops, ref.FIVE_BOTTOMS)
    pos = f.solve(start=x + 5.0)
    assert np.linalg.norm(pos - x) < 0.01


def test_prepared_outputs_are_read_only_views():
    """position and residuals cannot be written by the caller."""
    f = _finder()
    with pytest.raises(ValueError):
        f.position[0] = 1.0
    with pytest.raises(ValueError):
        f.residuals[0] = 1.0


@pytest.mark.parametrize(
    "lengths",
    [
        [400.0] * 5,
        np.full(5, 400.0, dtype=np.float32),
        np.full(10, 400.0)[::2],
        np.full(4, 400.0),
        np.full((5, 1), 400.0),
    ],
    ids=["list", "float32", "strided", "short", "2d"],
)
def test_prepared_refuses_unconverted_lengths(lengths):
    """The per-poll path refuses lists, other dtypes, strided and mis-shaped arrays."""
    f = _finder()
    with pytest.raises(nat.NativeInputError):
        f.solve(lengths, np.array([0.0, 0.0, 100.0]))


def test_prepared_refuses_first_solve_without_start():
    """The first solve needs an explicit start."""
    with pytest.raises(nat.NativeInputError, match="start"):
        _finder().solve(np.full(5, 600.0))


def test_prepared_failure_changes_no_output():
    """A refused solve raises and leaves residuals, rms and the solution untouched."""
    f = _finder()
    x = np.array([10.0, 10.0, 100.0])
    f.solve(nat.rope_lengths(x, ref.FIVE_TOPS, ref.FIVE_BOTTOMS), x)
    before = (f.position.copy(), f.residuals.copy(), f.rms, f.iterations)
    bad = np.full(5, 600.0)
    bad[2] = np.nan
    with pytest.raises(nat.NonFiniteError, match="lengths"):
        f.solve(bad)
    np.testing.assert_array_equal(f.position, before[0])
    np.testing.assert_array_equal(f.residuals, before[1])
    assert (f.rms, f.iterations) == before[2:]


def test_set_top_refuses_bad_points():
    """set_top refuses an index out of range and a non-finite point."""
    f = _finder()
    with pytest.raises(nat.NativeInputError):
        f.set_top(5, [0.0, 0.0, 0.0])
    with pytest.raises(nat.NativeInputError):
        f.set_top(0, [0.0, NAN, 0.0])
    np.testing.assert_array_equal(f.tops, ref.FIVE_TOPS)


# ------------------------------------------------------------------ bad input

X0 = np.array([0.0, 0.0, 100.0])
L5 = nat.rope_lengths(X0, ref.FIVE_TOPS, ref.FIVE_BOTTOMS)


def _with(array, index, value):
    out = np.array(array, dtype=float)
    out[index] = value
    return out


BAD_INPUTS = [
    ("nan top", dict(tops=_with(ref.FIVE_TOPS, (1, 2), NAN)), nat.NonFiniteError),
    ("inf top", dict(tops=_with(ref.FIVE_TOPS, (0, 0), math.inf)), nat.NonFiniteError),
    ("inf bottom", dict(bottoms=_with(ref.FIVE_BOTTOMS, (2, 1), -math.inf)), nat.NonFiniteError),
    ("partly nan bottom", dict(bottoms=_with(ref.FIVE_BOTTOMS, (2, 1), NAN)),
     nat.NativeInputError),
    ("nan length", dict(lengths=_with(L5, 3, NAN)), nat.NonFiniteError),
    ("nan start", dict(start=_with(X0, 0, NAN)), nat.NonFiniteError),
    ("nan offset", dict(offsets=_with(np.zeros((5, 3)), (4, 0), NAN)), nat.NonFiniteError),
    ("no ropes", dict(tops=np.zeros((0, 3)), bottoms=np.zeros((0, 3)), lengths=[]),
     nat.NativeInputError),
    ("17 ropes", dict(tops=np.ones((17, 3)), bottoms=np.ones((17, 3)), lengths=np.ones(17)),
     nat.NativeInputError),
    ("short lengths", dict(lengths=L5[:4]), nat.NativeInputError),
    ("bottoms shape", dict(bottoms=ref.FIVE_BOTTOMS[:4]), nat.NativeInputError),
    ("tops 2 columns", dict(tops=ref.FIVE_TOPS[:, :2]), nat.NativeInputError),
    ("start shape", dict(start=[0.0, 100.0]), nat.NativeInputError),
    ("offsets shape", dict(offsets=np.zeros((5, 2))), nat.NativeInputError),
    ("string lengths", dict(lengths=["600"] * 5), nat.NativeInputError),
    ("complex start", dict(start=X0 + 0j), nat.NativeInputError),
    ("bool tops", dict(tops=np.ones((5, 3), dtype=bool)), nat.NativeInputError),
    ("ragged tops", dict(tops=[[0, 0, 1], [0, 1]]), nat.NativeInputError),
    ("zero tol", dict(tol=0.0), nat.NativeInputError),
    ("nan tol", dict(tol=NAN), nat.NativeInputError),
    ("zero max_iter", dict(max_iter=0), nat.NativeInputError),
    ("float max_iter", dict(max_iter=5.5), nat.NativeInputError),
    ("all frozen", dict(freeze=(1, 1, 1)), nat.NativeInputError),
    ("freeze shape", dict(freeze=(1, 0)), nat.NativeInputError),
]


@pytest.mark.parametrize(("kwargs", "error"), [b[1:] for b in BAD_INPUTS],
                         ids=[b[0] for b in BAD_INPUTS])
def test_bad_input_is_refused(kwargs, error):
    """Bad input raises a clear NativeError subclass and never returns a position."""
    args = dict(tops=ref.FIVE_TOPS, bottoms=ref.FIVE_BOTTOMS, lengths=L5, start=X0)
    args.update(kwargs)
    with pytest.raises(error) as info:
        nat.find_position(**args)
    assert isinstance(info.value, NativeError) and isinstance(info.value, PyrtError)
    assert str(info.value)


GEOMETRY_BAD = [
    (name, {k: v for k, v in kw.items() if k != "lengths"}, err)
    for name, kw, err in BAD_INPUTS
    if set(kw) - {"lengths"} and set(kw) - {"lengths"} <= {"tops", "bottoms", "offsets"}
]


@pytest.mark.parametrize(("kwargs", "error"), [b[1:] for b in GEOMETRY_BAD],
                         ids=[b[0] for b in GEOMETRY_BAD])
def test_bad_geometry_refused_by_rope_lengths(kwargs, error):
    """rope_lengths and rope_segments refuse the same bad geometry."""
    args = dict(tops=ref.FIVE_TOPS, bottoms=ref.FIVE_BOTTOMS, offsets=None)
    args.update(kwargs)
    with pytest.raises(error):
        nat.rope_lengths(X0, **args)
    with pytest.raises(error):
        nat.rope_segments(X0, **args)


def test_singular_when_ropes_do_not_fix_the_position():
    """Two ropes cannot fix three directions; one central rope cannot fix x."""
    with pytest.raises(nat.SingularError):
        nat.find_position(ref.FIVE_TOPS[:2], ref.FIVE_BOTTOMS[:2], L5[:2], X0, freeze=(0, 0, 0))
    with pytest.raises(nat.SingularError):
        nat.find_position([[0.0, 0.0, 400.0]], [[NAN] * 3], [300.0], [0.0, 0.0, 90.0],
                          freeze=(0, 1, 1))


def test_source_at_a_pulley_is_degenerate():
    """A source on a top pulley or bottom attachment has no rope direction."""
    with pytest.raises(nat.DegenerateGeometryError):
        nat.rope_lengths(ref.FIVE_TOPS[1], ref.FIVE_TOPS, ref.FIVE_BOTTOMS)
    with pytest.raises(nat.DegenerateGeometryError):
        nat.rope_lengths(ref.FIVE_BOTTOMS[3], ref.FIVE_TOPS, ref.FIVE_BOTTOMS)
    with pytest.raises(nat.DegenerateGeometryError):
        nat.find_position(ref.FIVE_TOPS, ref.FIVE_BOTTOMS, L5, ref.FIVE_BOTTOMS[1])


def test_no_convergence_within_iteration_limit():
    """One iteration from 20 cm off is not enough: NoConvergenceError."""
    with pytest.raises(nat.NoConvergenceError):
        nat.find_position(ref.FIVE_TOPS, ref.FIVE_BOTTOMS, L5, X0 + np.array([20.0, 0.0, 0.0]), max_iter=1)
    assert issubclass(nat.NoConvergenceError, nat.SolverError)
    assert issubclass(nat.SingularError, nat.SolverError)
