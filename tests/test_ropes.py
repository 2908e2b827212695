"""The rope model: the one stretch formula (Python and C agree), one Gauss-Newton, statelessness."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pyrt.db import copy_station
from pyrt.errors import NativeError
from pyrt.robots.ropes import RopeModel, corrected_length, gauss_newton, payout
from pyrt.station.manipulator import ManipulatorStation


@pytest.fixture(scope="module")
def sno(tmp_path_factory):
    station = ManipulatorStation(copy_station("sno", tmp_path_factory.mktemp("ropes") / "sno"),
                                 tick_ns=5_000_000)
    yield station
    station.close()


_tension = st.floats(-50.0, 400.0)
_raw = st.floats(50.0, 3000.0)


@settings(max_examples=60, deadline=None)
@given(data=st.data())
def test_python_and_c_stretch_formula_agree(sno, data):
    """The poll kernel's corrected lengths (csrc/polyctl.c) are ropes.corrected_length's, negative tensions read as none."""
    pa = sno.polyaxis
    tens = [data.draw(_tension) for _ in range(pa.n)]
    raw = [data.draw(_raw) for _ in range(pa.n)]
    lengths = [0.0] * pa.n
    try:
        pa._ctl.measure(tens, raw, lengths)
    except NativeError:
        pass  # lengths that fix no position: the lengths are filled in all the same
    finally:
        pa._ctl.set_position(pa.position)
    for i, a in enumerate(pa.axes):
        want = corrected_length(raw[i], tens[i], a.stretch, a.dead_length)
        assert lengths[i] == pytest.approx(want, rel=1e-13, abs=1e-9)


@given(_raw, _tension, st.floats(0.0, 1e-3), st.floats(0.0, 100.0))
def test_payout_inverts_corrected_length(raw, tension, stretch, dead):
    """payout is the unstretched rope that corrected_length turns into a given length."""
    length = corrected_length(raw, tension, stretch, dead)
    assert payout(length, tension, stretch, dead) == pytest.approx(raw, rel=1e-12)
    if tension <= 0.0:
        assert length == raw - dead


@given(st.lists(st.floats(-100.0, 100.0), min_size=3, max_size=3),
       st.sampled_from([[0, 1, 2], [0, 2], [1]]))
def test_gauss_newton_moves_only_the_free_directions(target, free):
    """On a linear residual the solver reaches the target in the free directions and leaves the others."""
    goal = np.array(target)

    def resid(x):
        return x - goal

    x, r = gauss_newton(resid, (1.0, 2.0, 3.0), free, iterations=50, tol=1e-9)
    for k in range(3):
        if k in free:
            assert x[k] == pytest.approx(goal[k], abs=1e-6)
        else:
            assert x[k] == (1.0, 2.0, 3.0)[k]
    assert np.allclose(r[free], 0.0, atol=1e-6)


def test_position_from_lengths_recovers_the_point_without_one_rope(sno):
    """Exact lengths at a point give the point back from every rope but any one (the survey's solve)."""
    model = sno.polyaxis.model
    x = (30.0, -20.0, 100.0)
    lengths = model.lengths_at(x)
    for bad in range(model.n):
        others = [k for k in range(model.n) if k != bad]
        got, rms = model.position_from_lengths((0.0, 0.0, 0.0), lengths, others)
        assert math.dist(got, x) < 1e-3 and rms < 1e-4


def test_position_from_tensions_balances_the_weight(sno):
    """The equilibrium tensions at a point put tensionFind's position back at that point."""
    model = sno.polyaxis.model
    x = (20.0, 10.0, -50.0)
    t, left = model.equilibrium_tensions(x)
    assert left < 1e-6
    got = model.position_from_tensions((0.0, 0.0, 0.0), t)
    assert math.dist(got, x) < 0.05
    f = model.net_force_at(got, t)
    assert math.hypot(*f) < 1e-2


def test_the_model_is_stateless(sno):
    """Every question leaves the model as it was (no state kept between calls)."""
    model = sno.polyaxis.model
    before = copy.deepcopy({k: v for k, v in vars(model).items()
                            if k not in ("av", "neck", "_geometry")})
    x = (10.0, 5.0, 20.0)
    model.lengths_at(x)
    model.equilibrium_tensions(x)
    model.target_refusal(x)
    model.position_from_tensions(x, [20.0] * model.n)
    after = {k: v for k, v in vars(model).items() if k not in ("av", "neck", "_geometry")}
    assert after == before
    assert model.target_refusal((0.0, 0.0, 5000.0)) == "(0, 0, 5000) is outside the vessel"


def test_a_limit_set_on_the_polyaxis_is_the_models(sno):
    """A limit changed on the PolyAxis while running is the one the rope model's checks use."""
    pa = sno.polyaxis
    saved = pa.max_tension
    try:
        x = (0.0, 0.0, 0.0)
        need = max(pa.model.equilibrium_tensions(x)[0])
        assert pa.model.target_refusal(x) is None
        pa.max_tension = need + pa.tension_margin - 1.0
        assert pa.model.max_tension == pa.max_tension
        assert "MAX_TENSION" in pa.model.target_refusal(x)
    finally:
        pa.max_tension = saved


def test_every_default_has_one_home():
    """The POLYAXIS fields are spelled once, by the record: neither the PolyAxis nor its
    rope model takes one as a keyword (the schema's defaults reach them through the
    record); Axis's stretch default is the schema's."""
    import inspect

    from pyrt.db import defaults
    from pyrt.robots.axis import Axis
    from pyrt.robots.polyaxis import PolyAxis

    schema = defaults("POLYAXIS")
    assert len(schema) >= 12
    for cls in (PolyAxis, RopeModel):
        params = inspect.signature(cls).parameters
        assert "record" in params
        assert not [k for k in schema if k in params and k != "av"], cls.__name__
    assert inspect.signature(Axis).parameters["stretch"].default == defaults("AXIS")["stretch"]
