"""The trajectory tick of pyrt.motion: what the trajectory task pays per period.

Run: ``python -m pytest bench/bench_motion.py --benchmark-only``.

* ``cart-puma``: a Cartesian segment of the PUMA 560 (6 joints), mid-line:
  the drive transform's pose, T6 through the equation, Paul's closed form with
  the configuration held, the knot's central differences.  Target <= 20 us.
* ``cart-arm7``: the same on a 7-joint arm (the numerical inverse, seeded).
* ``joint-puma``: a joint segment (a polynomial and the forward kinematics).
* ``conveyor-puma``: following a point on a conveyor (a functional COORD
  evaluated once per sample).
* ``plan-puma``: queueing a Cartesian record (planning and its sampled
  checks, outside the loop), for scale.

Each benchmark ticks an evaluator that stays inside the same kind of piece
for every round (a slow, long segment).
"""

from __future__ import annotations

import numpy as np
import pytest
from _motion_rig import (
    ARM7,
    ARM7_HOME,
    ARM7_LIMITS,
    PUMA,
    PUMA_HOME,
    conveyor,
    equation,
    make,
    tool_pose,
)

from pyrt.motion import MotionSpec

ROUNDS = 2000


def _cart(chain, home, limits=None):
    ev = make(chain, limits, home) if limits else make(chain, q0=home)
    a = tool_pose(chain, home)
    b = a.copy()
    b[:3, 3] += [0.05, -0.05, 0.04]
    ev.queue(MotionSpec(mode="cart", equation=equation(b), speed=0.002))
    for _ in range(200):  # into the line
        ev.tick()
    return ev


@pytest.mark.benchmark(group="motion-tick")
def test_cartesian_tick_puma(benchmark):
    """One trajectory tick of a PUMA Cartesian line (interpolation + closed-form inverse)."""
    ev = _cart(PUMA, PUMA_HOME)
    benchmark.extra_info["impl"] = "cart-puma"
    benchmark.pedantic(ev.tick, rounds=ROUNDS, iterations=1)
    assert ev._pieces[ev._k].space == "cart"


@pytest.mark.benchmark(group="motion-tick")
def test_cartesian_tick_arm7(benchmark):
    """One trajectory tick of a 7-joint arm's Cartesian line (numerical inverse)."""
    ev = _cart(ARM7, ARM7_HOME, ARM7_LIMITS)
    benchmark.extra_info["impl"] = "cart-arm7"
    benchmark.pedantic(ev.tick, rounds=ROUNDS, iterations=1)
    assert ev._pieces[ev._k].space == "cart"


@pytest.mark.benchmark(group="motion-tick")
def test_joint_tick_puma(benchmark):
    """One trajectory tick of a PUMA joint segment."""
    ev = make()
    ev.queue(MotionSpec(mode="joint", target=PUMA_HOME + 0.3, speed=0.002))
    for _ in range(200):
        ev.tick()
    benchmark.extra_info["impl"] = "joint-puma"
    benchmark.pedantic(ev.tick, rounds=ROUNDS, iterations=1)
    assert ev._pieces[ev._k].space == "joint"


@pytest.mark.benchmark(group="motion-tick")
def test_conveyor_tick_puma(benchmark):
    """One trajectory tick following a point on a conveyor (functional COORD)."""
    ev = make()
    a = tool_pose(PUMA, PUMA_HOME)
    pos = a.copy()
    pos[:3, 3] += [0.05, -0.1, -0.08]
    ev.queue(MotionSpec(mode="cart", equation=equation(pos, name="C",
                                                       coord=conveyor(speed=0.001))))
    for _ in range(300):
        ev.tick()
    benchmark.extra_info["impl"] = "conveyor-puma"
    benchmark.pedantic(ev.tick, rounds=ROUNDS, iterations=1)
    assert ev._segs[-1].tracking


@pytest.mark.benchmark(group="motion-plan")
def test_plan_cartesian_record_puma(benchmark):
    """Queueing (planning and checking) a 10 cm Cartesian record on the PUMA."""
    a = tool_pose(PUMA, PUMA_HOME)
    b = a.copy()
    b[:3, 3] += [0.1, 0.0, -0.05]
    spec = MotionSpec(mode="cart", equation=equation(b))

    def plan():
        make().queue(spec)

    benchmark.extra_info["impl"] = "plan-puma"
    benchmark.pedantic(plan, rounds=20, iterations=1)
    np.testing.assert_allclose(a[3], [0, 0, 0, 1])
