"""The simulated arm's step: the PUMA 560 per simulated millisecond, C beside the Python reference.

Run: ``python -m pytest bench/bench_armworld.py --benchmark-only -s``.

:class:`pyrt.sim.arm.ArmWorld` (its step one call of csrc/armworld.c) and
tests/_ref_armworld.py's :class:`RefArmWorld` (the same physics in Python
over the kinematics kernels), each advancing 1 ms (one internal step) from
the board's registers to the board's registers:

* free: motors off, the arm swinging under gravity, damping and friction;
* driven: every amplifier enabled with a current on every DAC;
* servoed: new DAC values every millisecond, as a servo writes them (every
  encoder and F/T register changes: the station's case);
* on the table: the tool tip resting on the table (contact, friction, F/T);
* 10 ms in one call (ten internal steps), per simulated millisecond;
* the kernel alone (``ArmKernel.step``, no registers), for scale.

Target: <= 8 us per simulated ms free.  The summary at the end (``-s``) prints the
minimum (the machine's own speed; the median is printed beside it, the
figure on a machine that other work shares) and the ratio to the reference.
"""

from __future__ import annotations

import math
import random

import pytest
from _ref_armworld import RefArmWorld

from pyrt.kinematics.puma import puma560
from pyrt.sim.arm import PUMA560_MOTORS, ArmWorld

CHAIN = puma560(closed_form=False)
Q0 = [0.0, math.radians(60), math.radians(-120), 0.0, 0.3, 0.0]
TARGET_US = 8.0
_FIGURES: dict[tuple[str, str], tuple[float, float]] = {}


def _world(impl: str, **kw):
    cls = ArmWorld if impl == "C" else RefArmWorld
    return cls(CHAIN, motors=PUMA560_MOTORS, q0=Q0, **kw)


def _keep(benchmark, case: str, impl: str, per: int = 1) -> None:
    s = benchmark.stats.stats
    _FIGURES[(case, impl)] = (s.min / per * 1e6, s.median / per * 1e6)
    benchmark.extra_info.update(case=case, impl=impl, us_per_sim_ms=round(s.min / per * 1e6, 3))


@pytest.mark.parametrize("impl", ["C", "Python"])
@pytest.mark.benchmark(group="PUMA world per simulated ms: free")
def test_free(benchmark, impl):
    """1 ms of the PUMA, motors off, swinging under gravity, damping and friction."""
    w = _world(impl)
    benchmark(w.step, 1e-3)
    _keep(benchmark, "free", impl)


@pytest.mark.parametrize("impl", ["C", "Python"])
@pytest.mark.benchmark(group="PUMA world per simulated ms: driven")
def test_driven(benchmark, impl):
    """1 ms of the PUMA with every amplifier enabled and a current on every DAC."""
    w = _world(impl)
    for j in range(6):
        w.board.write("enable", 1, j)
        w.board.write("dac", 3000 * (-1) ** j, j)
    benchmark(w.step, 1e-3)
    _keep(benchmark, "driven", impl)


@pytest.mark.parametrize("impl", ["C", "Python"])
@pytest.mark.benchmark(group="PUMA world per simulated ms: servoed")
def test_servoed(benchmark, impl):
    """1 ms of the PUMA whose DACs change every millisecond, as under a servo (new currents,
    every encoder and F/T register changing)."""
    w = _world(impl)
    rng = random.Random(3)
    for j in range(6):
        w.board.write("enable", 1, j)
    dacs = [[rng.randint(-4000, 4000) for _ in range(6)] for _ in range(64)]
    k = [0]

    def new_currents():
        for j, d in enumerate(dacs[k[0] & 63]):
            w.board.write("dac", d, j)
        k[0] += 1
        return (1e-3,), {}

    benchmark.pedantic(w.step, setup=new_currents, rounds=3000 if impl == "C" else 600,
                       warmup_rounds=10)
    _keep(benchmark, "servoed", impl)


@pytest.mark.parametrize("impl", ["C", "Python"])
@pytest.mark.benchmark(group="PUMA world per simulated ms: on the table")
def test_on_the_table(benchmark, impl):
    """1 ms of the PUMA resting its tool tip on the table (contact, friction, F/T)."""
    w = _world(impl, tip=(0.0, 0.0, 0.1))
    w.set_table(float(w.truth().tip[2]) + 0.002)
    benchmark(w.step, 1e-3)
    assert w.truth().contact[2] > 0
    _keep(benchmark, "on the table", impl)


@pytest.mark.parametrize("impl", ["C", "Python"])
@pytest.mark.benchmark(group="PUMA world per simulated ms: 10 ms in one call")
def test_ten_ms_in_one_call(benchmark, impl):
    """10 ms of the free PUMA in one step (ten internal steps), per simulated ms."""
    w = _world(impl)
    benchmark(w.step, 10e-3)
    _keep(benchmark, "free, 10 ms a call", impl, per=10)


@pytest.mark.benchmark(group="PUMA world per simulated ms: the kernel alone")
def test_kernel_alone(benchmark):
    """ArmKernel.step of 1 ms (the C call and its wrapper, no board registers)."""
    w = _world("C")
    benchmark(w._k.step, 1e-3)
    _keep(benchmark, "kernel alone", "C")


@pytest.fixture(scope="module", autouse=True)
def _summary():
    """Print the figures side by side once the benchmarks above have run (``-s``)."""
    yield
    if not _FIGURES:
        return
    lines = ["", "PUMA 560 simulated arm, us per simulated ms: min (median)",
             f"  {'case':22s} {'C':>18s} {'Python reference':>20s} {'ratio':>7s}"]
    for case in ("free", "driven", "servoed", "on the table", "free, 10 ms a call", "kernel alone"):
        c = _FIGURES.get((case, "C"))
        p = _FIGURES.get((case, "Python"))
        cs = f"{c[0]:.2f} ({c[1]:.2f})" if c else "-"
        ps = f"{p[0]:.2f} ({p[1]:.2f})" if p else "-"
        ratio = f"{p[0] / c[0]:.0f}x" if c and p else ""
        lines.append(f"  {case:22s} {cs:>18s} {ps:>20s} {ratio:>7s}")
    free = _FIGURES.get(("free", "C"))
    if free:
        lines.append(f"  target free <= {TARGET_US:g} us: "
                     f"{'met' if free[0] <= TARGET_US else 'NOT met'} ({free[0]:.2f} us)")
    print("\n".join(lines))
