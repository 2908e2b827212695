"""C kernels against their references and the usual Python libraries.

Run: ``python -m pytest bench/bench_native.py --benchmark-only`` (add ``-s``
for the ratio summary against the targets, printed at the end).

* fuzzy: the ten Axis rules for one axis and for a 5-axis PolyAxis in one
  call -- prepared C batch, one-shot C ``fuzzy_step``, the pure-Python
  reference (tests/_ref_fuzzy.py), and scikit-fuzzy's
  ``ControlSystemSimulation`` on an equivalent ten-rule base.
* findpos: the same 3-rope (Table 3 prototype) and 5-rope problems for the
  prepared C ``PositionFinder``, one-shot ``find_position``, the numpy
  reference (tests/_ref_findpos.py) and ``scipy.optimize.least_squares``
  (method 'lm') with and without the analytic Jacobian.
* neck: one rope's contact with the SNO neck ring (csrc/neck.c through
  ``NeckRing.contact``, from the crossing and from last time's angle) and
  the pure-Python reference of the same model (tests/_ref_polyctl.py).

A comparator whose package is missing is skipped, not failed.
"""

from __future__ import annotations

import importlib.util
import itertools

import _ref_findpos as geo
import _ref_fuzzy as ref
import _ref_polyctl
import numpy as np
import pytest

import pyrt.native as nat

HAVE_SCIPY = importlib.util.find_spec("scipy") is not None
HAVE_SKFUZZY = importlib.util.find_spec("skfuzzy") is not None

# ------------------------------------------------------------------------ fuzzy

FI = nat.FuzzyInput
# Five axes in mid-move: errors and rates spread over the sets' slopes.
ROWS = np.array([
    [31.0, 0.0, 1.0, 0.35, 1.8, 0.4, 3.0, 0.12, 0.0, 3.0, 100.0],
    [12.5, 10.0, 0.0, -0.2, -1.1, -0.3, -8.0, -0.05, 0.0, 3.0, 100.0],
    [6.2, 10.0, 0.0, 0.8, 0.6, 1.2, 25.0, 0.3, 0.2, 3.0, 100.0],
    [44.0, 0.0, 1.0, -1.4, 5.6, -2.5, 0.0, -0.2, 0.0, 3.0, 100.0],
    [90.0, 0.0, 1.0, 0.05, -0.3, 0.02, -1.0, 0.01, 0.9, 3.0, 100.0],
])
PARAMS = nat.FuzzyParams()


@pytest.mark.benchmark(group="fuzzy 1 axis")
def test_fuzzy1_c_batch(benchmark, record):
    """Prepared C batch of one axis: one step per call."""
    batch = nat.FuzzyBatch(PARAMS, 1)
    batch.inputs[:] = ROWS[:1]
    benchmark.extra_info.update(axes=1, impl="c-batch")
    benchmark(batch.step)
    record(benchmark)


@pytest.mark.benchmark(group="fuzzy 1 axis")
def test_fuzzy1_c_oneshot(benchmark, record):
    """One-shot C fuzzy_step of one axis (converts its arguments every call)."""
    benchmark.extra_info.update(axes=1, impl="c-oneshot")
    benchmark(nat.fuzzy_step, PARAMS, ROWS[:1])
    record(benchmark)


@pytest.mark.benchmark(group="fuzzy 1 axis")
def test_fuzzy1_python(benchmark, record):
    """Pure-Python reference, one axis."""
    row = ROWS[0].tolist()
    benchmark.extra_info.update(axes=1, impl="python")
    benchmark(ref.axis_rules, PARAMS, row)
    record(benchmark)


@pytest.mark.benchmark(group="fuzzy 5 axes")
def test_fuzzy5_c_batch(benchmark, record):
    """Prepared C batch of five axes: one C call per PolyAxis poll."""
    batch = nat.FuzzyBatch(PARAMS, 5)
    batch.inputs[:] = ROWS
    benchmark.extra_info.update(axes=5, impl="c-batch")
    benchmark(batch.step)
    record(benchmark)


@pytest.mark.benchmark(group="fuzzy 5 axes")
def test_fuzzy5_c_oneshot(benchmark, record):
    """One-shot C fuzzy_step of five axes."""
    benchmark.extra_info.update(axes=5, impl="c-oneshot")
    benchmark(nat.fuzzy_step, PARAMS, ROWS)
    record(benchmark)


@pytest.mark.benchmark(group="fuzzy 5 axes")
def test_fuzzy5_python(benchmark, record):
    """Pure-Python reference, five axes."""
    rows = ROWS.tolist()
    benchmark.extra_info.update(axes=5, impl="python")
    benchmark(ref.fuzzy_step, PARAMS, rows)
    record(benchmark)


def _skfuzzy_controller():
    """An equivalent ten-rule base in scikit-fuzzy (Mamdani, centroid).

    Same inputs and sets as the defaults (shoulders as trapezoids, the signed
    "high" sets on magnitudes), same ten rules; the consequents are narrow
    triangles at the rules' velocity changes.
    """
    import skfuzzy as fuzz
    from skfuzzy import control as ctrl

    p = PARAMS

    def ante(name, lo, hi, step):
        return ctrl.Antecedent(np.arange(lo, hi + step, step), name)

    tension = ante("tension", 0.0, 120.0, 0.5)
    rel = ante("rel_tension", -30.0, 30.0, 0.1)
    length = ante("length_error", -5.0, 5.0, 0.01)
    near = ante("near_end", 0.0, 1.0, 0.01)
    vel = ante("speed", 0.0, 8.0, 0.05)
    elv = ante("length_rate", 0.0, 5.0, 0.02)
    etv = ante("tension_rate", 0.0, 100.0, 0.5)
    last = ante("last_dv", 0.0, 1.0, 0.01)
    dv = ctrl.Consequent(np.arange(-0.6, 0.6001, 0.005), "dv")
    lo, hi = 3.0, 100.0
    tension["low"] = fuzz.trapmf(tension.universe, [0, 0, lo + p.low_t_full, lo + p.low_t_zero])
    tension["high"] = fuzz.trapmf(tension.universe,
                                  [hi - p.high_t_zero, hi - p.high_t_full, 120, 120])
    rel["low"] = fuzz.trapmf(rel.universe, [-30, -30, -p.rel_full, -p.rel_zero])
    rel["high"] = fuzz.trapmf(rel.universe, [p.rel_zero, p.rel_full, 30, 30])
    length["short"] = fuzz.trapmf(length.universe, [-5, -5, -p.len_full, -p.len_zero])
    length["long"] = fuzz.trapmf(length.universe, [p.len_zero, p.len_full, 5, 5])
    near["near"] = fuzz.trapmf(near.universe, [0, 1, 1, 1])
    vel["high"] = fuzz.trapmf(vel.universe, [p.vel_zero, p.vel_full, 8, 8])
    elv["high"] = fuzz.trapmf(elv.universe, [p.len_rate_zero, p.len_rate_full, 5, 5])
    etv["high"] = fuzz.trapmf(etv.universe, [p.t_rate_zero, p.t_rate_full, 100, 100])
    last["high"] = fuzz.trapmf(last.universe, [p.dv_zero, p.dv_full, 1, 1])
    for name, centre in (("inc_tension", -p.dv_tension), ("dec_tension", p.dv_tension),
                         ("lengthen", p.dv_length), ("shorten", -p.dv_length),
                         ("inc_rel", -p.dv_rel_tension), ("dec_rel", p.dv_rel_tension),
                         ("slow", -p.dv_velocity), ("damp_length", -p.dv_len_rate),
                         ("damp_tension", p.dv_t_rate), ("damp_dv", -0.1)):
        dv[name] = fuzz.trimf(dv.universe, [centre - 0.05, centre, centre + 0.05])
    rules = [
        ctrl.Rule(tension["low"], dv["inc_tension"]),
        ctrl.Rule(tension["high"], dv["dec_tension"]),
        ctrl.Rule(length["short"], dv["lengthen"]),
        ctrl.Rule(length["long"], dv["shorten"]),
        ctrl.Rule(~near["near"] & rel["low"], dv["inc_rel"]),
        ctrl.Rule(~near["near"] & rel["high"], dv["dec_rel"]),
        ctrl.Rule(vel["high"], dv["slow"]),
        ctrl.Rule(elv["high"], dv["damp_length"]),
        ctrl.Rule(etv["high"], dv["damp_tension"]),
        ctrl.Rule(last["high"], dv["damp_dv"]),
    ]
    return ctrl.ControlSystemSimulation(ctrl.ControlSystem(rules))


def _skfuzzy_inputs(row):
    return {
        "tension": row[FI.TENSION],
        "rel_tension": (row[FI.TENSION] - row[FI.DESIRED_TENSION]) * (1.0 - row[FI.FREE]),
        "length_error": row[FI.LENGTH_ERROR],
        "near_end": row[FI.NEAR_END],
        "speed": abs(row[FI.VELOCITY]),
        "length_rate": abs(row[FI.LENGTH_ERROR_RATE]),
        "tension_rate": abs(row[FI.TENSION_ERROR_RATE]),
        "last_dv": abs(row[FI.LAST_DV]),
    }


@pytest.mark.benchmark(group="fuzzy 1 axis")
@pytest.mark.skipif(not HAVE_SKFUZZY, reason="scikit-fuzzy is not installed")
def test_fuzzy1_skfuzzy(benchmark, record):
    """scikit-fuzzy ControlSystemSimulation, one axis."""
    sim = _skfuzzy_controller()
    inputs = _skfuzzy_inputs(ROWS[0])

    def step():
        sim.inputs(inputs)
        sim.compute()
        return sim.output["dv"]

    benchmark.extra_info.update(axes=1, impl="skfuzzy")
    benchmark.pedantic(step, rounds=30, warmup_rounds=2)
    record(benchmark)


@pytest.mark.benchmark(group="fuzzy 5 axes")
@pytest.mark.skipif(not HAVE_SKFUZZY, reason="scikit-fuzzy is not installed")
def test_fuzzy5_skfuzzy(benchmark, record):
    """scikit-fuzzy ControlSystemSimulation, five axes one after another."""
    sim = _skfuzzy_controller()
    inputs = [_skfuzzy_inputs(row) for row in ROWS]

    def step():
        out = []
        for values in inputs:
            sim.inputs(values)
            sim.compute()
            out.append(sim.output["dv"])
        return out

    benchmark.extra_info.update(axes=5, impl="skfuzzy")
    benchmark.pedantic(step, rounds=10, warmup_rounds=1)
    record(benchmark)


# ---------------------------------------------------------------------- findpos

TRUTH = np.array([62.0, 0.0, 131.0])
PROBLEMS = {}
for _name, _tops, _bottoms, _free in (
    ("3 ropes", geo.PROTO_TOPS, geo.PROTO_BOTTOMS, [0, 2]),
    ("5 ropes", geo.FIVE_TOPS, geo.FIVE_BOTTOMS, [0, 1, 2]),
):
    _truth = TRUTH if _name == "3 ropes" else TRUTH + np.array([0.0, -35.0, 0.0])
    _noise = np.random.default_rng(7).normal(0.0, 0.1, len(_tops))
    # A control poll: the source moved about 1.5 cm since the last solution.
    _start = _truth + (np.array([1.0, 0.0, -0.9]) if _name == "3 ropes"
                       else np.array([1.0, 0.6, -0.9]))
    PROBLEMS[_name] = (_tops, _bottoms, nat.rope_lengths(_truth, _tops, _bottoms) + _noise,
                       _start, _free)
ROPES = sorted(PROBLEMS)


@pytest.mark.benchmark(group="findpos")
@pytest.mark.parametrize("ropes", ROPES)
def test_findpos_c_prepared(benchmark, ropes, record):
    """Prepared PositionFinder.solve(lengths, start): the per-poll path."""
    tops, bottoms, lengths, start, _ = PROBLEMS[ropes]
    finder = nat.PositionFinder(tops, bottoms)
    benchmark.extra_info.update(ropes=ropes, impl="c-prepared")
    benchmark(finder.solve, lengths, start)
    record(benchmark)
    benchmark.extra_info["iterations"] = finder.iterations


@pytest.mark.benchmark(group="findpos")
@pytest.mark.parametrize("ropes", ROPES)
def test_findpos_c_poll(benchmark, ropes, record):
    """Prepared PositionFinder.solve(lengths) from the last solution, as a control poll
    does: the lengths alternate between two positions about 1.5 cm apart."""
    tops, bottoms, lengths, start, _ = PROBLEMS[ropes]
    finder = nat.PositionFinder(tops, bottoms)
    finder.solve(lengths, start)
    moved = nat.rope_lengths(2.0 * finder.position - start, tops, bottoms)
    nxt = itertools.cycle([moved, lengths]).__next__
    benchmark.extra_info.update(ropes=ropes, impl="c-poll")
    benchmark(lambda: finder.solve(nxt()))
    record(benchmark)
    benchmark.extra_info["iterations"] = finder.iterations


@pytest.mark.benchmark(group="findpos")
@pytest.mark.parametrize("ropes", ROPES)
def test_findpos_c_oneshot(benchmark, ropes, record):
    """One-shot find_position (converts and checks its arguments every call)."""
    tops, bottoms, lengths, start, _ = PROBLEMS[ropes]
    benchmark.extra_info.update(ropes=ropes, impl="c-oneshot")
    benchmark(nat.find_position, tops, bottoms, lengths, start)
    record(benchmark)


@pytest.mark.benchmark(group="findpos")
@pytest.mark.parametrize("ropes", ROPES)
def test_findpos_numpy(benchmark, ropes, record):
    """numpy reference of the same iterated-linear method."""
    tops, bottoms, lengths, start, _ = PROBLEMS[ropes]
    benchmark.extra_info.update(ropes=ropes, impl="numpy")
    x = benchmark(geo.find_position, tops, bottoms, lengths, start)[0]
    record(benchmark)
    c = nat.find_position(tops, bottoms, lengths, start).position
    assert np.allclose(x, c, atol=1e-9)


@pytest.mark.benchmark(group="findpos")
@pytest.mark.skipif(not HAVE_SCIPY, reason="scipy is not installed")
@pytest.mark.parametrize("jacobian", [True, False], ids=["jac", "no-jac"])
@pytest.mark.parametrize("ropes", ROPES)
def test_findpos_least_squares(benchmark, ropes, jacobian, record):
    """scipy.optimize.least_squares(method='lm') on the same residuals and free directions."""
    from scipy.optimize import least_squares

    tops, bottoms, lengths, start, free = PROBLEMS[ropes]
    base = start.copy()

    def full(q):
        x = base.copy()
        x[free] = q
        return x

    def fun(q):
        return lengths - geo.rope_lengths(full(q), tops, bottoms)

    def jac(q):
        return geo.segments(full(q), tops, bottoms)[1][:, free]

    kw = {"jac": jac} if jacobian else {}
    benchmark.extra_info.update(ropes=ropes, impl=f"least_squares-lm{'-jac' if jacobian else ''}")
    sol = benchmark(least_squares, fun, start[free], method="lm", **kw)
    record(benchmark)
    c = nat.find_position(tops, bottoms, lengths, start).position
    # Equal accuracy: both land on the same least-squares minimum.
    assert np.allclose(full(sol.x), c, atol=1e-3)


# ------------------------------------------------------------------------- neck

NECK = nat.NeckRing((0.0, 0.0, 595.8), (0.0, 0.0, 1.0), 72.5)
NECK_FRAME = (*NECK.centre, *NECK.axis, *NECK.e1, *NECK.e2, NECK.radius)
NECK_TOP, NECK_CARRIAGE = (60.0, 0.0, 1299.0), (400.0, 30.0, 100.0)


@pytest.mark.benchmark(group="neck contact")
@pytest.mark.parametrize("impl", ["c", "c-hint", "python"])
def test_neck_contact(benchmark, impl):
    """One rope bearing on the ring: the rim point by Newton on the rim angle."""
    phi = NECK.contact(NECK_TOP, NECK_CARRIAGE)[1]
    if impl == "python":
        benchmark(_ref_polyctl.contact, NECK_FRAME, NECK_TOP, NECK_CARRIAGE)
    else:
        benchmark(NECK.contact, NECK_TOP, NECK_CARRIAGE, phi if impl == "c-hint" else None)
