"""The ``arm`` station: registered as ``arm`` in the entry-point group ``pyrt.stations``.

Built only from pyrt's public API.  The boards are one servo board of kind
:data:`pyrt_arm.boards.SERVO` (``sim:``: in this process, with the simulated
arm behind it; ``tcp://HOST:PORT``: ``pyrt board-sim arm`` in another
process).  The component tree::

    arm          the controller (root, :mod:`pyrt_arm.controller`): arm to / xy / show
      shoulder   joint q0
      elbow      joint q1
    sim          the simulated arm's truth and fault injection (sim show, sim fault ...)

One general ready queue runs the controller's two tasks, ``trajectory``
(100 Hz) and ``servo`` (every tick, 1 kHz at the default 1 ms tick).  A
fault trips the station: in the same tick every joint's reflex writes drive
0 and enable 0, the motion ends and queued moves are dropped.
"""

from __future__ import annotations

import argparse
import contextlib
import math
from collections.abc import Sequence
from typing import Any

from pyrt import (
    BoardKind,
    Boards,
    BoardWorld,
    CommandError,
    Component,
    ConfigError,
    Loop,
    MotionExecutor,
    MotionType,
    PyrtError,
    ReadyQueue,
    ShellProfile,
    Station,
    StationFactory,
    World,
    install,
    open_boards,
)

from pyrt_arm.boards import (
    ARM_BOARDS,
    DEFAULT_START_DEG,
    WORLD_STEP_S,
    ArmPhysics,
    ArmSim,
    arm_world,
)
from pyrt_arm.controller import AT_TARGET_DEG, TIP_TOLERANCE_MM, ArmController
from pyrt_arm.servo import ELBOW, SHOULDER

__all__ = ["ARM", "ArmFactory", "ArmStation", "build_arm"]


# -- the station ----------------------------------------------------------------------------------


class ArmStation(Station):
    """Everything ``pyrt arm`` runs (see the module text), built by :func:`build_arm`.

    ``boards``: the arm's (owned and closed by the station); ``world``: the
    simulated arm behind in-process boards, or None over ``tcp://``.
    """

    name = "arm"

    def __init__(self, loop: Loop, boards: Boards, world: World | None) -> None:
        super().__init__(loop)
        self.attach_boards(boards)
        self.world = world
        self.board = boards["servo"]
        if world is not None:
            physics = world.plant
            assert isinstance(physics, ArmPhysics)
            self.plant = physics.plant
            self.attach_world(physics.stepper, "physics")
        self.controller = ctl = ArmController(self, self.board, loop.period_ns,
                                              (SHOULDER, ELBOW))
        self.queue = ReadyQueue.general(name="arm")
        install(self.queue, ctl.tasks())
        loop.attach(self.queue, name="queue:arm")

        def done(motion: MotionType) -> None:
            reason = motion.stop_reason or "ended"
            if reason.startswith("refused"):
                ctl.say(f"move {reason}", "warning")
            ctl.motion_ended(reason)

        def error(cause: str, motion: MotionType) -> None:
            self.trip(cause, source="trajectory")

        self.executor = MotionExecutor(ctl, self.motion.get, done, error)
        extras: list[Component] = []
        if world is not None:
            extras.append(ArmSim(self.plant))
        elif boards.has_info:
            extras.append(BoardWorld(boards))
        self.adopt(ctl, queues=[self.queue], executors=[self.executor], extras=extras,
                   where=ctl.where, ended=self._ended, status=self._status)
        self.profile = ShellProfile(idle="nothing to wait for: arm idle at {where}")

    # -- what the operator reads (given to adopt) --------------------------------------

    def busy(self) -> bool:
        """A move runs, waits, or the arm settles or brakes."""
        return self.controller.state != "idle" or super().busy()

    def _ended(self) -> tuple[str, list[str]]:
        """How the move ended: at target, stopped, did not settle, or the fault."""
        if self.fault is not None:
            why = f"fault: {self.fault.cause}"
            return why, [f"FAULT: {self.fault.cause}; {self.where()}"]
        why = self.controller.last_stop or "ended"
        if why == "at target":
            return why, [f"at target (every joint within {AT_TARGET_DEG:g} deg): "
                         f"{self.where()}; the true tip is within {TIP_TOLERANCE_MM:g} mm of it"]
        return why, [f"{why}: {self.where()}"]

    def _status(self) -> str:
        """One line: joints, tip, state, following errors."""
        ctl = self.controller
        errs = (", following error " + ", ".join(f"{jt.error_deg:+.4f}"
                                                  for jt in ctl.joints) + " deg"
                if ctl.state != "idle" else ", amplifiers off")
        return f"{self.where()} (±{TIP_TOLERANCE_MM:g} mm at rest), {ctl.state}{errs}"

    def check_motion(self, record: Any) -> None:
        """Refuse a motion record while the arm brakes after a stop, or while a move of its
        own (arm to, arm xy) runs: the servo follows one source of knots at a time."""
        ctl = self.controller
        if ctl.state == "braking":
            raise CommandError("arm: braking to rest after a stop: wait, then move; "
                               "nothing queued")
        if ctl.evaluator is not None and not ctl.evaluator.idle:
            raise CommandError("arm: a move of the arm runs: wait, then queue the motion; "
                               "nothing queued")

    def stop(self) -> str:
        """The operator's stop: the move ended, queued moves dropped, the arm braked to rest
        at its acceleration limits and then switched off (idle: every motor off now)."""
        ctl = self.controller
        for ex in self.executors:
            ex.abort("stop command")
        self.motion.clear()
        if ctl.state == "idle":
            return super().stop()
        ctl.brake()
        return f"arm: stopping: braking to rest, then every motor off; {self.where()}"

    def close(self) -> None:
        """Every motor off (not braked: the loop stops), then pyrt's close."""
        runner = self.runner
        if runner is not None and runner.running:
            with contextlib.suppress(PyrtError):
                runner.call(self.reflex, "shutdown", take_fault=False, name="shutdown")
        super().close()


def build_arm(loop: Loop, *, boards: str | None = None,
              start: Sequence[float] | None = None,
              world_step_s: float = WORLD_STEP_S) -> ArmStation:
    """The arm on ``loop``, not yet started (call ``station.start()``).

    ``boards``: the board URL (default ``sim:``: the servo board in this
    process with the simulated arm behind it, starting at ``start`` degrees;
    ``tcp://HOST:PORT``: ``pyrt board-sim arm``, whose options set the arm).
    ``world_step_s`` is the simulated arm's longest internal integration step.
    ConfigError for bad settings; BoardError if the boards cannot be reached.
    """
    b = open_boards(boards, "arm", ARM_BOARDS)
    try:
        world = None
        if b.in_process:
            try:
                world = arm_world(b.simulated or b, DEFAULT_START_DEG if start is None else start,
                                  max_step_s=world_step_s)
            except ValueError as exc:
                raise ConfigError(str(exc)) from None
        elif start is not None:
            raise ConfigError(f"board URL {b.url!r}: the arm's start position is an option "
                              "of 'pyrt board-sim arm' (the world runs there)")
        return ArmStation(loop, b, world)
    except BaseException:
        b.close()
        raise


# -- the factory: pyrt arm ----------------------------------------------------------------------


def _start(text: str) -> tuple[float, float]:
    parts = text.split(",")
    try:
        q = tuple(float(p) for p in parts)
    except ValueError:
        q = ()
    if len(q) != 2 or not all(math.isfinite(v) for v in q):
        raise argparse.ArgumentTypeError(f"expected Q0,Q1 in degrees, got {text!r}")
    return q[0], q[1]


class ArmFactory(StationFactory):
    """pyrt arm: a two-joint planar arm (004's MRC II in miniature) on pyrt's public API.

Two DC motors with encoders behind one register-level servo board; a 1 kHz
servo task and a 100 Hz trajectory task on one ready queue.  Commands:
arm to Q0 Q1 (degrees), arm xy X Y [up|down] (mm), arm show; queued moves
blend.  wait says how a move ended, stop brakes the arm to rest, status
gives the joints and the tip.  A following error above 1 deg, a joint
beyond its limits or an amplifier without power trips the station: every
drive 0 and every amplifier disabled in the same tick; ack clears it.  The
simulated arm's truth and faults: sim show, sim fault jam|encoder|motor
q0|q1, sim fault none.

With --boards tcp://HOST:PORT the controller drives the servo board of a
'pyrt board-sim arm' in another process, at real time.
"""

    name = "arm"
    summary = "run a two-joint planar arm (servo board, 1 kHz servo, blended joint moves)"
    description = __doc__ or ""
    default_tick_us = 1000
    max_tick_us = 1000
    max_tick_why = "the servo task runs every tick and is tuned for 1 kHz"

    def board_kinds(self) -> dict[str, BoardKind]:
        return dict(ARM_BOARDS)

    def add_world_arguments(self, parser: argparse.ArgumentParser) -> None:
        g = parser.add_argument_group("simulation (sim: boards only; board-sim takes the same)")
        g.add_argument("--start", type=_start, metavar="Q0,Q1", default=None,
                       help="the simulated arm's joint angles at start, degrees "
                            f"(default {DEFAULT_START_DEG[0]:g},{DEFAULT_START_DEG[1]:g})")

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        self.add_world_arguments(parser)

    def world(self, boards: Boards, args: argparse.Namespace) -> World:
        start = getattr(args, "start", None)
        try:
            return arm_world(boards, DEFAULT_START_DEG if start is None else start)
        except ValueError as exc:
            raise ConfigError(str(exc)) from None

    def build(self, loop: Loop, args: argparse.Namespace) -> ArmStation:
        return build_arm(loop, boards=args.boards, start=args.start)


#: ``pyrt arm`` (the entry point ``pyrt_arm.station:ARM`` in ``pyrt.stations``).
ARM = ArmFactory()
