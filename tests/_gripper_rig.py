"""A simulated gripper on a SimClock loop, shared by the gripper tests."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from pyrt.boards import open_boards
from pyrt.boards.gripper import DAC_NULL, GripperBoard
from pyrt.boards.i8031 import I8031
from pyrt.robots.gripper import GripperController, JobResult
from pyrt.scheduler import Loop, SimClock
from pyrt.sim.gripper import JawPlant
from pyrt.sim.world import GRIPPER_BOARDS
from pyrt.station.gripper import GripperStation

MS = 1_000_000


@dataclass
class StallMonitor:
    """Loop handler: the longest time current was applied while the jaws did not move."""

    board: GripperBoard
    plant: JawPlant
    worst_ns: int = 0
    _since: int | None = None
    _pos: int = field(default=0)

    def __call__(self, now_ns: int) -> None:
        pos = int(self.plant.x // 1)
        if self.board.dac == DAC_NULL or pos != self._pos:
            self._since = None
            self._pos = pos
            return
        if self._since is None:
            self._since = now_ns
        self.worst_ns = max(self.worst_ns, now_ns - self._since)


@dataclass
class Rig:
    cpu: I8031
    board: GripperBoard
    plant: JawPlant
    ctl: GripperController
    loop: Loop
    stall: StallMonitor
    station: Any = None

    @property
    def runner(self):
        return self.station.runner

    def run_job(self, job, max_s: float = 60.0) -> JobResult:
        assert self.loop.run_until(lambda: job.done, int(max_s * 1000)), f"{job.name} hung"
        return job.value()

    def init(self) -> JobResult:
        result = self.run_job(self.ctl.start_init())
        assert result.ok, result.message
        return result

    def move(self, target: int, max_s: float = 30.0) -> int:
        self.ctl.move(target)
        assert self.loop.run_until(lambda: not self.ctl.moving, int(max_s * 1000))
        return signed(self.ctl.position())


def signed(word: int) -> int:
    return word - 0x10000 if word & 0x8000 else word


def make_rig(*, runner: bool = False, **plant_kw) -> Rig:
    """A gripper station (plant, controller, motion, scope, mailbox) and a stall monitor."""
    boards = open_boards("sim:", "gripper", GRIPPER_BOARDS)
    side = boards.simulated  # the world's side: the board the jaws drive
    assert side is not None
    cpu = boards["gripper"].cpu
    plant = JawPlant(side["gripper"], **plant_kw)
    board = plant.board  # the world's side of the cage, read as the controller reads it
    loop = Loop(SimClock())
    station = GripperStation(loop, boards, plant)
    ctl: GripperController = station.controller
    stall = StallMonitor(board, plant)
    loop.attach(stall, name="stall monitor")
    return Rig(cpu, board, plant, ctl, loop, stall, station)
