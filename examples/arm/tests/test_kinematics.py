"""The arm's kinematics: fk and ik agree, refusals are clear, the Jacobian is fk's derivative."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pyrt_arm.kinematics import (
    GEOMETRY,
    Geometry,
    JointLimitError,
    KinematicsError,
    ReachError,
    elbow_of,
    fk,
    ik,
    jacobian,
    within_limits,
)

L1, L2 = GEOMETRY.l1_mm, GEOMETRY.l2_mm
#: the nearest the tip comes to the base with the elbow within its limits
R_LIMIT = math.sqrt(L1 * L1 + L2 * L2 + 2 * L1 * L2 * math.cos(math.radians(150.0)))
TOL_MM = 1e-9
elbows = st.sampled_from(["up", "down"])


def polar(r: float, theta_deg: float) -> tuple[float, float]:
    return r * math.cos(math.radians(theta_deg)), r * math.sin(math.radians(theta_deg))


@settings(max_examples=400, deadline=None)
@given(r=st.floats(R_LIMIT + 1e-6, L1 + L2), theta=st.floats(-110.0, 110.0), elbow=elbows)
def test_fk_of_ik_is_the_point_over_the_annulus_within_the_limits_for_both_elbows(r, theta, elbow):
    """fk(ik(p)) = p for every point of the annulus the arm reaches within its joint limits, with either elbow."""
    x, y = polar(r, theta)
    q0, q1 = ik(x, y, elbow)
    assert within_limits(q0, q1)
    assert (q1 <= 0.0) if elbow == "up" else (q1 >= 0.0)
    fx, fy = fk(q0, q1)
    assert math.hypot(fx - x, fy - y) < TOL_MM


@settings(max_examples=400, deadline=None)
@given(r=st.floats(GEOMETRY.r_min_mm, L1 + L2), theta=st.floats(-180.0, 180.0), elbow=elbows)
def test_every_point_of_the_annulus_is_solved_or_refused_for_its_joint_limits(r, theta, elbow):
    """Anywhere in the annulus, ik gives a solution within the limits that fk maps back, or a JointLimitError naming the joint."""
    x, y = polar(r, theta)
    try:
        q0, q1 = ik(x, y, elbow)
    except JointLimitError as exc:
        assert ("q0 =" in str(exc)) or ("q1 =" in str(exc))
        assert f"elbow {elbow}" in str(exc)
        return
    assert within_limits(q0, q1)
    fx, fy = fk(q0, q1)
    assert math.hypot(fx - x, fy - y) < TOL_MM


@settings(max_examples=400, deadline=None)
@given(q0=st.floats(-170.0, 170.0),
       q1=st.floats(0.5, 150.0) | st.floats(-150.0, -0.5))
def test_ik_of_fk_returns_the_joint_angles_for_the_matching_elbow(q0, q1):
    """ik(fk(q), elbow of q) = q over the joint limits (the elbow kept off the stretched arm)."""
    x, y = fk(q0, q1)
    r0, r1 = ik(x, y, elbow_of(q1))
    assert r0 == pytest.approx(q0, abs=1e-7)
    assert r1 == pytest.approx(q1, abs=1e-7)


@settings(max_examples=200, deadline=None)
@given(q0=st.floats(-170.0, 170.0), q1=st.floats(5.0, 150.0))
def test_the_other_elbow_reaches_the_same_point_mirrored_about_the_base_tip_line(q0, q1):
    """The other elbow's solution of fk(q) has the opposite q1 and also lands on the point (when within limits)."""
    x, y = fk(q0, q1)
    try:
        u0, u1 = ik(x, y, "up")
    except JointLimitError:
        return
    assert u1 == pytest.approx(-q1, abs=1e-7)
    ux, uy = fk(u0, u1)
    assert math.hypot(ux - x, uy - y) < TOL_MM


def test_stretched_arm_is_the_same_for_both_elbows():
    """At full reach both elbows give q1 = 0 and the same q0, the point's own angle."""
    x, y = polar(L1 + L2, 30.0)
    for elbow in ("up", "down"):
        q0, q1 = ik(x, y, elbow)
        assert q1 == pytest.approx(0.0, abs=1e-6)
        assert q0 == pytest.approx(30.0, abs=1e-9)


def test_fk_of_the_stretched_arm_counts_as_within_reach_despite_rounding():
    """fk of a stretched arm, rounding outside L1 + L2 by a hair, is solved, not refused."""
    for q0 in np.linspace(-170.0, 170.0, 341):
        x, y = fk(float(q0), 0.0)
        q = ik(x, y, "down")
        assert q[0] == pytest.approx(float(q0), abs=1e-5)
        assert q[1] == pytest.approx(0.0, abs=1e-5)


@settings(max_examples=200, deadline=None)
@given(r=st.floats(L1 + L2 + 1e-6, 1e5) | st.floats(0.0, GEOMETRY.r_min_mm - 1e-6),
       theta=st.floats(-180.0, 180.0), elbow=elbows)
def test_points_outside_the_annulus_are_refused_as_out_of_reach(r, theta, elbow):
    """A point outside |L1 - L2| <= r <= L1 + L2 is a ReachError that gives r and the annulus."""
    x, y = polar(r, theta)
    with pytest.raises(ReachError) as info:
        ik(x, y, elbow)
    message = str(info.value)
    assert "out of reach" in message
    assert "50.000 <= r <= 550.000 mm" in message
    assert f"{math.hypot(x, y):.3f} mm from the base" in message


def test_a_point_too_close_for_the_elbow_limit_is_a_joint_limit_error_naming_q1():
    """Inside the annulus but nearer than the folded elbow allows, ik refuses naming q1 and its limits."""
    with pytest.raises(JointLimitError, match=r"q1 = -?1[5-9]\d\.\d{3} deg, outside its limits "
                                              r"\[-150\.000, 150\.000\] deg"):
        ik(100.0, 0.0, "down")


def test_a_point_behind_the_base_is_a_joint_limit_error_naming_q0():
    """Straight behind the base the shoulder would need 180 deg, beyond its 170 deg limit."""
    with pytest.raises(JointLimitError, match=r"q0 = .* outside its limits \[-170\.000, 170\.000\]"):
        ik(-L1 - L2, 0.0, "up")


def test_kinematics_errors_are_value_errors():
    """Both refusals are KinematicsError, itself a ValueError, so callers can catch either."""
    assert issubclass(ReachError, KinematicsError)
    assert issubclass(JointLimitError, KinematicsError)
    assert issubclass(KinematicsError, ValueError)


@pytest.mark.parametrize("args", [(math.nan, 0.0), (0.0, math.inf), ("1", 0.0)])
def test_ik_refuses_non_numbers(args):
    """A coordinate that is not a finite number is a ValueError naming it."""
    with pytest.raises(ValueError, match="must be a finite number"):
        ik(*args)


def test_ik_refuses_an_unknown_elbow():
    """An elbow other than 'up' or 'down' is a ValueError."""
    with pytest.raises(ValueError, match="elbow must be 'up' or 'down'"):
        ik(300.0, 100.0, "left")  # type: ignore[arg-type]


def test_fk_refuses_non_numbers():
    """fk of a NaN angle is a ValueError naming the angle."""
    with pytest.raises(ValueError, match="q1_deg"):
        fk(0.0, math.nan)


def test_fk_at_known_poses():
    """fk puts the tip at L1 + L2 on +x at zero, and at (L1, L2) with the elbow at 90 deg."""
    assert fk(0.0, 0.0) == pytest.approx((550.0, 0.0))
    assert fk(0.0, 90.0) == pytest.approx((300.0, 250.0))
    assert fk(90.0, -90.0) == pytest.approx((250.0, 300.0))


@settings(max_examples=200, deadline=None)
@given(q0=st.floats(-170.0, 170.0), q1=st.floats(-150.0, 150.0))
def test_jacobian_is_the_derivative_of_fk_in_mm_per_degree(q0, q1):
    """Each column of J matches fk's central difference per degree of that joint."""
    jac = jacobian(q0, q1)
    h = 1e-4
    for j in range(2):
        dq = [0.0, 0.0]
        dq[j] = h
        plus = fk(q0 + dq[0], q1 + dq[1])
        minus = fk(q0 - dq[0], q1 - dq[1])
        column = [(p - m) / (2 * h) for p, m in zip(plus, minus, strict=True)]
        assert jac[:, j] == pytest.approx(column, abs=1e-5)
    assert np.linalg.det(jac) == pytest.approx(
        L1 * L2 * math.sin(math.radians(q1)) * (math.pi / 180.0) ** 2, abs=1e-9)


def test_within_limits_includes_the_limits_themselves():
    """The limits are inclusive; a hair beyond either is outside."""
    assert within_limits(170.0, -150.0)
    assert not within_limits(170.0001, 0.0)
    assert not within_limits(0.0, -150.0001)


@pytest.mark.parametrize("kwargs", [{"l1_mm": 0.0}, {"l2_mm": -1.0},
                                    {"q0_limits_deg": (10.0, -10.0)},
                                    {"q1_limits_deg": (-200.0, 0.0)}])
def test_geometry_refuses_bad_lengths_and_limits(kwargs):
    """A non-positive link or limits out of order or beyond +-180 deg are ValueErrors."""
    with pytest.raises(ValueError):
        Geometry(**kwargs)


def test_another_geometry_is_honoured():
    """ik and fk take the geometry given: a 200 + 200 mm arm reaches 400 mm and 0 is its inner edge."""
    geo = Geometry(l1_mm=200.0, l2_mm=200.0)
    q = ik(0.0, 400.0, "up", geo)
    assert q == pytest.approx((90.0, 0.0), abs=1e-6)
    with pytest.raises(ReachError, match=r"0\.000 <= r <= 400\.000"):
        ik(401.0, 0.0, "up", geo)


@settings(max_examples=300, deadline=None)
@given(q0=st.floats(-170.0, 170.0), q1=st.floats(-150.0, 150.0))
def test_the_chain_pyrt_plans_on_is_the_arm_of_the_closed_form(q0, q1):
    """The arm's kinematic chain (pyrt.kinematics, from its URDF: what its moves are planned on) puts the tip where fk does, and its Jacobian's planar part is jacobian's; ik of that tip comes back to q for the matching elbow."""
    from pyrt_arm.controller import CHAIN

    q = np.radians([q0, q1])
    t = CHAIN.fk(q)
    x, y = fk(q0, q1)
    assert t[:3, 3] * 1e3 == pytest.approx([x, y, 0.0], abs=1e-6)
    jac = CHAIN.jacobian(q)[:2] * 1e3 * math.pi / 180.0  # m/rad -> mm/deg
    assert jac == pytest.approx(jacobian(q0, q1), abs=1e-6)
    back = ik(float(t[0, 3] * 1e3), float(t[1, 3] * 1e3), elbow_of(q1))
    if abs(math.sin(math.radians(q1))) > 1e-3:  # away from the stretched arm's rounding
        assert back == pytest.approx((q0, q1), abs=1e-6)


def test_the_chain_has_the_arms_joint_limits():
    """The chain's joint limits are the geometry's (the URDF keeps them to 1e-6 rad)."""
    from pyrt_arm.controller import CHAIN

    assert CHAIN.n == 2
    assert np.degrees(CHAIN.lower) == pytest.approx([-170.0, -150.0], abs=1e-4)
    assert np.degrees(CHAIN.upper) == pytest.approx([170.0, 150.0], abs=1e-4)
