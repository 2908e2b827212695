"""Kinematics and dynamics of the PUMA 560, per call from Python, beside the anchors.

Run: ``python -m pytest bench/bench_kinematics.py --benchmark-only`` (the
summary with the ratios against the targets is printed at the end).

* pyrt: ``Chain`` (csrc/kinematics.c) from the Robotics Toolbox's Puma560
  DH table (Corke and Armstrong-Helouvry's parameters), called with
  preallocated arrays (``out=``) as a control loop calls it, and without.
* Pinocchio (``pin``): the same chain written out as URDF and read by
  ``pin.buildModelFromXML``: ``forwardKinematics``,
  ``computeJointJacobian`` (the last joint's), ``rnea``, ``aba``.
* Robotics Toolbox: its ``Puma560`` (the same table) as an ETS:
  ``fkine``, ``jacob0``, ``ik_LM`` (Chan's damping, its defaults).

Targets: fk and Jacobian <= 2x Pinocchio; IK <= RTB's ``ik_LM``; RNEA <= 2x
Pinocchio's; forward dynamics <= 2x its ABA.  An anchor that is not
installed is skipped.
"""

from __future__ import annotations

import importlib.util
import math

import numpy as np
import pytest

from pyrt.kinematics import Chain, DHRow, rpy_of

HAVE_PIN = importlib.util.find_spec("pinocchio") is not None
HAVE_RTB = importlib.util.find_spec("roboticstoolbox") is not None
PI = math.pi

#: The Robotics Toolbox's Puma560 (standard DH; m, rad, kg, kg m^2).
ROWS = [
    DHRow(a=0.0, alpha=PI / 2, d=0.6718, lower=-2.7925, upper=2.7925, mass=0.0,
          inertia=np.diag([0.0, 0.35, 0.0])),
    DHRow(a=0.4318, alpha=0.0, d=0.0, lower=-0.7854, upper=3.9270, mass=17.4,
          com=(-0.3638, 0.006, 0.2275), inertia=np.diag([0.13, 0.524, 0.539])),
    DHRow(a=0.0203, alpha=-PI / 2, d=0.15005, lower=-3.9270, upper=0.7854, mass=4.8,
          com=(-0.0203, -0.0141, 0.070), inertia=np.diag([0.066, 0.086, 0.0125])),
    DHRow(a=0.0, alpha=PI / 2, d=0.4318, lower=-1.9199, upper=2.9671, mass=0.82,
          com=(0.0, 0.019, 0.0), inertia=np.diag([1.8e-3, 1.3e-3, 1.8e-3])),
    DHRow(a=0.0, alpha=-PI / 2, d=0.0, lower=-1.7453, upper=1.7453, mass=0.34,
          inertia=np.diag([0.3e-3, 0.4e-3, 0.3e-3])),
    DHRow(a=0.0, alpha=0.0, d=0.0, lower=-4.6426, upper=4.6426, mass=0.09,
          com=(0.0, 0.0, 0.032), inertia=np.diag([0.15e-3, 0.15e-3, 0.04e-3])),
]
PUMA = Chain.from_dh(ROWS, name="puma560")
Q = np.array([0.1, 0.7, -1.2, 0.3, 0.4, 0.5])
QD = np.array([0.3, 0.2, -0.1, 0.5, 0.4, 0.1])
QDD = np.array([1.0, 2.0, 3.0, -1.0, 0.5, 0.2])
TAU = PUMA.rnea(Q, QD, QDD)
TARGET = PUMA.fk(Q)
SEED = Q + 0.2

_MEDIANS: dict[str, float] = {}


def urdf_text(chain: Chain) -> str:
    """The chain as URDF (for Pinocchio), joint by joint."""
    def f(v) -> str:
        return " ".join(repr(float(x)) for x in v)

    out = [f'<robot name="{chain.name}"><link name="l0"/>']
    for k, j in enumerate(chain.joints, 1):
        i = j.inertial
        t = i.inertia
        out.append(
            f'<joint name="{j.name}" type="revolute"><parent link="l{k - 1}"/>'
            f'<child link="l{k}"/><origin xyz="{f(j.origin[:3, 3])}" rpy="{f(rpy_of(j.origin))}"/>'
            f'<axis xyz="{f(j.axis)}"/><limit lower="{float(j.lower)!r}" upper="{float(j.upper)!r}" '
            f'effort="100" velocity="3"/></joint>'
            f'<link name="l{k}"><inertial><origin xyz="{f(i.com)}"/>'
            f'<mass value="{float(i.mass)!r}"/><inertia ixx="{float(t[0, 0])!r}" '
            f'ixy="{float(t[0, 1])!r}" ixz="{float(t[0, 2])!r}" iyy="{float(t[1, 1])!r}" '
            f'iyz="{float(t[1, 2])!r}" izz="{float(t[2, 2])!r}"/></inertial></link>')
    out.append("</robot>")
    return "".join(out)


@pytest.fixture(scope="module", autouse=True)
def summary(request):
    """Print the figures side by side, with the ratios against the targets."""
    yield
    tr = request.config.pluginmanager.get_plugin("terminalreporter")
    if tr is None or not _MEDIANS:
        return

    def us(key: str) -> str:
        return f"{_MEDIANS[key] * 1e6:7.3f} us" if key in _MEDIANS else "    (n/a)"

    def ratio(a: str, b: str, limit: float) -> str:
        if a not in _MEDIANS or b not in _MEDIANS:
            return ""
        r = _MEDIANS[a] / _MEDIANS[b]
        return f"{r:.2f}x (target <= {limit:g}x: {'met' if r <= limit else 'NOT met'})"

    w = tr.write_line
    w("")
    w("kinematics, PUMA 560, median per call from Python")
    w(f"  {'':8s} {'pyrt out=':>11s} {'pyrt':>11s} {'pinocchio':>11s} {'rtb':>11s}")
    for op in ("fk", "jacobian", "ik", "rnea", "aba"):
        w(f"  {op:8s} {us(op + '/pyrt-out')} {us(op + '/pyrt')} {us(op + '/pin')} "
          f"{us(op + '/rtb')}")
    w(f"  fk       pyrt out= / pin:  {ratio('fk/pyrt-out', 'fk/pin', 2)}")
    w(f"  jacobian pyrt out= / pin:  {ratio('jacobian/pyrt-out', 'jacobian/pin', 2)}")
    w(f"  ik       pyrt / rtb ik_LM: {ratio('ik/pyrt', 'ik/rtb', 1)}")
    w(f"  rnea     pyrt out= / pin:  {ratio('rnea/pyrt-out', 'rnea/pin', 2)}")
    w(f"  aba      pyrt out= / pin:  {ratio('aba/pyrt-out', 'aba/pin', 2)}")


def run(benchmark, key: str, fn, *args) -> None:
    benchmark.extra_info["key"] = key
    benchmark(fn, *args)
    stats = getattr(benchmark, "stats", None)
    if stats is not None:
        _MEDIANS[key] = stats.stats.median


# ------------------------------------------------------------------- pyrt


@pytest.mark.benchmark(group="puma fk")
def test_fk_pyrt_out(benchmark):
    """pyrt fk into a preallocated 4x4."""
    out = np.empty((4, 4))
    run(benchmark, "fk/pyrt-out", PUMA.fk, Q, out)


@pytest.mark.benchmark(group="puma fk")
def test_fk_pyrt(benchmark):
    """pyrt fk returning a new array."""
    run(benchmark, "fk/pyrt", PUMA.fk, Q)


@pytest.mark.benchmark(group="puma jacobian")
def test_jacobian_pyrt_out(benchmark):
    """pyrt Jacobian into a preallocated 6x6."""
    out = np.empty((6, 6))
    run(benchmark, "jacobian/pyrt-out", PUMA.jacobian, Q, out)


@pytest.mark.benchmark(group="puma jacobian")
def test_jacobian_pyrt(benchmark):
    """pyrt Jacobian returning a new array."""
    run(benchmark, "jacobian/pyrt", PUMA.jacobian, Q)


@pytest.mark.benchmark(group="puma ik")
def test_ik_pyrt(benchmark):
    """pyrt numerical inverse to 1e-9 from a seed 0.2 rad off every joint."""
    r = PUMA.ik(TARGET, SEED)
    assert r.ok and r.residual <= 1e-9
    benchmark.extra_info.update(iterations=r.iterations, residual=r.residual)
    run(benchmark, "ik/pyrt", PUMA.ik, TARGET, SEED)


@pytest.mark.benchmark(group="puma rnea")
def test_rnea_pyrt_out(benchmark):
    """pyrt Newton-Euler into a preallocated vector."""
    out = np.empty(6)
    run(benchmark, "rnea/pyrt-out", PUMA.rnea, Q, QD, QDD, (0.0, 0.0, -9.81), out)


@pytest.mark.benchmark(group="puma rnea")
def test_rnea_pyrt(benchmark):
    """pyrt Newton-Euler returning a new vector."""
    run(benchmark, "rnea/pyrt", PUMA.rnea, Q, QD, QDD)


@pytest.mark.benchmark(group="puma aba")
def test_aba_pyrt_out(benchmark):
    """pyrt forward dynamics into a preallocated vector."""
    out = np.empty(6)
    run(benchmark, "aba/pyrt-out", PUMA.aba, Q, QD, TAU, (0.0, 0.0, -9.81), out)


@pytest.mark.benchmark(group="puma aba")
def test_aba_pyrt(benchmark):
    """pyrt forward dynamics returning a new vector."""
    run(benchmark, "aba/pyrt", PUMA.aba, Q, QD, TAU)


# -------------------------------------------------------------- Pinocchio


@pytest.fixture(scope="module")
def pin_model():
    if not HAVE_PIN:
        pytest.skip("pinocchio (pin) is not installed")
    import pinocchio as pin

    model = pin.buildModelFromXML(urdf_text(PUMA))
    data = model.createData()
    # the same arm: the offsets are zero in the RTB table, so q means the same
    pin.forwardKinematics(model, data, Q)
    np.testing.assert_allclose(data.oMi[6].homogeneous @ PUMA.tool, PUMA.fk(Q), atol=1e-12)
    np.testing.assert_allclose(pin.rnea(model, data, Q, QD, QDD), TAU, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(pin.aba(model, data, Q, QD, TAU), QDD, rtol=1e-9, atol=1e-9)
    return pin, model, data


@pytest.mark.benchmark(group="puma fk")
def test_fk_pin(benchmark, pin_model):
    """Pinocchio forwardKinematics."""
    pin, model, data = pin_model
    run(benchmark, "fk/pin", pin.forwardKinematics, model, data, Q)


@pytest.mark.benchmark(group="puma jacobian")
def test_jacobian_pin(benchmark, pin_model):
    """Pinocchio computeJointJacobian of the last joint."""
    pin, model, data = pin_model
    run(benchmark, "jacobian/pin", pin.computeJointJacobian, model, data, Q, 6)


@pytest.mark.benchmark(group="puma rnea")
def test_rnea_pin(benchmark, pin_model):
    """Pinocchio rnea."""
    pin, model, data = pin_model
    run(benchmark, "rnea/pin", pin.rnea, model, data, Q, QD, QDD)


@pytest.mark.benchmark(group="puma aba")
def test_aba_pin(benchmark, pin_model):
    """Pinocchio aba."""
    pin, model, data = pin_model
    run(benchmark, "aba/pin", pin.aba, model, data, Q, QD, TAU)


# ------------------------------------------------------- Robotics Toolbox


@pytest.fixture(scope="module")
def rtb_ets():
    if not HAVE_RTB:
        pytest.skip("roboticstoolbox-python is not installed")
    import roboticstoolbox as rtb

    ets = rtb.models.DH.Puma560().ets()
    np.testing.assert_allclose(ets.fkine(Q).A[:3, 3], PUMA.fk(Q)[:3, 3], atol=1e-3)
    return ets


@pytest.mark.benchmark(group="puma fk")
def test_fk_rtb(benchmark, rtb_ets):
    """Robotics Toolbox ETS fkine."""
    run(benchmark, "fk/rtb", rtb_ets.fkine, Q)


@pytest.mark.benchmark(group="puma jacobian")
def test_jacobian_rtb(benchmark, rtb_ets):
    """Robotics Toolbox ETS jacob0."""
    run(benchmark, "jacobian/rtb", rtb_ets.jacob0, Q)


@pytest.mark.benchmark(group="puma ik")
def test_ik_rtb(benchmark, rtb_ets):
    """Robotics Toolbox ik_LM (its defaults: tol 1e-6, Chan's damping), the same target and seed."""
    target = TARGET.copy()
    sol = rtb_ets.ik_LM(target, q0=SEED)
    assert sol.success
    benchmark.extra_info.update(iterations=int(sol.iterations), residual=float(sol.residual))
    run(benchmark, "ik/rtb", rtb_ets.ik_LM, target, SEED)
