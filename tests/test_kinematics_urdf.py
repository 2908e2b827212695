"""Chains from URDF: a URDF written from a DH table is the same arm as the
table (kinematics and dynamics); fixed joints and fixed links fold in;
malformed URDFs are refused with the file, the line and the reason, and any
mutation of a good URDF either reads or is refused that way."""

from __future__ import annotations

import math

import _ref_kinematics as ref
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pyrt.errors import ConfigError
from pyrt.kinematics import Chain, DHRow, rpy_of

SEEDS = st.integers(0, 2**32 - 1)


def _f(v) -> str:
    return " ".join(repr(float(x)) for x in v)


def _origin(t: np.ndarray) -> str:
    return f'<origin xyz="{_f(t[:3, 3])}" rpy="{_f(rpy_of(t))}"/>'


def _inertial(mass, com_pose: np.ndarray, inertia) -> str:
    i = np.asarray(inertia, dtype=float).tolist()
    return (f"<inertial>{_origin(com_pose)}<mass value=\"{float(mass)!r}\"/>"
            f"<inertia ixx=\"{i[0][0]!r}\" ixy=\"{i[0][1]!r}\" ixz=\"{i[0][2]!r}\" "
            f"iyy=\"{i[1][1]!r}\" iyz=\"{i[1][2]!r}\" izz=\"{i[2][2]!r}\"/></inertial>")


def _tf(rot=None, xyz=(0.0, 0.0, 0.0)) -> np.ndarray:
    t = np.eye(4)
    t[:3, :3] = np.eye(3) if rot is None else rot
    t[:3, 3] = xyz
    return t


def _rx(a):
    return ref.rotation((1.0, 0.0, 0.0), a)


def _rz(a):
    return ref.rotation((0.0, 0.0, 1.0), a)


def urdf_of_dh(rows: list[DHRow], name: str = "dharm", flange: float | None = None) -> str:
    """A URDF of a standard DH table, written as a user would: joint k's
    origin is Tx(a_(k-1)) Rx(alpha_(k-1)) times the row's constant Tz(d) Rz(theta),
    the inertial in DH frame k, the last Tx(a) Rx(alpha) a fixed joint to a
    'flange' link (with a point mass *flange* kg on it, when given)."""
    out = [f'<?xml version="1.0"?>\n<robot name="{name}">', '  <link name="base"/>']
    tail = np.eye(4)
    for k, row in enumerate(rows, 1):
        const = _tf(_rz(row.theta), (0, 0, row.d))
        kind = "revolute" if row.kind == "revolute" else "prismatic"
        out.append(f'  <joint name="j{k}" type="{kind}">\n'
                   f'    <parent link="{"base" if k == 1 else f"l{k - 1}"}"/>'
                   f'<child link="l{k}"/>\n    {_origin(tail @ const)}<axis xyz="0 0 1"/>\n'
                   f'    <limit lower="{float(row.lower)!r}" upper="{float(row.upper)!r}" effort="10" '
                   f'velocity="2"/>\n  </joint>')
        tail = _tf(_rx(row.alpha), (row.a, 0, 0))
        com_pose = tail @ _tf(xyz=row.com)
        out.append(f'  <link name="l{k}">{_inertial(row.mass, com_pose, row.inertia)}</link>')
    out.append(f'  <joint name="to_flange" type="fixed"><parent link="l{len(rows)}"/>'
               f'<child link="flange"/>{_origin(tail)}</joint>')
    if flange is None:
        out.append('  <link name="flange"/>')
    else:
        out.append(f'  <link name="flange">{_inertial(flange, np.eye(4), np.zeros((3, 3)))}'
                   f'</link>')
    out.append("</robot>\n")
    return "\n".join(out)


def random_dh(rng: np.random.Generator, n: int) -> list[DHRow]:
    """A random DH table with inertials (revolute and prismatic joints)."""
    rows = []
    for _ in range(n):
        mass = rng.uniform(0.5, 5.0)
        kind = "prismatic" if rng.random() < 0.25 else "revolute"
        rows.append(DHRow(a=rng.uniform(-0.5, 0.5), alpha=rng.uniform(-3, 3),
                          d=rng.uniform(-0.5, 0.5), theta=rng.uniform(-3, 3), kind=kind,
                          lower=-2.0, upper=2.0, mass=mass, com=rng.uniform(-0.2, 0.2, 3),
                          inertia=ref.random_inertia(rng, mass)))
    return rows


@settings(max_examples=40, deadline=None)
@given(seed=SEEDS, n=st.integers(1, 7))
def test_urdf_round_trip_agrees_with_dh(seed, n):
    """A chain read from a URDF written from a DH table agrees with the table's chain: fk, Jacobian, RNEA, mass matrix, limits."""
    rng = np.random.default_rng(seed)
    rows = random_dh(rng, n)
    # the URDF has no offsets: its joint values are the DH variables less theta (or d)
    u = Chain.from_urdf(urdf_of_dh(rows))
    dh = Chain.from_dh(rows)
    assert u.name == "dharm" and u.n == n
    assert u.joint_names == tuple(f"j{k}" for k in range(1, n + 1))
    np.testing.assert_array_equal(u.lower, dh.lower)
    q = rng.uniform(-2, 2, n)
    qd, qdd = rng.uniform(-1, 1, n), rng.uniform(-2, 2, n)
    np.testing.assert_allclose(u.fk(q), dh.fk(q), atol=1e-12)
    np.testing.assert_allclose(u.jacobian(q), dh.jacobian(q), atol=1e-12)
    np.testing.assert_allclose(u.rnea(q, qd, qdd), dh.rnea(q, qd, qdd), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(u.mass_matrix(q), dh.mass_matrix(q), rtol=1e-9, atol=1e-10)


def test_fixed_link_mass_folds_into_the_link_that_carries_it():
    """A 2 kg flange fixed after the last joint adds exactly a 2 kg point's gravity torque, -Jv' m g."""
    rows = random_dh(np.random.default_rng(11), 4)
    bare = Chain.from_urdf(urdf_of_dh(rows))
    loaded = Chain.from_urdf(urdf_of_dh(rows, flange=2.0))
    q = np.array([0.3, -0.4, 0.5, 0.2])
    np.testing.assert_allclose(loaded.fk(q), bare.fk(q), atol=0)
    extra = -bare.jacobian(q)[:3].T @ (2.0 * np.array([0.0, 0.0, -9.81]))
    np.testing.assert_allclose(loaded.gravity_torque(q) - bare.gravity_torque(q), extra,
                               atol=1e-10)


GOOD = urdf_of_dh(random_dh(np.random.default_rng(3), 3))

BRANCHED = """<robot name="two_fingers">
  <link name="base"/><link name="arm"/><link name="left"/><link name="right"/>
  <joint name="shoulder" type="continuous"><parent link="base"/><child link="arm"/>
    <axis xyz="0 0 1"/></joint>
  <joint name="lf" type="prismatic"><parent link="arm"/><child link="left"/>
    <origin xyz="0.5 0 0"/><axis xyz="0 1 0"/>
    <limit lower="0" upper="0.04" effort="20" velocity="0.2"/></joint>
  <joint name="rf" type="prismatic"><parent link="arm"/><child link="right"/>
    <origin xyz="0.5 0 0"/><axis xyz="0 -1 0"/>
    <limit lower="0" upper="0.04" effort="20" velocity="0.2"/></joint>
</robot>"""


def test_branched_tree_needs_a_tip_and_then_reads_the_branch():
    """A tree with two leaves names them and asks for the tip; with tip_link it reads that branch (a continuous joint has no limits)."""
    with pytest.raises(ConfigError, match=r"2 leaf links.*left, right.*name the tip"):
        Chain.from_urdf(BRANCHED)
    c = Chain.from_urdf(BRANCHED, tip_link="right")
    assert c.joint_names == ("shoulder", "rf")
    assert c.lower[0] == -math.inf and c.upper[0] == math.inf
    np.testing.assert_allclose(c.fk([math.pi / 2, 0.04])[:3, 3], [0.04, 0.5, 0.0], atol=1e-12)
    c2 = Chain.from_urdf(BRANCHED, base_link="arm", tip_link="left")
    assert c2.joint_names == ("lf",)
    with pytest.raises(ConfigError, match="not below"):
        Chain.from_urdf(BRANCHED, base_link="left", tip_link="right")
    with pytest.raises(ConfigError, match="'hand' is not a link"):
        Chain.from_urdf(BRANCHED, tip_link="hand")


def test_urdf_from_a_path(tmp_path):
    """A path reads the file; a missing file is a ConfigError naming it."""
    p = tmp_path / "arm.urdf"
    p.write_text(GOOD)
    assert Chain.from_urdf(p).n == 3
    assert Chain.from_urdf(str(p)).n == 3
    with pytest.raises(ConfigError, match=r"nothere\.urdf.*cannot read"):
        Chain.from_urdf(tmp_path / "nothere.urdf")


def _swap(old: str, new: str, count: int = 1):
    def f(text: str) -> str:
        assert old in text, old
        return text.replace(old, new, count)
    return f


# (mutation of GOOD, what the message must say, the line it must name or None)
MALFORMED = [
    (lambda t: t[: len(t) // 2], "not well-formed", None),
    (lambda t: t.replace("<robot ", "<robit ").replace("</robot>", "</robit>"),
     "root element is <robit>", 2),
    (_swap('<robot name="dharm">', "<robot>"), "needs a name", 2),
    (_swap('type="revolute"', 'type="ball"'), "type 'ball' is not one of", None),
    (_swap('<child link="l2"/>', '<child link="nowhere"/>'), "child link 'nowhere' is not defined",
     None),
    (_swap('<parent link="l1"/>', ""), "needs <parent link", None),
    (_swap('<axis xyz="0 0 1"/>', '<axis xyz="0 0 0"/>'), "axis is the zero vector", None),
    (_swap('<axis xyz="0 0 1"/>', '<axis xyz="0 one 1"/>'), "expected 3 finite numbers", None),
    (_swap('lower="-2.0"', 'lower="3.0"'), "above upper", None),
    (_swap('effort="10"', 'effort="-1"'), "effort >= 0", None),
    (_swap('effort="10" ', ""), "needs effort=", None),
    (lambda t: t.replace(t[t.index("<limit"): t.index("/>", t.index("<limit")) + 2], "", 1),
     "needs <limit", None),
    (_swap("<mass value=", '<mass value="-3" old='), "mass >= 0", None),
    (_swap('<link name="l2">', '<link name="l1">'), "link 'l1' is defined twice", None),
    (_swap('name="j2"', 'name="j1"'), "joint 'j1' is defined twice", None),
    (_swap('<child link="l3"/>', '<child link="l2"/>'), "already has a parent", None),
    (_swap('type="revolute"', 'type="floating"'), "cannot be part of a serial chain", None),
    (_swap("ixy=", 'ixy="1e3" old_ixy='), "positive semi-definite", None),
]


@pytest.mark.parametrize("mutate,message,line", MALFORMED)
def test_malformed_urdf_is_refused_with_the_reason_and_line(mutate, message, line):
    """Each malformed URDF raises ConfigError with the reason, the place (<urdf>:LINE) and the element."""
    text = mutate(GOOD)
    with pytest.raises(ConfigError) as info:
        Chain.from_urdf(text)
    err = info.value
    assert message in str(err), str(err)
    assert err.file == "<urdf>"
    assert err.line is not None
    if line is not None:
        assert err.line == line


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_mutated_urdf_reads_or_is_refused_clearly(data):
    """Any mutation of a good URDF (a cut, a deleted or inserted run, a changed number) reads as a chain or raises ConfigError: never another exception."""
    text = GOOD
    kind = data.draw(st.sampled_from(["delete", "insert", "number", "cut"]))
    i = data.draw(st.integers(0, len(text) - 1))
    if kind == "delete":
        j = data.draw(st.integers(i, min(len(text), i + 40)))
        text = text[:i] + text[j:]
    elif kind == "insert":
        junk = data.draw(st.text(alphabet='<>/="\' abcxyz0123456789.-e&;', max_size=12))
        text = text[:i] + junk + text[i:]
    elif kind == "cut":
        text = text[:i]
    else:
        quoted = [k for k in range(len(text)) if text[k] == '"']
        k = data.draw(st.sampled_from(quoted[::2]))
        value = data.draw(st.sampled_from(["nan", "inf", "-1e400", "1e308", "", "1 2", "-0",
                                           "1e-320", "x"]))
        end = text.index('"', k + 1)
        text = text[: k + 1] + value + text[end:]
    try:
        chain = Chain.from_urdf(text)
    except ConfigError as exc:
        assert str(exc)
        return
    q = np.zeros(chain.n)
    assert np.isfinite(chain.fk(q)).all()


def _with_fixed_links(text: str, mass: float | None) -> str:
    """*text* with a 'world' root fixed below its base, and a link 'mid' fixed
    to l1 (a point mass *mass* at its origin, when given)."""
    world = ('<link name="world"/><joint name="mount" type="fixed"><parent link="world"/>'
             '<child link="base"/><origin xyz="0.1 -0.2 0.3" rpy="0.2 0.1 -0.4"/></joint>')
    inertial = "" if mass is None else (
        f'<inertial><mass value="{mass!r}"/>'
        '<inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial>')
    mid = (f'<link name="mid">{inertial}</link><joint name="bracket" type="fixed">'
           '<parent link="l1"/><child link="mid"/><origin xyz="0.05 0.1 -0.2" rpy="0 0.3 0"/>'
           '</joint>')
    return text.replace('  <link name="base"/>', f'  <link name="base"/>{world}{mid}')


def test_fixed_joints_before_and_inside_the_chain():
    """A fixed mount before the first joint moves the whole arm; a mass on a link fixed to link 1 weighs only on joint 1, as a point there."""
    rows = random_dh(np.random.default_rng(12), 3)
    plain = Chain.from_urdf(urdf_of_dh(rows))
    bare = Chain.from_urdf(_with_fixed_links(urdf_of_dh(rows), None), tip_link="flange")
    loaded = Chain.from_urdf(_with_fixed_links(urdf_of_dh(rows), 3.0), tip_link="flange")
    assert bare.joint_names == ("j1", "j2", "j3")
    mount = np.eye(4)
    mount[:3, :3] = ref.rotation((0, 0, 1), -0.4) @ ref.rotation((0, 1, 0), 0.1) @ \
        ref.rotation((1, 0, 0), 0.2)
    mount[:3, 3] = (0.1, -0.2, 0.3)
    q = np.array([0.4, -0.3, 0.8])
    np.testing.assert_allclose(bare.fk(q), mount @ plain.fk(q), atol=1e-12)
    # the mass's Jacobian: the one-joint chain from the world to 'mid'
    to_mid = Chain.from_urdf(_with_fixed_links(urdf_of_dh(rows), None), tip_link="mid")
    assert to_mid.joint_names == ("j1",)
    jv = to_mid.jacobian(q[:1])[:3, 0]
    extra = np.array([-jv @ (3.0 * np.array([0.0, 0.0, -9.81])), 0.0, 0.0])
    np.testing.assert_allclose(loaded.gravity_torque(q) - bare.gravity_torque(q), extra,
                               atol=1e-10)
