"""Several robots in one station, each its own fault domain: a fault stops its own robot's
actuators in the same tick and leaves the others running (unless coupled); ack NAME, stop,
stop NAME, wait NAME; one board given to two robots is refused at build time."""

from __future__ import annotations

import io

import numpy as np
import pytest

from pyrt import Component, Station
from pyrt.boards import open_boards
from pyrt.boards.gripper import DAC_NULL
from pyrt.commands import RobotShell
from pyrt.errors import CommandError, ConfigError
from pyrt.scheduler import Loop, SimClock
from pyrt.sim.world import GRIPPER_BOARDS
from pyrt.station.cell import build_cell

#: The arm's move of these tests (deg) and how close the truth must end (deg per joint).
ARM_TARGET = (20.0, 60.0, -160.0, 10.0, -30.0, 15.0)
TRUTH_DEG = 0.05


@pytest.fixture
def cell():
    station = build_cell(Loop(SimClock()))
    runner = station.start()
    out = io.StringIO()
    shell = RobotShell(station, out)
    shell.onecmd("gripper I")
    assert runner.wait_until(lambda: not station.busy() and station.arm.powered, 30.0)
    _clear(out)
    yield station, runner, shell, out
    station.close()


def _clear(out: io.StringIO) -> None:
    out.seek(0)
    out.truncate(0)


def _arm_outputs(station) -> list[int]:
    b, n = station.board, station.chain.n
    return [b.read("dac", j) for j in range(n)] + [b.read("enable", j) for j in range(n)]


def _truth_deg(station) -> np.ndarray:
    return np.degrees(station.plant.truth().q)


def test_a_gripper_fault_stops_the_jaws_in_its_tick_and_the_arm_ends_its_move(cell):
    """A fault of the gripper while both robots move: its drive is null in that tick, the arm's amplifiers stay on, and the arm ends its move at the target in the simulation's truth."""
    station, runner, _shell, _out = cell
    runner.call(station.arm.move_joints, *ARM_TARGET)
    runner.call(station.controller.cmd_position, "20mm")
    assert runner.wait_until(lambda: station.jaws.current != 0, 5.0)

    def act():
        station.controller.fail("a test fault of the jaws")  # the gripper's own fault path
        return station.jaws.board.dac, _arm_outputs(station), station.arm.state

    dac, arm_out, arm_state = runner.call(act, take_fault=False)
    assert dac == DAC_NULL
    assert all(arm_out[6:]), "the arm's amplifiers were switched off by the gripper's fault"
    assert arm_state == "moving"
    assert station.gripper.fault is not None and station.puma.fault is None
    assert [f.robot for f in runner.take_faults()] == ["gripper"]
    assert runner.wait_until(lambda: not station.puma.busy(), 60.0)
    assert station.arm.last_stop == "at target"
    assert np.max(np.abs(_truth_deg(station) - ARM_TARGET)) < TRUTH_DEG
    assert station.jaws.board.dac == DAC_NULL


def test_an_arm_fault_switches_every_amplifier_off_in_its_tick_and_leaves_the_gripper_unfaulted(
        cell):
    """A fault of the arm: every DAC and enable of its board 0 in that tick; the gripper is not faulted (its motion stopped) and takes commands."""
    station, runner, shell, _out = cell
    runner.call(station.arm.move_joints, *ARM_TARGET)
    assert runner.wait_until(lambda: station.arm.state == "moving", 5.0)
    outs = runner.call(lambda: (station.arm.fail("a test fault of the arm"),
                                _arm_outputs(station))[1], take_fault=False)
    assert outs == [0] * 12
    assert station.puma.fault is not None and station.gripper.fault is None
    runner.take_faults()
    shell.onecmd("gripper P 40mm")
    assert runner.wait_until(lambda: not station.gripper.busy(), 30.0)
    assert abs(station.jaw_error()) <= 16


def test_ack_names_the_robot(cell):
    """ack gripper clears the gripper's fault alone; the arm's stays until ack puma; ack alone with none says so."""
    station, runner, shell, out = cell
    runner.call(lambda: (station.controller.fail("jaws"), station.arm.fail("arm")),
                take_fault=False)
    assert station.gripper.fault is not None and station.puma.fault is not None
    shell.onecmd("ack gripper")
    assert station.gripper.fault is None and station.puma.fault is not None
    assert "gripper: fault acknowledged (jaws)" in out.getvalue()
    shell.onecmd("puma movej 0 45 -180 0 -45 0")
    assert "refused: puma is stopped by a fault" in out.getvalue()
    shell.onecmd("ack puma")
    assert station.fault is None
    _clear(out)
    shell.onecmd("ack")
    assert "no fault to acknowledge" in out.getvalue()
    shell.onecmd("ack nobody")
    assert "no robot named 'nobody'" in out.getvalue()


def test_ack_alone_acknowledges_every_faulted_robot(cell):
    """ack with no name acknowledges both faulted robots, a line each."""
    station, runner, shell, out = cell
    runner.call(lambda: (station.controller.fail("jaws"), station.arm.fail("arm")),
                take_fault=False)
    shell.onecmd("ack")
    text = out.getvalue()
    assert "puma: fault acknowledged (arm)" in text and "gripper: fault acknowledged (jaws)" in text
    assert station.fault is None


def test_stop_stops_both_robots_and_stop_name_one(cell):
    """stop alone: the arm brakes to rest and holds, the jaws' drive is null at once; stop gripper stops the jaws and lets the arm's move end at its target."""
    station, runner, shell, out = cell
    runner.call(station.arm.move_joints, *ARM_TARGET)
    runner.call(station.controller.cmd_position, "20mm")
    assert runner.wait_until(lambda: station.jaws.current != 0, 5.0)
    shell.onecmd("stop")
    assert station.jaws.board.dac == DAC_NULL
    assert runner.wait_until(lambda: not station.busy(), 30.0)
    assert station.arm.last_stop == "stopped (stop command)"
    assert station.arm.powered and station.fault is None
    text = out.getvalue()
    assert "puma: stopping" in text and "gripper: every motor stopped" in text

    runner.call(station.arm.move_joints, *ARM_TARGET)
    runner.call(station.controller.cmd_position, "40mm")
    assert runner.wait_until(lambda: station.jaws.current != 0, 5.0)
    shell.onecmd("stop gripper")
    assert station.jaws.board.dac == DAC_NULL
    assert runner.wait_until(lambda: not station.busy(), 60.0)
    assert station.arm.last_stop == "at target"
    assert np.max(np.abs(_truth_deg(station) - ARM_TARGET)) < TRUTH_DEG


def test_status_has_a_line_per_robot_and_wait_name_waits_for_one(cell):
    """status: a line per robot, the fault on its own; wait puma reports the arm's move alone."""
    station, runner, shell, out = cell
    runner.call(station.controller.fail, "jaws")
    runner.take_faults()
    shell.onecmd("status")
    lines = out.getvalue().splitlines()
    assert lines[0].startswith("puma: ") and "FAULT" not in lines[0]
    assert lines[1].startswith("gripper: ") and lines[1].endswith("FAULT: jaws")
    shell.onecmd("ack gripper")
    _clear(out)
    shell.onecmd("puma movej 10 50 -170 0 -40 0")
    shell.onecmd("gripper P 50mm")
    watch = runner.call(station.watch_move, "puma")  # what 'wait puma' holds
    assert runner.wait_until(lambda: watch.done, 60.0)
    assert [e.robot for e in watch.ended] == ["puma"]
    assert watch.ended[0].reason == "at target"
    shell.onecmd("wait gripper")
    assert "gripper: at target" in out.getvalue()
    assert not station.busy()


class _Part(Component):
    """A robot's one actuator: on until its reflex runs."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.on = True

    def reflex(self) -> None:
        self.on = False


def _two(coupled: bool = False) -> tuple[Station, _Part, _Part]:
    station = Station(Loop(SimClock()))
    station.name = "two"
    station.coupled = coupled
    a, b = _Part("a"), _Part("b")

    class Root(Component):
        name = "root"

        def children(self) -> list[Component]:
            return [a, b]

    station.add_robot("left", a)
    station.add_robot("right", b)
    station.adopt(Root())
    return station, a, b


def test_a_component_fault_runs_its_own_robots_reflex_only():
    """A part's fail() trips its robot alone: the other robot's actuator stays on, one fault reported, named after the robot."""
    station, a, b = _two()
    a.fail("broken")
    assert not a.on and b.on
    assert station.robot("left").fault is not None and station.robot("right").fault is None
    fault = station.loop.take_fault()
    assert fault is not None and fault.robot == "left" and station.loop.take_fault() is None


def test_coupled_robots_all_stop():
    """A station that declares its robots coupled: one part's fault stops both robots."""
    station, a, b = _two(coupled=True)
    a.fail("broken")
    assert not a.on and not b.on
    assert "coupled to left" in station.robot("right").fault.cause


def test_a_loop_level_trip_stops_every_robot():
    """What cannot be attributed (the loop's fault_all: consecutive overruns) trips every robot."""
    station, a, b = _two()
    station.loop.fault_all("overruns", "loop")
    assert not a.on and not b.on
    assert all(r.fault is not None for r in station.robots)


def test_one_board_given_to_two_robots_is_refused_at_build_time():
    """The same Boards given to two robots: ConfigError naming the board and both robots."""
    station = Station(Loop(SimClock()))
    boards = open_boards(None, "jaws", GRIPPER_BOARDS)
    try:
        station.add_robot("one", _Part("x"), boards=[boards])
        with pytest.raises(ConfigError, match="given to robot 'one' and to robot 'two'"):
            station.add_robot("two", _Part("y"), boards=[boards])
        with pytest.raises(ConfigError, match="two robots of one station"):
            station.add_robot("ONE", _Part("z"))
    finally:
        boards.close()


def test_a_station_without_robots_is_one_robot_named_after_it():
    """A station that declares none is one robot with its name: stop_robot and ack by that name."""
    station = Station(Loop(SimClock()))
    station.name = "solo"
    part = _Part("p")
    station.adopt(part)
    assert station.robot_names() == ["solo"]
    part.fail("x")
    assert station.fault is not None and station.fault.robot == "solo"
    assert station.acknowledge("solo").startswith("fault acknowledged (x)")
    with pytest.raises(CommandError):
        station.robot("other")


def _link(url: str, fail_after: int, in_process: bool = True):
    """Boards whose read phase raises BoardError (naming the URL) from the Nth poll on."""
    from pyrt.boards import Backend, Boards
    from pyrt.errors import BoardError

    class Link(Backend):
        has_link = True  # its phases can fail: the station catches them
        polls = 0

        def read_phase(self, now_ns: int) -> None:
            self.polls += 1
            if self.polls > fail_after:
                raise BoardError(url, "no reply")

    backend = Link(url, {})
    boards = Boards(url, "test", {}, {}, backend)
    if in_process:  # the world's side is these boards themselves
        backend.simulated = boards
    return boards


def test_a_lost_board_trips_the_robot_that_owns_it_alone():
    """A board set whose read phase fails trips the robot it was given to; the other robot's actuator stays on and its own boards are still read."""
    station = Station(Loop(SimClock()))
    a, b = _Part("a"), _Part("b")

    class Root(Component):
        name = "root"

        def children(self) -> list[Component]:
            return [a, b]

    lost, good = _link("sim:lost", 5), _link("sim:good", 10**9)
    station.add_robot("left", a, boards=[lost])
    station.add_robot("right", b, boards=[good])
    station.adopt(Root())
    station.loop.run(ticks=20)
    assert not a.on and b.on
    left, right = station.robot("left"), station.robot("right")
    assert left.fault is not None and "sim:lost" in left.fault.cause and right.fault is None


def test_boards_with_one_url_outside_the_process_are_one_board():
    """Two Boards objects of one tcp:// URL are one board (refused for a second robot); two sim: sets are two."""
    from pyrt.station.domain import boards_clash

    assert boards_clash(_link("tcp://h:1", 0, False), _link("tcp://h:1", 0, False))
    assert not boards_clash(_link("tcp://h:1", 0, False), _link("tcp://h:2", 0, False))
    assert not boards_clash(_link("sim:", 0), _link("sim:", 0))


def test_wait_name_takes_seconds_and_stop_refuses_an_unknown_robot(cell):
    """wait gripper 0.2 while the jaws travel says it is still moving after 0.2 s; stop nobody is refused and stops nothing."""
    station, _runner, shell, out = cell
    shell.onecmd("gripper P 10mm")
    shell.onecmd("wait gripper 0.2")
    assert "still moving after 0.2 s" in out.getvalue()
    shell.onecmd("stop nobody")
    assert "no robot named 'nobody'" in out.getvalue()
    assert station.gripper.busy()
    shell.onecmd("wait gripper")
    assert not station.gripper.busy()


# -- where, last_stop, statusline: the robots' text signals ------------------------------------


class _Probe(Component):
    """A root with one numeric signal."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.x = 1.5

    def signals(self):
        from pyrt.component import Signal

        return [Signal.attr("x", "mm", self, "x")]


def test_a_one_robot_station_serves_where_last_stop_and_statusline_as_text_signals_of_its_root():
    """adopt(where=, ended=, status=): the root's where, last_stop and statusline signals (kind text) read what the station says: where, the last move's reason ('' before any), the status line with its fault."""
    station = Station(Loop(SimClock()))
    station.name = "solo"
    root = _Probe("probe")
    station.adopt(root, where=lambda: f"x at {root.x:g} mm", status=lambda: "idle, all well",
                  ended=lambda: ("at target", ["solo: at target"]))
    names = [n for n, _s in station.signals()]
    assert names == ["probe.x", "probe.where", "probe.last_stop", "probe.statusline"]
    assert all(s.is_text and s.units == "text" for s in station.signals_of(root)[1:])
    where, last, line = (station.resolve_signal(f"probe.{n}") for n in
                         ("where", "last_stop", "statusline"))
    assert station.resolve_signal("where") is where  # a bare name: the root's
    assert (where.read(), last.read(), line.read()) == ("x at 1.5 mm", "", "idle, all well")
    root.x = 2.0
    station.end_move("stopped by the operator")
    assert where.read() == station.where() == "x at 2 mm"
    assert last.read() == station.last_stop() == "stopped by the operator"
    root.fail("a broken probe")
    assert line.read() == station.status() == "idle, all well  FAULT: a broken probe"
    with pytest.raises(CommandError, match="scope samples numbers"):
        where.scope_source()


def test_each_robot_of_several_has_its_own_text_signals_and_the_station_line_joins_them():
    """Two robots: left.where / right.where read each robot's where; a move-ended event of one sets that robot's last_stop alone; the station's where (no line given) is 'NAME WHERE; ...'."""
    station = Station(Loop(SimClock()))
    station.name = "two"
    a, b = _Part("a"), _Part("b")

    class Root(Component):
        name = "root"

        def children(self) -> list[Component]:
            return [a, b]

    station.add_robot("left", a, where=lambda: "at 1")
    station.add_robot("right", b, where=lambda: "at 2", status=lambda: "holding")
    station.adopt(Root())
    sig = dict(station.signals())
    assert "root.where" not in sig  # the station's root is no robot's
    assert sig["a.where"].read() == "at 1" and sig["b.where"].read() == "at 2"
    assert station.where() == "left at 1; right at 2"
    assert station.where("right") == "at 2"
    station.end_move("left's move ended", robot="left")
    assert sig["a.last_stop"].read() == "left's move ended" and sig["b.last_stop"].read() == ""
    assert sig["b.statusline"].read() == "holding"


def test_the_cell_robots_text_signals_read_what_each_robot_says(cell):
    """In the cell: the arm's and the jaws' where signals read each robot's where, and after wait gripper the jaws' last_stop says how their move ended."""
    station, runner, shell, _out = cell
    arm, jaws = station.puma.root, station.gripper.root
    values = runner.call(lambda: {n: s.read() for n, s in station.signals() if s.is_text})
    assert values[f"{arm.name}.where"] == runner.call(station.puma.where)
    assert values[f"{jaws.name}.where"] == runner.call(station.gripper.where)
    shell.onecmd("gripper P 50mm")
    shell.onecmd("wait gripper")
    last = station.resolve_signal(f"{jaws.name}.last_stop")
    assert runner.call(last.read) == "at target" == runner.call(station.gripper.last_stop)


def test_a_root_with_a_signal_of_a_robot_text_signals_name_is_refused():
    """A root component that has a signal called where: adopt refuses it, naming the signal."""
    from pyrt.component import Signal
    from pyrt.errors import PyrtError

    class Clash(Component):
        name = "clash"

        def signals(self):
            return [Signal("where", "mm", lambda: 0.0)]

    station = Station(Loop(SimClock()))
    with pytest.raises(PyrtError, match="signal called where"):
        station.adopt(Clash())
