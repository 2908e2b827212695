"""pyrt urdf's simulated arm as its station steps it: advance_to and the step with new DACs."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pyrt.native import NativeInputError, NonFiniteError
from pyrt.sim.arm import PUMA560_MOTORS, ArmWorld
from pyrt.station.urdf import load_arm

CHAIN, MOTORS, _TEXT = load_arm(None)
START = np.radians([10.0, 45.0, -120.0, 20.0, 40.0, 30.0])


def _world() -> ArmWorld:
    w = ArmWorld(CHAIN, motors=PUMA560_MOTORS, q0=START, seed=7, table_z=0.2)
    for j in range(6):
        w.board.write("enable", 1, j)
        w.board.write("release", 1, j)
    return w


def _state(w: ArmWorld) -> tuple:
    k = w._k
    return (k.q.tolist(), k.qd.tolist(), k.count.tolist(), k.ft.tolist(), k.dac.tolist(),
            k.rng_state, w.board.values("count"), w.board.values("ft"), w.time)


dacs = st.lists(st.integers(-32767, 32767), min_size=6, max_size=6)


@settings(max_examples=30, deadline=None)
@given(st.lists(st.tuples(dacs, st.sampled_from([1, 2, 3]), st.booleans()), min_size=1,
                max_size=15))
def test_advance_to_is_step_by_the_time_that_passed(moves):
    """advance_to(now_ns) on one world and step(dt) on its twin, the DACs written alike
    (changed or held): the same state, registers, generator and time, bit for bit; the
    first call and a time not after the last step nothing."""
    a, b = _world(), _world()
    a.advance_to(5_000_000)  # the first: no step
    assert _state(a) == _state(b)
    now = 5_000_000
    for dac, ms, hold in moves:
        if not hold:
            for j, v in enumerate(dac):
                a.board.write("dac", v, j)
                b.board.write("dac", v, j)
        now += ms * 1_000_000
        a.advance_to(now)
        b.step(ms * 1e-3)
        assert _state(a) == _state(b)
    a.advance_to(now)
    a.advance_to(now - 1)
    assert _state(a) == _state(b)


@settings(max_examples=30, deadline=None)
@given(dacs, st.sampled_from([1e-4, 1e-3, 2.5e-3]))
def test_the_step_with_new_dacs_is_set_dac_then_step(dac, dt):
    """ArmKernel.step_dac(dt, dac) is set_dac(dac) then step(dt) (csrc/armworld.c's
    pyrt_arm_step_dac against the kernel's own two calls), bit for bit."""
    a, b = _world()._k, _world()._k
    for k in (a, b):
        k.set_enable([1] * 6)
    a.step_dac(dt, dac)
    b.set_dac(dac)
    b.step(dt)
    for name in ("q", "qd", "count", "ft", "dac", "torque", "current", "wrench", "contact"):
        assert getattr(a, name).tolist() == getattr(b, name).tolist(), name
    assert a.rng_state == b.rng_state


@pytest.mark.parametrize(("dt", "dac", "error"), [
    (math.nan, [1] * 6, NonFiniteError), (-1e-3, [1] * 6, NativeInputError),
    (1e-3, [1] * 5, NativeInputError), (1e-3, [2**40] * 6, NativeInputError),
])
def test_a_refused_step_with_new_dacs_changes_nothing(dt, dac, error):
    """A bad dt, a count of DACs that is not the arm's, a value beyond 32 bits: refused,
    the state, the DACs and the generator as they were."""
    w = _world()
    k = w._k
    k.step_dac(1e-3, [100, -200, 300, 0, 5, -5])
    before = _state(w)
    with pytest.raises(error):
        k.step_dac(dt, dac)
    assert _state(w) == before
