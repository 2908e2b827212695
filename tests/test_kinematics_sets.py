"""pyrt.kinematics joint sets: the PUMA split into arm and wrist, a two-arm torso
from a branched URDF, per-set fk composing to the whole, the decoupled inverse
against Paul's closed form, calibration across sets, and refused descriptions."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, example, given, settings
from hypothesis import strategies as st

from pyrt.errors import ConfigError
from pyrt.kinematics import Chain, JointSets
from pyrt.kinematics.calibration import CalibrationModel
from pyrt.kinematics.puma import DH, LOWER_DEG, UPPER_DEG, puma560

PUMA = puma560()
LOWER = np.radians(LOWER_DEG)
UPPER = np.radians(UPPER_DEG)
SPLIT = {"arm": ["joint1", "joint2", "joint3"], "wrist": [3, 4, 5]}


@st.composite
def joints(draw, lower=LOWER, upper=UPPER) -> np.ndarray:
    """Joint values within the given limits."""
    return np.array([draw(st.floats(float(lo), float(hi)))
                     for lo, hi in zip(lower, upper, strict=True)])


def torso_urdf() -> str:
    """A two-arm torso: a waist joint, a fixed chest, two 3-joint arms each with a tool."""
    def joint(name, parent, child, xyz, rpy="0 0 0", axis="0 0 1", kind="revolute"):
        lim = '<limit lower="-3" upper="3" effort="10" velocity="2"/>' if kind != "fixed" else ""
        return (f'<joint name="{name}" type="{kind}"><parent link="{parent}"/>'
                f'<child link="{child}"/><origin xyz="{xyz}" rpy="{rpy}"/>'
                f'<axis xyz="{axis}"/>{lim}</joint>')

    links = ["base", "waist", "chest", "l1", "l2", "l3", "l_tool", "r1", "r2", "r3", "r_tool"]
    body = "".join(f'<link name="{ln}"/>' for ln in links)
    body += joint("waist_yaw", "base", "waist", "0 0 0.8")
    body += joint("chest_mount", "waist", "chest", "0 0 0.3", "0 0.1 0", kind="fixed")
    for side, y in (("l", 0.2), ("r", -0.2)):
        body += joint(f"{side}_shoulder", "chest", f"{side}1", f"0 {y} 0.1", "1.5708 0 0")
        body += joint(f"{side}_elbow", f"{side}1", f"{side}2", "0.3 0 0", axis="0 1 0")
        body += joint(f"{side}_wrist", f"{side}2", f"{side}3", "0.25 0 0", "0 0 0.3",
                      axis="1 0 0")
        body += joint(f"{side}_flange", f"{side}3", f"{side}_tool", "0.05 0 0.02", kind="fixed")
    return f'<robot name="torso">{body}</robot>'


TORSO = torso_urdf()


def test_split_maps_each_set_to_its_indices_and_chain():
    """The PUMA split as arm = joints 1-3 and wrist = joints 4-6: indices, joint names, mounting."""
    sets = JointSets.split(PUMA, SPLIT)
    assert sets.names == ("arm", "wrist")
    assert sets.indices("arm") == (0, 1, 2) and sets.indices(["wrist"]) == (3, 4, 5)
    assert sets.indices(["wrist", "arm"]) == tuple(range(6))
    assert sets["wrist"].joint_names == ("joint4", "joint5", "joint6")
    assert sets["wrist"].parent == "arm" and sets["wrist"].parent_joint == 2
    assert sets.owner("joint5") == "wrist" and sets.owner(1) == "arm"
    assert sets.joint_names == PUMA.joint_names
    np.testing.assert_array_equal(sets.lower, PUMA.lower)
    np.testing.assert_array_equal(sets.upper, PUMA.upper)
    assert repr(sets) == "JointSets('puma560': arm=1-3, wrist=4-6)"


@settings(max_examples=100, deadline=None)
@given(q=joints())
def test_per_set_fk_composed_equals_the_whole_chain(q):
    """arm.fk(q1..3) @ wrist.fk(q4..6) is the PUMA's fk, and each set's world fk is its prefix's."""
    sets = JointSets.split(PUMA, SPLIT)
    arm, wrist = sets["arm"].chain, sets["wrist"].chain
    whole = PUMA.fk(q)
    np.testing.assert_allclose(arm.fk(q[:3]) @ wrist.fk(q[3:]), whole, rtol=0, atol=1e-12)
    np.testing.assert_allclose(sets.fk("wrist", q), whole, rtol=0, atol=1e-12)
    frames = PUMA.frames(q)
    np.testing.assert_allclose(sets.fk("arm", q), frames[3], rtol=0, atol=1e-12)
    np.testing.assert_allclose(sets.mount("wrist", q), frames[3], rtol=0, atol=1e-12)


@settings(max_examples=60, deadline=None)
@given(q=joints(), cut=st.integers(1, 5))
def test_any_serial_cut_composes_to_the_whole(q, cut):
    """A cut anywhere in the chain (two sets) gives the whole fk at the last set's tip."""
    sets = JointSets.split(PUMA, {"a": list(range(cut)), "b": list(range(cut, 6))})
    np.testing.assert_allclose(sets.fk("b", q), PUMA.fk(q), rtol=0, atol=1e-12)
    np.testing.assert_allclose(sets.fk("a", q), PUMA.frames(q)[cut], rtol=0, atol=1e-12)


def _reachable(q: np.ndarray) -> bool:
    """Away from the PUMA's singularities: the wrist (q5), the elbow and the shoulder."""
    pose = PUMA.fk(q)
    centre = pose[:3, 3] - PUMA.base[:3, 3]
    return (abs(math.sin(q[4])) > 0.15 and abs(math.cos(q[2] + math.atan2(DH[2][1], DH[3][0])))
            > 0.15 and math.hypot(centre[0], centre[1]) > DH[2][0] + 0.1)


@settings(max_examples=100, deadline=None)
@given(q=joints(), noise=st.lists(st.floats(-0.05, 0.05), min_size=6, max_size=6))
@example(q=np.array([0.0, 0.0, -2.25, 1.0, 1.0, UPPER[5]]),  # joint 6 at its limit
         noise=[0.0, 0.03125, 0.0, 0.0, 0.0, 0.0])
def test_decoupled_inverse_equals_pauls_closed_form_and_the_full_ik(q, noise):
    """Wrist centre from the arm set, orientation from the wrist set: the same joints as Paul's closed form (in q's configuration) and the full numerical inverse, and fk maps back to the pose."""
    assume(_reachable(q))
    sets = JointSets.split(PUMA, SPLIT)
    pose = PUMA.fk(q)
    seed = np.clip(q + np.array(noise), LOWER, UPPER)
    dec = sets.decoupled_ik(pose, seed)
    assert dec.ok, dec
    np.testing.assert_allclose(PUMA.fk(dec.q), pose, rtol=0, atol=1e-9)
    closed = PUMA.closed_form.solve(pose, PUMA.closed_form.config_of(q), q)
    assert closed is not None
    np.testing.assert_allclose(dec.q, closed, rtol=0, atol=1e-7)
    full = PUMA.ik(pose, seed)
    assert full.ok
    np.testing.assert_allclose(dec.q, full.q, rtol=0, atol=1e-7)


def test_decoupled_inverse_needs_a_spherical_wrist_on_the_arms_tip():
    """A wrist set whose axes do not meet, or not on the position set's tip, is refused by name."""
    sets = JointSets.split(PUMA, {"a": [0, 1], "b": [2, 3, 4, 5]})
    with pytest.raises(ConfigError, match="'b' is not a spherical wrist"):
        sets.decoupled_ik(PUMA.fk(np.zeros(6)), np.zeros(6), position="a", orientation="b")
    with pytest.raises(ConfigError, match="not mounted on the tip of joint set 'b'"):
        sets.decoupled_ik(PUMA.fk(np.zeros(6)), np.zeros(6), position="b", orientation="a")


@settings(max_examples=50, deadline=None)
@given(q=joints(), other=joints())
def test_per_set_inverses_move_only_their_set(q, other):
    """A set's inverse (position, orientation) reaches its target and leaves the other set's joints exactly as seeded."""
    assume(_reachable(q))
    sets = JointSets.split(PUMA, SPLIT)
    seed = np.concatenate([np.clip(q[:3] + 0.03, LOWER[:3], UPPER[:3]), other[3:]])
    point = sets.fk("arm", q)[:3, 3]
    r = sets.ik("arm", point, seed, task="position")
    assert r.ok
    np.testing.assert_allclose(sets.fk("arm", r.q)[:3, 3], point, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(r.q[3:], other[3:])
    seed2 = np.concatenate([q[:3], np.clip(q[3:] + 0.03, LOWER[3:], UPPER[3:])])
    rot = sets.fk("wrist", q)[:3, :3]
    r2 = sets.ik("wrist", rot, seed2, task="orientation")
    assert r2.ok
    np.testing.assert_allclose(sets.fk("wrist", r2.q)[:3, :3], rot, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(r2.q[:3], q[:3])
    whole = JointSets.split(PUMA, {"all": range(6)})
    r3 = whole.ik("all", PUMA.fk(q), np.clip(q + 0.03, LOWER, UPPER))
    assert r3.ok
    np.testing.assert_allclose(PUMA.fk(r3.q), PUMA.fk(q), rtol=0, atol=1e-9)


def test_ik_refuses_a_wrong_target_or_task():
    """Targets of the wrong shape and an unknown task are refused naming what was expected."""
    sets = JointSets.split(PUMA, SPLIT)
    with pytest.raises(ValueError, match="3 numbers"):
        sets.ik("arm", np.eye(4), np.zeros(6), task="position")
    with pytest.raises(ValueError, match=r"\(3, 3\)"):
        sets.ik("wrist", np.zeros(3), np.zeros(6), task="orientation")
    with pytest.raises(ValueError, match="task"):
        sets.ik("wrist", np.eye(4), np.zeros(6), task="speed")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="6 joint values"):
        sets.fk("arm", np.zeros(5))


BAD_SPLITS = [
    ({"arm": [0, 1, 2], "wrist": [2, 3, 4, 5]}, "joint 'joint3' is in joint sets 'arm' and 'wrist'"),
    ({"arm": [0, 1, 2], "wrist": [3, 4]}, r"joint\(s\) joint6 in no joint set"),
    ({"arm": [0, 1, 2], "wrist": ["joint4", "elbow", "joint6"]}, "'elbow' is not a joint"),
    ({"arm": [0, 1, 2], "wrist": [3, 4, 9]}, "joint index 9"),
    ({"arm": [0, 2], "wrist": [1, 3, 4, 5]}, "not a contiguous run"),
    ({"arm": [0, 1, 2], "my wrist": [3, 4, 5]}, "letters, digits and _"),
    ({"arm": [0, 1, 2, 3, 4, 5], "wrist": []}, "'wrist': no joint"),
    ({}, "no joint set"),
]


@pytest.mark.parametrize("spec, message", BAD_SPLITS)
def test_invalid_splits_are_refused_naming_what_is_wrong(spec, message):
    """Overlapping sets, a joint in none, unknown names, gaps and bad names: ConfigError saying which."""
    with pytest.raises(ConfigError, match=message):
        JointSets.split(PUMA, spec)


def test_an_unknown_set_name_is_refused_naming_the_sets():
    """Asking for a set the robot does not have names the sets it has."""
    sets = JointSets.split(PUMA, SPLIT)
    with pytest.raises(ConfigError, match=r"no joint set 'hand' \(its sets: arm, wrist\)"):
        sets.indices(["wrist", "hand"])
    assert "hand" not in sets and "arm" in sets and len(sets) == 2


@settings(max_examples=40, deadline=None)
@given(q=st.lists(st.floats(-3.0, 3.0), min_size=7, max_size=7))
def test_torso_sets_from_a_branched_urdf_compose_to_each_tips_chain(q):
    """trunk / left / right from a two-arm torso URDF: each arm's world fk is the URDF chain to its tip at the trunk's and its own joints."""
    qa = np.array(q)
    sets = JointSets.from_urdf(TORSO, {"trunk": "chest", "left": "l_tool", "right": "r_tool"})
    assert sets.names == ("trunk", "left", "right")
    assert sets.indices("trunk") == (0,) and sets.indices("right") == (4, 5, 6)
    assert sets["left"].parent == "trunk" and sets["right"].parent == "trunk"
    for side, tip in (("left", "l_tool"), ("right", "r_tool")):
        whole = Chain.from_urdf(TORSO, tip_link=tip)
        idx = [0, *sets.indices(side)]
        np.testing.assert_allclose(sets.fk(side, qa), whole.fk(qa[idx]), rtol=0, atol=1e-12)
    chest = Chain.from_urdf(TORSO, tip_link="chest")
    np.testing.assert_allclose(sets.fk("trunk", qa), chest.fk(qa[:1]), rtol=0, atol=1e-12)


def test_shared_trunk_joints_are_ambiguous_unless_one_set_owns_them():
    """One set per tip shares the waist: refused as ambiguous naming it; starting one arm at the chest gives the waist to the other."""
    with pytest.raises(ConfigError, match=r"'l_tool' and 'r_tool' would both own joint\(s\) "
                                          r"waist_yaw: ambiguous.*link 'waist'"):
        JointSets.from_urdf(TORSO)
    sets = JointSets.from_urdf(TORSO, {"left": "l_tool", "right": ("chest", "r_tool")})
    assert sets["left"].joint_names == ("waist_yaw", "l_shoulder", "l_elbow", "l_wrist")
    assert sets["right"].parent == "left" and sets["right"].parent_joint == 0
    q = np.array([0.4, 0.1, -0.5, 0.7, -0.2, 0.9, 0.3])
    whole = Chain.from_urdf(TORSO, tip_link="r_tool")
    np.testing.assert_allclose(sets.fk("right", q), whole.fk(q[[0, 4, 5, 6]]), rtol=0,
                               atol=1e-12)


BAD_URDF_SETS = [
    ({"left": "l_tool", "right": "r_tool"}, r"waist_yaw.*ambiguous"),
    ({"trunk": "chest", "left": "l_tool"}, r"r_elbow, r_shoulder, r_wrist in no joint set"),
    ({"trunk": "chest", "left": "l_tool", "right": "hand"}, "link 'hand' is not a link"),
    ({"trunk": "chest", "left": "l_tool", "right": ("l1", "r_tool")}, "'r_tool' is not below"),
    ({"trunk": "waist", "flange": ("l3", "l_tool"), "left": "l3", "right": "r_tool"},
     "no movable joint between links 'l3' and 'l_tool'"),
    ({"trunk": "chest", "left": ["l_tool"], "right": "r_tool"}, "expected a tip link"),
]


@pytest.mark.parametrize("spec, message", BAD_URDF_SETS)
def test_invalid_urdf_sets_are_refused_naming_what_is_wrong(spec, message):
    """Shared joints, joints in no set, unknown links and empty sets: ConfigError saying which."""
    with pytest.raises(ConfigError, match=message):
        JointSets.from_urdf(TORSO, spec)


def test_a_malformed_urdf_is_refused_with_its_line():
    """The URDF's own faults come from the URDF reader, with the line."""
    with pytest.raises(ConfigError, match="<urdf>:1: joint 'j'"):
        JointSets.from_urdf('<robot name="r"><link name="a"/><link name="b"/>'
                            '<joint name="j" type="spin"><parent link="a"/>'
                            '<child link="b"/></joint></robot>')


def _model() -> CalibrationModel:
    """A model coupling both sets: offsets on an arm and a wrist joint, base and tool."""
    model = CalibrationModel(PUMA.joint_names)
    model.update({"offset.joint2": math.radians(0.5), "offset.joint5": math.radians(-0.3),
                  "base.x": 0.001, "base.rz": math.radians(0.2), "tool.z": 0.002,
                  "tool.rx": math.radians(0.1)})
    return model


@settings(max_examples=40, deadline=None)
@given(q=joints())
def test_calibration_coupling_the_sets_matches_the_calibrated_whole_arm(q):
    """One model over both sets: the calibrated sets' fk is the calibrated chain's, origins corrected too."""
    model = _model()
    model.update({"origin.joint4.y": 0.0005, "origin.joint3.rx": math.radians(0.05)})
    sets = JointSets.split(PUMA, SPLIT).calibrated(model)
    whole = model.apply(PUMA)
    np.testing.assert_allclose(sets.fk("wrist", q), whole.fk(q), rtol=0, atol=1e-12)
    np.testing.assert_allclose(sets.fk("arm", q), whole.frames(q)[3], rtol=0, atol=1e-12)


@settings(max_examples=40, deadline=None)
@given(q=joints())
def test_calibrated_sets_invert_what_they_forward(q):
    """Both directions: the calibrated sets' decoupled inverse of their own fk gives q back, and it is the calibrated arm's closed form."""
    assume(_reachable(q))
    model = _model()
    sets = JointSets.split(PUMA, SPLIT).calibrated(model)
    pose = sets.fk("wrist", q)
    r = sets.decoupled_ik(pose, np.clip(q + 0.02, LOWER, UPPER))
    assert r.ok
    np.testing.assert_allclose(r.q, q, rtol=0, atol=1e-7)
    cal = model.apply(PUMA)
    closed = cal.closed_form.solve(pose, cal.closed_form.config_of(q), q)
    np.testing.assert_allclose(r.q, closed, rtol=0, atol=1e-7)


def test_direct_description_is_checked():
    """Sets given directly: a parent named after its child, or an index in two sets, is refused."""
    from pyrt.kinematics import JointSet

    s = JointSets.split(PUMA, SPLIT)
    arm, wrist = s["arm"], s["wrist"]
    with pytest.raises(ConfigError, match="parent 'arm' is not a joint set named before it"):
        JointSets("p", [wrist, arm])
    with pytest.raises(ConfigError, match="joint 3 is in joint sets 'arm' and 'w2'"):
        JointSets("p", [arm, JointSet("w2", wrist.chain, (2, 3, 4), "arm", 2)])
    with pytest.raises(ConfigError, match="named twice"):
        JointSets("p", [arm, arm])


@settings(max_examples=30, deadline=None)
@given(q=joints(), noise=st.lists(st.floats(-0.05, 0.05), min_size=6, max_size=6))
def test_puma_sets_from_its_urdf_are_the_split(q, noise):
    """The packaged PUMA URDF read as arm (to link3) and wrist: the same fk as the split, and the decoupled inverse on it matches Paul's."""
    from pyrt.kinematics.puma import URDF

    assume(_reachable(q))
    sets = JointSets.from_urdf(URDF, {"arm": "link3", "wrist": "link6"})
    assert sets.indices("wrist") == (3, 4, 5) and sets["wrist"].parent == "arm"
    pose = PUMA.fk(q)
    np.testing.assert_allclose(sets.fk("wrist", q), pose, rtol=0, atol=1e-12)
    r = sets.decoupled_ik(pose, np.clip(q + np.array(noise), LOWER, UPPER))
    assert r.ok
    closed = PUMA.closed_form.solve(pose, PUMA.closed_form.config_of(q), q)
    np.testing.assert_allclose(r.q, closed, rtol=0, atol=1e-7)


def test_default_urdf_sets_skip_a_leaf_fixed_to_the_trunk():
    """One set per tip by default: a camera fixed to the chest ends no set (the arms' shared waist is still what is refused); a serial URDF gives one set."""
    with_camera = TORSO.replace(
        "</robot>", '<link name="camera"/><joint name="cam" type="fixed"><parent link="chest"/>'
                    '<child link="camera"/></joint></robot>')
    with pytest.raises(ConfigError, match=r"'l_tool' and 'r_tool' would both own"):
        JointSets.from_urdf(with_camera)
    sets = JointSets.from_urdf(with_camera, {"trunk": "chest", "left": "l_tool",
                                             "right": "r_tool"})
    assert sets.n == 7
    from pyrt.kinematics.puma import URDF

    one = JointSets.from_urdf(URDF)
    assert one.names == ("link6",) and one.n == 6
