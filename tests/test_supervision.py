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
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from pyrt.commands.robot import RobotShell
from pyrt.console import Console
from pyrt.db import load_station
from pyrt.errors import FaultError, NativeError
from pyrt.robots.polyaxis import MIN_TOP_SEGMENT

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
        assert "LEN 0..713.7 cm (the rope's physical length range)" in text
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
        assert "to LEN: change the rope length to LEN cm [LEN 0..713.7 cm" in text
        assert "[DIST 0..713.7 cm" in text and "[SPEED 0.07..7 cm/s" in text
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
        assert station.axes[1].length() < 616.9 + 5.0 - 1.0  # stopped well short
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
        here = ax.length()
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
    loadcell; fifty-one reads over half a second are, once the motor has moved a centimetre
    of rope (a slow creep with a noise-free loadcell is not)."""
    station, runner = make_station(tmp_path)
    try:
        ax = station.axes[1]
        runner.call(ax.run_command, "up", "1")

        def sparse():
            return [ax.supervise(100.0, True), ax.supervise(100.6, True)]

        def dense(t0, creep_steps):
            out = []
            for k in range(52):
                ax.motor.position_steps -= creep_steps
                out.append(ax.supervise(t0 + k * 0.01, True))
            return out

        assert runner.call(sparse) == [None, None]
        steps = ax.motor.steps_per_cm
        assert runner.call(dense, 200.0, 0) == [None] * 52  # a creep: the code may stay
        out = runner.call(dense, 300.0, int(steps / 40) + 1)  # 1 cm in 40 reads
        assert out[:50] == [None] * 50
        assert out[-1].startswith("LOADCELL_FAULT: axis1Loadcell has read ADC code")
        assert "cm of rope (stuck)" in out[-1]
    finally:
        station.close()


@pytest.fixture(scope="module", params=["prototype", "sno"])
def ranged_station(request, tmp_path_factory):
    station, _runner = make_station(tmp_path_factory.mktemp(request.param), request.param)
    yield request.param, station
    station.close()


@settings(max_examples=300, derandomize=True, deadline=None)
@given(u=st.floats(-1.0, 1.0), w=st.floats(-1.0, 1.0), h=st.floats(0.0, 1.05),
       in_neck=st.booleans())
def test_every_accepted_target_is_inside_every_ropes_length_range(ranged_station, u, w, h,
                                                                   in_neck):
    """Any point a move may go to (the vessel and the whole neck, as 'to' allows) has
    every rope within its length range, so the range never stops a move PolyAxis accepted."""
    name, station = ranged_station
    pa, av = station.polyaxis, station.polyaxis.av
    planar = name == "prototype"
    if in_neck:
        ring = av.neck_ring_static_position
        v = (ring[0] + u * av.neck_radius, ring[1] + (0.0 if planar else w * av.neck_radius),
             ring[2] + h * av.neck_length)
    else:
        r = av.vessel_radius
        v = (u * r, 0.0 if planar else w * r, (2.0 * h / 1.05 - 1.0) * r)
    x = av.vtog(v)
    assume(pa.model.refusal(x) is None)
    # 'to' also keeps the carriage MIN_TOP_SEGMENT from every top pulley.
    assume(all(math.dist((x[0] + o[0], x[1] + o[1], x[2] + o[2]), top) >= MIN_TOP_SEGMENT
               for top, o in zip(pa.tops, pa.offsets, strict=True)))
    try:
        lengths = pa.model.lengths_at(x)
    except NativeError:  # exactly on a pulley, an attachment or the ring's rim
        assume(False)
    for a, length in zip(station.axes, lengths, strict=True):
        lo, hi = a.length_range
        assert lo <= length <= hi, (a.name, x, length, (lo, hi))
