"""The PUMA 560: the packaged URDF, its DH twin, and Paul's closed-form inverse with RCCL's configurations."""

from __future__ import annotations

import math
from importlib import resources

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from pyrt.kinematics.puma import (
    CONFIGURATIONS,
    DH,
    LOWER_DEG,
    UPPER_DEG,
    URDF,
    PaulInverse,
    Unreachable,
    parse_config,
    puma560,
    puma560_dh,
)

LOWER = np.radians(LOWER_DEG)
UPPER = np.radians(UPPER_DEG)


@st.composite
def joints(draw, lower=LOWER, upper=UPPER) -> np.ndarray:
    """Joint values within the given limits."""
    return np.array([draw(st.floats(float(lo), float(hi))) for lo, hi in zip(lower, upper, strict=True)])


def wrapped(a: np.ndarray) -> np.ndarray:
    return np.arctan2(np.sin(a), np.cos(a))


def assert_pose(a: np.ndarray, b: np.ndarray, tol: float = 1e-9) -> None:
    np.testing.assert_allclose(a, b, rtol=0.0, atol=tol)


@pytest.fixture(scope="module")
def chain():
    return puma560()


@settings(max_examples=150, deadline=None)
@given(joints())
def test_all_eight_configurations_of_a_reachable_pose_are_found_and_map_back(q):
    """For a pose the arm reaches, each of the eight configurations gives joints whose pose is it (to 1e-9) and which are in that configuration."""
    paul = PaulInverse()
    pose = paul.fk(q)
    # keep away from the shoulder singularity (the wrist centre on joint 1's axis cylinder)
    assume(math.hypot(pose[0, 3], pose[1, 3]) > DH[2][0] + 1e-4)
    found = {}
    for cfg in CONFIGURATIONS:
        sol = paul.inverse(pose, cfg, limits=False)
        assert_pose(paul.fk(sol), pose)
        found[cfg] = sol
        if abs(math.sin(sol[4])) > 1e-9:
            assert paul.config_of(sol) == cfg
    # eight distinct joint vectors (away from the singular sets: the wrist's, and the
    # stretched or folded elbow's, where the wrist centre is on the upper arm's line)
    pairs = [(a, b) for a in CONFIGURATIONS for b in CONFIGURATIONS if a < b]
    elbow = DH[2][1] * math.sin(q[2]) + DH[3][0] * math.cos(q[2])
    if abs(math.sin(q[4])) > 1e-3 and abs(elbow) > 1e-3:
        for a, b in pairs:
            assert np.max(np.abs(wrapped(found[a] - found[b]))) > 1e-6, (a, b)


@settings(max_examples=150, deadline=None)
@given(joints())
def test_config_of_names_the_configuration_that_gives_the_joints_back(q):
    """Solving fk(q) in config_of(q), seeded with q, gives q back (joints 4 and 6 up to their sum at the wrist singularity)."""
    paul = PaulInverse(lower=LOWER, upper=UPPER)
    cfg = paul.config_of(q)
    assert cfg in CONFIGURATIONS
    back = paul.inverse(paul.fk(q), cfg, seed=q)
    assert_pose(paul.fk(back), paul.fk(q))
    if abs(math.sin(q[4])) > 1e-4 and math.hypot(*paul.fk(q)[:2, 3]) > DH[2][0] + 1e-4:
        np.testing.assert_allclose(back, q, atol=1e-7)


@settings(max_examples=100, deadline=None)
@given(joints())
def test_the_attached_closed_form_honours_the_joint_limits(chain, q):
    """The chain's closed form returns only joints within the limits that map back through the chain's own fk; a refusal names the joint and its limits; q's own configuration is always found."""
    cf = chain.closed_form
    pose = chain.fk(q)
    assume(math.hypot(pose[0, 3], pose[1, 3]) > DH[2][0] + 1e-4)
    assert cf.configurations == CONFIGURATIONS
    for cfg in cf.configurations:
        sol = cf.solve(pose, cfg)
        if sol is None:
            why = cf.reason(pose, cfg)
            assert why.startswith(cfg) and "beyond its limits" in why and "joint q" in why
            continue
        assert np.all(sol >= chain.lower) and np.all(sol <= chain.upper)
        assert chain.limit_violation(sol) is None
        assert_pose(chain.fk(sol), pose)
    assert cf.solve(pose, cf.config_of(q)) is not None


@settings(max_examples=50, deadline=None)
@given(joints())
def test_urdf_and_dh_give_the_same_arm(chain, q):
    """The chain read from the packaged URDF, the chain from the DH table and the closed form's own DH product agree (poses and Jacobians)."""
    dh = puma560_dh()
    assert_pose(chain.fk(q), dh.fk(q), 1e-12)
    assert_pose(chain.fk(q), PaulInverse().fk(q), 1e-12)
    np.testing.assert_allclose(chain.jacobian(q), dh.jacobian(q), atol=1e-12)


def test_the_urdf_carries_the_published_parameters(chain):
    """The URDF's chain has the six joints, the source's limits, masses and centres of mass, and the motors' damping and friction referred to the joints."""
    assert chain.name == "puma560" and chain.n == 6
    assert chain.joint_names == tuple(f"joint{i}" for i in range(1, 7))
    np.testing.assert_allclose(chain.lower, LOWER, atol=1e-15)
    np.testing.assert_allclose(chain.upper, UPPER, atol=1e-15)
    masses = [j.inertial.mass for j in chain.joints]
    assert masses == [0.0, 17.4, 4.8, 0.82, 0.34, 0.09]
    # link 2's centre of mass: (a2, 0, 0) + r2 in its joint frame
    np.testing.assert_allclose(chain.joints[1].inertial.com, [0.4318 - 0.3638, 0.006, 0.2275], atol=1e-12)
    # joint 1: damping B G^2, friction G (|Tc+| + |Tc-|) / 2
    assert chain.joints[0].damping == pytest.approx(1.48e-3 * 62.6111**2, rel=1e-5)
    assert chain.joints[0].friction == pytest.approx(62.6111 * (0.395 + 0.435) / 2, rel=1e-5)
    assert all(j.effort > 0 and j.velocity > 0 for j in chain.joints)


def test_the_urdf_ships_inside_the_package():
    """puma560.urdf is package data of pyrt.kinematics (found through importlib.resources)."""
    data = resources.files("pyrt.kinematics") / "data" / "puma560.urdf"
    assert data.is_file() and URDF.is_file()
    assert '<robot name="puma560">' in data.read_text(encoding="utf-8")


UNREACHABLE = [
    ((1.5, 0.0, 0.8), "beyond the arm's reach"),
    ((0.05, 0.0, 0.8), "closer than the shoulder offset"),
]


@pytest.mark.parametrize(("xyz", "why"), UNREACHABLE)
def test_an_unreachable_pose_is_refused_with_a_reason(chain, xyz, why):
    """A pose out of reach, inside the shoulder offset's cylinder or too near the shoulder is refused in every configuration, with the reason."""
    pose = np.eye(4)
    pose[:3, 3] = xyz
    cf = chain.closed_form
    for cfg in CONFIGURATIONS:
        assert cf.solve(pose, cfg) is None
        assert why in cf.reason(pose, cfg)
        with pytest.raises(Unreachable, match=why):
            cf.inverse(pose, cfg)
    assert cf.solve_all(pose) == {}


def test_a_wrist_centre_too_near_the_shoulder_is_refused():
    """With a forearm shorter than the upper arm, a wrist centre nearer the shoulder than their difference is refused as too close."""
    short = [list(row) for row in DH]
    short[3][0] = 0.2  # d4: forearm 0.2 m against a2 = 0.4318 m
    paul = PaulInverse(dh=[tuple(r) for r in short])
    pose = np.eye(4)
    pose[:3, 3] = (0.0, 0.2, 0.672 + 0.1)  # 0.1 m above the shoulder, in the arm's plane
    with pytest.raises(Unreachable, match="too close to the shoulder"):
        paul.inverse(pose, "righty-above-noflip")


def test_a_configuration_beyond_a_joint_limit_is_refused_naming_the_joint(chain):
    """A configuration that needs a joint beyond its limit is refused naming the joint, the angle and its limits; the pose's own configuration is reached."""
    import re

    q = np.radians([150.0, 30.0, -60.0, 10.0, 40.0, 0.0])
    pose = chain.fk(q)
    cf = chain.closed_form
    why = cf.reason(pose, "lefty-above-flip")
    m = re.fullmatch(r"lefty-above-flip: joint q(\d) would be at (-?[\d.]+) deg, "
                     r"beyond its limits (-?[\d.]+) \.\. (-?[\d.]+) deg", why or "")
    assert m, why
    k, at, lo, hi = int(m[1]) - 1, float(m[2]), float(m[3]), float(m[4])
    assert (lo, hi) == (LOWER_DEG[k], UPPER_DEG[k]) and not lo <= at <= hi
    assert cf.solve(pose, "lefty-above-flip") is None
    assert cf.config_of(q) == "righty-below-flip"
    np.testing.assert_allclose(cf.solve(pose, "righty-below-flip"), q, atol=1e-9)
    sol = cf.inverse(pose, "lefty-above-flip", limits=False)
    assert_pose(chain.fk(sol), pose)


def test_a_closed_form_for_another_arm_is_refused(chain):
    """PaulInverse.for_chain refuses a chain whose forward kinematics is not the PUMA table's (a longer forearm; three joints)."""
    from pyrt.kinematics import Chain
    from pyrt.kinematics.joint import transform

    longer = chain.replace(origins=[j.origin for j in chain.joints[:3]]
                           + [chain.joints[3].origin @ transform((0.0, 0.01, 0.0))]
                           + [j.origin for j in chain.joints[4:]])
    with pytest.raises(ValueError, match="not the arm of this DH table"):
        PaulInverse.for_chain(longer)
    with pytest.raises(ValueError, match="needs 6"):
        PaulInverse.for_chain(Chain("three", chain.joints[:3]))


def test_configuration_words_in_any_order_and_bad_ones_refused():
    """A configuration is one word of each pair in any order and case; a missing pair or an unknown word is refused naming the pairs."""
    assert parse_config("Flip, lefty above") == "lefty-above-flip"
    assert parse_config("righty/below/noflip") == "righty-below-noflip"
    for bad in ("righty-above", "righty-lefty-above-flip", "righty-above-noflip-extra", ""):
        with pytest.raises(ValueError, match="righty"):
            parse_config(bad)
    with pytest.raises(ValueError, match="configuration"):
        PaulInverse().inverse(np.eye(4), "sideways")


@settings(max_examples=50, deadline=None)
@given(joints(), st.lists(st.floats(-0.3, 0.3), min_size=12, max_size=12),
       st.lists(st.floats(-0.05, 0.05), min_size=6, max_size=6))
def test_base_tool_and_offsets_are_honoured_both_ways(chain, q, six, offsets):
    """With a base, a tool and joint offsets on the chain, the closed form built for it still maps back through the chain's fk."""
    from pyrt.kinematics.joint import transform

    base = transform(six[:3], six[3:6])
    tool = transform(six[6:9], six[9:12])
    moved = chain.replace(base=base, tool=tool, offsets=offsets)
    cf = PaulInverse.for_chain(moved)
    pose = moved.fk(q)
    theta = q + np.asarray(offsets)
    wrist = PaulInverse().fk(theta)
    assume(math.hypot(wrist[0, 3], wrist[1, 3]) > DH[2][0] + 1e-4)
    for cfg in CONFIGURATIONS:
        sol = cf.inverse(pose, cfg, limits=False)
        assert_pose(moved.fk(sol), pose)
    assert_pose(cf.fk(q), pose, 1e-12)


# ---------------------------------------------------------------- the C kernel


@st.composite
def arms(draw):
    """A PUMA with a random base, tool and offsets (limits the PUMA's, or none)."""
    from pyrt.kinematics.joint import transform

    six = [draw(st.floats(-0.5, 0.5)) for _ in range(12)]
    offsets = [draw(st.floats(-0.3, 0.3)) for _ in range(6)]
    limited = draw(st.booleans())
    return PaulInverse(base=transform(six[:3], six[3:6]), tool=transform(six[6:9], six[9:12]),
                       offsets=offsets, lower=LOWER if limited else None,
                       upper=UPPER if limited else None)


@settings(max_examples=300, deadline=None)
@given(arms(), joints(), st.sampled_from(CONFIGURATIONS), st.booleans(), st.booleans(),
       st.lists(st.floats(-1.2, 1.2), min_size=3, max_size=3), st.booleans())
def test_the_c_inverse_matches_its_python_reference(arm, q, cfg, seeded, nearest, xyz, moved):
    """csrc/puma.c gives the reference's joints (to 1e-9), reason and deciding number, reachable or not, seeded or not."""
    import _ref_puma as ref

    pose = arm.fk(q)
    if moved:  # anywhere in a box: out of reach or inside the shoulder offset too
        pose = pose.copy()
        pose[:3, 3] = xyz
    seed = q + 0.3 if seeded else None
    lengths = (DH[0][0], DH[1][1], DH[2][1], DH[2][0], DH[3][0])
    lower = arm.lower if arm.lower is not None else np.full(6, -np.inf)
    upper = arm.upper if arm.upper is not None else np.full(6, np.inf)
    want, why, detail = ref.inverse(lengths, arm.base, arm.tool, arm.offsets, lower, upper, pose,
                                    cfg, seed, nearest=nearest)
    bits = _bits(cfg) | (8 if nearest else 0)
    got, gwhy, gdetail = arm._kernel.inverse(pose, bits, seed)
    assert gwhy == why
    if why >= ref.LIMIT:  # the joint's angle (180 deg may be -180, as below)
        # at the wrist's singularity (joint 5 at 0) the split between joints 4 and 6 is fixed
        # only to about eps / sin(q5): 1e-9 there is rounding, not a disagreement
        wrist = min(abs(math.sin(q[4])), abs(math.sin(q[4] + arm.offsets[4])))
        assert abs(wrapped(gdetail - detail)) < (1e-9 if wrist > 1e-5 else 1e-6)
    else:
        assert gdetail == pytest.approx(detail, abs=1e-9)
    if want is None:
        assert got is None
        return
    # the same angles (an angle of exactly 180 deg may come back as -180: the sign of a
    # zero decides atan2 there), within the limits, on the pose
    if arm.lower is not None:
        assert np.all(got >= arm.lower) and np.all(got <= arm.upper)
    if not nearest and not moved:
        assert_pose(arm.fk(got), pose)
    if abs(math.sin(want[4])) < 1e-5:
        # near the wrist's singularity only q4 + q6 is well determined
        keep = [0, 1, 2, 4]
        np.testing.assert_allclose(wrapped(got[keep] - want[keep]), 0, atol=1e-9)
        assert abs(wrapped(got[3] + got[5] - want[3] - want[5])) < 1e-9
    else:
        np.testing.assert_allclose(wrapped(got - want), 0, atol=1e-9)


def _bits(cfg: str) -> int:
    arm, elbow, wrist = cfg.split("-")
    return (arm == "lefty") * 1 + (elbow == "below") * 2 + (wrist == "flip") * 4


def test_the_c_inverse_refuses_bad_arrays():
    """A pose of the wrong shape, or NaN in the pose or the seed, is refused before any answer."""
    from pyrt.errors import NativeError

    paul = PaulInverse()
    pose = paul.fk(np.zeros(6))
    with pytest.raises(NativeError, match="pose"):
        paul.inverse(np.eye(3), "righty-above-noflip")
    bad = pose.copy()
    bad[0, 3] = np.nan
    with pytest.raises(NativeError, match=r"non-finite|NaN"):
        paul.inverse(bad, "righty-above-noflip")
    with pytest.raises(NativeError, match=r"non-finite|NaN"):
        paul.inverse(pose, "righty-above-noflip", seed=[0, 0, np.nan, 0, 0, 0])


@pytest.mark.sanitize
def test_the_c_inverse_under_the_sanitizers(tmp_path):
    """pyrt_puma_inverse under ASan and UBSan: every configuration and option, out of reach, NULL pointers and NaN."""
    import textwrap

    from _sanitize import PRELUDE, assert_clean, run_under_asan

    driver = PRELUDE + textwrap.dedent(
        """
        import numpy as np
        from pyrt.kinematics.puma import CONFIGURATIONS, PaulInverse, LOWER_DEG, UPPER_DEG
        ffi, lib = native.ffi, native.lib
        paul = PaulInverse(lower=np.radians(LOWER_DEG), upper=np.radians(UPPER_DEG))
        rng = np.random.default_rng(0)
        for _ in range(300):
            q = rng.uniform(-3, 3, 6)
            pose = paul.fk(q)
            pose[:3, 3] += rng.normal(0, 0.3, 3) * rng.integers(0, 2)
            for bits in range(32):
                paul._kernel.inverse(pose, bits, q if bits & 1 else None)
        arm = paul._kernel._arm
        q = ffi.new("double[6]"); why = ffi.new("int32_t *"); d = ffi.new("double[2]")
        p = ffi.new("double[16]", list(np.eye(4).ravel()))
        assert lib.pyrt_puma_inverse(ffi.NULL, p, 0, ffi.NULL, q, why, d) == lib.PYRT_EINVAL
        assert lib.pyrt_puma_inverse(arm, ffi.NULL, 0, ffi.NULL, q, why, d) == lib.PYRT_EINVAL
        assert lib.pyrt_puma_inverse(arm, p, 0, ffi.NULL, ffi.NULL, why, d) == lib.PYRT_EINVAL
        p[3] = float("nan")
        assert lib.pyrt_puma_inverse(arm, p, 0, ffi.NULL, q, why, d) == lib.PYRT_ENONFINITE
        print("SANITIZE-DRIVER-OK")
        """
    )
    assert_clean(run_under_asan(driver, tmp_path))


def test_the_examples_of_docs_kinematics_run_as_written():
    """The python blocks of docs/kinematics.md, run one after the other in one namespace, raise nothing (their asserts hold)."""
    import re
    from pathlib import Path

    page = Path(__file__).resolve().parent.parent / "docs" / "kinematics.md"
    blocks = re.findall(r"```python\n(.*?)```", page.read_text(encoding="utf-8"), re.S)
    assert len(blocks) >= 6
    namespace: dict = {"print": lambda *a, **k: None}
    exec(compile("\n".join(blocks), str(page), "exec"), namespace)
    assert namespace["fit"].converged


def test_a_chain_replaced_with_new_geometry_never_keeps_a_stale_closed_form(chain):
    """replace(base/tool/offsets) remakes the closed form for the new arm; a foreign one is dropped."""
    from pyrt.kinematics.joint import rpy_matrix

    base = np.eye(4)
    base[:3, :3] = rpy_matrix(0.0, 0.0, 0.3)
    base[:3, 3] = (0.1, -0.2, 0.05)
    moved = chain.replace(base=base, offsets=np.full(6, 0.01))
    assert moved.closed_form is not None and moved.closed_form is not chain.closed_form
    q = np.array([0.2, -0.5, 0.3, 0.4, -0.6, 0.7])
    pose = moved.fk(q)
    cfg = moved.closed_form.config_of(q)
    assert_pose(moved.fk(moved.closed_form.solve(pose, cfg)), pose)

    class Foreign:
        configurations = ("only",)

        def solve(self, pose, config):
            return np.zeros(6)

        def config_of(self, q):
            return "only"

    foreign = chain.replace(closed_form=Foreign())
    assert foreign.replace(name="same geometry").closed_form is foreign.closed_form
    assert foreign.replace(base=base).closed_form is None


@settings(max_examples=60, deadline=None)
@given(joints(), st.lists(st.floats(-0.05, 0.05), min_size=6, max_size=6),
       st.integers(1, 30), st.sampled_from(CONFIGURATIONS), st.booleans())
def test_a_batch_of_poses_is_solved_as_one_by_one_each_seeded_at_the_one_before(
        chain, q, step, m, cfg, far):
    """solve_many gives, to the last bit, what the inverse gives pose by pose seeded at the
    answer before, stopping at the first pose out of reach with its reason; the prepared
    solver answers one pose as solve does."""
    paul = chain.closed_form
    poses = np.array([chain.fk(q + np.asarray(step) * i) for i in range(m)])
    if far:  # a pose beyond the reach part-way
        poses[m // 2, :3, 3] += 5.0
    rows, why = paul.solve_many(poses, cfg, q)
    ref, seed, reason = [], q, None
    for pose in poses:
        try:
            got = paul.inverse(pose, cfg, seed)
        except Unreachable as exc:
            reason = str(exc)
            break
        ref.append(got)
        seed = got
    assert rows.shape == (len(ref), 6)
    assert np.array_equal(rows, np.array(ref).reshape(-1, 6))
    assert why == reason
    solver = paul.solver()
    solver.pose[...] = poses[0]
    solver.seed[...] = q
    reached = solver(paul.bits(cfg)) == solver.REACHED
    one = paul.solve(poses[0], cfg, q)
    assert reached == (one is not None)
    if reached:
        assert np.array_equal(solver.q, one)


def test_the_batch_refuses_arrays_it_cannot_bind(chain):
    """inverse_many takes float64 C-contiguous arrays of matching shapes only; others are refused, nothing written."""
    from pyrt.native._errors import NativeInputError

    kernel = chain.closed_form._kernel
    poses = np.array([chain.fk(np.zeros(6))] * 3)
    out = np.full((3, 6), 7.0)
    for bad in (poses.astype(np.float32), poses[:, :, ::-1].copy()[:, :, ::-1], poses[:2]):
        with pytest.raises(NativeInputError):
            kernel.inverse_many(bad, 0, np.zeros(6), out)
    assert (out == 7.0).all()
