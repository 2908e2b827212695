"""pyrt cell: the PUMA 560 with 002's gripper, two robots in one runtime; pick ends with the
object lifted in the simulation's truth; a jam during the close stops the sequence with the
arm holding still; the arm's servo and trajectory groups and the gripper's SYSCLK group keep
their rates whatever the tick; the conformance suite (pyrt.testing) on the cell and on each
robot in it."""

from __future__ import annotations

import argparse
import io
import os
import subprocess
import sys
from pathlib import Path
from typing import ClassVar

import numpy as np
import pytest

from pyrt.boards.gripper import DAC_NULL
from pyrt.boards.i8031 import FLAGS
from pyrt.commands import RobotShell
from pyrt.scheduler import Loop, SimClock
from pyrt.station.cell import CELL, build_cell
from pyrt.testing import StationConformance

ROOT = Path(__file__).resolve().parents[1]
#: The object of these tests (mm) and how far it must end lifted (mm, of the 150 mm lift).
OBJECT = (600.0, -150.0, 400.0)
LIFTED_MM = 140.0
#: A joint of the simulated arm moving faster than this (deg/s) is driven.
MOVING_DEG_S = 0.5
MS = 1_000_000


@pytest.fixture
def cell():
    yield from _started_cell(MS)


@pytest.fixture
def cell_500():
    """The cell at --tick-us 500."""
    yield from _started_cell(MS // 2)


def _started_cell(tick_ns: int):
    station = build_cell(Loop(SimClock(), period_ns=tick_ns))
    runner = station.start()
    out = io.StringIO()
    shell = RobotShell(station, out)
    shell.onecmd("gripper I")
    assert runner.wait_until(lambda: not station.busy() and station.arm.powered, 30.0)
    yield station, runner, shell, out
    station.close()


def _object(station) -> np.ndarray:
    return np.array([station.resolve_signal(f"sim.object.{a}").read() for a in "xyz"])


def test_pick_lifts_the_object_in_the_simulations_truth(cell):
    """pick X Y Z: approach, open, descend, close, lift; the object ends lifted by 150 mm with the tool, held by the jaws (the world's truth), and the cell says it picked."""
    station, _runner, shell, out = cell
    shell.onecmd("sim object {} {} {}".format(*OBJECT))
    shell.onecmd("pick {} {} {}".format(*OBJECT))
    shell.onecmd("wait")
    text = out.getvalue()
    assert "picked: the object lifted" in text, text
    obj = _object(station)
    assert obj[2] - OBJECT[2] > LIFTED_MM
    assert np.hypot(obj[0] - OBJECT[0], obj[1] - OBJECT[1]) < 5.0
    assert station.resolve_signal("sim.object.held").read()
    tool = station.plant.truth().tool[:3, 3] * 1e3
    assert np.linalg.norm(tool - obj) < 15.0
    assert station.fault is None


def test_pick_at_tick_us_500_lifts_the_object(cell_500):
    """--tick-us 500: the servo still at 1 kHz, the gripper's clock interrupt still every 1 ms; pick ends with the object lifted by the jaws (the world's truth)."""
    station, _runner, shell, out = cell_500
    assert station.loop.period_ns == MS // 2
    shell.onecmd("sim object {} {} {}".format(*OBJECT))
    shell.onecmd("pick {} {} {}".format(*OBJECT))
    shell.onecmd("wait")
    assert "picked: the object lifted" in out.getvalue(), out.getvalue()
    assert _object(station)[2] - OBJECT[2] > LIFTED_MM
    assert station.resolve_signal("sim.object.held").read() and station.fault is None


def _cell_second(tick_ns: int) -> tuple[dict[str, tuple[int, int]], dict[str, int]]:
    """One second of loop time of the cell on the SimClock: each group's (period, releases)
    and the calls of each task in a group."""
    loop = Loop(SimClock(), period_ns=tick_ns)
    station = build_cell(loop)
    try:
        loop.run(duration_ns=1_000 * MS)
        st = loop.statistics()
        assert station.fault is None and station.arm.powered
        return ({k: (g.period_ns, g.releases) for k, g in st.groups.items()},
                {k: t.calls for k, t in st.tasks.items() if t.group})
    finally:
        station.close()


def test_the_cells_rate_groups_keep_their_rates_whatever_the_tick():
    """At --tick-us 500 as at 1000: servo 1000 and trajectory 100 releases a second, the gripper's SYSCLK group 1000 (its routines, which SYSCLKPD and their schedules divide, run as often)."""
    groups, calls = _cell_second(MS)
    assert groups == {"servo": (MS, 1_000), "SYSCLK": (MS, 1_000), "trajectory": (10 * MS, 100)}
    assert calls["servo"] == 1_000 and calls["trajectory"] == 100
    assert calls["MVJAWS"] > 0 and calls["SENSORS"] > 0
    assert _cell_second(MS // 2) == (groups, calls)


def test_a_pick_with_nothing_there_closes_on_nothing_and_says_so(cell):
    """With the object elsewhere, the close ends at closed: the sequence stops there (no lift), the object is where it was."""
    station, _runner, shell, out = cell
    shell.onecmd("sim object 500 100 300")
    shell.onecmd("pick {} {} {}".format(*OBJECT))
    shell.onecmd("wait")
    assert "pick stopped at close: the jaws closed on nothing" in out.getvalue()
    assert np.allclose(_object(station), (500.0, 100.0, 300.0))


def test_a_jam_during_the_close_stops_the_sequence_with_the_arm_holding_still(cell):
    """sim fault jam while the jaws close: the close ends short of the object, the sequence stops at close (no lift), the jaws' drive is null, the arm keeps its amplifiers on and does not move in truth, the object stays on the table."""
    station, runner, shell, out = cell
    shell.onecmd("sim object {} {} {}".format(*OBJECT))
    shell.onecmd("pick {} {} {}".format(*OBJECT))
    assert runner.wait_until(lambda: station.pick.step_index == 4 and station.jaws.x < -1500,
                             60.0)
    shell.onecmd("sim fault jam")
    shell.onecmd("wait")
    text = out.getvalue()
    assert not station.pick.running and "pick stopped at close" in text, text
    assert "picked" not in text and station.puma.fault is None
    assert runner.wait_until(lambda: station.jaws.board.dac == DAC_NULL, 5.0)
    before = station.plant.truth().q.copy()
    runner.sleep(1.0)
    after = station.plant.truth()
    assert station.arm.powered
    assert np.max(np.abs(np.degrees(after.q - before))) < 0.01
    assert np.max(np.abs(np.degrees(after.qd))) < MOVING_DEG_S
    assert not station.resolve_signal("sim.object.held").read()
    assert abs(_object(station)[2] - OBJECT[2]) < 1e-6


def test_a_gripper_fault_during_the_close_stops_the_sequence_and_the_arm_holds(cell):
    """A gripper fault while the jaws close: the drive null in that tick, the sequence stopped at close, the arm not faulted and holding; ack gripper clears the gripper alone."""
    station, runner, shell, _out = cell
    shell.onecmd("sim object {} {} {}".format(*OBJECT))
    shell.onecmd("pick {} {} {}".format(*OBJECT))
    assert runner.wait_until(lambda: station.pick.step_index == 4 and station.jaws.x < -1500,
                             60.0)
    dac, running = runner.call(lambda: (station.controller.fail("jaw test fault"),
                                        station.jaws.board.dac, station.pick.running)[1:],
                               take_fault=False)
    assert dac == DAC_NULL and not running
    assert station.gripper.fault is not None and station.puma.fault is None
    assert station.arm.powered
    assert station.pick.last == "pick stopped at close: gripper fault: jaw test fault"
    shell.onecmd("ack gripper")
    assert station.fault is None


def test_an_arm_fault_during_a_pick_stops_the_arm_the_jaws_and_the_sequence(cell):
    """An arm fault mid-pick: every amplifier off in that tick, the jaws' drive null, the sequence ended; the gripper itself is not faulted."""
    station, runner, shell, _out = cell
    shell.onecmd("sim object {} {} {}".format(*OBJECT))
    shell.onecmd("pick {} {} {}".format(*OBJECT))
    assert runner.wait_until(lambda: station.pick.step_index == 2, 60.0)

    def act():
        station.arm.fail("arm test fault")
        b = station.board
        return ([b.read("enable", j) for j in range(6)], station.jaws.board.dac,
                station.pick.running)

    enables, dac, running = runner.call(act, take_fault=False)
    assert enables == [0] * 6 and dac == DAC_NULL and not running
    assert station.gripper.fault is None and station.puma.fault is not None


def test_a_pick_out_of_reach_is_refused_and_nothing_moves(cell):
    """pick at a place the arm cannot reach: refused before anything moves."""
    station, _runner, shell, out = cell
    shell.onecmd("pick 1500 0 0")
    shell.onecmd("pick 1900 1900 0")
    assert "pick: refused" in out.getvalue()
    assert not station.busy() and not station.pick.running


def test_pyrt_cell_runs_a_piped_pick_at_speed_max():
    """pyrt cell --speed max with a piped script: the pick ends picked; status has a line per robot."""
    script = "\n".join(["sim object 600 -150 400", "pick 600 -150 400", "wait", "status",
                        "status object", "quit"]) + "\n"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    r = subprocess.run([sys.executable, "-m", "pyrt", "cell", "--speed", "max"], input=script,
                       cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    assert "picked: the object lifted from (600, -150, 400) mm" in r.stdout
    assert "puma: q1=" in r.stdout and "gripper: jaws" in r.stdout
    z = next(float(line.split("=")[1].split()[0]) for line in r.stdout.splitlines()
             if line.startswith("object.z"))
    assert z > OBJECT[2] + LIFTED_MM


# -- the conformance suite ----------------------------------------------------------------


def _cell_driven(station) -> list[str]:
    return _jaws_driven(station) + _arm_driven(station)


def _jaws_driven(station) -> list[str]:
    out = []
    if station.jaws.board.dac != DAC_NULL:
        out.append(f"jaw DAC {station.jaws.board.dac:02X}")
    if station.controller.moving:
        out.append(f"jaw drive/jog bits in FLAGS {station.controller.cpu.ram[FLAGS]:02X}")
    return out


def _arm_driven(station) -> list[str]:
    out = []
    if station.arm.state != "idle":
        out.append(f"the arm {station.arm.state}")
    if station.puma.fault is not None or not station.arm.powered:
        # amplifiers off: an output that is not 0 drives (the arm may sink: the world)
        board = station.board
        return out + [f"{r.name}[{j}] = {board.read(r.name, j)}" for r in board.kind.outputs()
                      for j in range(r.count) if board.read(r.name, j) != 0]
    qd = np.degrees(station.plant.truth().qd)
    return out + [f"q{j + 1} at {v:.3f} deg/s" for j, v in enumerate(qd)
                  if abs(v) > MOVING_DEG_S]


class TestCellConformance(StationConformance):
    """The cell as 'pyrt cell' builds it: both robots in one station."""

    samples: ClassVar[dict[str, list[list[str]]]] = {
        "GripperController.X": [["33"]],
        "GripperMonitor.C": [["4A", "00"]],
        "GripperMonitor.D": [["4A"]],
        "GripperMonitor.L": [["FFFF"]],
        "UrdfSim.table": [["-2000"], ["off"]],
        "UrdfArm.tool": [["0", "0", "50", "0", "0", "0"], ["0"] * 6],
        "UrdfArm.coord": [["0", "0", "50", "0", "0", "0"], ["0"] * 6],
        "UrdfArm.conveyor": [["0", "50", "0"], ["0"] * 3],
        "CellSim.fault": [["none"]],
        "CellSim.object": [["500", "100", "300"]],
    }

    def build(self, tmp_path):
        return CELL.build(Loop(SimClock()), argparse.Namespace(boards=None))

    def driven(self, station):
        return _cell_driven(station)

    def settings(self, station):
        board, arm = station.board, station.arm
        regs = tuple(board.read(r.name, j) for r in board.kind.outputs() for j in range(r.count))
        return (regs, arm.state, arm.powered, arm.servo.knots.tobytes(), arm.last_stop,
                bytes(station.controller.cpu.ram), station.jaws.board.dac,
                len(station.jaw_moves), station.pick.running, station.plant.table_z)

    def ready(self, station, runner):
        assert runner.wait_until(lambda: station.arm.powered and not station.busy(), 5.0)
        runner.sleep(0.2)

    def rest(self, station, runner):
        runner.call(station.stop, take_fault=False)

    def after_record(self, station, runner):
        if not station.controller.clock_enabled:
            runner.call(station.controller.toggle_clock, take_fault=False)  # monitor I

    def start_move(self, station, runner):
        runner.call(station.arm.move_joints, 40, 60, -150, 30, -40, 50)
        runner.call(station.controller.cmd_position, "20mm")
        assert runner.wait_until(lambda: bool(self.driven(station)), 5.0)


class TestCellPumaConformance(TestCellConformance):
    """The cell's robot puma on its own: its records, its busy, its trip (the gripper keeps no fault)."""

    robot_name = "puma"

    def driven(self, station):
        return _arm_driven(station)

    def start_move(self, station, runner):
        runner.call(station.arm.move_joints, 40, 60, -150, 30, -40, 50)
        assert runner.wait_until(lambda: bool(self.driven(station)), 5.0)


class TestCellGripperConformance(TestCellConformance):
    """The cell's robot gripper on its own: its records, its busy, its trip (the arm keeps holding, no fault)."""

    robot_name = "gripper"

    def driven(self, station):
        return _jaws_driven(station)

    def rest(self, station, runner):
        runner.call(station.robot("gripper").stop, take_fault=False)

    def start_move(self, station, runner):
        runner.call(station.controller.cmd_position, "20mm")
        assert runner.wait_until(lambda: bool(self.driven(station)), 5.0)


def test_pyrt_cell_refuses_a_journal_and_boards_elsewhere():
    """--journal (it records one set of boards) and --boards tcp://... are refused in a sentence, exit 2 or 1, nothing run."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    for extra, words in ((["--journal", "x.pj"], "--journal: a journal records one set"),
                         (["--boards", "tcp://127.0.0.1:1"], "runs on in-process boards")):
        r = subprocess.run([sys.executable, "-m", "pyrt", "cell", "--speed", "max", *extra],
                           input="quit\n", cwd=ROOT, env=env, capture_output=True, text=True,
                           timeout=120)
        assert r.returncode != 0 and words in r.stderr + r.stdout, r.stderr
        assert "Traceback" not in r.stderr


def test_the_served_cell_has_each_robots_state_and_flags(cell):
    """The served station: EPICS's puma:state and gripper:state (idle, moving, fault) and STATUS's per-robot fault flags follow each robot on its own."""
    from pyrt.server.station import ServedStation

    station, runner, _shell, _out = cell
    served = ServedStation(station)
    fields = {f.name: f for f in served.extra_fields}
    assert {"puma:state", "gripper:state"} <= set(fields)
    status = dict(zip(served.status_names, served.fields, strict=True))
    assert {"puma_fault", "gripper_fault", "puma_busy", "gripper_busy"} <= set(status)

    def read():
        return (fields["puma:state"].source.read(), fields["gripper:state"].source.read(),
                status["gripper_fault"][1].read(), status["puma_fault"][1].read())

    assert runner.call(read) == (0, 0, False, False)
    runner.call(station.controller.fail, "jaws", take_fault=False)
    assert runner.call(read, take_fault=False) == (0, 2, True, False)


def test_each_robot_of_the_served_cell_has_its_own_epics_prefix(cell):
    """EPICS: every PV of a robot's components is under its robot's prefix (PUMA:JOINT1:POSITION, GRIPPER:MONITOR:ADDRESS, the roots' PUMA:Q1 and GRIPPER:ENCODER), with PUMA:FAULT_MSG and GRIPPER:FAULT_MSG each its own robot's fault; the world's PVs stay unprefixed."""
    from pyrt.server import Server
    from pyrt.server.epics import EpicsService, caproto_available
    from pyrt.server.station import ServedStation

    station, runner, _shell, _out = cell
    served = ServedStation(station)
    fields = {f.name.upper(): f for f in served.extra_fields}
    for name in ("PUMA:STATE", "PUMA:FAULT_MSG", "PUMA:Q1", "PUMA:JOINT1:POSITION",
                 "PUMA:JOINT6:DAC", "GRIPPER:STATE", "GRIPPER:FAULT_MSG", "GRIPPER:ENCODER",
                 "GRIPPER:MONITOR:ADDRESS", "OBJECT:Z", "SIM:JAWS"):
        assert name in fields, name
    assert not any(n.startswith(("JOINT1:", "MONITOR:")) for n in fields)
    for comp in station.components():  # every signal of a robot's component, under its prefix
        robot = station.robot_of(comp)
        if robot is None or comp.name == robot.name:
            continue
        for sig in comp.signals():
            assert f"{robot.name}:{comp.name}:{sig.name}".upper() in fields
            assert f"{comp.name}:{sig.name}".upper() not in fields

    def read():
        return fields["PUMA:FAULT_MSG"].source.read(), fields["GRIPPER:FAULT_MSG"].source.read()

    assert runner.call(read) == ("", "")
    runner.call(station.controller.fail, "jaws jammed", take_fault=False)
    puma, gripper = runner.call(read, take_fault=False)
    assert puma == "" and "jaws jammed" in gripper
    if caproto_available():  # the PVs the IOC serves are these names under its prefix
        epics = EpicsService(runner, served, Server(runner, served, "127.0.0.1", 0), "CELL:")
        assert {"CELL:PUMA:JOINT1:POSITION", "CELL:GRIPPER:FAULT_MSG"} <= set(epics.pvdb)


def test_pick_solves_its_poses_outside_the_loop(cell, monkeypatch):
    """pick X Y Z from the console: its three poses are solved with the loop not ticking (counted, not timed); an unreachable pick is refused before anything moves."""
    from pyrt.station._urdf_moves import ArmMoves

    station, runner, shell, out = cell
    ticking: list[bool] = []
    solve = ArmMoves.solve

    def watched(self, *a, **k):
        ticking.append(runner.loop.running)
        return solve(self, *a, **k)

    monkeypatch.setattr(ArmMoves, "solve", watched)
    shell.onecmd("pick 1500 0 0")
    assert "pick: refused" in out.getvalue() and not runner.call(station.busy)
    shell.onecmd("sim object {} {} {}".format(*OBJECT))
    shell.onecmd("pick {} {} {}".format(*OBJECT))
    assert len(ticking) >= 4 and not any(ticking)
    shell.onecmd("wait")
    assert "picked: the object lifted" in out.getvalue()
