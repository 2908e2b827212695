"""The fuzzy Axis controller (csrc/fuzzy.c through pyrt.native)."""

from __future__ import annotations

import dataclasses
import math

import _ref_findpos as geo
import _ref_fuzzy as ref
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import pyrt.native as nat
from pyrt.errors import NativeError
from pyrt.native._fuzzy import c_default_params

FI = nat.FuzzyInput
FIELDS = [f.name for f in dataclasses.fields(nat.FuzzyParams)]

# A quiet axis: tension at its target, no errors, nothing moving; every rule is silent.
QUIET = [30.0, 30.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 3.0, 100.0]


def _row(**changes: float) -> list[float]:
    row = list(QUIET)
    for name, value in changes.items():
        row[FI[name.upper()]] = value
    return row


# ----------------------------------------------------------- hypothesis: C == reference


def _shoulder(lo: float, hi: float):
    """(zero, full) with 0 <= zero < full."""
    return st.tuples(st.floats(lo, hi), st.floats(0.01, hi)).map(lambda t: (t[0], t[0] + t[1]))


@st.composite
def params_strategy(draw):
    low_full = draw(st.floats(0.0, 10.0))
    high_full = draw(st.floats(0.0, 10.0))
    values = {
        "low_t_full": low_full,
        "low_t_zero": low_full + draw(st.floats(0.01, 20.0)),
        "high_t_full": high_full,
        "high_t_zero": high_full + draw(st.floats(0.01, 30.0)),
        "near_end_relax": draw(st.floats(0.0, 1.0)),
        "dv_damping": draw(st.floats(0.0, 1.0)),
    }
    for zero, full, hi in (("len_zero", "len_full", 2.0), ("rel_zero", "rel_full", 5.0),
                           ("vel_zero", "vel_full", 7.0), ("len_rate_zero", "len_rate_full", 3.0),
                           ("t_rate_zero", "t_rate_full", 50.0), ("dv_zero", "dv_full", 0.5)):
        values[zero], values[full] = draw(_shoulder(0.0, hi))
    for name in ("dv_tension", "dv_length", "dv_rel_tension", "dv_velocity", "dv_len_rate",
                 "dv_t_rate"):
        values[name] = draw(st.floats(0.0, 1.0))
    return nat.FuzzyParams(**values)


@st.composite
def row_strategy(draw):
    t_low = draw(st.floats(0.0, 20.0))
    truth = st.one_of(st.just(0.0), st.just(1.0), st.floats(0.0, 1.0))
    return [
        draw(st.floats(-10.0, 150.0)),               # tension
        draw(st.floats(0.0, 60.0)),                  # desired tension
        draw(truth),                                 # free
        draw(st.floats(-20.0, 20.0)),                # length error
        draw(st.floats(-8.0, 8.0)),                  # velocity
        draw(st.floats(-5.0, 5.0)),                  # length error rate
        draw(st.floats(-100.0, 100.0)),              # tension error rate
        draw(st.floats(-1.0, 1.0)),                  # last dv
        draw(truth),                                 # near end
        t_low,
        t_low + draw(st.floats(0.5, 150.0)),         # tension high
    ]


@settings(max_examples=200, deadline=None)
@given(params=params_strategy(), rows=st.lists(row_strategy(), min_size=1, max_size=16))
def test_c_equals_reference_shared_params(params, rows):
    """C dv and rule outputs equal the pure-Python reference to 1e-12 (shared parameters)."""
    dv, rules = nat.fuzzy_step(params, rows)
    ref_dv, ref_rules = ref.fuzzy_step(params, rows)
    np.testing.assert_allclose(dv, ref_dv, rtol=0, atol=1e-12)
    np.testing.assert_allclose(rules, ref_rules, rtol=0, atol=1e-12)
    np.testing.assert_allclose(dv, rules.sum(axis=1), rtol=0, atol=1e-12)


@settings(max_examples=40, deadline=None)
@given(data=st.data(), n=st.integers(1, 16))
def test_c_equals_reference_per_axis_params(data, n):
    """One parameter set per axis, through the prepared batch, equals the reference to 1e-12."""
    params = [data.draw(params_strategy()) for _ in range(n)]
    rows = [data.draw(row_strategy()) for _ in range(n)]
    batch = nat.FuzzyBatch(params, n)
    batch.inputs[:] = rows
    dv = batch.step()
    ref_dv, ref_rules = ref.fuzzy_step(params, rows)
    np.testing.assert_allclose(dv, ref_dv, rtol=0, atol=1e-12)
    np.testing.assert_allclose(batch.rules, ref_rules, rtol=0, atol=1e-12)
    one_dv, one_rules = nat.fuzzy_step(params, rows)
    np.testing.assert_array_equal(one_dv, dv)
    np.testing.assert_array_equal(one_rules, batch.rules)


# ---------------------------------------------------------------- the rules themselves

RULE_CASES = [
    ("quiet axis", {}, {}),
    ("tension at low bound", {"tension": 3.5, "desired_tension": 3.5}, {0: -0.4}),
    ("tension low, half way", {"tension": 6.0, "desired_tension": 6.0}, {0: -0.2}),
    ("tension at high bound", {"tension": 99.0, "desired_tension": 99.0}, {1: 0.4}),
    ("rope short", {"length_error": -2.0}, {2: 0.1}),
    ("rope long", {"length_error": 0.5}, {3: -0.05}),
    ("tension below target", {"desired_tension": 40.0}, {4: -0.2}),
    ("below target near end", {"desired_tension": 40.0, "near_end": 1.0}, {4: -0.05}),
    ("below target, free rope", {"desired_tension": 40.0, "free": 1.0}, {}),
    ("tension above target", {"desired_tension": 27.25}, {5: 0.1}),
    ("inside the dead band", {"desired_tension": 30.4}, {}),
    ("fast paying out", {"velocity": 6.0}, {6: -0.15}),
    ("fast hauling in", {"velocity": -8.0}, {6: 0.3}),
    ("length error growing", {"length_error_rate": 1.0}, {7: -0.125}),
    ("tension error falling", {"tension_error_rate": -40.0}, {8: -0.25}),
    ("tension error rate, free rope", {"tension_error_rate": -40.0, "free": 1.0}, {}),
    ("last dv high", {"last_dv": 0.3}, {9: -0.075}),
    ("last dv small", {"last_dv": -0.05}, {}),
]


@pytest.mark.parametrize(("changes", "expected"), [c[1:] for c in RULE_CASES],
                         ids=[c[0] for c in RULE_CASES])
def test_default_rules(changes, expected):
    """Each rule fires with the documented sign and size under the default sets."""
    dv, rules = nat.fuzzy_step(nat.FuzzyParams(), [_row(**changes)])
    want = np.zeros(10)
    for k, v in expected.items():
        want[k] = v
    np.testing.assert_allclose(rules[0], want, rtol=0, atol=1e-15)
    assert dv[0] == pytest.approx(want.sum(), abs=1e-15)


def test_rule_and_input_columns():
    """FuzzyRule names the ten output columns and FuzzyInput the eleven input columns."""
    assert [r.value for r in nat.FuzzyRule] == list(range(10))
    assert [c.value for c in FI] == list(range(11))
    assert nat.FuzzyBatch.MAX_AXES == 16 == nat.PositionFinder.MAX_ROPES
    assert nat.FuzzyParams.REFERENCE_POLL_S == 0.05


def test_defaults_equal_c_defaults():
    """FuzzyParams' fields and defaults are exactly pyrt_fuzzy_default_params, in order."""
    c = c_default_params()
    assert list(c) == FIELDS
    assert dataclasses.asdict(nat.FuzzyParams()) == c


# ------------------------------------------------------------------------ parameters


def test_from_mapping_overrides_case_insensitively():
    """Database-style overrides replace named fields and keep the rest."""
    p = nat.FuzzyParams.from_mapping({"DV_LENGTH": "0.2", "rel_full": 4})
    assert p.dv_length == 0.2 and p.rel_full == 4.0
    assert p.dv_tension == nat.FuzzyParams().dv_tension
    assert p.replace(dv_tension=0.3).dv_tension == 0.3


@pytest.mark.parametrize(
    "values",
    [{"dv_lenght": 0.1}, {"dv_length": "fast"}, {"len_full": 0.0}, {"low_t_zero": 0.5},
     {"dv_tension": -0.4}, {"near_end_relax": 1.5}, {"dv_damping": math.nan},
     {"vel_full": math.inf}],
    ids=["unknown key", "not a number", "empty set", "crossed guard", "negative change",
         "relax over 1", "nan", "inf"],
)
def test_bad_parameters_are_refused(values):
    """An unknown key, a non-number or inconsistent breakpoints raise NativeError."""
    with pytest.raises(NativeError):
        nat.FuzzyParams.from_mapping(values)


def test_params_copy_and_pickle_by_value():
    """FuzzyParams survive copy and pickle with equal values and a working C struct."""
    import copy
    import pickle

    p = nat.FuzzyParams(dv_length=0.15)
    for q in (copy.copy(p), copy.deepcopy(p), pickle.loads(pickle.dumps(p))):
        assert q == p
        np.testing.assert_array_equal(nat.fuzzy_step(q, [QUIET])[0], nat.fuzzy_step(p, [QUIET])[0])


def test_constructor_refuses_non_numbers():
    """FuzzyParams refuses strings and booleans for its fields."""
    with pytest.raises(nat.NativeInputError):
        nat.FuzzyParams(dv_length="0.1")  # type: ignore[arg-type]
    with pytest.raises(nat.NativeInputError):
        nat.FuzzyParams(dv_length=True)


def test_for_poll_period_scales_per_poll_changes():
    """A 20 ms poll gets 0.4 of every per-poll velocity change; rates and fractions stay."""
    base = nat.FuzzyParams()
    fast = base.for_poll_period(0.02)
    assert fast.dv_tension == pytest.approx(0.4 * base.dv_tension)
    assert fast.dv_full == pytest.approx(0.4 * base.dv_full)
    assert fast.len_rate_full == base.len_rate_full and fast.dv_damping == base.dv_damping
    with pytest.raises(nat.NativeInputError):
        base.for_poll_period(0.0)


# ------------------------------------------------------------------------- bad input

BAD_ROWS = [
    ("nan tension", _row(tension=math.nan), nat.NonFiniteError),
    ("inf length error", _row(length_error=math.inf), nat.NonFiniteError),
    ("free above 1", _row(free=1.5), nat.NativeInputError),
    ("near end negative", _row(near_end=-0.1), nat.NativeInputError),
    ("bounds crossed", _row(tension_low=50.0, tension_high=50.0), nat.NativeInputError),
]


@pytest.mark.parametrize(("row", "error"), [b[1:] for b in BAD_ROWS], ids=[b[0] for b in BAD_ROWS])
def test_bad_rows_are_refused(row, error):
    """A bad input row raises, naming the axis, in both the one-shot and the batch form."""
    rows = [QUIET, row]
    with pytest.raises(error, match="axis 1"):
        nat.fuzzy_step(nat.FuzzyParams(), rows)
    batch = nat.FuzzyBatch(nat.FuzzyParams(), 2)
    batch.inputs[:] = [QUIET, _row(length_error=1.0)]
    batch.step()
    before = (batch.dv.copy(), batch.rules.copy())
    batch.inputs[:] = rows
    with pytest.raises(error):
        batch.step()
    np.testing.assert_array_equal(batch.dv, before[0])
    np.testing.assert_array_equal(batch.rules, before[1])


@pytest.mark.parametrize(
    ("params", "inputs"),
    [
        (nat.FuzzyParams(), np.zeros((0, 11))),
        (nat.FuzzyParams(), [QUIET] * 17),
        (nat.FuzzyParams(), np.zeros((2, 10))),
        (nat.FuzzyParams(), np.zeros((2, 11, 1))),
        (nat.FuzzyParams(), [["a"] * 11]),
        (nat.FuzzyParams(), np.array([QUIET], dtype=complex)),
        ([nat.FuzzyParams()] * 3, [QUIET] * 2),
        ({"dv_length": 0.1}, [QUIET]),
        ([nat.FuzzyParams(), "x"], [QUIET] * 2),
    ],
    ids=["no axes", "17 axes", "10 columns", "3-d", "strings", "complex", "params count",
         "params mapping", "params item"],
)
def test_bad_shapes_and_types_are_refused(params, inputs):
    """Wrong sizes, shapes, dtypes or parameter lists raise NativeInputError."""
    with pytest.raises(nat.NativeInputError):
        nat.fuzzy_step(params, inputs)


def test_one_row_is_one_axis():
    """A single 11-value row is evaluated as one axis."""
    dv, rules = nat.fuzzy_step(nat.FuzzyParams(), _row(length_error=2.0))
    assert dv.shape == (1,) and rules.shape == (1, 10)
    assert dv[0] == pytest.approx(-0.1)


def test_batch_refuses_bad_construction_and_params():
    """FuzzyBatch checks its size and parameters; set_params changes one axis."""
    for n in (0, 17, 2.0, True):
        with pytest.raises(nat.NativeInputError):
            nat.FuzzyBatch(nat.FuzzyParams(), n)
    batch = nat.FuzzyBatch(nat.FuzzyParams(), 3)
    batch.inputs[:] = [_row(length_error=2.0)] * 3
    batch.set_params(1, nat.FuzzyParams(dv_length=0.2))
    np.testing.assert_allclose(batch.step(), [-0.1, -0.2, -0.1])
    assert batch.params[1].dv_length == 0.2 and batch.params[0] == nat.FuzzyParams()
    batch.set_params(1, nat.FuzzyParams())
    np.testing.assert_allclose(batch.step(), [-0.1, -0.1, -0.1])
    with pytest.raises(nat.NativeInputError):
        batch.set_params(3, nat.FuzzyParams())
    with pytest.raises(ValueError):
        batch.dv[0] = 1.0


# ------------------------------------------------------------- the controller works


def _closed_loop(target, poll=0.05, t_end=250.0, compliance=2e-5, t_low=3.0):
    """The prototype (Table 3 + mirror rope, 5.3357 kg source) under the default rules.

    Each poll: lengths from the source position (a perfect stretch-corrected
    encoder), position by the prepared finder, corrected-length errors against
    a hare moving at up to 2 cm/s with 20 cm ramps, the off-side rope driven
    toward 10 N and the others free, one batched fuzzy step, DV_LIMIT and the
    7 cm/s speed limit at the motor, then the statics plant.
    Returns (final in-plane error, lowest tension, highest tension).
    """
    tops, bottoms = geo.PROTO_TOPS, geo.PROTO_BOTTOMS
    weight = 5.3357 * 9.81
    dead = np.full(3, 453.0)
    x0 = np.array([-0.199943, 0.0, 95.569618419])
    # Payouts that hold the start with the off-side rope at 10 N.
    seg = nat.rope_segments(x0, tops, bottoms)
    a = seg.top_dir + seg.bottom_dir
    tension = np.array([0.0, 0.0, 10.0])
    tension[:2] = np.linalg.lstsq(a[:2].T, [0.0, 0.0, weight] - a[2] * 10.0, rcond=None)[0]
    payout = (dead + seg.total) / (1.0 + tension * compliance)
    plant = nat.StaticsSolver(tops.tolist(), [None, bottoms[1].tolist(), bottoms[2].tolist()],
                              None, dead.tolist(), [compliance] * 3, payout.tolist(),
                              weight=weight, position=x0.tolist(), max_iter=200)
    plant.solve()
    finder = nat.PositionFinder(tops, bottoms)
    finder.solve(nat.rope_lengths(plant.position, tops, bottoms), np.array(plant.position))
    batch = nat.FuzzyBatch(nat.FuzzyParams().for_poll_period(poll), 3)
    inp = batch.inputs
    inp[:, FI.TENSION_LOW], inp[:, FI.TENSION_HIGH] = t_low, 100.0
    v = np.zeros(3)
    start = finder.position.copy()
    goal = np.asarray(target, float)
    dist = np.linalg.norm(goal - start)
    s, prev_e, prev_te = 0.0, None, None
    lowest, highest = math.inf, -math.inf
    for _ in range(int(t_end / poll)):
        if s < dist:
            s = min(dist, s + 2.0 * min(1.0, max(0.05, min(s, dist - s) / 20.0)) * poll)
        hare = start + (goal - start) * (s / dist)
        measured = nat.rope_lengths(plant.position, tops, bottoms)
        est = finder.solve(measured)
        e = (measured - finder.residuals) - nat.rope_lengths(hare, tops, bottoms)
        tens = np.array(plant.tensions())
        off = np.array([False, bottoms[1, 0] * est[0] < 0, bottoms[2, 0] * est[0] < 0])
        te = np.where(off, tens - 10.0, 0.0)
        inp[:, FI.TENSION] = tens
        inp[:, FI.DESIRED_TENSION] = np.where(off, 10.0, 0.0)
        inp[:, FI.FREE] = np.where(off, 0.0, 1.0)
        inp[:, FI.LENGTH_ERROR] = e
        inp[:, FI.VELOCITY] = v
        inp[:, FI.LENGTH_ERROR_RATE] = 0.0 if prev_e is None else (e - prev_e) / poll
        inp[:, FI.TENSION_ERROR_RATE] = 0.0 if prev_te is None else (te - prev_te) / poll
        inp[:, FI.NEAR_END] = min(1.0, max(0.0, 1.0 - np.linalg.norm(goal - est) / 10.0))
        prev_e, prev_te = e, te
        dv = np.clip(batch.step(), -0.5, 0.5)
        inp[:, FI.LAST_DV] = dv
        v = np.clip(v + dv, -7.0, 7.0)
        for i in range(3):
            plant.set_payout(i, plant.payout(i) + v[i] * poll)
        plant.solve()
        tens = plant.tensions()
        lowest, highest = min(lowest, *tens), max(highest, *tens)
        err = math.hypot(plant.position[0] - goal[0], plant.position[2] - goal[2])
        if s >= dist and err < 0.1 and np.abs(v).max() < 0.07:
            break
    return err, lowest, highest


@pytest.mark.parametrize("target", [(100.0, 0.0, 150.0), (-250.0, 0.0, 100.0), (0.0, 0.0, 300.0)])
def test_default_rules_bring_the_prototype_source_to_target(target):
    """On the prototype statics the default rules end within 0.1 cm, tensions kept in 8-60 N."""
    err, lowest, highest = _closed_loop(target)
    assert err < 0.1
    assert lowest > 8.0 and highest < 60.0


@pytest.mark.parametrize(("poll", "compliance"), [(0.02, 2e-5), (0.05, 5e-6), (0.05, 1e-4)],
                         ids=["20ms-poll", "stiff-rope", "soft-rope"])
def test_default_rules_are_robust(poll, compliance):
    """The defaults (rescaled for the poll) still end within 0.1 cm on other polls and ropes."""
    err, lowest, highest = _closed_loop((-250.0, 0.0, 100.0), poll=poll, compliance=compliance)
    assert err < 0.1
    assert lowest > 7.0 and highest < 60.0


def test_guards_hold_off_a_target_that_needs_a_slack_rope():
    """A target needing a negative central tension is not forced: no rope falls below 5 N."""
    err, lowest, _ = _closed_loop((150.0, 0.0, -150.0), t_end=150.0)
    assert err > 1.0
    assert lowest > 5.0
