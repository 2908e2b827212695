"""Every move supervised: faults injected in the simulated world during a
PolyAxis move and during an axis move end in a named stop or fault, with
every motor stopped, the source where it was, and nothing written back."""

from __future__ import annotations

import contextlib
import io
import math
import re

import pytest
from _manipulator_rig import make_station

from pyrt.commands.robot import RobotShell
from pyrt.console import Console
from pyrt.db import load_station
from pyrt.errors import FaultError

#: (fault kind, rope, the named stop or fault it must end in)
POLY_CASES = [
    ("dead", "axis1", "LOW_TENSION_STOP: axis1 tension"),
    ("stuck", "axis1", "LOADCELL_FAULT: axis1Loadcell has read ADC code"),
    ("stall", "axis1", "TRACKING_FAULT: axis1: the motor moved"),
    ("break", "axis2", "LOW_TENSION_STOP: axis"),
]
AXIS_CASES = [
    ("dead", "axis1", "LOADCELL_FAULT: axis1Loadcell reads ADC code 0"),
    ("stuck", "axis1", "LOADCELL_FAULT: axis1Loadcell has read ADC code"),
    ("stall", "axis1", "TRACKING_FAULT: axis1: the motor moved"),
    ("break", "axis1", "LOW_TENSION_STOP: axis"),
]

#: How far (cm) the true source may be from where it was when the fault began.
DRIFT_CM = 2.0


def _dist(a, b) -> float:
    return math.dist(a, b)


def _db_values(directory) -> tuple:
    st = load_station(directory)
    pa = st.polyaxis()
    return (tuple(pa.position), tuple(a.length for a in st.axes_of(pa)),
            tuple(st.encoder_of(a).zerolength for a in st.axes_of(pa)))


def _payouts(station) -> list[float]:
    return [station.plant.payout(i) for i in range(len(station.axes))]


def _check_source(station, kind: str, at, payouts) -> None:
    """The source within DRIFT_CM of where it was when the fault began; for a
    broken rope (whose source swings on the ropes left, whatever the motors
    do) the motors gave or took no more than DRIFT_CM of rope after it."""
    if kind == "break":
        moved = sum(abs(a - b) for a, b in zip(_payouts(station), payouts, strict=True))
        assert moved <= DRIFT_CM
    else:
        assert _dist(station.plant.position, at) <= DRIFT_CM


def _inject_and_finish(station, runner, kind: str, rope: str) -> tuple:
    plant = station.plant
    at = (plant.position, _payouts(station))
    runner.call(station.component("sim").run_command, "fault", rope, kind)
    with contextlib.suppress(FaultError):
        runner.wait_until(lambda: station.fault is not None, 20.0)
    assert station.fault is not None
    written = _db_values(station.directory)
    with contextlib.suppress(FaultError):
        runner.sleep(15.0)  # longer than the 10 s stationary write-back period
    return at, written


@pytest.mark.parametrize("kind,rope,named", POLY_CASES)
def test_fault_during_polyaxis_move(tmp_path, kind, rope, named):
    """A sensor, motor or rope fault in a PolyAxis move: named fault, motors
    stopped, the source within 2 cm of where it was, nothing written back."""
    station, runner = make_station(tmp_path)
    try:
        runner.call(station.polyaxis.to, (0.0, 0.0, 60.0))
        runner.sleep(6.0)
        assert station.polyaxis.active
        at, written = _inject_and_finish(station, runner, kind, rope)
        fault = station.fault
        assert named in fault.cause, fault.cause
        assert named in str(station.polyaxis.last_stop)
        assert not station.motors_running() and not station.polyaxis.active
        _check_source(station, kind, *at)
        assert _db_values(station.directory) == written
    finally:
        station.close()


@pytest.mark.parametrize("kind,rope,named", AXIS_CASES)
def test_fault_during_axis_move(tmp_path, kind, rope, named):
    """A sensor, motor or rope fault in an axis move: named fault, motors
    stopped, the source within 2 cm of where it was, nothing written back."""
    station, runner = make_station(tmp_path)
    try:
        runner.call(station.component("axis1").run_command, "up", "3")
        runner.sleep(0.2)
        assert station.motors_running()
        at, written = _inject_and_finish(station, runner, kind, rope)
        fault = station.fault
        assert named in fault.cause, fault.cause
        assert not station.motors_running()
        _check_source(station, kind, *at)
        assert _db_values(station.directory) == written
    finally:
        station.close()


# -- numbers without bounds, unguarded axis moves (console transcripts) ---------------

def _run(station, runner, lines: list[str]) -> str:
    out = io.StringIO()
    sh = RobotShell(station, out)
    Console(sh, io.StringIO("".join(ln + "\n" for ln in lines)), out,
            messages=runner.messages).run()
    return out.getvalue()


UNBOUNDED = ["axis0 down 1e9", "axis0 to 1e300", "axis0 to 1e308", "axis0 down 1e308",
             "axis0Encoder setZeroLength 1e308", "axis0 to 2000", "axis0 up 1e308",
             "axis0Motor maxspeed 1e308", "axis0Loadcell point 1e308"]


def test_numbers_outside_their_range_are_refused(tmp_path):
    """Huge lengths, distances and speeds: one error naming the range each, no
    motor moved, no register written, no database changed."""
    station, runner = make_station(tmp_path)
    try:
        files = {p.name: p.read_text() for p in station.directory.glob("*.dat")}
        zero = [a.encoder.zero_length for a in station.axes]
        writes = station.tio10.writes
        text = _run(station, runner, ["axis0Loadcell calibrate", *UNBOUNDED, "wait",
                                      "axis0Loadcell calibrate"])
        assert text.count("error:") == len(UNBOUNDED) + 1  # + too few calibration points
        assert text.count("is out of range: ") == len(UNBOUNDED)
        assert "internal error" not in text and "moving to length" not in text
        assert "LEN 2.8..713.7 cm (the rope's physical length range)" in text
        assert station.tio10.writes == writes
        assert not station.motors_running()
        runner.sleep(12.0)  # write-back runs (stationary period): nothing absurd in it
        for name, before in files.items():
            after = (station.directory / name).read_text()
            assert not re.search(r"\d{20}", after), name
            assert len(after) < len(before) + 200, name
        assert [a.encoder.zero_length for a in station.axes] == zero
    finally:
        station.close()


def test_help_shows_the_ranges(tmp_path):
    """'help axis0' shows each numeric argument's physical range."""
    station, runner = make_station(tmp_path)
    try:
        text = _run(station, runner, ["help axis0", "help axis0Encoder", "help axis0Motor"])
        assert "to LEN: change the rope length to LEN cm [LEN 2.8..713.7 cm" in text
        assert "[DIST 0..710.9 cm" in text and "[SPEED 0.07..7 cm/s" in text
        assert "setZeroLength LEN: set the length (cm) the counter reads at zero [LEN " in text
    finally:
        station.close()


def test_axis_move_that_slackens_a_rope_stops_named(tmp_path):
    """An axis move that slackens a rope ends in LOW_TENSION_STOP with every motor
    stopped, and no rope below 2 N for longer than one axis poll's travel."""
    station, runner = make_station(tmp_path)
    try:
        text = _run(station, runner, ["axis1 down 5", "wait"])
        assert "FAULT: LOW_TENSION_STOP: axis1 tension" in text
        assert not station.motors_running()
        assert min(station.plant.tensions()) > 0.5
        assert station.axes[1].getLength() < 616.9 + 5.0 - 1.0  # stopped well short
    finally:
        station.close()


def test_tension_stop_off_lets_axis_moves_through(tmp_path):
    """With tensionStop off (000: to control single axes out of bounds) the move
    that would slacken a rope runs to its end, and so does the move back."""
    station, runner = make_station(tmp_path)
    try:
        text = _run(station, runner, ["prototype tensionStop", "axis1 down 2", "wait",
                                      "axis1 up 2", "wait", "prototype tensionStop"])
        assert "tension stops OFF" in text and "tension stops on" in text
        assert "FAULT" not in text and text.count("move ended at length") == 2
        assert station.fault is None
    finally:
        station.close()


def test_length_range_is_enforced_in_the_loop(tmp_path):
    """A rope driven outside its physical range by whatever drives it stops with
    LENGTH_RANGE_STOP (the range narrowed under a running move)."""
    station, runner = make_station(tmp_path)
    try:
        ax = station.axes[1]
        runner.call(ax.run_command, "up", "1")
        here = ax.getLength()
        runner.call(ax.set_supervision, (here + 0.1, here + 500.0), ax.tension_limits)
        with contextlib.suppress(FaultError):
            runner.sleep(1.0)
        assert station.fault is not None
        assert "LENGTH_RANGE_STOP: axis1 length" in station.fault.cause
        assert not station.motors_running()
    finally:
        station.close()


def test_stuck_loadcell_needs_many_reads_not_just_time(tmp_path):
    """Two reads of one code 0.6 s apart (late ticks on a loaded machine) are not a stuck
    loadcell; fifty-one reads over half a second are."""
    station, runner = make_station(tmp_path)
    try:
        ax = station.axes[1]
        runner.call(ax.run_command, "up", "1")

        def sparse():
            return [ax.supervise(100.0, True), ax.supervise(100.6, True)]

        def dense():
            return [ax.supervise(200.0 + k * 0.01, True) for k in range(52)]

        assert runner.call(sparse) == [None, None]
        out = runner.call(dense)
        assert out[:50] == [None] * 50
        assert out[-1].startswith("LOADCELL_FAULT: axis1Loadcell has read ADC code")
    finally:
        station.close()
