"""The component contract, checked over every robot pyrt ships with the conformance suite
(:mod:`pyrt.testing`, the one a station of one's own runs): names, help, grammar,
classification, signals, the reflex, garbage arguments, and the tables derived from the
records.  The example arm runs the same suite in examples/arm/tests.

The classification rule (one per record, asserted below):

* ``reads_only``: changes nothing of the robot (its RAM, its registers, its
  settings); allowed while faulted; any client may give it;
* ``moves``: may start an actuator; refused while faulted and never
  ``anyone``; a record that is not ``reads_only`` and does not move is a
  *setting* (it changes the robot, but starts nothing);
* ``anyone`` beyond the reads only for the stop (``stop`` records), which
  must not move;
* a record not marked ``moves`` never starts an actuator from rest (checked
  by running it with sample arguments and looking at the simulation's truth).

The simulated world's ``sim`` component is the world, not the controller:
its ``jog`` moves (the hand on the front-panel switch) and stays allowed
while faulted, so that ``sim jog off`` can always release the switch.
"""

from __future__ import annotations

import io

import pytest
from _manipulator_rig import make_station

from pyrt.boards.gripper import DAC_NULL
from pyrt.boards.i8031 import COMMAND_CNT, FLAGS, STOPCNT
from pyrt.boards.tio10 import AWO_BITS
from pyrt.commands.robot import RobotShell
from pyrt.errors import PyrtInternalError
from pyrt.robots.gripper import _MASK_DRVON
from pyrt.scheduler import Loop, SimClock
from pyrt.station.gripper import build_gripper
from pyrt.testing import StationConformance

# -- the gripper ---------------------------------------------------------------------------


def _gripper_driven(station) -> list[str]:
    out = []
    if station.board.dac != DAC_NULL:
        out.append(f"DAC {station.board.dac:02X}")
    if station.controller.moving:
        out.append(f"drive/jog bits in FLAGS {station.cpu.ram[FLAGS]:02X}")
    return out


class TestGripperConformance(StationConformance):
    """The 002 gripper."""

    samples = {
        "GripperController.X": [["33"]],
        # the target's high byte far closed, STOPCNT, then the drive bit in FLAGS (what P does)
        "GripperMonitor.C": [[f"{COMMAND_CNT + 1:02X}", "E4"], [f"{STOPCNT:02X}", "FF"],
                             [f"{FLAGS:02X}", f"{_MASK_DRVON:02X}"]],
        "GripperMonitor.D": [["4A"]],
        "GripperMonitor.L": [["FFFF"]],
        "GripperSim.object": [["20"]],
        "GripperSim.jog": [["close", "0.5"]],
        "GripperSim.fault": [["none"]],
    }

    def build(self, tmp_path):
        return build_gripper(Loop(SimClock()))

    def driven(self, station):
        return _gripper_driven(station)

    def settings(self, station):
        return bytes(station.cpu.ram), station.board.dac, station.cpu.sp, len(station.motion)

    def start_move(self, station, runner):
        ctl = station.controller
        job = runner.call(ctl.start_init)
        assert runner.wait_until(lambda: job.done, 60.0) and job.value().ok
        runner.call(ctl.run_command, "P", "E47A")
        assert runner.wait_until(lambda: station.board.dac != DAC_NULL and ctl.moving, 5.0)

    def rest(self, station, runner):
        runner.call(station.stop, take_fault=False)
        runner.call(station.plant.jog, "off", None, take_fault=False)

    def after_record(self, station, runner):
        if not station.controller.clock_enabled:
            runner.call(station.controller.toggle_clock, take_fault=False)  # monitor I


# -- the manipulator -----------------------------------------------------------------------


def _manipulator_driven(station) -> list[str]:
    tio = station.tio10
    out = []
    for a in station.axes:
        ch = a.motor.channel
        if tio.armed(ch):
            out.append(f"{a.motor.name}: channel {ch} armed")
        if not tio.bit(*AWO_BITS[ch]):
            out.append(f"{a.motor.name}: windings on")
    return out


class TestPrototypeConformance(StationConformance):
    """The 000 manipulator's three-rope prototype."""

    name = "prototype"
    samples = {
        "ManipulatorSim.fault": [["0", "none"]],
        "ManipulatorSim.load": [["0", "10"]],
        "ManipulatorSim.unload": [["0"]],
        "Axis.point": [["10 N"]],
        "Axis.maxspeed": [["3"]],
        "Loadcell.point": [["10 N"]],
        "Motor.maxspeed": [["3"]],
        "Encoder.setZeroLength": [["100"]],
        "PolyAxis.setpos": [["0", "0", "1e5"]],
    }

    def build(self, tmp_path):
        return make_station(tmp_path, self.name)[0]

    def driven(self, station):
        return _manipulator_driven(station)

    def settings(self, station):
        side = station.boards.simulated["tio10"]  # the world's side: every register
        regs = tuple(tuple(side.values(r.name)) for r in side.kind.registers)
        devs = tuple((a.motor.state, a.motor.mode, a.motor.cruise_speed, a.encoder.zero_length,
                      a.loadcell.slope, a.loadcell.offset, a.mode) for a in station.axes)
        pa = station.polyaxis
        return regs, devs, pa.active, pa.tension_stop, pa.signal_all, len(station.motion)

    def start_move(self, station, runner):
        pa = station.polyaxis
        x, y, z = pa.position
        runner.call(pa.run_command, "to", f"{x:.2f}", f"{y:.2f}", f"{z - 20:.2f}")
        assert runner.wait_until(lambda: bool(_manipulator_driven(station)), 30.0)


class TestSnoConformance(TestPrototypeConformance):
    """The 000 manipulator's five-rope SNO station."""

    name = "sno"


@pytest.mark.parametrize("name", ["prototype", "sno"])
def test_the_reflex_disarms_every_manipulator_motor_during_an_axis_move(tmp_path, name):
    """Manipulator: an axis move running, a trip disarms every TIO10 channel and turns the windings off before any further tick."""
    station, runner = make_station(tmp_path, name)
    try:
        runner.call(station.axes[0].run_command, "up", "2")
        assert runner.wait_until(lambda: bool(_manipulator_driven(station)), 30.0)

        def act() -> list[str]:
            station.trip("conformance trip", "test")
            return _manipulator_driven(station)

        assert runner.call(act, take_fault=False) == []
        runner.sleep(0.2)
        assert runner.call(lambda: _manipulator_driven(station), take_fault=False) == []
    finally:
        station.close()


# -- a bug in pyrt is not the operator's error ------------------------------------------------


def test_a_bug_is_an_internal_error_with_its_traceback_and_the_console_goes_on(monkeypatch):
    """An unexpected exception prints 'internal error: Type: msg (a bug in pyrt ...)' with the traceback on the error stream; a CommandError stays 'error: ...'; the next line runs."""
    station = build_gripper(Loop(SimClock()))
    runner = station.start()
    try:
        out, err = io.StringIO(), io.StringIO()
        shell = RobotShell(station, out, runner=runner)
        shell.stderr = err

        def broken() -> str:
            raise KeyError("no such register")

        monkeypatch.setattr(station, "status", broken)
        assert shell.onecmd("status") is False
        text = out.getvalue()
        assert text.splitlines() == [
            "internal error: KeyError: 'no such register' (a bug in pyrt; please report it "
            "with this traceback)"]
        assert "Traceback (most recent call last)" in err.getvalue()
        assert "in broken" in err.getvalue() and "KeyError" in err.getvalue()

        out.seek(0)
        out.truncate()
        shell.onecmd("P 1234")  # the operator's mistake: positive target
        assert out.getvalue().startswith("error: ") and "internal" not in out.getvalue()
        out.seek(0)
        out.truncate()
        shell.onecmd("W")  # the console keeps running
        assert out.getvalue().strip() == "0000"

        def invariant() -> str:
            raise PyrtInternalError("ready queue image corrupt")

        monkeypatch.setattr(station, "status", invariant)
        out.seek(0)
        out.truncate()
        shell.onecmd("status")  # pyrt's own invariant broken: a bug as well
        assert out.getvalue().startswith("internal error: PyrtInternalError: ready queue")
    finally:
        station.close()
