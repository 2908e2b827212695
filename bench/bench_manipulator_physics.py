"""Manipulator physics benchmarks: one plant step, and the prototype's real-time ratio.

Run: ``python -m pytest bench/bench_manipulator_physics.py --benchmark-only -s``.

* ``step``: one :meth:`ManipulatorPlant.step` with the statics solved again
  (the worst case: some rope moved this tick) for the 3-rope prototype and
  the 5-rope full-scale station, and one idle step (nothing moved: step
  generators and sensor conversions only).  Target: the 5-rope step under
  50 µs.
* ``realtime``: the prototype (plant + three Axis objects polled every tick)
  on a SimClock loop at a 1 ms tick, idle and with axis0 moving; reports
  simulated seconds per wall second.  Target: at least 20x real time.
"""

from __future__ import annotations

import time

import pytest

from pyrt.boards.dataconcentrator import DataConcentrator
from pyrt.boards.tio10 import TIO10
from pyrt.db import load_station, station_directory
from pyrt.robots.av import AV
from pyrt.robots.axis import Axis
from pyrt.scheduler import Loop, SimClock
from pyrt.sim.manipulator import ManipulatorPlant, rig_from_station

STEP_TARGET_US = 50.0
REALTIME_TARGET = 20.0


def _plant(name: str):
    station = load_station(station_directory(name))
    tio, dc = TIO10(), DataConcentrator()  # the cards over register files of their own
    plant = ManipulatorPlant(rig_from_station(station), tio.registers, dc.registers)
    return station, plant, tio, dc


@pytest.mark.benchmark(group="manipulator-physics-step")
@pytest.mark.parametrize("station", ["prototype", "sno"])
def test_step_with_solve(benchmark, station):
    """One physics step with the equilibrium solved again."""
    _, plant, _, _ = _plant(station)
    state = {"t": 0}

    def step():
        state["t"] += 1_000_000
        plant.invalidate()
        plant.step(state["t"])

    benchmark.pedantic(step, rounds=2000, iterations=5, warmup_rounds=50)
    us = benchmark.stats.stats.mean * 1e6
    med = benchmark.stats.stats.median * 1e6
    n = len(plant.ropes)
    benchmark.extra_info.update(ropes=n, mean_us=us, median_us=med, target_us=STEP_TARGET_US)
    print(f"\n{station}: {n}-rope physics step with solve: mean {us:.1f} µs, median {med:.1f} µs "
          f"(target < {STEP_TARGET_US:.0f} µs: median at {med / STEP_TARGET_US:.2f} of budget)")


@pytest.mark.benchmark(group="manipulator-physics-step")
@pytest.mark.parametrize("station", ["prototype", "sno"])
def test_step_idle(benchmark, station):
    """One physics step with nothing moving (no solve)."""
    _, plant, _, _ = _plant(station)
    state = {"t": 0}

    def step():
        state["t"] += 1_000_000
        plant.step(state["t"])

    benchmark.pedantic(step, rounds=2000, iterations=5, warmup_rounds=50)
    us = benchmark.stats.stats.mean * 1e6
    med = benchmark.stats.stats.median * 1e6
    benchmark.extra_info.update(ropes=len(plant.ropes), mean_us=us, median_us=med)
    print(f"\n{station}: {len(plant.ropes)}-rope idle physics step: mean {us:.1f} µs, "
          f"median {med:.1f} µs")


def _prototype_stack():
    station, plant, tio, dc = _plant("prototype")
    pa = station.polyaxis()
    av = AV.from_record(station.av_of(pa))
    axes = [Axis.from_records(f"axis{i}", rec, station, tio, dc, av=av)
            for i, rec in enumerate(station.axes_of(pa))]
    loop = Loop(SimClock(), 1_000_000, timing=False)
    loop.attach(plant.step, "plant")
    for ax in axes:
        loop.attach(lambda now, ax=ax: ax.poll(now * 1e-9), ax.name)
    loop.run(10)
    return loop, axes, plant


@pytest.mark.benchmark(group="manipulator-realtime")
@pytest.mark.parametrize("moving", [False, True], ids=["idle", "axis0-moving"])
def test_prototype_realtime_ratio(benchmark, moving):
    """Simulated seconds per wall second of the prototype at a 1 ms tick."""
    loop, axes, _ = _prototype_stack()
    sim_s = 5.0
    ticks = int(sim_s * 1000)

    def run():
        if moving:
            axes[0].stop()
            axes[0].cmd_down(30)
        loop.run(ticks)

    benchmark.pedantic(run, rounds=3, iterations=1, warmup_rounds=1)
    wall = benchmark.stats.stats.mean
    ratio = sim_s / wall
    benchmark.extra_info.update(sim_seconds_per_wall_second=ratio, target=REALTIME_TARGET)
    print(f"\nprototype {'axis0 moving' if moving else 'idle'} at 1 ms: {ratio:.1f}x real time "
          f"({wall / ticks * 1e6:.1f} µs/tick; target >= {REALTIME_TARGET:.0f}x: "
          f"{ratio / REALTIME_TARGET:.1f} of target)")


def test_realtime_ratio_quick():
    """A plain timing of 2 s of the idle prototype (no pytest-benchmark needed)."""
    loop, _, _ = _prototype_stack()
    t0 = time.perf_counter()
    loop.run(2000)
    ratio = 2.0 / (time.perf_counter() - t0)
    print(f"\nprototype idle quick check: {ratio:.1f}x real time")
    assert ratio > 1.0
