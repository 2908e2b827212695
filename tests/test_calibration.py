"""Loadcell calibration as on the rig: known loads hung in the simulation
('sim load'), fits refused when no loadcell could give them, DATE and
CALIBRATIONPOINT written with SLOPE and OFFSET."""

from __future__ import annotations

import io
import re

import pytest
from _manipulator_rig import make_station

from pyrt.boards.dataconcentrator import ADC_MAX
from pyrt.commands.robot import RobotShell
from pyrt.console import Console
from pyrt.db import load_station
from pyrt.errors import CommandError
from pyrt.sim.sensors import Imperfections


def _run(station, runner, lines: list[str]) -> str:
    out = io.StringIO()
    Console(RobotShell(station, out), io.StringIO("".join(ln + "\n" for ln in lines)), out,
            messages=runner.messages).run()
    return out.getvalue()


@pytest.fixture
def rig(tmp_path):
    station, runner = make_station(tmp_path)
    yield station, runner
    station.close()


def test_calibration_with_hung_loads_recovers_the_loadcell(rig):
    """Three known loads hung with 'sim load': the fit is the simulated loadcell's
    within its noise, and LOADCELL.dat gets SLOPE, OFFSET, DATE and CALIBRATIONPOINT."""
    station, runner = rig
    rope = station.plant.ropes[1].rig
    lines = ["axis1Loadcell calibrate"]
    for n in (0, 50, 100, 150, 200):
        lines += [f"sim load axis1 {n}", "sleep 0.1", f"axis1Loadcell point {n} N"]
    lines += ["axis1Loadcell calibrate", "sim unload axis1", "sleep 0.5"]
    text = _run(station, runner, lines)
    assert "error" not in text
    slope, offset = station.axes[1].loadcell.slope, station.axes[1].loadcell.offset
    assert slope == pytest.approx(rope.loadcell_slope, rel=0.03)
    assert -offset / slope == pytest.approx(-rope.loadcell_offset / rope.loadcell_slope, abs=8)
    rec = load_station(station.directory).loadcell("loadcell1")
    assert rec.slope == pytest.approx(slope) and rec.offset == pytest.approx(offset)
    assert re.fullmatch(r"\d\d-\d\d-\d{4}", rec.date)
    pts = [p.split() for p in rec.calibration_points.split(";")]
    assert [float(n) for _, n in pts] == [0, 50, 100, 150, 200]
    assert all(0 < int(c) < ADC_MAX for c, _ in pts)
    text = (station.directory / "LOADCELL.dat").read_text()
    assert text.count("CALIBRATIONPOINT:") == 1  # only the calibrated loadcell's entry


@pytest.mark.parametrize("loads,given,why", [
    ((100, 0), (0, 100), "gain .* is not positive"),  # loads entered the wrong way round
    ((0, 100), (1000, 1100), "zero load would read ADC code -"),  # a tare forgotten
    ((0, 50, 100), (0, 90, 100), "scatter .* N RMS about the fit"),
])
def test_implausible_fit_is_refused_and_nothing_written(rig, loads, given, why):
    """A negative gain, zero load off the ADC, points off the line: refused, SLOPE and
    OFFSET unchanged in memory and in the database, calibration mode kept."""
    station, runner = rig
    lc = station.axes[1].loadcell
    lc.maxload = 0.0  # let the wrong loads through 'point' (MAXLOAD is another check)
    before = (lc.slope, lc.offset, (station.directory / "LOADCELL.dat").read_text())
    lines = ["axis1Loadcell calibrate"]
    for hung, said in zip(loads, given, strict=True):
        lines += [f"sim load axis1 {hung}", "sleep 0.1", f"axis1Loadcell point {said}"]
    lines += ["axis1Loadcell calibrate", "sim unload axis1", "sleep 11"]
    text = _run(station, runner, lines)
    assert re.search(f"calibrate: refused, .*{why}", text), text
    assert "SLOPE and OFFSET unchanged" in text
    assert (lc.slope, lc.offset, (station.directory / "LOADCELL.dat").read_text()) == before
    assert lc.calibrating and lc.points == []


def test_calibration_load_above_maxload_is_refused(rig):
    """A calibration point above the loadcell's MAXLOAD (50 lb) names the range."""
    station, runner = rig
    text = _run(station, runner, ["axis1Loadcell calibrate", "axis1Loadcell point 300 N"])
    assert "LOAD 300 is out of range: LOAD 0..222.411 N (up to the loadcell's MAXLOAD)" in text
    assert station.axes[1].loadcell.points == []


def test_sim_load_is_read_instead_of_the_rope(tmp_path):
    """With ideal sensors a hung load reads back through the old calibration exactly
    (to one ADC code); unloaded, the rope's tension comes back."""
    station, runner = make_station(tmp_path, imperfections=Imperfections.ideal())
    try:
        lc = station.axes[2].loadcell
        rope_t = runner.call(lc.measured)
        runner.call(lc.calibrate)
        runner.call(station.plant.hang_load, "axis2", 120.0)
        runner.sleep(0.05)
        assert runner.call(lc.measured) == pytest.approx(120.0, abs=lc.slope)
        runner.call(station.plant.hang_load, "axis2", None)
        runner.sleep(0.05)
        assert runner.call(lc.measured) == pytest.approx(rope_t, abs=2 * lc.slope)
        with pytest.raises(ValueError, match="finite number of N >= 0"):
            station.plant.hang_load("axis2", -1.0)
        with pytest.raises(CommandError, match="NEWTONS 1e\\+09 is out of range"):
            runner.call(station.component("sim").run_command, "load", "axis2", "1e9")
        assert station.fault is None
    finally:
        station.close()


def test_calibration_mode_holds_the_ropes_tension_and_refuses_moves(tmp_path):
    """While a loadcell calibrates, the controller keeps the rope's tension from before
    (a 200 N calibration load neither faults the position estimate nor reaches the
    stretch correction), and PolyAxis moves are refused naming the loadcell (the rope's
    own axis may still move, to lift a calibration load)."""
    station, runner = make_station(tmp_path, imperfections=Imperfections.ideal())
    try:
        lc = station.axes[1].loadcell
        before = runner.call(lc.tension)
        text = _run(station, runner, ["axis1Loadcell calibrate", "sim load axis1 200",
                                      "sleep 2", "prototype to 0 0 60", "axis1 up 1"])
        assert runner.call(lc.measured) == pytest.approx(200.0, abs=3 * lc.slope)
        assert runner.call(lc.tension) == before
        assert station.fault is None and station.polyaxis.estimate_lost is None
        assert "prototype to: refused: axis1Loadcell in calibration mode" in text
        assert text.count("refused") == 1 and "axis1: moving to length" in text
        assert not station.polyaxis.active
    finally:
        station.close()
