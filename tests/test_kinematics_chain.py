"""pyrt.kinematics: the C kernels against the world-frame Python reference,
over random chains and joint values; DH tables against their products;
argument checks."""

from __future__ import annotations

import math

import _ref_kinematics as ref
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pyrt.errors import ConfigError
from pyrt.kinematics import Chain, DHRow, Inertial, Joint
from pyrt.native import NativeInputError, NonFiniteError, SingularError

SEEDS = st.integers(0, 2**32 - 1)
SIZES = st.integers(1, 7)
ANGLES = st.floats(-3.0, 3.0)


def build(d: dict) -> Chain:
    """The pyrt chain of a reference chain dict."""
    joints = [Joint(d["names"][i], d["kinds"][i], d["origins"][i], d["axes"][i],
                    d["lower"][i], d["upper"][i],
                    inertial=Inertial(d["masses"][i], d["coms"][i], d["inertias"][i]))
              for i in range(len(d["kinds"]))]
    return Chain("random", joints, base=d["base"], tool=d["tool"], offsets=d["offsets"])


def case(seed: int, n: int) -> tuple[dict, Chain, np.random.Generator]:
    rng = np.random.default_rng(seed)
    d = ref.random_chain(rng, n)
    return d, build(d), rng


@settings(max_examples=60, deadline=None)
@given(seed=SEEDS, n=SIZES, data=st.data())
def test_fk_and_frames_match_reference(seed, n, data):
    """fk and frames agree with the reference's 4x4 products on random chains."""
    d, chain, _ = case(seed, n)
    q = np.array(data.draw(st.lists(ANGLES, min_size=n, max_size=n)))
    np.testing.assert_allclose(chain.fk(q), ref.fk(d, q), rtol=0, atol=1e-12)
    frames = chain.frames(q)
    assert frames.shape == (n + 1, 4, 4)
    np.testing.assert_allclose(frames, np.array(ref.link_frames(d, q)), rtol=0, atol=1e-12)
    np.testing.assert_allclose(frames[-1] @ chain.tool, chain.fk(q), rtol=0, atol=1e-12)


@settings(max_examples=60, deadline=None)
@given(seed=SEEDS, n=SIZES, data=st.data())
def test_jacobian_matches_reference_and_finite_differences(seed, n, data):
    """The Jacobian agrees with the reference and with central differences of fk."""
    d, chain, _ = case(seed, n)
    q = np.array(data.draw(st.lists(ANGLES, min_size=n, max_size=n)))
    jac = chain.jacobian(q)
    np.testing.assert_allclose(jac, ref.jacobian(d, q), rtol=0, atol=1e-12)
    h = 1e-6
    for i in range(n):
        dq = np.zeros(n)
        dq[i] = h
        tp, tm = chain.fk(q + dq), chain.fk(q - dq)
        np.testing.assert_allclose(jac[:3, i], (tp[:3, 3] - tm[:3, 3]) / (2 * h), atol=1e-8)
        rdot = (tp[:3, :3] - tm[:3, :3]) / (2 * h)
        w = rdot @ chain.fk(q)[:3, :3].T  # [w]x
        np.testing.assert_allclose(jac[3:, i], [w[2, 1], w[0, 2], w[1, 0]], atol=1e-8)


@settings(max_examples=60, deadline=None)
@given(seed=SEEDS, n=SIZES, data=st.data())
def test_rnea_matches_reference(seed, n, data):
    """Newton-Euler in link frames (C) agrees with the world-frame reference, any gravity."""
    d, chain, rng = case(seed, n)
    q = np.array(data.draw(st.lists(ANGLES, min_size=n, max_size=n)))
    qd, qdd = rng.uniform(-2, 2, n), rng.uniform(-5, 5, n)
    g = rng.uniform(-10, 10, 3)
    np.testing.assert_allclose(chain.rnea(q, qd, qdd, g), ref.rnea(d, q, qd, qdd, g),
                               rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(chain.gravity_torque(q), ref.rnea(d, q, np.zeros(n), np.zeros(n)),
                               rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(chain.rnea(q, None, None, None), np.zeros(n), atol=0)


@settings(max_examples=60, deadline=None)
@given(seed=SEEDS, n=SIZES, data=st.data())
def test_mass_matrix_matches_reference_and_is_spd(seed, n, data):
    """The mass matrix equals the sum over links of m Jv'Jv + Jw' I Jw, and is symmetric positive definite."""
    d, chain, _ = case(seed, n)
    q = np.array(data.draw(st.lists(ANGLES, min_size=n, max_size=n)))
    m = chain.mass_matrix(q)
    np.testing.assert_allclose(m, ref.mass_matrix(d, q), rtol=1e-10, atol=1e-10)
    np.testing.assert_array_equal(m, m.T)
    assert np.linalg.eigvalsh(m).min() > 0


@settings(max_examples=60, deadline=None)
@given(seed=SEEDS, n=SIZES, data=st.data())
def test_forward_dynamics_inverts_rnea(seed, n, data):
    """aba(q, qd, rnea(q, qd, qdd)) = qdd, and aba agrees with the reference solve."""
    d, chain, rng = case(seed, n)
    q = np.array(data.draw(st.lists(ANGLES, min_size=n, max_size=n)))
    qd, qdd = rng.uniform(-2, 2, n), rng.uniform(-5, 5, n)
    tau = chain.rnea(q, qd, qdd)
    scale = max(1.0, np.linalg.cond(chain.mass_matrix(q)))
    np.testing.assert_allclose(chain.aba(q, qd, tau), qdd, rtol=0, atol=1e-12 * scale * 10)
    tau2 = rng.uniform(-20, 20, n)
    np.testing.assert_allclose(chain.aba(q, qd, tau2), ref.forward_dynamics(d, q, qd, tau2),
                               rtol=1e-8, atol=1e-12 * scale * 100)


def test_zero_velocity_rnea_is_mass_matrix_times_acceleration_plus_gravity():
    """rnea(q, 0, qdd) = M(q) qdd + g(q): the dynamics' two halves agree."""
    _, chain, rng = case(7, 6)
    q, qdd = rng.uniform(-2, 2, 6), rng.uniform(-3, 3, 6)
    np.testing.assert_allclose(chain.rnea(q, None, qdd),
                               chain.mass_matrix(q) @ qdd + chain.gravity_torque(q), atol=1e-10)


def test_forward_dynamics_refuses_a_joint_that_moves_nothing():
    """A last joint whose link has no mass and no inertia makes aba raise SingularError."""
    d, _, _ = case(3, 3)
    d["masses"][-1] = 0.0
    d["inertias"][-1] = np.zeros((3, 3))
    d["coms"][-1] = np.zeros(3)
    chain = build(d)
    with pytest.raises(SingularError, match="not positive definite"):
        chain.aba(np.zeros(3), np.zeros(3), np.ones(3))


# --------------------------------------------------------------- DH tables


def _standard(a, alpha, d, theta):
    ca, sa, ct, st_ = math.cos(alpha), math.sin(alpha), math.cos(theta), math.sin(theta)
    return np.array([[ct, -st_ * ca, st_ * sa, a * ct], [st_, ct * ca, -ct * sa, a * st_],
                     [0, sa, ca, d], [0, 0, 0, 1]])


def _modified(a, alpha, d, theta):
    ca, sa, ct, st_ = math.cos(alpha), math.sin(alpha), math.cos(theta), math.sin(theta)
    return np.array([[ct, -st_, 0, a], [st_ * ca, ct * ca, -sa, -sa * d],
                     [st_ * sa, ct * sa, ca, ca * d], [0, 0, 0, 1]])


@settings(max_examples=40, deadline=None)
@given(seed=SEEDS, n=SIZES, modified=st.booleans())
def test_dh_chain_is_the_product_of_its_link_transforms(seed, n, modified):
    """A DH chain's fk is the textbook product of A_i (standard or modified), prismatic joints too."""
    rng = np.random.default_rng(seed)
    rows = [DHRow(a=rng.uniform(-0.5, 0.5), alpha=rng.uniform(-3, 3), d=rng.uniform(-0.5, 0.5),
                  theta=rng.uniform(-3, 3), kind="prismatic" if rng.random() < 0.3 else "revolute")
            for _ in range(n)]
    base = ref.random_pose(rng)
    chain = Chain.from_dh(rows, modified=modified, base=base)
    q = rng.uniform(-1, 1, n)
    expected = base.copy()
    for row, qi in zip(rows, q, strict=True):
        th = row.theta + qi if row.kind == "revolute" else row.theta
        dd = row.d + qi if row.kind == "prismatic" else row.d
        expected = expected @ (_modified if modified else _standard)(row.a, row.alpha, dd, th)
    np.testing.assert_allclose(chain.fk(q), expected, atol=1e-12)


def test_dh_inertials_are_given_in_dh_frames():
    """A point mass on the last link of a standard DH chain weighs where its DH frame puts it."""
    com = np.array([0.1, 0.2, 0.3])
    rows = [DHRow(a=0.5, alpha=0.3, d=0.1), DHRow(a=0.4, alpha=-1.0, d=0.2, mass=2.0, com=com)]
    chain = Chain.from_dh(rows)
    q = np.array([0.4, -0.7])
    # a standard chain's tool frame is DH frame 2: the mass's Jacobian is the
    # Jacobian of a tool moved by com
    at_com = np.eye(4)
    at_com[:3, 3] = com
    jac = chain.replace(tool=chain.tool @ at_com).jacobian(q)
    expected = -jac[:3].T @ (2.0 * np.array([0.0, 0.0, -9.81]))
    np.testing.assert_allclose(chain.gravity_torque(q), expected, atol=1e-12)


def test_dh_table_needs_rows():
    """An empty DH table is a ConfigError."""
    with pytest.raises(ConfigError, match="no rows"):
        Chain.from_dh([])


# ------------------------------------------------------------ the chain API


def test_out_arrays_are_reused():
    """With out= each algorithm writes into the given array and returns it."""
    _, chain, rng = case(1, 6)
    q = rng.uniform(-1, 1, 6)
    pose, jac, tau, mm = np.empty((4, 4)), np.empty((6, 6)), np.empty(6), np.empty((6, 6))
    assert chain.fk(q, out=pose) is pose
    assert chain.jacobian(q, out=jac) is jac
    assert chain.rnea(q, q, q, out=tau) is tau
    assert chain.mass_matrix(q, out=mm) is mm
    np.testing.assert_array_equal(pose, chain.fk(q))
    with pytest.raises(NativeInputError, match="out"):
        chain.fk(q, out=np.empty((4, 4), dtype=np.float32))


def test_bad_joint_values_are_refused_and_change_nothing():
    """NaN joint values raise NonFiniteError, a wrong length NativeInputError; the out array is left alone."""
    _, chain, _ = case(2, 4)
    out = np.full((4, 4), 7.0)
    with pytest.raises(NonFiniteError):
        chain.fk([0.0, math.nan, 0.0, 0.0], out=out)
    np.testing.assert_array_equal(out, 7.0)
    with pytest.raises(NativeInputError, match="shape"):
        chain.fk([0.0, 0.0])
    with pytest.raises(NativeInputError, match="real numbers"):
        chain.jacobian(["a", "b", "c", "d"])
    with pytest.raises(NonFiniteError):
        chain.rnea(np.zeros(4), None, None, (0.0, math.inf, 0.0))


def test_lists_and_integers_are_accepted():
    """Joint values may be any real sequence; the answer is the same as for float64 arrays."""
    _, chain, _ = case(4, 3)
    np.testing.assert_array_equal(chain.fk([0, 1, 0]), chain.fk(np.array([0.0, 1.0, 0.0])))


def test_replace_changes_offsets_base_tool_and_origins():
    """replace() makes a new chain: new offsets shift q, a new base moves the whole arm, origins swap."""
    d, chain, rng = case(5, 5)
    q = rng.uniform(-1, 1, 5)
    shift = rng.uniform(-0.1, 0.1, 5)
    np.testing.assert_allclose(chain.replace(offsets=chain.offsets + shift).fk(q),
                               chain.fk(q + shift), atol=1e-12)
    b = ref.random_pose(rng)
    np.testing.assert_allclose(chain.replace(base=b @ chain.base).fk(q), b @ chain.fk(q),
                               atol=1e-12)
    t = ref.random_pose(rng)
    np.testing.assert_allclose(chain.replace(tool=chain.tool @ t).fk(q), chain.fk(q) @ t,
                               atol=1e-12)
    origins = [j.origin for j in chain.joints]
    origins[2] = origins[2] @ ref.random_pose(rng, 0.01)
    moved = chain.replace(origins=origins)
    np.testing.assert_array_equal(moved.joints[2].origin, origins[2])
    d["origins"][2] = origins[2]
    np.testing.assert_allclose(moved.fk(q), ref.fk(d, q), atol=1e-12)
    np.testing.assert_array_equal(chain.joints[2].origin, ref.random_chain(
        np.random.default_rng(5), 5)["origins"][2])
    with pytest.raises(TypeError, match="unknown field"):
        chain.replace(colour="red")


def test_chain_description_is_checked():
    """Duplicate joint names, a non-rigid base and bad joints are refused with the reason."""
    j = Joint("a", "revolute", np.eye(4), (0, 0, 1))
    with pytest.raises(ConfigError, match="used twice"):
        Chain("c", [j, j])
    with pytest.raises(ConfigError, match="not a rotation"):
        Chain("c", [j], base=np.diag([2.0, 1, 1, 1]))
    with pytest.raises(ConfigError, match="no movable joint"):
        Chain("c", [])
    with pytest.raises(ValueError, match="lower <= upper"):
        Joint("b", "revolute", np.eye(4), (0, 0, 1), lower=1.0, upper=0.0)
    with pytest.raises(ValueError, match="kind"):
        Joint("b", "ball", np.eye(4), (0, 0, 1))
    with pytest.raises(ValueError, match="non-zero"):
        Joint("b", "revolute", np.eye(4), (0, 0, 0))
    with pytest.raises(ValueError, match="positive semi-definite"):
        Inertial(1.0, (0, 0, 0), np.diag([1.0, -1.0, 1.0]))


def test_limit_violation_names_the_joint():
    """limit_violation names the first joint out of its range, None when all are within."""
    chain = Chain.from_dh([DHRow(lower=-1, upper=1, name="waist"),
                           DHRow(a=0.3, lower=-2, upper=2, name="elbow")])
    assert chain.limit_violation([0.5, -1.5]) is None
    assert "elbow" in chain.limit_violation([0.5, 2.5])
    assert "waist" in chain.limit_violation([-1.5, 2.5])


def test_arrays_are_read_only():
    """A chain's description arrays cannot be written in place."""
    _, chain, _ = case(6, 2)
    for arr in (chain.base, chain.tool, chain.offsets, chain.lower, chain.upper,
                chain.joints[0].origin, chain.joints[0].axis):
        with pytest.raises(ValueError):
            arr[...] = 0


def test_a_bound_array_changed_in_place_is_read_afresh():
    """A preallocated joint array written in place between calls (as a control loop does) gives each call's own answer."""
    d, chain, rng = case(8, 6)
    q = np.zeros(6)
    pose, jac, tau = np.empty((4, 4)), np.empty((6, 6)), np.empty(6)
    for _ in range(5):
        q[:] = rng.uniform(-2, 2, 6)
        chain.fk(q, out=pose)
        chain.jacobian(q, out=jac)
        chain.rnea(q, q, q, out=tau)
        np.testing.assert_allclose(pose, ref.fk(d, q), atol=1e-12)
        np.testing.assert_allclose(chain.fk(q), ref.fk(d, q), atol=1e-12)
        np.testing.assert_allclose(jac, ref.jacobian(d, q), atol=1e-12)
        np.testing.assert_allclose(tau, ref.rnea(d, q, q, q), rtol=1e-10, atol=1e-9)


def test_arrays_lists_and_outputs_may_alternate():
    """Calls that alternate arrays, lists and out arrays (and results kept from earlier calls) each get their own answer."""
    d, chain, rng = case(9, 5)
    qs = [rng.uniform(-2, 2, 5) for _ in range(3)]
    outs = [np.empty((4, 4)) for _ in range(2)]
    kept = []
    for k in range(9):
        q = qs[k % 3] if k % 2 else qs[k % 3].tolist()
        out = outs[k % 2]
        assert chain.fk(q, out=out) is out
        np.testing.assert_allclose(out, ref.fk(d, qs[k % 3]), atol=1e-12)
        kept.append((chain.jacobian(q), qs[k % 3]))
    for jac, q in kept:
        np.testing.assert_allclose(jac, ref.jacobian(d, q), atol=1e-12)
    other = build(ref.random_chain(np.random.default_rng(10), 5))
    np.testing.assert_allclose(other.fk(qs[0]) @ np.eye(4), other.fk(qs[0].tolist()), atol=0)
    np.testing.assert_allclose(chain.fk(qs[0]), ref.fk(d, qs[0]), atol=1e-12)


def test_a_chain_pickles_and_copies_as_its_description():
    """pickle and copy give an equal chain with a workspace of its own."""
    import copy
    import pickle

    _, chain, rng = case(13, 4)
    q = rng.uniform(-1, 1, 4)
    for other in (pickle.loads(pickle.dumps(chain)), copy.deepcopy(chain), copy.copy(chain)):
        assert other is not chain and other._k is not chain._k
        np.testing.assert_array_equal(other.fk(q), chain.fk(q))
        np.testing.assert_array_equal(other.rnea(q, q, q), chain.rnea(q, q, q))
        assert other.joint_names == chain.joint_names


def test_the_planning_copy_is_made_once_per_chain_and_answers_as_the_chain():
    """Every planner of a chain shares one copy (its own kernels) and its lock; the copy
    answers as the chain; a chain made by replace has its own; a changed closed form
    makes it again."""
    _d, chain, rng = case(3, 4)
    copy, lock = chain.planning_copy()
    assert chain.planning_copy() == (copy, lock)
    assert copy is not chain and copy._k is not chain._k
    q = rng.uniform(-1.0, 1.0, 4)
    assert np.array_equal(copy.fk(q), chain.fk(q))
    other = chain.replace()
    assert other.planning_copy()[0] is not copy
    chain.closed_form = object()  # type: ignore[assignment]
    again, _ = chain.planning_copy()
    assert again is not copy and again.closed_form is chain.closed_form
