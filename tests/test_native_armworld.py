"""The simulated arm's C step (csrc/armworld.c, pyrt.native.ArmKernel) against its
pure-Python reference (tests/_ref_armworld.py), its noise generator, and its refusals."""

from __future__ import annotations

import math
import textwrap

import numpy as np
import pytest
from _ref_armworld import NoiseSource, RefArmWorld
from _sanitize import PRELUDE, assert_clean, run_under_asan
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pyrt.errors import ConfigError
from pyrt.kinematics import Chain, Inertial, Joint
from pyrt.kinematics.puma import puma560
from pyrt.native import (
    ARM_ROWS,
    ArmKernel,
    ChainKernels,
    NativeInputError,
    NonFiniteError,
    SingularError,
)
from pyrt.sim.arm import PUMA560_MOTORS, ArmWorld, default_motors

PUMA = puma560(closed_form=False)


def _origin(x: float = 0.0, y: float = 0.0, z: float = 0.0) -> np.ndarray:
    t = np.eye(4)
    t[:3, 3] = (x, y, z)
    return t


def _rpr() -> Chain:
    """A three-joint arm with a prismatic joint in the middle, damping and friction."""
    body = Inertial(2.0, (0.1, 0.0, 0.05), np.diag([0.02, 0.03, 0.02]))
    return Chain("rpr", [
        Joint("waist", "revolute", _origin(z=0.3), (0, 0, 1), -2.5, 2.5, effort=60.0,
              damping=0.5, friction=1.0, inertial=body),
        Joint("slide", "prismatic", _origin(x=0.2), (1, 0, 0), -0.1, 0.3, effort=200.0,
              damping=5.0, friction=4.0, inertial=body),
        Joint("wrist", "revolute", _origin(x=0.25), (0, 1, 0), -2.0, 2.0, effort=15.0,
              damping=0.05, friction=0.2, inertial=Inertial(0.8, (0.05, 0, 0),
                                                            np.diag([0.002] * 3))),
    ])


RPR = _rpr()
CHAINS = {"puma": (PUMA, PUMA560_MOTORS), "rpr": (RPR, default_motors(RPR))}
TIPS = [(0.0, 0.0, 0.0), (0.0, 0.0, 0.1), (0.02, -0.01, 0.08)]
STEPS = [1e-3, 0.5e-3, 2.5e-3, 1e-4, 4e-3]


def _pair(name: str, **kw):
    chain, motors = CHAINS[name]
    return (ArmWorld(chain, motors=motors, **kw), RefArmWorld(chain, motors=motors, **kw))


def _same(c: ArmWorld, r: RefArmWorld) -> None:
    tc, tr = c.truth(), r.truth()
    np.testing.assert_allclose(tc.q, tr.q, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(tc.qd, tr.qd, rtol=1e-9, atol=1e-9)
    for field in ("contact", "wrench", "torque", "current"):
        np.testing.assert_allclose(getattr(tc, field), getattr(tr, field), rtol=1e-9,
                                   atol=1e-7, err_msg=field)
    assert c.board.values("count") == r.board.values("count")
    assert c.board.values("ft") == r.board.values("ft")


@st.composite
def scenarios(draw):
    name = draw(st.sampled_from(sorted(CHAINS)))
    chain, _ = CHAINS[name]
    n = chain.n
    margin = math.radians(3.0)   # the stops are 2 deg beyond the limits: into them by 1 deg
    lo = np.where(np.isfinite(chain.lower), chain.lower - margin, -math.pi)
    hi = np.where(np.isfinite(chain.upper), chain.upper + margin, math.pi)
    q = [draw(st.floats(float(a), float(b))) for a, b in zip(lo, hi, strict=True)]
    qd = draw(st.lists(st.floats(-2.0, 2.0), min_size=n, max_size=n))
    dac = draw(st.lists(st.integers(-32767, 32767), min_size=n, max_size=n))
    enable = draw(st.lists(st.integers(0, 1), min_size=n, max_size=n))
    table = draw(st.none() | st.floats(-0.005, 0.01))   # above the tip (into contact) or below
    return dict(name=name, q=q, qd=qd, dac=dac, enable=enable, table=table,
                tip=draw(st.sampled_from(TIPS)), payload=draw(st.sampled_from([0.0, 1.5])),
                seed=draw(st.integers(0, 2**64 - 1)),
                dts=draw(st.lists(st.sampled_from(STEPS), min_size=3, max_size=6)))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(scenarios())
def test_the_c_step_matches_the_python_reference(s):
    """From random joint states and velocities, DAC values and enables, table heights
    (touching or not), tips and payloads, every step of the C kernel gives the Python
    reference's joints, rates, contact, wrench, torques and currents to 1e-9 and the same
    encoder and F/T registers (the sensor's noise included)."""
    c, r = _pair(s["name"], tip=s["tip"], payload=s["payload"], seed=s["seed"])
    for w in (c, r):
        w.set_state(s["q"], s["qd"])
        if s["table"] is not None:
            w.set_table(float(w.truth().tip[2]) + s["table"])
            w.set_state(s["q"], s["qd"])
        for j, (d, e) in enumerate(zip(s["dac"], s["enable"], strict=True)):
            w.board.write("dac", d, j)
            w.board.write("enable", e, j)
    _same(c, r)
    for dt in s["dts"]:
        c.step(dt)
        r.step(dt)
        _same(c, r)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(scenarios(), st.data())
def test_the_brakes_match_the_python_reference(s, data):
    """With brakes (random holding torques up to twice the effort) engaged or released joint by joint, from random states and drives, every step of the C kernel gives the Python reference's joints and rates to 1e-9."""
    chain, _ = CHAINS[s["name"]]
    n = chain.n
    brake = [data.draw(st.floats(0.0, 2.0 * j.effort)) for j in chain.joints]
    release = data.draw(st.lists(st.integers(0, 1), min_size=n, max_size=n))
    c, r = _pair(s["name"], seed=s["seed"], brake=brake)
    for w in (c, r):
        w.set_state(s["q"], s["qd"])
        for j, v in enumerate(release):
            w.board.write("release", v, j)
        for j, (d, e) in enumerate(zip(s["dac"], s["enable"], strict=True)):
            w.board.write("dac", d, j)
            w.board.write("enable", e, j)
    for dt in s["dts"]:
        c.step(dt)
        r.step(dt)
        _same(c, r)


def test_an_engaged_brake_holds_the_arm_against_gravity():
    """The PUMA at rest with its amplifiers off: with a brake per joint (rated at the effort), engaged by the board's release registers at 0, it moves less than 0.01 deg in 2 s; without brakes, or with them released, the upper arm falls."""
    q0 = np.radians([0.0, 60.0, -150.0, 0.0, -45.0, 0.0])
    held = ArmWorld(PUMA, motors=PUMA560_MOTORS, q0=q0,
                    brake=[m.torque_limit for m in PUMA560_MOTORS])
    assert held.board.values("release") == [0] * 6  # off: engaged
    free = ArmWorld(PUMA, motors=PUMA560_MOTORS, q0=q0)
    for _ in range(200):
        held.step(0.01)
        free.step(0.01)
    assert np.degrees(np.abs(held.truth().q - q0)).max() < 0.01
    assert np.degrees(np.abs(free.truth().q - q0)).max() > 5.0
    for j in range(6):
        held.board.write("release", 1, j)
    held.step(0.5)
    assert np.degrees(np.abs(held.truth().q - q0)).max() > 1.0


def test_a_long_run_on_the_table_matches_the_reference():
    """The PUMA driven for 0.3 s with its tip sliding on the table: C and reference agree
    to 1e-9 at every millisecond, the contact force and its friction included."""
    c, r = _pair("puma", tip=(0.0, 0.0, 0.1), seed=11, q0=np.radians([10, 45, -120, 20, 40, 30]))
    z = float(c.truth().tip[2]) + 0.002
    for w in (c, r):
        w.set_table(z)
        for j in range(6):
            w.board.write("enable", 1, j)
            w.board.write("dac", (1500, -800, 600, 300, -200, 100)[j], j)
    touched = 0
    for _ in range(300):
        c.step(1e-3)
        r.step(1e-3)
        _same(c, r)
        touched += c.truth().contact[2] > 0
    assert touched > 100
    assert np.abs(c.truth().contact[:2]).max() > 1.0   # it slid: friction acted


def test_one_call_of_four_ms_is_four_internal_steps_of_one():
    """step(4 ms) integrates exactly as four step(1 ms) calls (the same internal steps), the
    board's outputs held over it."""
    a, _ = _pair("puma", q0=np.radians([10, 45, -120, 20, 40, 30]), seed=1)
    b, _ = _pair("puma", q0=np.radians([10, 45, -120, 20, 40, 30]), seed=1)
    for w in (a, b):
        w.board.write("enable", 1, 2)
        w.board.write("dac", 9000, 2)
    a.step(4e-3)
    for _ in range(4):
        b.step(1e-3)
    assert a.truth().q.tolist() == b.truth().q.tolist()
    assert a.truth().qd.tolist() == b.truth().qd.tolist()
    assert a.board.values("count") == b.board.values("count")


# ------------------------------------------------------------------ the kernel alone


PARAMS = dict(armature=[0.1], damping=[0.2], friction=[0.5], stop_lo=[-2.0], stop_hi=[2.0],
              stop_k=[1e3], stop_c=[10.0], nm_per_count=[1e-3], amps_per_count=[1e-4],
              effort=[30.0], counts=[1000.0])
OPTIONS = dict(max_step=1e-3, friction_velocity=0.005, gravity=(0.0, 0.0, -9.81),
               tip=(0.0, 0.0, 0.0), table_stiffness=5e4, table_damping=500.0,
               table_friction=0.3, ft_scale=[1e3] * 3 + [1e4] * 3, ft_offsets=[0.0] * 6,
               ft_sigma=[0.0] * 6)


def _one(mass: float = 1.0, inertia: float = 1.0) -> ChainKernels:
    return ChainKernels(["revolute"], [np.eye(4)], [[0.0, 1.0, 0.0]], [0.0], np.eye(4),
                        np.eye(4), [-1.0], [1.0], [mass], [[0.1, 0.0, 0.0]],
                        [np.eye(3) * inertia])


def _kernel(chain: ChainKernels | None = None, **changes) -> ArmKernel:
    params = dict(PARAMS)
    options = dict(OPTIONS)
    for k, v in changes.items():
        (params if k in ARM_ROWS else options)[k] = v
    return ArmKernel(chain if chain is not None else _one(), params, **options)


def _snapshot(k: ArmKernel) -> list:
    return [k.q.tolist(), k.qd.tolist(), k.counts(), k.ft_counts(), k.contact.tolist(),
            k.wrench.tolist(), k.torque.tolist(), k.rng_state]


def test_the_noise_is_the_documented_generator_and_standard_normal():
    """The sensor's noise is splitmix64 with Box-Muller pairs (the reference's NoiseSource
    draws the same numbers from the same seed), zero mean and unit variance; another seed
    gives another sequence."""
    k = _kernel(ft_sigma=[1.0] * 6, ft_scale=[1e6] * 6, seed=12345)
    src = NoiseSource(12345)
    draws = []
    for _ in range(3000):
        k.publish()
        got = k.ft_counts()
        want = [int(np.rint(z * 1e6)) for z in src.normals6()]
        assert got == want
        draws.append(got)
    z = np.array(draws) / 1e6
    assert abs(z.mean()) < 0.03
    assert z.std() == pytest.approx(1.0, abs=0.03)
    assert abs(np.corrcoef(z[:, 0], z[:, 1])[0, 1]) < 0.05
    other = _kernel(ft_sigma=[1.0] * 6, ft_scale=[1e6] * 6, seed=12346)
    other.publish()
    assert other.ft_counts() != draws[0]


def test_drives_give_torque_and_current_within_the_effort():
    """DAC counts times the torque and current per count, zero while disabled, the torque
    clamped at the effort."""
    k = _kernel()
    k.set_drive([20000], [1])
    k.step(1e-3)
    assert k.torque.tolist() == [20.0] and k.current.tolist() == [2.0]
    k.set_drive([-32767], [1])
    k.step(1e-3)
    assert k.torque.tolist() == [-30.0]
    k.set_drive([32767], [0])
    k.step(1e-3)
    assert k.torque.tolist() == [0.0] and k.current.tolist() == [0.0]


def test_zero_dt_changes_nothing():
    """step(0) neither moves the arm nor draws noise."""
    k = _kernel(ft_sigma=[0.1] * 6)
    k.q[0] = 0.3
    k.publish()
    before = _snapshot(k)
    k.step(0.0)
    assert _snapshot(k) == before


REFUSED_STEPS = [
    (math.nan, NonFiniteError), (math.inf, NonFiniteError), (-1e-3, NativeInputError),
    (1e7, NativeInputError),   # beyond PYRT_ARM_MAX_SUBSTEPS internal steps
]


@pytest.mark.parametrize(("dt", "error"), REFUSED_STEPS)
def test_a_refused_step_changes_nothing(dt, error):
    """A step of NaN, infinite, negative or absurdly long dt is refused with its error and
    leaves the state, the registers, the truth and the generator as they were."""
    k = _kernel(ft_sigma=[0.1] * 6)
    k.q[0] = 0.3
    k.step(1e-3)
    before = _snapshot(k)
    with pytest.raises(error):
        k.step(dt)
    assert _snapshot(k) == before


def test_a_blown_state_is_refused_and_nothing_changes():
    """NaN written into the state: step and publish refuse it (NonFiniteError) and change
    nothing else."""
    k = _kernel(ft_sigma=[0.1] * 6)
    k.step(1e-3)
    k.qd[0] = math.nan
    before = _snapshot(k)
    with pytest.raises(NonFiniteError):
        k.step(1e-3)
    with pytest.raises(NonFiniteError):
        k.publish()
    assert str(_snapshot(k)) == str(before)


def test_a_joint_that_moves_nothing_is_singular_and_nothing_changes():
    """No mass, no inertia and no rotor: the step's matrix is singular; SingularError, the
    state unchanged."""
    k = _kernel(_one(mass=0.0, inertia=0.0), armature=[0.0], damping=[0.0], friction=[0.0])
    before = _snapshot(k)
    with pytest.raises(SingularError, match="positive definite"):
        k.step(1e-3)
    assert _snapshot(k) == before


BAD_DESCRIPTIONS = [
    (dict(damping=[-0.1]), NativeInputError),
    (dict(armature=[math.nan]), NonFiniteError),
    (dict(effort=[0.0]), NativeInputError),
    (dict(counts=[math.inf]), NonFiniteError),
    (dict(stop_lo=[1.0], stop_hi=[-1.0]), NativeInputError),
    (dict(max_step=0.0), NativeInputError),
    (dict(friction_velocity=math.nan), NonFiniteError),
    (dict(table_stiffness=-1.0), NativeInputError),
    (dict(ft_scale=[0.0] * 6), NativeInputError),
    (dict(ft_sigma=[-1.0] * 6), NativeInputError),
    (dict(gravity=(0.0, 0.0, math.inf)), NonFiniteError),
    (dict(seed=-1), NativeInputError),
    (dict(seed=2**64), NativeInputError),
    (dict(damping=[0.1, 0.2]), NativeInputError),
]


@pytest.mark.parametrize(("bad", "error"), BAD_DESCRIPTIONS)
def test_a_bad_description_is_refused(bad, error):
    """Out-of-range, non-finite or mis-sized parameters are refused when the kernel is made."""
    with pytest.raises(error):
        _kernel(**bad)


def test_infinite_end_stops_are_allowed():
    """A continuous joint has no end stops (infinite): accepted, and it turns freely."""
    k = _kernel(stop_lo=[-math.inf], stop_hi=[math.inf])
    k.q[0] = 3.0
    k.step(0.01)
    assert math.isfinite(k.q[0])


def test_refused_table_and_payload_change_nothing():
    """A NaN table height or payload is refused; the table and payload stay as they were."""
    chain = _one()
    k = _kernel(chain, tip=(0.0, 0.0, 0.0))
    k.q[0] = 0.5   # the tip (0.1 m along x) dips below z = 0
    k.set_table(0.01)
    k.publish()
    pressed = k.contact.tolist()
    assert pressed[2] > 0
    with pytest.raises(NativeInputError):
        k.set_table(math.nan)
    with pytest.raises(NativeInputError):
        k.set_payload(-1.0, chain)
    with pytest.raises(NativeInputError):
        k.set_payload(1.0, ChainKernels(["revolute"] * 2, [np.eye(4)] * 2, [[0, 0, 1]] * 2,
                                        [0, 0], np.eye(4), np.eye(4), [-1, -1], [1, 1], [1, 1],
                                        [[0, 0, 0]] * 2, [np.eye(3)] * 2))
    k.publish()
    assert k.contact.tolist() == pressed


def test_the_world_refuses_a_bad_seed_or_noise():
    """ArmWorld: a seed outside 0 .. 2**64 - 1 or a negative noise is a ConfigError."""
    with pytest.raises(ConfigError, match="seed"):
        ArmWorld(PUMA, motors=PUMA560_MOTORS, seed=-3)
    with pytest.raises(ConfigError, match="ft_noise"):
        ArmWorld(PUMA, motors=PUMA560_MOTORS, ft_noise=(-0.1, 0.0))


SANITIZE_DRIVER = textwrap.dedent(
    """
    import math
    import numpy as np
    from pyrt.errors import NativeError
    from pyrt.kinematics.puma import puma560
    from pyrt.sim.arm import PUMA560_MOTORS, ArmWorld

    ffi, lib = native.ffi, native.lib
    import pyrt.native._lib as bound
    assert bound.lib is lib, "pyrt.native is not using the sanitized build"
    rng = np.random.default_rng(2)
    chain = puma560(closed_form=False)
    for tip, payload in (((0, 0, 0), 0.0), ((0.01, 0, 0.1), 2.0)):
        w = ArmWorld(chain, motors=PUMA560_MOTORS, tip=tip, payload=payload, seed=5,
                     q0=np.radians([10, 45, -120, 20, 40, 30]))
        w.set_table(float(w.truth().tip[2]) + 0.003)
        for k in range(60):
            j = k % 6
            w.board.write("enable", int(rng.integers(0, 2)), j)
            w.board.write("dac", int(rng.integers(-32767, 32768)), j)
            w.step(float(rng.choice([1e-4, 1e-3, 2.5e-3])))
        w.set_state(np.radians([0, 0, 0, 0, 45, 0]), rng.uniform(-1, 1, 6))
        for bad in (math.nan, -1.0, 1e9):
            try:
                w.step(bad)
            except (NativeError, ValueError):
                pass
    size = ffi.new("int32_t *")
    assert lib.pyrt_arm_work_size(0, size) == lib.PYRT_EINVAL
    assert lib.pyrt_arm_work_size(1, ffi.NULL) == lib.PYRT_EINVAL
    assert lib.pyrt_arm_work_size(lib.PYRT_ARM_MAX_JOINTS + 1, size) == lib.PYRT_EINVAL
    c = ffi.new("pyrt_arm *")
    for fn in (lib.pyrt_arm_check, lib.pyrt_arm_publish):
        assert fn(ffi.NULL) == lib.PYRT_EINVAL
        assert fn(c) == lib.PYRT_EINVAL
    assert lib.pyrt_arm_step(ffi.NULL, 1e-3) == lib.PYRT_EINVAL
    assert lib.pyrt_arm_step(c, 1e-3) == lib.PYRT_EINVAL
    k = w._k
    k._c.n = 7
    assert lib.pyrt_arm_step(k._c, 1e-3) == lib.PYRT_EINVAL
    k._c.n = 6
    print("SANITIZE-DRIVER-OK")
    """
)


@pytest.mark.sanitize
def test_arm_kernel_is_clean_under_the_sanitizers(tmp_path):
    """Every arm entry point, good input and bad, runs without an ASan or UBSan report."""
    assert_clean(run_under_asan(PRELUDE + SANITIZE_DRIVER, tmp_path))
