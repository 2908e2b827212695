"""PolyAxis control on the simulated prototype and full-scale stations (SimClock, 5 ms tick)."""

from __future__ import annotations

import contextlib
import math

import pytest
from _manipulator_rig import make_station, move, read_log

from pyrt.db import load_station
from pyrt.errors import CommandError, FaultError
from pyrt.robots.stops import StopReason

#: Spread over the prototype vessel: low, near the wall, into the neck (two
#: segments through the point under the ring) and back out (two again).
PROTOTYPE_TARGETS = [(20.0, 0.0, -100.0), (-200.0, 0.0, 110.0), (5.7, 0.0, 375.0),
                     (0.0, 0.0, 250.0)]


def _motors_still(station) -> bool:
    return not station.motors_running() and all(
        a.motor.velocity == 0.0 for a in station.axes)


@pytest.fixture(scope="module")
def prototype_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("proto")
    station, runner = make_station(tmp)
    db_before = {t: station.station.text(t) for t in ("POLYAXIS", "AXIS")}
    log = station.start_log(tmp / "moves.log")
    stops = [move(station, runner, t) for t in PROTOTYPE_TARGETS]
    runner.sleep(2.0)
    station.stop_log()
    yield station, runner, stops, read_log(log), db_before
    station.close()


def test_every_target_ends_with_endpoint_stop(prototype_run):
    """Each move over the prototype vessel ends with ENDPOINT_STOP."""
    _, _, stops, _, _ = prototype_run
    assert [s.reason for s in stops] == [StopReason.ENDPOINT_STOP] * len(PROTOTYPE_TARGETS)


def test_endpoint_condition_is_met(prototype_run):
    """The estimated position at the stop is within max(0.1, min(END_ERROR, distErr))."""
    _station, _, stops, _log, _ = prototype_run
    for target, stop in zip(PROTOTYPE_TARGETS, stops, strict=True):
        d = math.dist(stop.position, target)
        assert d <= 1.0  # END_ERROR of the prototype
        limit = float(stop.detail.split("limit ")[1].split()[0])
        assert 0.1 <= limit <= 1.0 and d <= limit


def test_true_position_follows(prototype_run):
    """The real source ends close to the last target (in the rope plane)."""
    station, _, _, _, _ = prototype_run
    x, _, z = station.plant.position
    assert math.hypot(x - PROTOTYPE_TARGETS[-1][0], z - PROTOTYPE_TARGETS[-1][2]) < 1.0


def test_tensions_stay_within_bounds_on_the_way(prototype_run):
    """No rope is logged below LOW_TENSION or above MAX_TENSION during any move."""
    station, _, _, log, _ = prototype_run
    tensions = [float(p[4]) for p in log["S"]]
    assert len(tensions) > 1000
    pa = station.polyaxis
    assert min(tensions) >= pa.low_tension
    assert max(tensions) <= pa.max_tension


def test_neck_moves_take_two_segments(prototype_run):
    """Into and out of the neck the path turns under the ring; in the vessel it is straight."""
    _, _, _, log, _ = prototype_run
    segments = [int(p[5]) for p in log["TO"]]
    assert segments == [1, 1, 2, 2]


def test_log_names_each_stop(prototype_run):
    """The state log records every stop with its reason."""
    _, _, _, log, _ = prototype_run
    assert [p[2] for p in log["STOP"]] == ["ENDPOINT_STOP"] * len(PROTOTYPE_TARGETS)


def test_database_position_and_lengths_written_back(prototype_run):
    """POLYAXIS POSITION and AXIS LENGTH in the working database follow the source."""
    station, _, _, _, before = prototype_run
    again = load_station(station.directory)
    pos = again.polyaxis().position
    assert math.dist(pos, station.polyaxis.position) < 0.5
    assert station.station.text("POLYAXIS") != before["POLYAXIS"]
    assert station.station.text("AXIS") != before["AXIS"]
    for rec, axis in zip(again.axes_of(), station.axes, strict=True):
        assert rec.length == pytest.approx(axis.length(), abs=0.5)
        # the encoder counter restarts at zero: the current length is the next zero length
        enc = again.encoder_of(rec)
        assert enc.zerolength == pytest.approx(axis.encoder.length(), abs=1e-6)


def test_motors_off_after_endpoint(prototype_run):
    """After ENDPOINT_STOP every motor is stopped with its windings off."""
    station, _, _, _, _ = prototype_run
    assert _motors_still(station)
    for a in station.axes:
        assert station.tio10.bit(*a.motor._awo)


@pytest.mark.parametrize(("fault", "reason"), [("dead", StopReason.LOW_TENSION_STOP),
                                               ("break", StopReason.LOW_TENSION_STOP)])
def test_sensor_and_rope_failures_stop_everything(tmp_path, fault, reason):
    """A dead loadcell or a broken rope during a move: the tension stop, every motor off."""
    station, runner = make_station(tmp_path)
    runner.call(station.polyaxis.to, (60.0, 0.0, 140.0))
    runner.sleep(15.0)
    assert runner.call(lambda: station.polyaxis.active)
    inject = station.plant.inject_loadcell_dead if fault == "dead" else station.plant.break_rope
    runner.call(inject, "axis1")
    with pytest.raises(FaultError) as info:
        runner.wait_until(lambda: not station.polyaxis.active, 30.0)
    assert info.value.fault.cause.startswith(reason.value)
    assert station.polyaxis.last_stop.reason is reason
    assert _motors_still(station)
    runner.sleep(2.0)
    assert _motors_still(station)
    to = station.polyaxis.find_command("to")
    with pytest.raises(CommandError, match="give 'ack' first"):
        runner.call(station.execute, station.polyaxis, to, to.parse(["0", "0", "100"]))
    assert "acknowledged" in runner.call(station.acknowledge)
    station.close()


def test_stalled_motor_past_half_way_stops(tmp_path):
    """A motor stalling past half way: the source gets no closer; the move stops, motors off."""
    station, runner = make_station(tmp_path)
    pa = station.polyaxis
    target = (60.0, 0.0, 140.0)
    runner.call(pa.to, target)
    assert runner.wait_until(lambda: math.dist(pa.position, target) < 25.0, 200.0)
    runner.call(station.plant.inject_stall, "axis0")
    with contextlib.suppress(FaultError):
        runner.wait_until(lambda: not pa.active, 200.0)
    assert not pa.active
    assert pa.last_stop.reason in (StopReason.STUCK_STOP, StopReason.LOW_TENSION_STOP,
                                   StopReason.HIGH_TENSION_STOP, StopReason.NET_FORCE_STOP,
                                   StopReason.FAULT)  # FAULT: the encoder does not follow
    assert _motors_still(station)
    station.close()


@pytest.mark.parametrize(("target", "why"), [
    ((0.0, 0.0, 400.0), "outside the vessel"),
    ((400.0, 0.0, 0.0), "outside the vessel"),
    ((60.0, 0.0, 380.0), "neck's allowed radius"),
    ((-250.0, 0.0, 150.0), "tension bounds"),
    ((0.0, 0.0, 386.0), "top pulley"),
    ((0.0, 5.0, 300.0), "out of the manipulator's plane"),
])
def test_unreachable_target_refused_without_motion(tmp_path, target, why):
    """A target outside the vessel/neck, out of the plane or needing tensions out of bounds is
    refused; nothing moves."""
    station, runner = make_station(tmp_path)
    writes = station.tio10.writes
    with pytest.raises(CommandError, match=why):
        runner.call(station.polyaxis.to, target)
    runner.sleep(1.0)
    assert station.tio10.writes == writes
    assert not station.polyaxis.active and _motors_still(station)
    station.close()


def test_stop_command_stops_every_motor(tmp_path):
    """'stop' mid-move: the move ends with STOP, every motor off."""
    station, runner = make_station(tmp_path)
    runner.call(station.polyaxis.to, (60.0, 0.0, 140.0))
    runner.sleep(10.0)
    assert station.motors_running()
    runner.call(station.polyaxis.run_command, "stop")
    assert station.polyaxis.last_stop.reason is StopReason.STOP
    assert _motors_still(station)
    station.close()


def test_tension_stop_toggle_and_rearm(tmp_path):
    """tensionStop toggles the tension stops; 'to' switches them on again."""
    station, runner = make_station(tmp_path)
    pa = station.polyaxis
    assert "OFF" in runner.call(pa.run_command, "tensionStop")
    assert not pa.tension_stop
    runner.call(pa.to, (10.0, 0.0, 110.0))
    assert pa.tension_stop and pa.stops.tension_stops
    runner.call(pa.run_command, "stop")
    station.close()


def _start_pattern(station, runner, path):
    pa = station.polyaxis
    runner.call(pa.run_command, "pattern", str(path))
    return pa.pattern_job


def _pattern(tmp_path, points):
    pat = tmp_path / "five.pat"
    pat.write_text("five.log\n" + "".join(f"{x} {y} {z}\n" for x, y, z in points))
    return pat


def test_pattern_of_five_points(tmp_path):
    """A five-point pattern completes; its log names each endpoint's stop."""
    station, runner = make_station(tmp_path)
    points = [(0.0, 0.0, 110.0), (15.0, 0.0, 110.0), (15.0, 0.0, 125.0), (0.0, 0.0, 125.0),
              (-10.0, 0.0, 100.0)]
    job = _start_pattern(station, runner, _pattern(tmp_path, points))
    assert runner.wait_until(lambda: job.done, 600.0)
    results = job.value()
    assert [r.reason for r in results] == [StopReason.ENDPOINT_STOP] * 5
    lines = [ln for ln in (tmp_path / "five.log").read_text().splitlines()
             if not ln.startswith("#")]
    assert len(lines) == 5
    assert all(" ENDPOINT_STOP at " in ln for ln in lines)
    assert (tmp_path / "five.log").read_text().rstrip().endswith("# pattern complete")
    station.close()


# -- the 5-rope full-scale station -----------------------------------------------------


@pytest.fixture(scope="module")
def sno_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("sno")
    station, runner = make_station(tmp, "sno")
    log = station.start_log(tmp / "sno.log")
    targets = [(80.0, 60.0, 100.0), (-40.0, 50.0, 150.0), (0.0, 0.0, 700.0)]
    stops, written = [], []
    for t in targets:
        stops.append(move(station, runner, t))
        written.append(load_station(station.directory).polyaxis().position)
    station.stop_log()
    yield station, runner, targets, stops, read_log(log), written
    station.close()


def test_sno_out_of_plane_moves_end_at_endpoint(sno_run):
    """Out-of-plane targets and the neck on the 5-rope station end with ENDPOINT_STOP there."""
    station, _, targets, stops, log, _ = sno_run
    assert [s.reason for s in stops] == [StopReason.ENDPOINT_STOP] * 3
    for t, s in zip(targets, stops, strict=True):
        assert math.dist(s.position, t) <= 1.0
    assert math.dist(station.plant.position, targets[-1]) < 1.5
    assert [int(p[5]) for p in log["TO"]] == [1, 1, 2]  # into the neck through the turn


def test_sno_tensions_within_bounds(sno_run):
    """No rope of the 5-rope station is logged out of its tension bounds."""
    station, _, _, _, log, _ = sno_run
    tensions = [float(p[4]) for p in log["S"]]
    assert {int(p[2]) for p in log["S"]} == {0, 1, 2, 3, 4}
    assert station.polyaxis.low_tension <= min(tensions)
    assert max(tensions) <= station.polyaxis.max_tension


def test_sno_database_written_back(sno_run):
    """The full-scale station's POSITION follows the source out of plane."""
    station, _, _, _, _, written = sno_run
    pos = load_station(station.directory).polyaxis().position
    assert math.dist(pos, station.polyaxis.position) < 0.5
    first = written[0]  # on disk right after the out-of-plane move
    assert math.dist(first, (80.0, 60.0, 100.0)) < 3.0


def test_sno_refusals(tmp_path):
    """The 5-rope station refuses a target it cannot hold, and one outside the neck; nothing moves."""
    station, runner = make_station(tmp_path, "sno")
    writes = station.tio10.writes
    with pytest.raises(CommandError, match="tension bounds"):
        runner.call(station.polyaxis.to, (200.0, 100.0, 0.0))
    with pytest.raises(CommandError, match="allowed radius"):
        runner.call(station.polyaxis.to, (0.0, 100.0, 900.0))
    assert station.tio10.writes == writes and _motors_still(station)
    station.close()


@pytest.mark.parametrize("fault", ["dead", "break"])
def test_sno_failures_stop_everything(tmp_path, fault):
    """A dead loadcell or a broken rope on the 5-rope station mid-move: LOW_TENSION_STOP,
    every motor off."""
    station, runner = make_station(tmp_path, "sno")
    runner.call(station.polyaxis.to, (50.0, -40.0, 80.0))
    runner.sleep(10.0)
    inject = station.plant.inject_loadcell_dead if fault == "dead" else station.plant.break_rope
    runner.call(inject, 3)
    with pytest.raises(FaultError, match="LOW_TENSION_STOP: axis3"):
        runner.wait_until(lambda: not station.polyaxis.active, 30.0)
    assert _motors_still(station)
    station.close()


def test_sno_pattern_of_five_points(tmp_path):
    """A five-point pattern out of the rope planes completes on the 5-rope station; the log
    names each stop."""
    station, runner = make_station(tmp_path, "sno")
    points = [(10.0, 10.0, 20.0), (25.0, 10.0, 30.0), (25.0, 25.0, 40.0), (0.0, 20.0, 40.0),
              (-10.0, 0.0, 20.0)]
    job = _start_pattern(station, runner, _pattern(tmp_path, points))
    assert runner.wait_until(lambda: job.done, 900.0)
    assert [r.reason for r in job.value()] == [StopReason.ENDPOINT_STOP] * 5
    lines = [ln for ln in (tmp_path / "five.log").read_text().splitlines()
             if not ln.startswith("#")]
    assert len(lines) == 5 and all(" ENDPOINT_STOP at " in ln for ln in lines)
    station.close()
