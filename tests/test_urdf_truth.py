"""pyrt urdf against the simulated arm's truth, over random feasible targets: blends within their
stated tolerance, a conveyor tracked, and 'at target' said only when the truth is there."""

from __future__ import annotations

import contextlib
import math

import numpy as np
import pytest
from _urdf_rig import puma_station
from _urdf_rig import settle as _settle
from hypothesis import HealthCheck, Phase, assume, given, settings
from hypothesis import strategies as st

from pyrt.errors import CommandError, FaultError
from pyrt.kinematics import transform
from pyrt.kinematics.puma import puma560

CHAIN = puma560()
#: The tool's orientation for the Cartesian cases (its wrist well away from q5 = 0).
RPY = (180.0, 20.0, 90.0)
#: The middle of the region the random points are drawn in (mm).
CENTRE = np.array([520.0, 20.0, 380.0])
#: At target in truth: within these (mm, deg) of the target and at rest (deg/s).
POS_MM, ROT_DEG, REST_DEG_S = 0.5, 0.1, 0.5
#: The true tool's largest distance from its point on a moving conveyor (mm).
TRACK_MM = 2.0

_SETTINGS = settings(max_examples=8, deadline=None, database=None,
                     phases=[Phase.explicit, Phase.reuse, Phase.generate],
                     suppress_health_check=[HealthCheck.function_scoped_fixture,
                                            HealthCheck.too_slow])


def _pose(p, rpy=RPY) -> np.ndarray:
    return transform(np.asarray(p, dtype=float) * 1e-3, np.radians(rpy))


def _rot_deg(a: np.ndarray, b: np.ndarray) -> float:
    r = a[:3, :3].T @ b[:3, :3]
    return math.degrees(math.acos(max(-1.0, min(1.0, (float(np.trace(r)) - 1.0) / 2.0))))


@pytest.fixture(scope="module")
def puma():
    """One PUMA station on simulated time for this module."""
    yield from puma_station()


def _home(station, runner, p=CENTRE) -> None:
    """The tool at ``p`` (mm) with RPY by a joint move (righty-above-noflip), at rest."""
    runner.call(station.arm.set_conveyor, 0, 0, 0)
    runner.call(station.arm.set_coord, 0, 0, 0, 0, 0, 0)
    q = CHAIN.closed_form.inverse(_pose(p), "righty-above-noflip")
    runner.call(station.arm.move_joints, *np.degrees(q).tolist())
    _settle(station, runner)
    assert station.fault is None


def _offsets(r: float):
    return st.tuples(*[st.floats(-r, r)] * 3).map(np.array)


def _dist_to_segment(p, a, b) -> float:
    ab = b - a
    s = min(max(float((p - a) @ ab) / max(float(ab @ ab), 1e-18), 0.0), 1.0)
    return float(np.linalg.norm(p - (a + s * ab)))


def _movel(station, runner, p, options: str = "") -> None:
    """movel to ``p`` (mm) with RPY; a refused line (singularity, reach) is not an example."""
    try:
        runner.call(station.arm.move_line, *(float(v) for v in p), *RPY, *(
            [options] if options else []))
    except CommandError as exc:
        assume("refused" not in str(exc))
        raise


@_SETTINGS
@given(d1=_offsets(90.0), d2=_offsets(90.0), tol=st.floats(1.0, 20.0))
def test_a_blend_between_two_lines_stays_within_its_tolerance_in_truth(puma, d1, d2, tol):
    """Over random corners (two lines from the centre through a via point, the second with blend=T, T 1 .. 20 mm): the simulated true tool never goes further than T from the two lines (the servo's tracking included); it ends at the last target, 'at target'."""
    station, runner = puma
    assume(float(np.linalg.norm(d1)) > 20.0 and float(np.linalg.norm(d2 - d1)) > 20.0)
    _home(station, runner)
    a = runner.call(lambda: station.plant.truth().tool[:3, 3].copy())
    via, end = CENTRE + d1, CENTRE + d2
    _movel(station, runner, via)
    try:
        _movel(station, runner, end, f"blend={tol:.3f}")
    except BaseException:
        runner.call(station.stop)
        _settle(station, runner)
        raise
    worst = [0.0]
    v, e = via * 1e-3, end * 1e-3

    def watch() -> bool:
        p = station.plant.truth().tool[:3, 3]
        worst[0] = max(worst[0], min(_dist_to_segment(p, a, v), _dist_to_segment(p, v, e)))
        return not station.busy()

    assert runner.wait_until(watch, 60.0)
    assert station.fault is None
    assert worst[0] * 1e3 <= tol, (worst[0] * 1e3, tol)
    assert station.last_stop() == "at target"
    truth = runner.call(lambda: station.plant.truth().tool)
    assert np.linalg.norm(truth[:3, 3] - e) * 1e3 <= POS_MM


@_SETTINGS
@given(speed=st.floats(10.0, 60.0), heading=st.floats(0.0, 2 * math.pi),
       d=_offsets(50.0))
def test_the_conveyor_is_tracked_in_truth(puma, speed, heading, d):
    """Over random conveyor velocities (10 .. 60 mm/s in any direction of the horizontal plane) and random points on the belt near the tool: once the tool tracks its point, the true tool stays within 2 mm of the point as it moves for 1 s; stop brakes to rest without a fault."""
    station, runner = puma
    arm = station.arm
    _home(station, runner)
    v = (speed * math.cos(heading), speed * math.sin(heading), 0.0)
    runner.call(arm.set_conveyor, *v)
    point = CENTRE + d
    try:
        _movel(station, runner, point)
    finally:
        if not runner.call(station.busy):
            runner.call(arm.set_conveyor, 0, 0, 0)
    belt = arm.conveyor
    _settle(station, runner)
    assert station.fault is None and arm.state == "tracking", station.last_stop()
    local = _pose(point)
    worst = [0.0]
    t0 = runner.call(lambda: station.plant.truth().time)

    def watch() -> bool:
        tr = station.plant.truth()
        want = (belt.pose_at(tr.time) @ local)[:3, 3]
        worst[0] = max(worst[0], float(np.linalg.norm(tr.tool[:3, 3] - want)))
        return tr.time - t0 >= 1.0

    assert runner.wait_until(watch, 10.0)
    assert worst[0] * 1e3 <= TRACK_MM, worst[0] * 1e3
    runner.call(station.stop)
    _settle(station, runner)
    assert station.fault is None
    runner.call(arm.set_conveyor, 0, 0, 0)


def _truth_at(station, runner, want: np.ndarray) -> tuple[float, float, float]:
    tr = runner.call(station.plant.truth)
    return (float(np.linalg.norm(tr.tool[:3, 3] - want[:3, 3])) * 1e3,
            _rot_deg(tr.tool, want), float(np.max(np.abs(np.degrees(tr.qd)))))


@_SETTINGS
@given(d=_offsets(120.0), verb=st.sampled_from(["movel", "moveto", "movej"]),
       speed=st.sampled_from(["", "speed=0.3", "speed=1"]),
       table=st.one_of(st.none(), st.floats(-150.0, -10.0)))
def test_at_target_is_said_only_when_the_truth_is_there(puma, d, verb, speed, table):
    """Over random targets by movel, moveto or movej, at random speeds, with or without a table below the start that may be across the path: whenever the move ends 'at target', the true tool is within 0.5 mm and 0.1 deg of the target and at rest; a move that ends otherwise (pressed on the table, a fault) says why."""
    station, runner = puma
    arm = station.arm
    _home(station, runner)
    runner.call(station.find("sim").table, "off" if table is None else f"{CENTRE[2] + table:.1f}")
    try:
        p = CENTRE + d
        want = _pose(p)
        if verb == "movej":
            try:
                q = CHAIN.closed_form.inverse(want, "righty-above-noflip")
            except ValueError:
                assume(False)
            words: list = [*np.degrees(q).tolist()]
            call = arm.move_joints
        else:
            words = [*(float(v) for v in p), *RPY]
            call = arm.move_line if verb == "movel" else arm.move_to
        try:
            runner.call(call, *words, *([speed] if speed else []))
        except CommandError as exc:
            assume("refused" not in str(exc))
            raise
        with contextlib.suppress(FaultError):  # a fault is an end too (said below)
            _settle(station, runner)
        said = station.last_stop()
        pos, rot, speed_now = _truth_at(station, runner, want)
        if said == "at target":
            assert station.fault is None
            assert pos <= POS_MM and rot <= ROT_DEG and speed_now <= REST_DEG_S, (pos, rot)
        else:
            assert said, "a move ended without saying how"
    finally:
        if station.fault is not None:
            runner.call(station.acknowledge, take_fault=False)
        runner.call(station.find("sim").table, "off")


def test_a_target_inside_the_table_is_not_said_to_be_reached(puma):
    """movel to a point 40 mm inside the table: the arm presses on it and cannot get there (the truth is not at the target), and the move does not end 'at target'."""
    station, runner = puma
    _home(station, runner)
    runner.call(station.find("sim").table, f"{CENTRE[2] - 30:.1f}")
    try:
        runner.call(station.arm.move_line, CENTRE[0], CENTRE[1], CENTRE[2] - 70, *RPY,
                    "speed=0.1")
        with contextlib.suppress(FaultError):  # pressing beyond the following error: a fault
            _settle(station, runner)
        want = _pose(CENTRE - [0, 0, 70])
        pos, _rot, _speed = _truth_at(station, runner, want)
        assert pos > POS_MM
        assert station.last_stop() != "at target", station.last_stop()
    finally:
        if station.fault is not None:
            runner.call(station.acknowledge, take_fault=False)
        runner.call(station.find("sim").table, "off")
