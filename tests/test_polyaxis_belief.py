"""The manipulator's belief matches the world: the neck model, the rope plane, estimate integrity."""

from __future__ import annotations

import math
import re

import pytest
from _truth_rig import TOLERANCE, motors_still, station_at, true_error

import pyrt.native as nat
from pyrt.db import copy_station
from pyrt.errors import CommandError, ConfigError, FaultError
from pyrt.native._neck import LOWER, UPPER
from pyrt.robots.stops import StopReason
from pyrt.station.manipulator import ManipulatorStation


def _move(station, runner, target, timeout_s=900.0):
    runner.call(station.polyaxis.to, target)
    assert runner.wait_until(lambda: not station.polyaxis.active, timeout_s)
    return station.polyaxis.last_stop


# -- one neck model for the world and the controller ---------------------------------


def test_controller_and_world_let_the_same_segments_bear():
    """The controller's poll kernel lets both rope segments bear on the neck ring, as the world does."""
    both = UPPER | LOWER
    assert nat.PolyControl.RING_SEGMENTS == nat.StaticsSolver.RING_SEGMENTS == both


def test_sno_neck_targets_end_where_the_source_is(tmp_path):
    """sno to 0 0 1250 and 20 0 1200 (lower segments on the ring) end at ENDPOINT_STOP with the
    simulated source within 1 cm; 40 0 1200 is refused for its tension, nothing moves."""
    station, runner = station_at(tmp_path, "sno", (0.0, 0.0, 1150.0))
    pa = station.polyaxis
    for target in [(0.0, 0.0, 1250.0), (20.0, 0.0, 1200.0)]:
        stop = _move(station, runner, target)
        assert stop.reason is StopReason.ENDPOINT_STOP
        assert true_error(station, target) <= TOLERANCE["sno"]
        assert any(a is not None for a in pa._ctl.lower_rim_angles)  # the lower segments bear
        assert any(station.plant.wrapped())
    before = station.plant.position
    with pytest.raises(CommandError, match=r"axis1 would need .* N \(MAX_TENSION"):
        runner.call(pa.to, (40.0, 0.0, 1200.0))
    runner.sleep(1.0)
    assert station.plant.position == pytest.approx(before, abs=1e-9) and motors_still(station)
    station.close()


def test_rope_lengths_in_the_neck_agree_with_the_world(tmp_path):
    """Up in the sno neck the controller's rope lengths are the world's (lower segments over the ring)."""
    station, _runner = station_at(tmp_path, "sno", (0.0, 0.0, 1150.0))
    pa = station.polyaxis
    world = station.plant.solver
    for x in [(0.0, 0.0, 1250.0), (30.0, -20.0, 1100.0), (-50.0, 0.0, 700.0)]:
        g, _, wrapped = world.evaluate(x)
        assert any(wrapped)
        for i in range(pa.n):
            assert pa.model.length_at(i, x) == pytest.approx(g[i], abs=1e-6)
    station.close()


# -- the prototype's rope plane --------------------------------------------------------


def test_prototype_source_hangs_in_the_controller_plane(tmp_path):
    """A move into the prototype's neck ends with the simulated source in y = 0 and within 0.5 cm."""
    station, runner = station_at(tmp_path, "prototype", (0.0, 0.0, 330.0))
    stop = _move(station, runner, (5.7, 0.0, 375.0))
    assert stop.reason is StopReason.ENDPOINT_STOP
    assert abs(station.plant.position[1]) < 0.05
    assert true_error(station, (5.7, 0.0, 375.0)) <= TOLERANCE["prototype"]
    station.close()


def test_a_top_pulley_out_of_the_plane_is_refused_at_start(tmp_path):
    """A planar station whose central top pulley leaves the plane of its ropes does not start."""
    directory = copy_station("prototype", tmp_path / "p")
    path = directory / "AXIS.dat"
    path.write_text(path.read_text().replace("TOP: 0. 0. 389.0", "TOP: 0. 5.0 389.0"))
    with pytest.raises(ConfigError, match=r"axis0 top pulley \(AXIS.dat TOP\) is at y = 5 cm, "
                                          r"out of the plane y = 0 cm"):
        ManipulatorStation(directory)


# -- estimate integrity ---------------------------------------------------------------


def _db_values(station) -> dict[str, list[str]]:
    """POSITION, LENGTH and ZEROLENGTH lines as the files hold them now."""
    out = {}
    for type_, key in [("POLYAXIS", "POSITION"), ("AXIS", "LENGTH"), ("ENCODER", "ZEROLENGTH")]:
        out[key] = re.findall(rf"^{key}:.*$", station.station.text(type_), flags=re.M)
    return out


def _fault_ends(station, runner, timeout_s=60.0) -> str:
    with pytest.raises(FaultError) as info:
        runner.wait_until(lambda: False, timeout_s)
    return info.value.fault.cause


@pytest.mark.parametrize(("name", "start", "target", "rope"), [
    ("prototype", (0.0, 0.0, 95.57), (0.0, 0.0, 40.0), "axis0"),
    ("sno", (0.0, 0.0, 100.0), (0.0, 0.0, 40.0), "axis0"),
])
def test_slip_during_a_move_is_a_named_fault(tmp_path, name, start, target, rope):
    """An encoder slipping during a PolyAxis move: a fault naming the axis, every motor
    stopped, the source no more than 2 cm from where it was when the slip began, nothing
    measured written back, moves refused until 'survey'; then a move ends where the source is."""
    station, runner = station_at(tmp_path, name, start)
    pa = station.polyaxis
    runner.call(pa.to, target)
    runner.sleep(8.0)
    assert pa.active
    runner.sleep(1.0)  # one write-back period: the files hold the last trusted values
    at_fault = station.plant.position
    runner.call(station.plant.inject_slip, rope, 0.5)
    cause = _fault_ends(station, runner)
    assert cause.startswith(f"{rope}: position estimate lost")
    assert pa.last_stop.reason is StopReason.FAULT and motors_still(station)
    assert math.dist(station.plant.position, at_fault) <= 2.0
    held = _db_values(station)
    runner.sleep(25.0)  # past the stationary write-back period
    assert _db_values(station) == held
    assert motors_still(station)
    runner.call(station.acknowledge)
    with pytest.raises(CommandError, match="survey' or 'setpos X Y Z'; nothing moved"):
        runner.call(pa.to, target)
    assert "POSITION NOT TRUSTED" in runner.call(station.status)
    runner.call(station.plant.clear_faults, rope)
    text = runner.call(pa.run_command, "survey")
    assert f"from every rope but {rope}" in text and "moves allowed" in text
    assert math.dist(pa.position, station.plant.position) <= TOLERANCE[name]
    stop = _move(station, runner, target)
    assert stop.reason is StopReason.ENDPOINT_STOP
    assert true_error(station, target) <= TOLERANCE[name]
    runner.sleep(12.0)
    assert _db_values(station) != held  # trusted again: written back
    station.close()


def test_slip_during_an_axis_move_is_a_named_fault(tmp_path):
    """An encoder slipping during a standalone axis move: the same named fault, every motor
    stopped, the source within 2 cm, nothing written back; 'setpos' where the source is
    re-establishes the estimate."""
    station, runner = station_at(tmp_path, "prototype", (-0.2, 0.0, 95.57))
    pa = station.polyaxis
    axis1 = station.axes[1]
    runner.sleep(1.0)  # one write-back period
    # A side rope taken in while its encoder wheel slips completely.  (Taking in
    # the central rope slackens the side ropes, and a rope paid out past a
    # slipping encoder goes slack: either ends in LOW_TENSION_STOP first.)
    runner.call(axis1.cmd_up, "10")
    runner.sleep(1.0)
    assert axis1.motor.running
    at_fault = station.plant.position
    runner.call(station.plant.inject_slip, "axis1", 1.0)
    cause = _fault_ends(station, runner)
    assert cause.startswith("axis1: position estimate lost"), cause
    assert motors_still(station)
    assert math.dist(station.plant.position, at_fault) <= 2.0
    held = _db_values(station)
    runner.sleep(25.0)
    assert _db_values(station) == held
    runner.call(station.acknowledge)
    with pytest.raises(CommandError, match="not trusted"):
        runner.call(pa.to, (0.0, 0.0, 100.0))
    for ax in station.axes:  # single-rope moves too: their lengths are not trusted either
        with pytest.raises(CommandError, match=r"not trusted.*'prototype survey'"):
            runner.call(ax.run_command, "down", "1")
    with pytest.raises(CommandError, match="outside the vessel; nothing changed"):
        runner.call(pa.run_command, "setpos", "0", "0", "5000")
    runner.call(station.plant.clear_faults, "axis1")
    x, y, z = station.plant.position
    text = runner.call(pa.run_command, "setpos", f"{x:.3f}", f"{y:.3f}", f"{z:.3f}")
    assert "moves allowed" in text and pa.estimate_lost is None
    assert math.dist(pa.position, station.plant.position) <= TOLERANCE["prototype"]
    runner.call(pa.to, (0.0, 0.0, 100.0))  # accepted again
    assert pa.active
    runner.call(station.stop)
    assert motors_still(station)
    station.close()


def test_endpoint_message_prints_the_station_tolerance(tmp_path):
    """The ENDPOINT_STOP message's limit is the station's END_ERROR, whatever distErr was."""
    station, runner = station_at(tmp_path, "prototype", (0.0, 0.0, 100.0))
    stop = _move(station, runner, (20.0, 0.0, 80.0))
    assert stop.reason is StopReason.ENDPOINT_STOP
    assert "(limit 0.5 cm; distErr " in stop.detail
    station.close()


def test_tension_margin_from_the_database(tmp_path):
    """A target whose holding tensions lie within TENSION_MARGIN of a bound is refused, naming it."""
    directory = copy_station("prototype", tmp_path / "p")
    path = directory / "POLYAXIS.dat"
    path.write_text(path.read_text().replace("END;", "TENSION_MARGIN: 40 N\nEND;"))
    station = ManipulatorStation(directory, tick_ns=5_000_000)
    runner = station.start()
    with pytest.raises(CommandError, match=r"TENSION_MARGIN 40 N\).*nothing moved"):
        runner.call(station.polyaxis.to, (0.0, 0.0, 100.0))
    station.close()


def test_encoder_reset_loses_the_estimate(tmp_path):
    """An encoder counter reset after a move (its length jumps back to ZEROLENGTH): a fault
    naming the axis though nothing moves, and moves refused until the position is re-established."""
    station, runner = station_at(tmp_path, "prototype", (0.0, 0.0, 100.0))
    pa = station.polyaxis
    assert _move(station, runner, (0.0, 0.0, 85.0)).reason is StopReason.ENDPOINT_STOP
    runner.sleep(3.0)
    runner.call(station.axes[0].encoder.reset)
    cause = _fault_ends(station, runner, 5.0)
    assert cause.startswith("axis0: position estimate lost")
    assert "out of step with its motor" in cause and motors_still(station)
    runner.call(station.acknowledge)
    with pytest.raises(CommandError, match="not trusted"):
        runner.call(pa.to, (0.0, 0.0, 100.0))
    assert "from every rope but axis0" in runner.call(pa.run_command, "survey")
    assert math.dist(pa.position, station.plant.position) <= TOLERANCE["prototype"]
    station.close()


def test_a_path_through_unholdable_points_is_refused(tmp_path):
    """From a start held within the tension bounds, a feasible target whose straight path
    passes where a rope would go slack is refused before anything moves, saying where."""
    station, runner = station_at(tmp_path, "prototype", (-280.0, 0.0, 100.0))
    before = station.plant.position
    with pytest.raises(CommandError, match=r"the path passes \(-2\d\d\.\d, 0\.0, \d+\.\d\), "
                                           r"where axis0 would need .* \(LOW_TENSION 2 N\)"):
        runner.call(station.polyaxis.to, (-60.0, 0.0, -200.0))
    runner.sleep(1.0)
    assert station.plant.position == pytest.approx(before, abs=1e-9) and motors_still(station)
    station.close()
