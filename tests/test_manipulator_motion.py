"""Manipulator motions as motion types: hare_path, the 'motion' word, plug-in types and the stop conditions."""

from __future__ import annotations

import io
import math
import sys
from pathlib import Path

import pytest
from _manipulator_rig import make_station
from hypothesis import given, settings
from hypothesis import strategies as st

from pyrt.commands import RobotShell
from pyrt.commands._motion import parse_motion, parse_value
from pyrt.errors import CommandError
from pyrt.robots.paths import HarePath, path_target
from pyrt.robots.polyaxis import PolyAxis
from pyrt.robots.stops import StopReason
from pyrt.scheduler import Loop, SimClock
from pyrt.scheduler import motion as motion_mod
from pyrt.scheduler.motion import MotionRecord, MotionType, register_motion_type
from pyrt.station.gripper import build_gripper

#: A plug-in motion published by a test distribution: the documented example (it
#: reads a different sensor, a rope's loadcell tension, and moves the hare
#: sideways until that tension has fallen to ``until`` newtons).
GUIDE = Path(__file__).resolve().parent.parent / "docs" / "motion-types.md"


def readme_example() -> str:
    """The python block of docs/motion-types.md ('Writing a motion type')."""
    text = GUIDE.read_text(encoding="utf-8")
    section = text.split("# Writing a motion type", 1)[1]
    return section.split("```python\n", 1)[1].split("```", 1)[0]


@pytest.fixture
def sway(tmp_path, monkeypatch):
    """The 'sway' motion type, found only through its distribution's entry point."""
    pkg = tmp_path / "plugins" / "labsway"
    pkg.mkdir(parents=True)
    (pkg / "__init__.py").write_text(readme_example())
    dist = tmp_path / "plugins" / "labsway-1.0.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: labsway\nVersion: 1.0\n")
    (dist / "entry_points.txt").write_text("[pyrt.motion_types]\nsway = labsway:Sway\n")
    monkeypatch.syspath_prepend(str(tmp_path / "plugins"))
    monkeypatch.setattr(motion_mod, "_loaded_entry_points", False)
    monkeypatch.delitem(motion_mod._registry, "sway", raising=False)
    yield
    motion_mod._registry.pop("sway", None)
    sys.modules.pop("labsway", None)


@pytest.fixture
def shell(tmp_path):
    station, runner = make_station(tmp_path)
    out = io.StringIO()
    sh = RobotShell(station, out)

    def run(*lines: str) -> str:
        start = out.tell()
        for line in lines:
            assert not sh.onecmd(line)
        runner.sleep(0.0)
        return out.getvalue()[start:]

    yield run, station, runner
    station.close()


def test_to_runs_as_a_hare_path_record(shell):
    """'to x y z' submits a hare_path record; the PolyAxis's executor runs it to ENDPOINT_STOP."""
    run, station, _runner = shell
    text = run("prototype to 20 0 110", "wait")
    pa = station.polyaxis
    assert pa.executor.record == MotionRecord("hare_path", {"x": 20.0, "y": 0.0, "z": 110.0,
                                                           "blend": 0})
    assert pa.executor.last.stop_reason.startswith("ENDPOINT_STOP: within")
    assert "ENDPOINT_STOP" in text and not station.motors_running()


def test_motion_word_runs_hare_path_like_to(shell):
    """'motion hare_path x=.. y=.. z=..' is the same move as 'to'; a bad target is refused at once."""
    run, station, runner = shell
    text = run("motion hare_path x=-20 y=0 z=110", "wait")
    assert "motion hare_path queued (1 waiting)" in text and "ENDPOINT_STOP" in text
    assert math.dist(station.polyaxis.position, (-20.0, 0.0, 110.0)) <= 1.0
    moves = station.polyaxis.moves
    text = run("motion hare_path x=1000 y=0 z=110", "motion hare_path x=0 z=110",
               "motion hare_path x=0 y=0 z=110 speed=3", "motion hare_path x=0 y=0 z=nan",
               "motion warp x=1", "motion hare_path 1 2 3")
    errors = [ln for ln in text.splitlines() if ln.startswith("error:")]
    assert len(errors) == 6
    assert "outside the vessel" in errors[0] and "'y' missing" in errors[1]
    assert "unknown parameter(s) speed" in errors[2] and "finite" in errors[3]
    assert "warp: not a motion type of prototype (it has hare_path)" in errors[4]
    assert "key=value" in errors[5]
    runner.sleep(0.5)
    assert station.polyaxis.moves == moves and not station.motors_running()
    assert len(station.motion) == 0


def test_plugin_motion_is_listed_and_ends_with_its_reason(shell, sway):
    """An entry-point motion type is listed by 'motion' and runs from the console to its own stop."""
    run, station, _runner = shell
    listing = run("motion")
    assert "hare_path" in listing and "sway " in listing
    assert "until one rope's tension falls" in listing
    text = run("motion sway rope=1 until=8.5", "wait")
    pa = station.polyaxis
    assert pa.last_stop.reason is StopReason.DONE
    assert pa.last_stop.detail.startswith("axis1 eased to")
    assert "DONE: axis1 eased to" in text
    assert pa.tensions[1] <= 8.5 and not station.motors_running()
    assert station.fault is None and type(pa.executor.last).__module__ == "labsway"


def test_plugin_motion_cannot_bypass_the_tension_stops(shell, sway):
    """A plug-in motion driving a rope below LOW_TENSION is stopped by the PolyAxis: a fault, motors off."""
    run, station, _runner = shell
    pa = station.polyaxis
    log = []
    pa.on_stop.append(lambda rec: log.append(list(pa.tensions)))
    text = run("motion sway rope=1 until=0.5", "prototype to 0 0 100", "wait")
    assert pa.last_stop.reason is StopReason.LOW_TENSION_STOP
    assert "FAULT: LOW_TENSION_STOP: axis1 tension" in text
    assert min(log[0]) < pa.low_tension
    assert not station.motors_running() and len(station.motion) == 0
    assert pa.executor.last.stop_reason.startswith("LOW_TENSION_STOP")
    text = run("motion sway rope=1 until=5")
    assert "refused: prototype is stopped by a fault" in text
    run("ack")
    assert station.fault is None and not pa.active


class _Raises(MotionType):
    """Fails on its third step."""

    name = "raises_test"
    drives = (PolyAxis,)

    def start(self, robot, record, now_ns):
        self.pa = robot
        self.n = 0

    def step(self, now_ns):
        self.n += 1
        if self.n == 3:
            raise ZeroDivisionError("sensor gone")
        self.pa.hare_position = self.pa.position


class _Escapes(MotionType):
    """Puts the hare outside the vessel."""

    name = "escapes_test"
    drives = (PolyAxis,)

    def start(self, robot, record, now_ns):
        self.pa = robot

    def step(self, now_ns):
        self.pa.hare_position = (0.0, 0.0, -5000.0)


@pytest.mark.parametrize(("cls", "cause"), [(_Raises, "ZeroDivisionError: sensor gone"),
                                             (_Escapes, "outside the vessel")])
def test_a_failing_motion_is_a_fault_with_the_reflex(shell, cls, cause):
    """An exception in a motion's step, or a hare outside the vessel, trips the manipulator:
    every motor stopped, the queue dropped, motion refused until ack."""
    register_motion_type(cls.name, cls, replace=True)
    run, station, _runner = shell
    pa = station.polyaxis
    text = run(f"motion {cls.name}", "prototype to 20 0 110", "wait")
    assert f"FAULT: motion {cls.name}" in text and cause in text
    assert pa.last_stop.reason is StopReason.FAULT
    assert not station.motors_running() and len(station.motion) == 0 and not pa.active
    assert all(a.mode == "standalone" for a in station.axes)
    assert "refused" in run("prototype to 20 0 110")
    run("ack")
    assert "ENDPOINT_STOP" in run("prototype to 20 0 110", "wait")


def test_queued_record_refused_at_start_is_dropped(shell):
    """A queued record its type refuses when it comes to start is reported and moves nothing."""
    run, station, runner = shell
    pa = station.polyaxis
    text = run("prototype to 10 0 100", "motion hare_path x=0 y=0 z=100 blend=1", "wait")
    runner.messages()
    runner.call(station.motion.put, MotionRecord("hare_path", {"x": 0, "y": 0, "z": 9000}))
    runner.sleep(0.2)
    assert "ENDPOINT_STOP" in text and not pa.active
    assert any("queued move dropped: " in m and "outside the vessel" in m
               for m in runner.messages())
    assert pa.executor.last.stop_reason.startswith("refused: ")
    assert not station.motors_running()


def test_hare_path_parameters():
    """path_target reads x, y, z and blend; anything else is refused."""
    assert path_target({"x": 1, "y": 2.5, "z": -3}) == ((1.0, 2.5, -3.0), False)
    assert path_target({"x": 1, "y": 2, "z": 3, "blend": 1}) == ((1.0, 2.0, 3.0), True)
    for bad in [{"x": 1, "y": 2}, {"x": "a", "y": 2, "z": 3}, {"x": True, "y": 2, "z": 3},
                {"x": 1, "y": 2, "z": 3, "blend": 2}, {"x": 1, "y": 2, "z": 3, "w": 0},
                {"x": math.inf, "y": 2, "z": 3}]:
        with pytest.raises(CommandError):
            path_target(bad)
    assert HarePath.name == "hare_path"


@settings(max_examples=200, deadline=None)
@given(st.text(alphabet=st.characters(blacklist_categories=("Cs",)), max_size=40))
def test_motion_line_parser_never_crashes(text):
    """Any line is a record, None, or a CommandError; never another exception."""
    try:
        rec = parse_motion("hare_path " + text)
    except CommandError:
        return
    assert rec is not None and rec.type == "hare_path"
    assert all(k.isidentifier() for k in rec.params)


@settings(max_examples=200, deadline=None)
@given(st.one_of(st.integers(), st.floats(allow_nan=False, allow_infinity=False), st.text()))
def test_values_parse_as_numbers_where_they_parse(value):
    """Numbers come back as numbers (ints as ints); other words stay words."""
    got = parse_value(str(value))
    if isinstance(value, int):
        assert got == value and isinstance(got, int)
    elif isinstance(value, float):
        assert got == value
    elif isinstance(got, int):  # exact, even beyond 2**53 where float() would round
        assert got == int(value)
    elif not isinstance(got, str):
        assert math.isfinite(got) and float(value) == got


def test_gripper_console_motion_word():
    """The gripper console lists the motion types and queues a gripper_move by name."""
    gs = build_gripper(Loop(SimClock()))
    out = io.StringIO()
    sh = RobotShell(gs, out)
    gs.runner.start()
    try:
        sh.onecmd("I")
        gs.runner.messages()
        out.seek(0)
        out.truncate()
        for line in ("motion", "motion gripper_move target=-4096", "wait", "T",
                     "motion gripper_move", "motion nosuch"):
            sh.onecmd(line)
        lines = out.getvalue().splitlines()
        assert any(ln.strip().startswith("gripper_move") for ln in lines)
        assert "motion gripper_move queued (1 waiting)" in lines
        assert "F000" in lines
        assert gs.executor.last.stop_reason is not None
        errors = [ln for ln in lines if ln.startswith("error:")]
        # a gripper_move without its target is refused when it is queued, not later
        assert len(errors) == 2 and "target=COUNTS missing" in errors[0]
        assert "nosuch: not a motion type of gripper (it has gripper_move)" in errors[1]
        gs.runner.sleep(0.05)
        assert not any(m.startswith("move refused: ") for m in gs.runner.messages())
    finally:
        gs.shutdown()


class _BadEndpoint(MotionType):
    """Declares an endpoint that is not a point."""

    name = "badend_test"
    drives = (PolyAxis,)
    endpoint = (0.0, math.nan, 100.0)

    def step(self, now_ns):
        pass


def test_motion_with_a_bad_endpoint_is_dropped_unmoved(shell):
    """A motion whose endpoint is not a finite point is refused when it starts: no fault, no motor."""
    register_motion_type(_BadEndpoint.name, _BadEndpoint, replace=True)
    run, station, runner = shell
    runner.messages()
    text = run("motion badend_test", "wait")
    runner.sleep(0.2)
    pa = station.polyaxis
    assert any("queued move dropped" in m and "not a finite point" in m
               for m in text.splitlines() + runner.messages())
    assert station.fault is None and not pa.active and pa.moves == 0
    assert not station.motors_running()
    with pytest.raises(CommandError, match="not a finite point"):
        runner.call(pa.begin, MotionRecord("badend_test"))


_VALUES = st.one_of(st.sampled_from(["0", "1", "-0", "nan", "inf", "1e999", "x", "", "100",
                                     "9000", "2.5"]),
                    st.integers(-400, 400).map(str))
_PARAMS = st.lists(st.tuples(st.sampled_from(["x", "y", "z", "blend", "speed", "1x", "X"]),
                             _VALUES).map("=".join), max_size=5)


@settings(max_examples=25, deadline=None)
@given(kind=st.sampled_from(["hare_path", "HARE_PATH", "warp", "9", "gripper_move"]),
       params=_PARAMS)
def test_motion_word_refusals_move_nothing(tmp_path_factory, kind, params):
    """Any 'motion' line: no exception escapes, and after a refusal no motor moves."""
    station, runner = make_station(tmp_path_factory.mktemp("motion"))
    try:
        out = io.StringIO()
        sh = RobotShell(station, out)
        side = station.boards.simulated["tio10"]  # the world's TIO10: its outputs as they stand
        before = [side.values(r.name) for r in side.kind.outputs()]
        assert not sh.onecmd(" ".join(["motion", kind, *params]))
        runner.sleep(0.05)
        text = out.getvalue()
        assert "internal error" not in text
        if "error:" in text:
            assert [side.values(r.name) for r in side.kind.outputs()] == before
            assert not station.motors_running() and not station.polyaxis.active
            assert len(station.motion) == 0
    finally:
        station.close()


def test_the_grippers_motion_type_is_neither_offered_nor_run_by_the_manipulator(shell):
    """motion gripper_move in the manipulator is refused when queued (not an AttributeError later)."""
    run, station, _runner = shell
    assert "gripper_move" not in run("motion")
    said = run("motion gripper_move target=-100")
    assert said.startswith("error: motion gripper_move: not a motion type of prototype")
    assert "internal error" not in said and not station.busy()
