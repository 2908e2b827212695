"""pyrt.motion's comply: an admittance on the wrist's force along the tool frame's axes, the
other directions on the path, against an ideal arm pressing on a spring wall."""

from __future__ import annotations

import numpy as np
import pytest
from _motion_rig import PUMA, PUMA_HOME, equation, make, run, tool_pose
from hypothesis import given, settings
from hypothesis import strategies as st

from pyrt.motion import Comply, MotionSpec, Termination

#: The wall's stiffness (N/m): a contact the default gain suits.
WALL_K = 5e4
#: A 30 deg tilt of the tool about its x axis, as the TOOL term (the sensor sees the flange).
TILT = np.eye(4)
TILT[1:3, 1:3] = [[np.cos(0.5), -np.sin(0.5)], [np.sin(0.5), np.cos(0.5)]]
TILT[2, 3] = 0.05


def _wall(tool, depth0):
    """A spring wall across the tool's z at the start, ``depth0`` m into it: the wrench the
    flange feels (flange frame) when the tool is at a knot (an arm that follows exactly)."""
    start = tool_pose(PUMA, PUMA_HOME, tool)
    n = start[:3, 2]
    surface = float(start[:3, 3] @ n) - depth0

    def wrench(knot):
        t6 = PUMA.fk(knot.q)
        p = float((t6 @ tool)[:3, 3] @ n) - surface
        f_world = -WALL_K * max(p, 0.0) * n  # pushes the tool back out
        return np.concatenate([t6[:3, :3].T @ f_world, np.zeros(3)])

    return wrench, n


@settings(max_examples=10, deadline=None)
@given(newtons=st.floats(1.0, 20.0), depth=st.floats(0.0, 0.002),
       dx=st.floats(-0.06, 0.06), dy=st.floats(-0.06, 0.06), tilted=st.booleans())
def test_comply_holds_the_force_on_a_wall_and_the_path_across_it(newtons, depth, dx, dy, tilted):
    """Over random forces (1 .. 20 N), starting depths and lines across the wall, tool tilted or not: the force the wall feels settles to the setpoint within 2 %, and the tool's motion across the wall's normal is the planned line's (within 0.01 mm); the record is reached."""
    tool = TILT if tilted else equation(np.eye(4)).transforms[1].value
    ev = make(force_sensor=True)
    wrench, n = _wall(tool, depth)
    a = tool_pose(PUMA, PUMA_HOME, tool)
    b = a.copy()
    b[:3, 3] += a[:3, :3] @ np.array([dx, dy, 0.0])  # across the tool's z
    move = ev.queue(MotionSpec(mode="cart", equation=equation(b, tool=tool),
                               comply=Comply("z", newtons), speed=0.3))
    knots = run(ev, wrench=wrench)
    assert move.code == Termination.REACHED
    felt = [float(np.linalg.norm(wrench(k)[:3])) for k in knots[-5:]]
    assert max(abs(f - newtons) for f in felt) <= 0.02 * newtons, felt
    for k in knots:
        p = tool_pose(PUMA, k.q, tool)[:3, 3] - a[:3, 3]
        across = p - (p @ n) * n
        want = b[:3, 3] - a[:3, 3]
        s = float(across @ want) / max(float(want @ want), 1e-12)
        on_line = across - min(max(s, 0.0), 1.0) * want
        assert float(np.linalg.norm(on_line)) <= 1e-5


def test_comply_keeps_within_its_travel_and_ends_where_the_force_put_the_arm():
    """With nothing to press on, comply z moves the tool along its z at most `travel` from the path (at most `speed`); the record ends there, and the next record starts from there (the plan's first knot is the last one)."""
    ev = make(force_sensor=True)
    a = tool_pose(PUMA, PUMA_HOME, equation(np.eye(4)).transforms[1].value)
    spec = MotionSpec(mode="cart", equation=equation(a),
                      comply=Comply("z", 10.0, gain=5e-3, travel=0.01, speed=0.02, dwell=1.0))
    move = ev.queue(spec)
    knots = run(ev, wrench=lambda k: np.zeros(6))
    assert move.code == Termination.REACHED
    z = a[:3, 2]
    depth = [float((tool_pose(PUMA, k.q)[:3, 3] - a[:3, 3]) @ z) for k in knots]
    assert max(depth) == pytest.approx(0.01, abs=1e-6)
    steps = np.diff(depth)
    assert float(np.max(steps)) <= 0.02 * ev.period + 1e-9
    last = knots[-1].q.copy()
    ev.queue(MotionSpec(mode="joint", target=PUMA_HOME))
    nxt = run(ev, limit=1)
    assert np.allclose(nxt[0].q, last, atol=1e-12)
