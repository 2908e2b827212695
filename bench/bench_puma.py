"""The PUMA 560's closed-form inverse and calibration, against the Robotics Toolbox.

Run: ``python -m pytest bench/bench_puma.py --benchmark-only``.

* closed form: Paul's inverse of one reachable pose in one configuration,
  from Python -- ``PaulInverse.solve`` (the chain's closed form: csrc/puma.c
  through cffi), the kernel's wrapper alone, the pure-Python reference
  (tests/_ref_puma.py), and the Robotics Toolbox's ``Puma560.ikine_a`` (the
  anchor, skipped when roboticstoolbox-python is not installed);
* all eight configurations of one pose (``solve_all``), and ``config_of``;
* calibration: identifying 11 parameters (five joint offsets and the base)
  from 20 measured poses.

The target for the closed form is 5 us per call.
"""

from __future__ import annotations

import importlib.util
import math

import _ref_puma
import numpy as np
import pytest

from pyrt.kinematics.calibration import CalibrationModel, observations
from pyrt.kinematics.puma import CONFIGURATIONS, DH, puma560

HAVE_RTB = importlib.util.find_spec("roboticstoolbox") is not None

CHAIN = puma560()
CF = CHAIN.closed_form
Q = np.radians([10.0, 40.0, -120.0, 40.0, 50.0, 60.0])
POSE = CHAIN.fk(Q)
CONFIG = CF.config_of(Q)


def _rtb_code(cfg: str) -> str:
    arm, elbow, wrist = cfg.split("-")
    return arm[0] + ("u" if elbow == "above" else "d") + wrist[0]


@pytest.mark.benchmark(group="puma closed form")
def test_pyrt_closed_form(benchmark):
    """PaulInverse.solve: one pose, one configuration, C through cffi."""
    q = benchmark(CF.solve, POSE, CONFIG)
    np.testing.assert_allclose(q, Q, atol=1e-9)


@pytest.mark.benchmark(group="puma closed form")
def test_pyrt_kernel_alone(benchmark):
    """The C kernel's wrapper with the configuration already as bits."""
    arm, elbow, wrist = CONFIG.split("-")
    bits = (arm == "lefty") * 1 + (elbow == "below") * 2 + (wrist == "flip") * 4
    q, why, _ = benchmark(CF._kernel.inverse, POSE, bits)
    assert why == 0
    np.testing.assert_allclose(q, Q, atol=1e-9)


@pytest.mark.benchmark(group="puma closed form")
def test_python_reference(benchmark):
    """The pure-Python reference of csrc/puma.c."""
    lengths = (DH[0][0], DH[1][1], DH[2][1], DH[2][0], DH[3][0])
    q, _, _ = benchmark(_ref_puma.inverse, lengths, CHAIN.base, CHAIN.tool, CHAIN.offsets,
                          CHAIN.lower, CHAIN.upper, POSE, CONFIG)
    np.testing.assert_allclose(q, Q, atol=1e-9)


@pytest.mark.skipif(not HAVE_RTB, reason="roboticstoolbox-python is not installed")
@pytest.mark.benchmark(group="puma closed form")
def test_rtb_ikine_a(benchmark):
    """The anchor: the Robotics Toolbox's Puma560.ikine_a (Python)."""
    from roboticstoolbox.models.DH import Puma560
    from spatialmath import SE3

    rtb = Puma560()
    target = SE3(POSE, check=False)
    sol = benchmark(rtb.ikine_a, target, _rtb_code(CONFIG))
    np.testing.assert_allclose(np.arctan2(np.sin(sol.q - Q), np.cos(sol.q - Q)), 0, atol=1e-9)


@pytest.mark.skipif(not HAVE_RTB, reason="roboticstoolbox-python is not installed")
def test_rtb_agrees_on_every_configuration():
    """The Toolbox's model has the same pose and the same eight named solutions (not a timing)."""
    from roboticstoolbox.models.DH import Puma560
    from spatialmath import SE3

    rtb = Puma560()
    rng = np.random.default_rng(0)
    for _ in range(50):
        q = rng.uniform(CHAIN.lower, CHAIN.upper)
        pose = CHAIN.fk(q)
        np.testing.assert_allclose(rtb.fkine(q).A, pose, atol=1e-12)
        if abs(math.sin(q[4])) < 1e-3:
            continue
        for cfg in CONFIGURATIONS:
            theirs = rtb.ikine_a(SE3(pose, check=False), _rtb_code(cfg)).q
            ours = CF.inverse(pose, cfg, limits=False)
            np.testing.assert_allclose(np.arctan2(np.sin(theirs - ours), np.cos(theirs - ours)),
                                       0, atol=1e-7)


@pytest.mark.benchmark(group="puma all eight")
def test_pyrt_solve_all(benchmark):
    """solve_all: the eight configurations of one pose, within the limits."""
    found = benchmark(CF.solve_all, POSE)
    assert CONFIG in found


@pytest.mark.benchmark(group="puma all eight")
def test_pyrt_config_of(benchmark):
    """config_of: the configuration of a joint vector."""
    assert benchmark(CF.config_of, Q) == CONFIG


@pytest.mark.benchmark(group="calibration")
def test_identify_20_poses(benchmark):
    """Identify five joint offsets and the base (11 parameters) from 20 measured poses."""
    truth = CalibrationModel.for_chains(CHAIN)
    truth.update({"offset.joint2": math.radians(0.5), "base.x": 1e-3,
                  "base.ry": math.radians(0.2)})
    real = truth.apply(CHAIN)
    rng = np.random.default_rng(7)
    mid, half = (CHAIN.lower + CHAIN.upper) / 2, (CHAIN.upper - CHAIN.lower) / 2
    qs = [mid + 0.7 * half * rng.uniform(-1, 1, 6) for _ in range(20)]
    data = observations(CHAIN, qs, [real.fk(q) for q in qs])
    free = ["offset.joint2", "offset.joint3", "offset.joint4", "offset.joint5", "offset.joint6",
            "base"]

    def fit():
        return CalibrationModel.for_chains(CHAIN).identify(data, free)

    result = benchmark.pedantic(fit, rounds=5, iterations=1)
    assert result.converged and result.rms_position < 1e-9
    benchmark.extra_info["iterations"] = result.iterations
