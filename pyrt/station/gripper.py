"""The gripper station: 8031, cage boards, simulated jaws, controller, scope,
motion executor and runner on one loop, wired in the order a tick needs them.

Per tick: the jaws move (physics, dt = now - last), the clock interrupt
walks the ready queue, the stall watchdog looks, the scope samples, the
motion executor starts or follows a queued ``P`` move, and the mailbox is
served.  A fault's reflex nulls the drive (the controller's own reflex),
ends the current motion and drops every queued one, in the same tick.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterable
from dataclasses import dataclass

from pyrt.boards.gripper import DAC_NULL, SimGripperBoard
from pyrt.boards.i8031 import I8031
from pyrt.errors import ConfigError, Fault, PyrtError
from pyrt.robots.gripper import GripperController
from pyrt.scheduler import Loop
from pyrt.scheduler.motion import MotionExecutor, MotionType
from pyrt.scheduler.runner import Runner
from pyrt.scope import Scope
from pyrt.sim.gripper import JawPlant

__all__ = ["GripperStation", "build_gripper"]


@dataclass
class GripperStation:
    """Everything ``pyrt gripper`` runs, built by :func:`build_gripper`."""

    cpu: I8031
    board: SimGripperBoard
    plant: JawPlant
    controller: GripperController
    loop: Loop
    scope: Scope
    executor: MotionExecutor
    runner: Runner

    def shutdown(self) -> None:
        """Null the drive, stop the loop and close the timing log."""
        with contextlib.suppress(PyrtError):
            self.runner.call(self.controller.drive, DAC_NULL)
        self.runner.stop()
        self.loop.close()


def build_gripper(
    loop: Loop,
    *,
    start: int = -0x0C00,
    object_mm: float | None = None,
    faults: Iterable[str] = (),
) -> GripperStation:
    """Wire a simulated gripper onto ``loop`` and power it up (not yet started:
    call ``station.runner.start()``).  Bad simulation settings raise ConfigError."""
    cpu = I8031()
    board = SimGripperBoard(cpu)
    try:
        plant = JawPlant(board, start=start)
        plant.set_object(object_mm)
        for fault in faults:
            plant.inject(fault)
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    ctl = GripperController(cpu)
    loop.attach(plant.step, name="jaws")
    ctl.attach(loop)
    scope = Scope()
    loop.attach(scope.sample, name="scope")
    runner_box: list[Runner] = []

    def motion_done(motion: MotionType) -> None:
        reason = motion.stop_reason or ""
        if reason.startswith("refused") and runner_box:
            runner_box[0].post(f"move {reason}")

    def motion_error(cause: str, motion: MotionType) -> None:
        ctl.queue.trip(cause, source="P move")

    executor = MotionExecutor(ctl, lambda: runner_box[0].motion.get(), motion_done, motion_error)
    loop.attach(executor.poll, name="motion")
    runner = Runner(loop)
    runner_box.append(runner)
    own_reflex = ctl.reflex

    def reflex(fault: Fault) -> None:
        own_reflex(fault)
        executor.abort(f"fault: {fault.cause}")
        runner.motion.clear()

    ctl.queue.reflex = reflex
    ctl.power_up()
    return GripperStation(cpu, board, plant, ctl, loop, scope, executor, runner)
