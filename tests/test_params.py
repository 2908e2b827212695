"""Parameters by name at run time (get/set): ranges, refusals while moving, both robots, the DAQ link."""

from __future__ import annotations

import io

import pytest
from _manipulator_rig import make_station
from _server_rig import served
from hypothesis import given
from hypothesis import strategies as st

from pyrt.client import ServerError
from pyrt.commands import RobotShell
from pyrt.component import Param
from pyrt.errors import CommandError
from pyrt.native import FuzzyInput
from pyrt.scheduler import Loop, SimClock
from pyrt.station.gripper import build_gripper


class Box:
    value = 5.0


def test_param_parse_checks_the_range_and_the_kind():
    """A Param parses decimal or hex, refuses a value out of range or not a number, naming the range."""
    p = Param("speed", "speed byte", lambda: 0x7F, lambda v: None, 1, 0x7F, integer=True, hex=True)
    assert p.parse("w", "33") == 0x33 and p.range_text == "01..7F speed byte"
    with pytest.raises(CommandError, match=r"80 is out of range \(01..7F speed byte\)"):
        p.parse("w", "80")
    with pytest.raises(CommandError, match="not a hexadecimal number"):
        p.parse("w", "zz")
    q = Param("G", "N", lambda: 1.0, lambda v: None, 0.0, 10.0)
    for bad in ("nan", "inf", "x", "11"):
        with pytest.raises(CommandError):
            q.parse("w", bad)
    assert "not written back" in q.describe("o", 1.0) and "not while moving" in q.describe("o", 1)


@given(st.floats(allow_nan=True, allow_infinity=True))
def test_param_parse_never_passes_a_value_out_of_range(x):
    """Whatever the text, a parsed value is finite and inside the range."""
    q = Param("G", "N", lambda: 1.0, lambda v: None, -3.0, 7.5)
    try:
        v = q.parse("w", repr(x))
    except CommandError:
        return
    assert -3.0 <= v <= 7.5


@pytest.fixture
def gripper():
    station = build_gripper(Loop(SimClock()))
    station.start()
    out = io.StringIO()
    shell = RobotShell(station, out)

    def run(*lines: str) -> list[str]:
        out.seek(0)
        out.truncate()
        for line in lines:
            shell.onecmd(line)
        return out.getvalue().splitlines()

    run("I")
    yield station, run
    station.close()


def test_gripper_speed_and_schedule_round_trip(gripper):
    """set gripper.speed 33 changes X (get shows it); 80 is refused, nothing changed."""
    station, run = gripper
    ctl = station.controller
    assert run("get gripper.speed")[0].startswith("gripper.speed = 7F speed byte (range 01..7F")
    said = run("set gripper.speed 33", "get gripper.speed")
    assert said[0].startswith("gripper.speed 7F -> 33 speed byte (not written back")
    assert said[1].startswith("gripper.speed = 33")
    assert run("set gripper.speed 80") == [
        "error: set gripper.speed: 80 is out of range (01..7F speed byte); nothing changed"]
    assert run("set gripper.MVJAWSPD 0E")[0].startswith("gripper.MVJAWSPD 0C -> 0E")
    assert station.runner.call(lambda: ctl.schedule().mvjawspd) == 0x0E
    assert run("get gripper")[0].startswith("gripper.speed = 33")


def test_gripper_schedule_uses_the_monitors_checks(gripper):
    """A schedule byte set by name gets the monitor's C checks: 00 refused, an oscillating one warned of."""
    _station, run = gripper
    assert run("set gripper.WTCHJWSPD 0")[0].startswith("error: set gripper.WTCHJWSPD: 00 is "
                                                         "out of range")
    said = run("set gripper.WTCHJWSPD FF")[0]
    monitor = run("M", "C 45 FF", "Q")
    assert said.startswith("gripper.WTCHJWSPD 01 -> FF clock periods")
    warning = next(ln for ln in monitor if ln.startswith("warning: "))
    assert said.endswith("; " + warning)


def test_gripper_set_refused_while_moving(gripper):
    """While a P move runs, set gripper.speed is refused and nothing changes."""
    _station, run = gripper
    run("P E47A")
    said = run("set gripper.speed 20")
    assert said == ["error: set gripper.speed: refused while a move runs (changing it then is "
                    "unsafe); stop or wait first; nothing changed"]
    assert run("get gripper.speed")[0].startswith("gripper.speed = 7F")


def test_unknown_names_say_what_there_is(gripper):
    """get of an unknown parameter names the object's parameters; get OBJ.X of no object names the objects."""
    _station, run = gripper
    assert run("get gripper.nosuch")[0] == ("error: gripper has no parameter 'nosuch'; it has "
                                            "speed, SYSCLKPD, MVJAWSPD, SENSORPD, WTCHJWSPD")
    assert run("get nosuch.x")[0].startswith("error: no object named 'nosuch'")
    assert run("get")[0] == "parameters (get OBJECT lists them): gripper (5)"


@pytest.fixture(scope="module")
def manip(tmp_path_factory):
    station, runner = make_station(tmp_path_factory.mktemp("params"))
    out = io.StringIO()
    shell = RobotShell(station, out)

    def run(*lines: str) -> list[str]:
        out.seek(0)
        out.truncate()
        for line in lines:
            shell.onecmd(line)
        return out.getvalue().splitlines()

    yield station, runner, run
    station.close()


def test_manipulator_max_tension_round_trip(manip):
    """set prototype.MAX_TENSION reaches the fuzzy rules and every rope's tension stop; out of range is refused."""
    station, _runner, run = manip
    pa = station.polyaxis
    said = run("set prototype.MAX_TENSION 150")
    assert said[0].startswith("prototype.MAX_TENSION 200 -> 150 N (not written back")
    assert pa.max_tension == 150.0
    assert set(pa.batch.inputs[:, FuzzyInput.TENSION_HIGH]) == {150.0}
    assert all(a.tension_limits[1] == 150.0 for a in pa.axes)
    assert run("get axis1.HIGH_TENSION")[0].startswith("axis1.HIGH_TENSION = 150 N (read only)")
    bad = run("set prototype.MAX_TENSION 9999")[0]
    assert bad.startswith("error: set prototype.MAX_TENSION: 9999 is out of range (") \
        and bad.endswith("nothing changed")
    assert pa.max_tension == 150.0
    run("set prototype.MAX_TENSION 200")


def test_manipulator_gains_and_speeds_round_trip(manip):
    """A fuzzy gain and a motor speed change by name and read back; a read-only one is refused."""
    station, _runner, run = manip
    pa = station.polyaxis
    old = pa.batch.params[0].dv_length
    run(f"set axis0.DV_LENGTH {2 * old:g}")
    assert pa.batch.params[0].dv_length == pytest.approx(2 * old)
    assert pa.batch.params[1].dv_length == pytest.approx(old)
    run(f"set axis0.DV_LENGTH {old:g}")
    assert run("set axis0Motor.CRUISE_SPEED 5")[0].startswith("axis0Motor.CRUISE_SPEED 7 -> 5")
    assert pa.axes[0].motor.cruise_speed == 5.0
    assert run("set axis0Motor.CRUISE_SPEED 0.01")[0].startswith("error:")
    assert run("set axis0Motor.START_SPEED 6")[0].startswith("error:")  # above CRUISE_SPEED
    assert run("set axis0Motor.START_SPEED 4")[0].startswith("axis0Motor.START_SPEED 0.5 -> 4")
    assert run("set axis0Motor.CRUISE_SPEED 3")[0].startswith("error:")  # below START_SPEED
    assert pa.axes[0].motor.cruise_speed == 5.0
    run("set axis0Motor.START_SPEED 0.5", "set axis0Motor.CRUISE_SPEED 7")
    assert run("set axis0.LOW_TENSION 3") == ["error: set axis0.LOW_TENSION: read only; "
                                              "nothing changed"]
    assert "written back" in run("get axis0Loadcell.SLOPE")[0]


def test_manipulator_end_error_refused_while_moving(manip):
    """During a move set prototype.END_ERROR is refused; after it, it is taken."""
    station, _runner, run = manip
    run("prototype to 10 0 100")
    said = run("set prototype.END_ERROR 0.3")
    assert said[0].startswith("error: set prototype.END_ERROR: refused while a move runs")
    run("wait")
    assert run("set prototype.END_ERROR 0.3")[0].startswith("prototype.END_ERROR 0.5 -> 0.3")
    assert station.polyaxis.end_error == 0.3


def test_set_over_the_daq_link_needs_privilege():
    """Over the DAQ link get is served to anyone; set needs AUTH, round-trips, and is range-checked."""
    from _server_rig import TOKEN

    with served() as s:
        guest = s.client()
        assert guest.command("get gripper.speed")[0].startswith("gripper.speed = 7F")
        with pytest.raises(ServerError) as denied:
            guest.command("set gripper.speed 33")
        assert denied.value.code == "denied"
        op = s.client()
        op.auth(TOKEN)
        assert op.command("set gripper.speed 33")[0].startswith("gripper.speed 7F -> 33")
        assert guest.command("get gripper.speed")[0].startswith("gripper.speed = 33")
        with pytest.raises(ServerError) as bad:
            op.command("set gripper.speed 80")
        assert "out of range" in bad.value.text
        assert guest.command("get gripper.speed")[0].startswith("gripper.speed = 33")
