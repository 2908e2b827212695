"""pyrt's conformance suite (pyrt.testing) on the pyrt urdf station (the PUMA 560),
built through its factory as 'pyrt urdf' builds it.

The arm carries its own weight: the servo holds it from the first tick, so "driven" here
means an actuator that moves the arm (a move that runs, or a joint of the simulated arm
moving), not an amplifier that holds it still; the registers of a trip are checked in
tests/test_urdf_station.py (every DAC and enable 0 in the tick of the fault).
"""

from __future__ import annotations

import argparse
import math
from typing import ClassVar

import numpy as np
import pytest

from pyrt.scheduler import Loop, SimClock
from pyrt.station.urdf import URDF
from pyrt.testing import StationConformance

#: A joint of the simulated arm moving faster than this (deg/s) is driven.
MOVING_DEG_S = 0.5

def _urdf_driven(station) -> list[str]:
    out = [f"the arm {station.arm.state}"] if station.arm.state != "idle" else []
    if station.fault is not None or not station.arm.powered:
        # amplifiers off: an output that is not 0 drives (the arm, with no brakes,
        # may still sink under its own weight: that is the world, not an actuator)
        board = station.board
        return out + [f"{r.name}[{j}] = {board.read(r.name, j)}" for r in board.kind.outputs()
                      for j in range(r.count) if board.read(r.name, j) != 0]
    qd = np.degrees(station.plant.truth().qd)
    out += [f"q{j + 1} at {v:.3f} deg/s" for j, v in enumerate(qd) if abs(v) > MOVING_DEG_S]
    return out


def _urdf_settings(station) -> tuple:
    board, arm = station.board, station.arm
    regs = tuple(board.read(r.name, j) for r in board.kind.outputs() for j in range(r.count))
    return (regs, arm.state, arm.powered, arm.servo.knots.tobytes(), arm.servo.gains.tobytes(),
            station.plant.table_z, len(station.motion), arm.last_stop)


@pytest.fixture
def robot():
    station = _build()
    runner = station.start()
    assert runner.wait_until(lambda: station.arm.powered and not station.busy(), 5.0)
    runner.sleep(0.2)
    yield station, runner
    station.close()


def test_the_holding_arm_is_not_driven(robot):
    """At start the servo holds the PUMA against gravity: amplifiers on, no move, the truth still."""
    station, runner = robot
    assert station.arm.powered
    assert runner.call(lambda: _urdf_driven(station)) == []
    assert math.isfinite(runner.call(lambda: station.signals()[0][1].read()))


def _build():
    return URDF.build(Loop(SimClock()), argparse.Namespace(boards=None, urdf=None, start=None))


class TestUrdfConformance(StationConformance):
    """The PUMA 560 as 'pyrt urdf' runs it."""

    samples: ClassVar[dict[str, list[list[str]]]] = {
        "UrdfSim.table": [["-2000"], ["off"]],
        "UrdfArm.tool": [["0", "0", "50", "0", "0", "0"], ["0"] * 6],
        "UrdfArm.coord": [["0", "0", "50", "0", "0", "0"], ["0"] * 6],
        "UrdfArm.conveyor": [["0", "50", "0"], ["0"] * 3],
    }

    def build(self, tmp_path):
        return _build()

    def driven(self, station):
        return _urdf_driven(station)

    def settings(self, station):
        return _urdf_settings(station)

    def ready(self, station, runner):
        # the servo closes the loop by itself and brings a swinging arm to rest first
        assert runner.wait_until(lambda: station.arm.powered and not station.busy(), 5.0)
        runner.sleep(0.2)

    def start_move(self, station, runner):
        runner.call(station.arm.move_joints, 40, 60, -150, 30, -40, 50)
        assert runner.wait_until(lambda: bool(self.driven(station)), 5.0)


def _drive_driven(station) -> list[str]:
    """Hardware (a): with the arm unpowered, the board drives only while enabled (its
    setpoints and limits stay as written, read by a board that is off)."""
    if station.fault is not None or not station.arm.powered:
        out = [f"the arm {station.arm.state}"] if station.arm.state != "idle" else []
        enable = station.board.read("enable")
        return out + ([f"enable = {enable}"] if enable else [])
    return _urdf_driven(station)


class TestUrdfHardwareAConformance(TestUrdfConformance):
    """The PUMA 560 as 'pyrt urdf --hardware a --tick-us 10000' runs it: the motion-control
    board servos, the host writes setpoints at 100 Hz."""

    samples: ClassVar[dict[str, list[list[str]]]] = {
        "UrdfSim.table": [["-2000"], ["off"]],
        "DrivenArm.tool": [["0", "0", "50", "0", "0", "0"], ["0"] * 6],
        "DrivenArm.coord": [["0", "0", "50", "0", "0", "0"], ["0"] * 6],
        "DrivenArm.conveyor": [["0", "50", "0"], ["0"] * 3],
    }

    def build(self, tmp_path):
        return URDF.build(Loop(SimClock(), period_ns=10_000_000),
                          argparse.Namespace(boards=None, urdf=None, start=None, hardware="a"))

    def driven(self, station):
        return _drive_driven(station)
