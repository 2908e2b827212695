"""Axis: stretch-corrected length, standalone STEP_MODE control, Table 4 commands, hooks."""

from __future__ import annotations

import dataclasses
import math

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pyrt.boards.dataconcentrator import DataConcentrator
from pyrt.boards.tio10 import TIO10
from pyrt.db import load_station, station_directory
from pyrt.devices.motor import STANDBY, VELOCITY_MODE
from pyrt.errors import CommandError
from pyrt.robots.av import AV
from pyrt.robots.axis import POLYAXIS, Axis, TrackingError
from pyrt.scheduler import Loop, SimClock
from pyrt.sim.cards import set_adc
from pyrt.sim.manipulator import ManipulatorPlant, rig_from_station
from pyrt.sim.sensors import Imperfections


@pytest.fixture(scope="module")
def station():
    return load_station(station_directory("prototype"))


class Rig:
    """The prototype's central rope alone (a pendulum), with its Axis on a SimClock loop."""

    def __init__(self, station, imp=None, ropes=1, persist=None):
        pa = station.polyaxis()
        rig = rig_from_station(station)
        rig = dataclasses.replace(rig, ropes=rig.ropes[:ropes])
        self.tio, self.dc = TIO10(), DataConcentrator()
        self.plant = ManipulatorPlant(rig, self.tio.registers, self.dc.registers,
                                      imperfections=imp or Imperfections(seed=3))
        self.av = AV.from_record(station.av_of(pa))
        rec = station.axes_of(pa)[0]
        self.axis = Axis.from_records("axis0", rec, station, self.tio, self.dc, av=self.av,
                                      persist=persist)
        self.loop = Loop(SimClock(), 1_000_000)
        self.loop.attach(self.plant.step, "plant")
        self.loop.attach(lambda now: self.axis.poll(now / 1e9), "axis0")
        self.loop.run(5)

    def finish(self, max_s=120):
        assert self.loop.run_until(lambda: not self.axis.motor.running, max_s * 1000)


def test_up_5_changes_the_length_by_5_cm(station):
    """axis0 up 5 shortens the measured length by 5 cm within the encoder resolution, and the
    real rope by as much."""
    r = Rig(station)
    ax = r.axis
    slope = ax.encoder.slope
    l0, g0 = ax.length(), r.plant.lengths()[0]
    z0 = r.plant.position[2]
    ax.run_command("up", "5")
    assert ax.motor.running
    r.finish()
    r.loop.run(5)
    assert ax.length() - l0 == pytest.approx(-5.0, abs=slope)
    assert r.plant.lengths()[0] - g0 == pytest.approx(-5.0, abs=slope + 0.05)
    assert r.plant.position[2] - z0 == pytest.approx(5.0, abs=slope + 0.05)
    assert not r.tio.armed(ax.motor.channel)
    assert ax.target is None


def test_down_and_to(station):
    """down lengthens; to goes to an absolute length."""
    r = Rig(station)
    ax = r.axis
    slope = ax.encoder.slope
    l0 = ax.length()
    ax.cmd_down(2.5)
    r.finish()
    assert ax.length() - l0 == pytest.approx(2.5, abs=slope)
    ax.cmd_to(f"{l0 - 3.0}")
    r.finish()
    assert ax.length() == pytest.approx(l0 - 3.0, abs=slope)


@pytest.mark.parametrize("command,args,match", [
    ("up", ("-5",), r"DIST -5 is out of range: DIST >= 0 cm"),
    ("down", ("five",), "DIST must be a number"),
    ("up", ("nan",), "DIST must be a number"),
    ("to", ("0",), "length must be > 0"),
    ("to", ("1e400",), "LEN must be a number"),
    ("up", ("5000",), "lengths must stay > 0"),
    ("maxspeed", ("9",), r"SPEED 9 is out of range: SPEED 0.07..7 cm/s"),
    ("maxspeed", ("0.01",), r"SPEED 0.01 is out of range"),
    ("up", (), "takes 1 argument"),
    ("zero", ("1",), "takes no argument"),
    ("jump", ("1",), "unknown command"),
])
def test_bad_arguments_move_nothing(station, command, args, match):
    """A bad command raises CommandError and touches no register."""
    r = Rig(station)
    writes = r.tio.writes
    with pytest.raises(CommandError, match=match):
        r.axis.run_command(command, *args)
    r.loop.run(100)
    assert r.tio.writes == writes
    assert not r.tio.armed(r.axis.motor.channel)
    assert r.axis.motor.cruise_speed == 7.0


def test_step_mode_never_reverses(station):
    """While moving up, down is refused (STEP_MODE never reverses); stop then works."""
    r = Rig(station)
    ax = r.axis
    ax.cmd_up(5)
    r.loop.run(200)
    with pytest.raises(CommandError, match="other way"):
        ax.cmd_down(3)
    assert ax.motor.direction < 0
    ax.stop()
    assert not r.tio.armed(ax.motor.channel)
    assert r.tio.bit(*_awo(ax))  # windings off


def _awo(ax):
    from pyrt.boards.tio10 import AWO_BITS

    return AWO_BITS[ax.motor.channel]


def test_get_length_corrects_for_stretch(station):
    """length = encoder length * (1 + STRETCH * tension) - DEADLENGTH."""
    r = Rig(station)
    ax = r.axis
    expect = ax.encoder.length() * (1 + ax.stretch * ax.tension()) - ax.dead_length
    assert ax.length() == pytest.approx(expect)
    assert ax.tension() > 40.0  # the central rope carries the source
    assert ax.length() > ax.encoder.length() - ax.dead_length


def test_length_tracks_the_real_rope(station):
    """With the encoder zeroed on the true payout, length reads the geometric length."""
    r = Rig(station, imp=Imperfections.ideal())
    r.axis.encoder.setZeroLength(r.plant.payout(0))
    assert r.axis.length() == pytest.approx(r.plant.lengths()[0], abs=0.02)


def test_polyaxis_hooks(station):
    """poly_activate: VELOCITY_MODE on standby, commands refused, stop still accepted; poly_deactivate gives the axis back."""
    r = Rig(station)
    ax = r.axis
    ax.poly_activate()
    assert ax.mode == POLYAXIS
    assert ax.motor.mode == VELOCITY_MODE and ax.motor.state == STANDBY
    with pytest.raises(CommandError, match="PolyAxis"):
        ax.cmd_up(1)
    ax.motor.set_desired_velocity(-1.0)
    r.loop.run(50)
    assert ax.motor.velocity == -1.0
    assert ax.signal("errorLength").read() == 0.0  # no PolyAxis: no error signal
    ax.stop()
    assert not r.tio.armed(ax.motor.channel)
    ax.poly_deactivate()
    ax.cmd_up(0.5)
    assert ax.motor.running


def test_calibration_through_the_axis(station):
    """calibrate / point / calibrate fits the loadcell from points taken on the rig."""
    saved = []
    r = Rig(station, imp=Imperfections.ideal(),
            persist=lambda *a: saved.append(a))
    ax = r.axis
    ax.cmd_calibrate()
    ax.cmd_point(f"{r.plant.tensions()[0]} N")
    with pytest.raises(CommandError, match="at least two"):
        ax.cmd_calibrate()
    ax.cmd_up(3)  # the pendulum's tension does not change; hang a different load by hand
    ax.stop()
    set_adc(r.dc.registers, ax.loadcell.channel.channel, 1000)
    r.plant.inject_loadcell_stuck(0)
    ax.cmd_point("100 N")
    slope, offset = ax.cmd_calibrate()
    assert slope > 0
    assert ("LOADCELL", "loadcell0", "SLOPE", slope) in saved
    assert ("LOADCELL", "loadcell0", "OFFSET", offset) in saved


def test_zero_resets_the_counter(station):
    """zero clears the encoder counter."""
    r = Rig(station)
    r.axis.cmd_down(1)
    r.finish()
    assert r.axis.encoder.count() != 0
    r.axis.cmd_zero()
    assert r.axis.encoder.count() == 0


def test_bottom_goes_through_vtog(station):
    """A side axis's bottom attachment is carried through the AV's pose."""
    pa = station.polyaxis()
    av = AV.from_record(station.av_of(pa))
    av.set_pose((0.0, 0.0, 10.0), (0.0, 0.0, 0.0))
    tio, dc = TIO10(), DataConcentrator()
    rec = station.axes_of(pa)[1]
    ax = Axis.from_records("axis1", rec, station, tio, dc, av=av)
    assert ax.bottom == pytest.approx((317.0, 0.0, 99.53))
    assert ax.motor.name == "axis1Motor" and ax.encoder.name == "axis1Encoder"


@pytest.mark.parametrize("fault", ["stall", "slip"])
def test_stall_or_slip_stops_the_axis(station, fault):
    """When the encoder stops following the motor the axis stops it and raises TrackingError."""
    r = Rig(station)
    if fault == "stall":
        r.plant.inject_stall(0)
    else:
        r.plant.inject_slip(0)
    r.axis.cmd_down(10)
    with pytest.raises(TrackingError, match="stall or encoder slip"):
        r.loop.run(60_000)
    assert not r.tio.armed(r.axis.motor.channel)
    assert r.tio.bit(*_awo(r.axis))


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(text=st.text(max_size=12))
def test_any_up_argument_is_a_distance_or_refused(station, text):
    """Whatever text `up` is given, it is a finite distance >= 0 or a CommandError that
    touches no register."""
    r = _shared_rig(station)
    r.axis.stop()
    writes = r.tio.writes
    try:
        value = float(text)
    except ValueError:
        value = None
    try:
        r.axis.cmd_up(text)
    except CommandError:
        assert r.tio.writes == writes
        assert not r.tio.armed(r.axis.motor.channel)
        return
    assert value is not None and math.isfinite(value) and value >= 0


_RIGS: dict[int, Rig] = {}


def _shared_rig(station) -> Rig:
    rig = _RIGS.get(id(station))
    if rig is None:
        rig = _RIGS[id(station)] = Rig(station)
    return rig
