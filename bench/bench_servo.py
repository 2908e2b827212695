"""The servo tick and the simulated arm's step for the PUMA 560.

Run: ``python -m pytest bench/bench_servo.py --benchmark-only``.

* servo: one tick of :class:`pyrt.native.Servo` for 6 joints from Python
  (measured joints written in place, as a loop does; and passed as an
  array), mid-segment; the pure-Python reference (tests/_ref_servo.py) for
  scale.  Target: <= 5 us per tick.
* world: :class:`pyrt.sim.arm.ArmWorld` with the PUMA advancing 1 ms
  (its default internal step, 1 ms), free under gravity, driven by its
  motors, and pressing on the table; the figure is the cost per simulated
  millisecond.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from _ref_servo import RefServo

from pyrt.kinematics.puma import puma560
from pyrt.native import Servo, tuned_gains
from pyrt.sim.arm import PUMA560_MOTORS, ArmWorld

PERIOD = 1e-3
INERTIA = np.array([3.6, 4.9, 0.95, 0.19, 0.17, 0.19])
EFFORT = np.array([97.6, 186.4, 89.4, 24.2, 20.1, 21.3])


def _servo() -> Servo:
    s = Servo(6, PERIOD, gains=dict(tuned_gains(INERTIA, EFFORT, PERIOD, 10.0), felim=[1.0] * 6))
    s.reset(np.zeros(6), ff=np.ones(6))
    # a segment long enough that every timed tick is inside it
    s.segment(1e6, np.zeros(6), np.zeros(6), np.full(6, 0.1), np.zeros(6), np.zeros(6),
              np.zeros(6), np.ones(6), np.ones(6))
    return s


@pytest.mark.benchmark(group="servo tick 6 joints")
def test_servo_tick_in_place(benchmark):
    """One tick, the measured joints written into servo.q by the caller (the loop's way)."""
    s = _servo()
    s.q[:] = 0.001
    benchmark(s.tick)
    assert not s.tripped


@pytest.mark.benchmark(group="servo tick 6 joints")
def test_servo_tick_array(benchmark):
    """One tick, the measured joints passed as an array."""
    s = _servo()
    q = np.full(6, 0.001)
    benchmark(s.tick, q)
    assert not s.tripped


@pytest.mark.benchmark(group="servo tick 6 joints")
def test_servo_tick_python_reference(benchmark):
    """The pure-Python reference of the same tick."""
    g = tuned_gains(INERTIA, EFFORT, PERIOD, 10.0)
    g["felim"] = np.ones(6)
    r = RefServo(6, PERIOD, {k: v.tolist() for k, v in g.items()})
    r.load(1e6, [0.0] * 6, [0.0] * 6, [0.1] * 6, [0.0] * 6, [0.0] * 6, [0.0] * 6)
    q = [0.001] * 6
    benchmark(r.tick, q)


def _world(**kw) -> ArmWorld:
    return ArmWorld(puma560(closed_form=False), motors=PUMA560_MOTORS,
                    q0=[0.0, math.radians(60), math.radians(-120), 0.0, 0.3, 0.0], **kw)


@pytest.mark.benchmark(group="PUMA world per simulated ms")
def test_world_free(benchmark):
    """1 ms of the PUMA, motors off, swinging under gravity, damping and friction."""
    w = _world()
    benchmark(w.step, 1e-3)


@pytest.mark.benchmark(group="PUMA world per simulated ms")
def test_world_driven(benchmark):
    """1 ms of the PUMA with every amplifier enabled and a current on every DAC."""
    w = _world()
    for j in range(6):
        w.board.write("enable", 1, j)
        w.board.write("dac", 3000 * (-1) ** j, j)
    benchmark(w.step, 1e-3)


@pytest.mark.benchmark(group="PUMA world per simulated ms")
def test_world_on_the_table(benchmark):
    """1 ms of the PUMA resting its tool tip on the table (contact, friction, F/T)."""
    w = _world(tip=(0.0, 0.0, 0.1))
    w.set_table(float(w.truth().tip[2]) + 0.002)
    benchmark(w.step, 1e-3)
    assert w.truth().contact[2] > 0
