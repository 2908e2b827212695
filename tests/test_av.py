"""AV: vessel<->global transforms and containment."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pyrt.db import load_station, station_directory
from pyrt.errors import ConfigError
from pyrt.robots.av import AV
from pyrt.sim.manipulator import rotation_xyz

coord = st.floats(-1000, 1000)
angle = st.floats(-180, 180)


def _proto():
    return AV.from_record(load_station(station_directory("prototype")).av("PROTOVESSEL"))


def test_identity_pose_changes_nothing():
    """With the vessel at the origin and upright, vtog and gtov are the identity."""
    av = _proto()
    assert av.vtog((317.0, 0.0, 89.53)) == (317.0, 0.0, 89.53)
    assert av.gtov((1.0, 2.0, 3.0)) == (1.0, 2.0, 3.0)


def test_rotation_then_translation():
    """A vessel turned 90 degrees about z and moved up 10 cm maps vessel x to global y."""
    av = _proto()
    av.set_pose((0.0, 0.0, 10.0), (0.0, 0.0, 90.0))
    g = av.vtog((100.0, 0.0, 0.0))
    assert g == pytest.approx((0.0, 100.0, 10.0), abs=1e-12)
    assert av.neck_ring_position == pytest.approx((0.0, 5.7, 374.0), abs=1e-12)


@settings(max_examples=60, deadline=None)
@given(p=st.tuples(coord, coord, coord), pos=st.tuples(coord, coord, coord),
       ori=st.tuples(angle, angle, angle))
def test_gtov_inverts_vtog(p, pos, ori):
    """gtov(vtog(x)) == x for any pose, and vtog agrees with the physics' rotation."""
    av = _proto()
    av.set_pose(pos, ori)
    g = av.vtog(p)
    assert av.gtov(g) == pytest.approx(p, abs=1e-8)
    r = rotation_xyz(ori)
    expect = r @ p + pos
    assert g == pytest.approx(tuple(expect), abs=1e-8)
    assert math.dist(g, pos) == pytest.approx(math.dist(p, (0, 0, 0)), abs=1e-8)


def test_containment():
    """Inside the sphere or the neck cylinder is contained; beyond either is not."""
    av = _proto()
    assert av.contains((0.0, 0.0, 0.0))
    assert av.contains((0.0, 0.0, 319.0))
    assert not av.contains((0.0, 0.0, 321.0)) or av.in_neck((0.0, 0.0, 321.0))
    # the neck: ring at (5.7, 0, 364), radius 42, 27 cm long
    assert av.in_neck((5.7, 0.0, 380.0))
    assert av.in_neck((45.0, 0.0, 364.5))
    assert not av.in_neck((50.0, 0.0, 380.0))  # outside the neck radius
    assert not av.in_neck((5.7, 0.0, 392.0))  # above the neck's top
    assert not av.contains((300.0, 0.0, 300.0))
    assert not av.contains((5.7, 0.0, 400.0))


def test_containment_follows_the_vessel():
    """Moving the vessel moves what is inside it."""
    av = _proto()
    av.set_pose((0.0, 0.0, -100.0), (0.0, 0.0, 0.0))
    assert not av.contains((0.0, 0.0, 250.0))
    assert av.contains((0.0, 0.0, -400.0))


def test_bad_geometry_refused():
    """A non-positive radius is a ConfigError."""
    with pytest.raises(ConfigError, match="VESSEL_RADIUS"):
        AV("x", (0, 0, 1), 1.0, 1.0, 1.0, 0.0)
