"""``pyrt cell``: a work cell of two robots in one runtime, each its own fault domain.

The PUMA 560 (the arm of ``pyrt urdf``, robot ``puma``) carries 002's
parallel-jaw gripper (robot ``gripper``) as its end effector.  One loop, one
console; each robot has its own boards (the arm's passive servo board, the
gripper's 8031 cage), its own ready queues in rate groups whose periods are
time, not ticks (the arm's ``servo`` group at 1 kHz and ``trajectory`` group
at 100 Hz; the gripper's 8031 queue, with 002's three routines, its ``CMD:``
letters and its monitor, the group ``SYSCLK`` at its clock interrupt's 1 ms,
which SYSCLKPD divides as on 002's board), its own motion queue and its own
fault:

* a **gripper fault** stops the gripper (drive nulled) and the cell's
  sequence; the arm keeps holding where it is;
* an **arm fault** stops the arm (every amplifier off) and the gripper's
  motion (its drive nulled, its move ended), and the sequence;
* ``ack NAME`` acknowledges one robot, ``stop`` stops both, ``stop NAME`` one.

The simulated world (:mod:`pyrt.station._cell_world`) has an object on the
table (``sim object X Y Z``; its truth ``sim.object.x`` ...) that moves with
the tool only while the jaws hold it.  ``pick X Y Z`` runs the sequence
(:mod:`pyrt.station._cell_pick`) in the loop: approach above the object,
open, descend, close on it, lift.

Declaring the robots (what any station of several robots does)::

    station.add_robot("puma", arm, queues=arm_queues, boards=[arm_boards],
                      stop=arm_stop, busy=arm.busy, where=arm.where)
    station.add_robot("gripper", ctl, queues=[ctl.queue], executors=[executor],
                      motion=jaw_moves, boards=[jaw_boards], stop=jaw_stop)
"""

from __future__ import annotations

import argparse
import contextlib
import functools
from collections.abc import Callable

from pyrt.boards import Boards, open_boards
from pyrt.boards.armservo import arm_servo_kind
from pyrt.boards.i8031 import COMMAND_CNT, ENCODER_CNT
from pyrt.component import Arg, Component, Signal, command, finite
from pyrt.errors import ConfigError, Fault, PyrtError
from pyrt.robots.gripper import GripperController, JawCalibration
from pyrt.scheduler import Loop
from pyrt.scheduler.motion import MotionExecutor, MotionType
from pyrt.scheduler.runner import MotionQueue
from pyrt.sim.arm import FTCalibration
from pyrt.sim.gripper import JawPlant
from pyrt.sim.world import GRIPPER_BOARDS
from pyrt.station._cell_pick import PickSequence, PickSnapshot, PickWork
from pyrt.station._cell_world import CellSim, CellWorld
from pyrt.station._urdf_arm import SERVO_PERIOD_NS, UrdfArm
from pyrt.station._urdf_sim import UrdfPhysics, UrdfSim
from pyrt.station.base import Robot, Station
from pyrt.station.factory import StationFactory
from pyrt.station.gripper import AT_TARGET_COUNTS, DEFAULT_START
from pyrt.station.profile import ShellProfile
from pyrt.station.urdf import _drives, arm_world, load_arm
from pyrt.tasks import register_tasks

__all__ = ["CELL", "CellFactory", "CellStation", "build_cell"]


#: The gripper's clock interrupt period (ns): 002's board's 1 ms, whatever the loop's tick.
GRIPPER_CLOCK_NS = 1_000_000


def _signed(word: int) -> int:
    return word - 0x10000 if word & 0x8000 else word


def _faulted(robot: Robot) -> bool:
    return robot.fault is not None


class CellStation(Station):
    """Everything ``pyrt cell`` runs (see the module text), built by :func:`build_cell`."""

    name = "cell"

    def __init__(self, loop: Loop, arm_boards: Boards, jaw_boards: Boards) -> None:
        super().__init__(loop)
        self.attach_boards(arm_boards, jaw_boards)
        # -- the world (in process): the arm, the jaws, the object -------------------
        chain, motors, text = load_arm(None)
        self.chain = chain
        self.urdf_text = text
        arm_side, jaw_side = arm_boards.simulated, jaw_boards.simulated
        if arm_side is None or jaw_side is None:
            raise ConfigError("the cell's world runs in this process: its boards are sim:")
        world = arm_world(arm_side, chain, motors)
        physics = world.plant
        assert isinstance(physics, UrdfPhysics)
        self.plant = physics.arm
        self.jaws = JawPlant(jaw_side["gripper"], start=DEFAULT_START)
        self.world = CellWorld(physics.arm, self.jaws)
        self.attach_world(world.step, "physics", boards=arm_boards)
        self.attach_world(self.jaws.step, "jaws", boards=jaw_boards)
        # after the arm and the jaws moved, before the jaws' inputs are read
        self.attach_world(self.world.step, "object", boards=jaw_boards)
        # -- robot puma: the arm, its trajectory and servo tasks ------------------------
        self.board = arm_boards["servo"]
        self.arm = arm = UrdfArm(self, "puma", chain, self.board, _drives(motors),
                                 SERVO_PERIOD_NS, wrench=FTCalibration().wrench)
        #: The arm's rate groups: servo (1 kHz) and trajectory (100 Hz), whatever the tick.
        self.arm_groups = arm.rate_groups("puma")
        for group in self.arm_groups:
            loop.attach(group)
        arm_queues = [q for g in self.arm_groups for q in g.queues]
        # -- robot gripper: 002's controller, its ready queue and its P moves -----------
        self.jaw_board = jaw_boards["gripper"]
        p = self.jaws.p
        ctl = GripperController(self.jaw_board.cpu,
                                calibration=JawCalibration(p.closed, p.open_mm, p.gain,
                                                           p.deadband))
        self.controller = ctl
        ctl.attach(loop, register=False, clock_ns=GRIPPER_CLOCK_NS)  # group SYSCLK
        register_tasks(ctl.queue, ctl)
        self.jaw_moves = MotionQueue(capacity=16)
        ctl.motion = self.jaw_moves
        self.executor = MotionExecutor(ctl, self.jaw_moves.get, self._jaw_move_done,
                                       self._jaw_move_error)
        loop.attach(self.executor.poll, name="motion:gripper")
        # -- the cell: its sequence, the robots, the tree --------------------------------
        self.pick = PickSequence(self)
        loop.attach(self.pick.step, name="sequence")
        self.puma = self.add_robot("puma", arm, queues=arm_queues, boards=[arm_boards],
                                   stop=self._stop_arm, busy=arm.busy, where=arm.where,
                                   ended=self._arm_ended)
        self.gripper = self.add_robot("gripper", ctl, queues=[ctl.queue],
                                      executors=[self.executor], motion=self.jaw_moves,
                                      boards=[jaw_boards], stop=self._stop_jaws,
                                      busy=self._jaws_busy, where=self._jaws_where,
                                      status=self._jaws_status, ended=self._jaws_ended)
        arm.station = self.puma  # the arm answers to its own fault, not the gripper's
        armsim = UrdfSim(physics.arm)
        armsim.name = "armsim"
        self.sim = CellSim(self.world, armsim)
        self.root_component = CellRoot(self)
        #: The component whose commands are the cell's console words (``pick``).
        self.words = self.root_component
        loop.fault_listeners.append(self._on_fault)
        self.adopt(self.root_component, extras=[self.sim], where=self._where,
                   status=None)
        self.profile = ShellProfile(
            prompt="cell> ", words=self.root_component,
            level_prompts={ctl.name: "CMD: ", ctl.monitor.name: "* "},
            startup_commands=("gripper I",), idle="nothing to wait for{last}",
            announce_stops=True)
        ctl.power_up()

    # -- the robots' words ---------------------------------------------------------------

    def _on_fault(self, fault: Fault) -> None:
        """An arm fault stops the gripper's motion too (no fault of its own); any fault
        of either robot ends the cell's sequence.  Loop thread, in the fault's tick."""
        if fault.robot not in ("puma", "gripper"):
            return
        self.pick.abort(f"{fault.robot} fault: {fault.cause}")
        if fault.robot == "puma" and self.gripper.fault is None:
            self.gripper.reflex(f"the arm stopped by a fault ({fault.cause})")
            self.controller.move_ended("arm fault")

    def _stop_arm(self) -> str:
        self.pick.abort("stop command")
        said = self.arm.stop()
        if said:
            return f"{said}; {self.arm.where()}"
        if self.arm.powered:
            return f"puma: nothing moving; holding at {self.arm.where()}"
        failed = self.puma.reflex("stop command")
        return "puma: every motor stopped" + (f" ({failed})" if failed else "")

    def _stop_jaws(self) -> str:
        self.pick.abort("stop command")
        failed = self.gripper.reflex("stop command")
        self.controller.move_ended("stop command")
        said = "gripper: every motor stopped" + (f" ({failed})" if failed else "")
        return f"{said}; {self._jaws_where()}"

    def _jaws_busy(self) -> bool:
        ctl = self.controller
        return ctl.moving or ctl.busy or len(self.jaw_moves) > 0 or self.executor.busy

    def _jaws_where(self) -> str:
        ctl = self.controller
        pos, tgt = ctl.word(ENCODER_CNT), ctl.word(COMMAND_CNT)
        mm = ctl.calibration.mm
        return (f"jaws {pos:04X} ({mm(_signed(pos)):.1f} mm), target {tgt:04X} "
                f"({mm(_signed(tgt)):.1f} mm)")

    def jaw_error(self) -> int:
        """The jaws' position minus their target, counts (the controller's view)."""
        ctl = self.controller
        return _signed(ctl.word(ENCODER_CNT)) - _signed(ctl.word(COMMAND_CNT))

    def _jaws_status(self) -> str:
        ctl = self.controller
        state = ("fault" if self.gripper.fault is not None else "moving" if self._jaws_busy()
                 else "idle")
        return f"{self._jaws_where()}, {state}, drive {ctl.dac - 0x80:+d}"

    def _jaws_ended(self) -> tuple[str, list[str]]:
        if self.gripper.fault is not None:
            why = f"fault: {self.gripper.fault.cause}"
        elif abs(self.jaw_error()) <= AT_TARGET_COUNTS:
            why = "at target"
        else:
            why = (f"stopped short of the target by {abs(self.jaw_error())} counts "
                   f"({self.controller.last_stop or 'ended'})")
        return why, [f"gripper: {why}: {self._jaws_where()}"]

    def _arm_ended(self) -> tuple[str, list[str]]:
        if self.puma.fault is not None:
            why = f"fault: {self.puma.fault.cause}"
        elif not self.arm.last_stop:
            return "", []  # the servo brought the arm to rest at power-on: not a move
        else:
            why = self.arm.last_stop
        return why, [f"puma: {why}: {self.arm.where()}"]

    def _jaw_move_done(self, motion: MotionType) -> None:
        reason = motion.stop_reason or ""
        if reason.startswith("refused"):
            self.controller.say(f"move {reason}", "warning")
            return
        if reason == "stop command":
            self.controller.move_ended(reason)

    def _jaw_move_error(self, cause: str, motion: MotionType) -> None:
        self.trip(cause, source="P move", robot="gripper")

    def _where(self) -> str:
        return f"puma {self.arm.where()}; gripper {self._jaws_where()}"

    # -- the station's hooks -------------------------------------------------------------

    def busy(self) -> bool:
        """A robot moves, or the cell's sequence runs."""
        return super().busy() or self.pick.running

    def stop(self) -> str:
        """Both robots stopped (the arm brakes to rest and holds), the sequence ended."""
        self.pick.abort("stop command")
        return super().stop()

    def status_fields(self) -> list[tuple[str, Signal, str]]:
        """STATUS: each robot's busy and fault flags, the sequence's state, the object."""
        out: list[tuple[str, Signal, str]] = []
        for r in self.robots:
            out.append((f"{r.name}_busy", Signal(f"{r.name}_busy", "bool", r.busy,
                                                 f"{r.name} moves", "d"), "d"))
            out.append((f"{r.name}_fault", Signal(
                f"{r.name}_fault", "bool", functools.partial(_faulted, r),
                f"a fault stopped {r.name}", "d"), "d"))
        out.append(("sequence", Signal("sequence", "step", lambda: self.pick.step_index,
                                       "the pick's step (0: none)", "d"), "d"))
        out.append(self.fault_field())
        return out

    def journal_databases(self) -> dict[str, bytes]:
        return {}

    def close(self) -> None:
        """Every amplifier off and the drive nulled, then pyrt's close."""
        runner = self.runner
        if runner is not None and runner.running:
            with contextlib.suppress(PyrtError):
                runner.call(self.reflex, "shutdown", take_fault=False, name="shutdown")
        super().close()


class CellRoot(Component):
    """The cell: its robots below it and its words (``pick``)."""

    name = "cell"

    def __init__(self, station: CellStation) -> None:
        self.station = station

    def children(self) -> list[Component]:
        return [self.station.arm, self.station.controller]

    def signals(self) -> list[Signal]:
        pick = self.station.pick
        return [Signal("step", "step", lambda: pick.step_index,
                       "the pick sequence's step (0: none)", "d")]

    @command(Arg("X", finite("x", -2000.0, 2000.0), units="mm"),
             Arg("Y", finite("y", -2000.0, 2000.0), units="mm"),
             Arg("Z", finite("z", -2000.0, 2000.0), units="mm"), name="pick", moves=True,
             prepare="_pick_prepare", snapshot="_pick_snapshot")
    def pick(self, work: PickWork) -> str:
        """pick X Y Z: pick the object at X Y Z mm on the table: approach, open, descend,
        close on it, lift (the loop runs the sequence; wait waits for it).

        Every pose is solved first: one out of reach refuses the pick and
        nothing moves.  A fault of either robot or stop ends the sequence
        where it is; the arm then holds."""
        return self.station.pick.begin(work)

    def _pick_snapshot(self) -> PickSnapshot:
        return self.station.pick.snapshot()

    def _pick_prepare(self, snap: PickSnapshot, x: float, y: float, z: float) -> PickWork:
        return self.station.pick.prepare(snap, x, y, z)

    def reflex(self) -> None:
        """The cell's sequence ends (the robots' reflexes stop their actuators)."""
        self.station.pick.abort("stopped")


def build_cell(loop: Loop, *, boards: str | None = None) -> CellStation:
    """The cell on ``loop``, not yet started.  ``boards``: ``sim:`` (the default)
    only: each robot gets its own in-process boards."""
    url = boards or "sim:"
    if not url.lower().startswith("sim:"):
        raise ConfigError(f"--boards {boards!r}: the cell runs on in-process boards "
                          "(sim:), a set of its own for each robot")
    chain, _motors, _text = load_arm(None)
    arm_boards = open_boards(url, "puma", {"servo": arm_servo_kind(chain.n)})
    try:
        jaw_boards = open_boards(url, "gripper", GRIPPER_BOARDS)
    except BaseException:
        arm_boards.close()
        raise
    try:
        return CellStation(loop, arm_boards, jaw_boards)
    except BaseException:
        arm_boards.close()
        jaw_boards.close()
        raise


class CellFactory(StationFactory):
    """pyrt cell: the PUMA 560 with 002's parallel-jaw gripper, two robots in one runtime.

Robot puma (the arm of pyrt urdf: puma movej / moveto / movel / where) and
robot gripper (002's controller: gripper P 0, gripper I, gripper M for the
monitor; its ready queue, CMD: letters and supervision), each with its own
boards and its own fault: a gripper fault stops the gripper and the
sequence while the arm holds; an arm fault stops the arm and the gripper's
motion.  ack NAME acknowledges one robot (ack alone: every faulted one);
stop stops both, stop NAME one; status has a line per robot; wait NAME
waits for one robot's moves.

The simulated world has an object on the table: sim object X Y Z places it
(mm), its truth is sim.object.x / y / z; it moves with the tool only while
the jaws hold it.  pick X Y Z runs approach, open, descend, close on the
object and lift, in the loop; wait waits for it to end.
"""

    name = "cell"
    summary = "run a work cell: the PUMA 560 with 002's gripper, two robots in one runtime"
    description = __doc__ or ""
    default_tick_us = 1000
    max_tick_us = 1000
    max_tick_why = ("the arm's servo group runs at 1 kHz and the gripper's clock "
                    "interrupt every 1 ms (a tick that divides 1000 µs)")

    def configure(self, args: argparse.Namespace, say: Callable[[str], None]) -> None:
        """A journal is refused: it records one set of boards, and the cell has one per
        robot (the black box keeps the arm's inputs and every signal)."""
        if getattr(args, "journal", None):
            raise ConfigError("--journal: a journal records one set of boards and "
                              "the cell has one for each robot (puma, gripper); not recorded")

    def build(self, loop: Loop, args: argparse.Namespace) -> CellStation:
        return build_cell(loop, boards=getattr(args, "boards", None))


#: ``pyrt cell`` (the entry point ``pyrt.station.cell:CELL`` in ``pyrt.stations``).
CELL = CellFactory()
