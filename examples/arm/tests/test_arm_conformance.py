"""The arm passes pyrt's conformance suite (pyrt.testing), as any station of one's own can."""

from __future__ import annotations

import argparse
from typing import ClassVar

from pyrt import Loop, SimClock
from pyrt.testing import StationConformance

from pyrt_arm.station import ARM


def _driven(station) -> list[str]:
    """The servo board's outputs that are on."""
    board = station.board
    return [f"{reg}[{j}] = {board.read(reg, j)}" for reg in ("drive", "enable")
            for j in (0, 1) if board.read(reg, j) != 0]


class TestArmConformance(StationConformance):
    """The two-joint arm, built by its factory as 'pyrt arm' builds it."""

    samples: ClassVar[dict[str, list[list[str]]]] = {"ArmSim.fault": [["none"]]}

    def build(self, tmp_path):
        return ARM.build(Loop(SimClock()), argparse.Namespace(boards=None, start=None))

    def driven(self, station):
        return _driven(station)

    def settings(self, station):
        board = station.board
        regs = tuple(board.read(r.name, j) for r in board.kind.registers for j in range(r.count))
        joints = tuple((jt.engaged, jt.drive, jt.config, jt.limits_deg)
                       for jt in station.controller.joints)
        gains = station.controller.servo.gains.tobytes()
        return (regs, joints, gains, station.controller.state, tuple(station.plant.active_faults()),
                len(station.motion))

    def start_move(self, station, runner):
        runner.call(station.controller.run_command, "to", "60", "30")
        assert runner.wait_until(lambda: len(_driven(station)) == 4, 5.0)
