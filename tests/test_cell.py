"""pyrt cell: the PUMA 560 with 002's gripper, two robots in one runtime; pick ends with the
object lifted in the simulation's truth; a jam during the close stops the sequence with the
arm holding still; the conformance suite (pyrt.testing) on the cell."""

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


@pytest.fixture
def cell():
    station = build_cell(Loop(SimClock()))
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
    out = []
    if station.jaws.board.dac != DAC_NULL:
        out.append(f"jaw DAC {station.jaws.board.dac:02X}")
    if station.controller.moving:
        out.append(f"jaw drive/jog bits in FLAGS {station.controller.cpu.ram[FLAGS]:02X}")
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
