"""The gripper station: 8031, cage boards, simulated jaws, controller, motion
executor and scope on one loop, wired in the order a tick needs them.

The boards come from a back end chosen by URL (:func:`pyrt.boards.open_boards`):
``sim:`` (the default) puts the cage in this process with the simulated jaws
(:class:`~pyrt.sim.gripper.JawPlant`) behind it; ``tcp://HOST:PORT`` reaches
the cage of a ``pyrt board-sim gripper`` in another process, whose jaws move
at real time there (so the loop must run at real time, and the jaws'
settings are board-sim's options); ``modbus://HOST:PORT?map=builtin:gripper``
the same over Modbus TCP (``pyrt board-sim gripper --modbus``, or a real
I/O module with a map of its own: docs/hardware.md).

Per tick: the boards' inputs come into the process image (``io:read``, a
back end with a link: one exchange, raising the encoder interrupts that
arrived; a BoardError there faults the robot), or the jaws move (in-process
physics, dt = now - last); the clock interrupt walks the ready queue, the
stall watchdog looks, the motion executor starts or follows a queued ``P``
move, the scope samples, the mailbox is served, and the outputs the tick
changed are written (``io:write``).  A fault's reflex (the station's) nulls the
drive, ends the current motion and drops every queued one, in the same tick.

The component tree: ``gripper`` (the controller: RAM signals, ``CMD:``
letters) with its child ``monitor``; beside it ``sim``: the simulated jaws
in process (their true state, ``sim object|jog|fault``), or over tcp the
world's state as board-sim tells it (``sim`` shows it; nothing else).
"""

from __future__ import annotations

import argparse
import re
from collections.abc import Callable, Iterable
from typing import Any

from pyrt.boards import Boards, open_boards
from pyrt.boards.i8031 import COMMAND_CNT, ENCODER_CNT
from pyrt.boards.registers import BoardKind
from pyrt.component import Arg, Component, Signal, command, finite
from pyrt.errors import CommandError, ConfigError
from pyrt.robots.gripper import GripperController, JawCalibration
from pyrt.robots.gripper_commands import parse_hex
from pyrt.scheduler import Loop
from pyrt.scheduler.motion import MotionExecutor, MotionType
from pyrt.sim.gripper import FAULTS, JawParameters, JawPlant
from pyrt.sim.world import GRIPPER_BOARDS, GripperWorld, World, WorldFactory
from pyrt.station.base import BoardWorld, Station, refuse_sim_options
from pyrt.station.factory import StationFactory
from pyrt.station.profile import ShellProfile
from pyrt.station.snapshot import restore_into, state_of
from pyrt.tasks import register_tasks

__all__ = ["GRIPPER", "GripperFactory", "GripperSim", "GripperStation", "GripperWorlds",
           "build_gripper",
           "counts_type", "parse_counts"]

#: ``wait`` says "at target" within this many counts (the deadband and the
#: last bumps leave a few counts; the tests of 002's moves allow 16).
AT_TARGET_COUNTS = 16
#: Longest jog the ``sim jog`` word holds the switch for, seconds.
MAX_JOG_S = 3600.0


def _signed(word: int) -> int:
    return word - 0x10000 if word & 0x8000 else word


class GripperSim(Component):
    """The simulated jaws as a component: the world's truth and its settings."""

    name = "sim"

    def __init__(self, plant: JawPlant):
        self.plant = plant

    def signals(self) -> list[Signal]:
        p = self.plant
        return [
            Signal.attr("x", "counts", p, "x", "true jaw position"),
            Signal.attr("v", "counts/s", p, "v", "true jaw speed"),
            Signal.attr("squeeze", "force", p, "squeeze", "squeeze on the object"),
            Signal.attr("dac", "byte", p, "dac", "DAC byte the motor sees", fmt="02X"),
        ]

    def _apply(self, fn: Callable[..., Any], *args: Any) -> None:
        try:
            fn(*args)
        except ValueError as exc:
            raise CommandError(str(exc)) from None

    @command(name="show", reads_only=True)
    def show(self) -> str:
        """sim: the simulated world's state (where the jaws really are)."""
        return f"{self.plant.status()}; LEDs {self.plant.board.leds:04X}"

    @command(Arg("MM", lambda t: None if t.lower() == "none" else finite(
        "object width", 0.0, 1e4)(t)), name="object")
    def set_object(self, width: float | None) -> None:
        """sim object MM|none: put an object MM wide between the jaws (none: take it away)."""
        self._apply(self.plant.set_object, width)

    @command(Arg("DIR", str.lower, choices=("open", "close", "off")),
             Arg("S", finite("jog time", 0.0, MAX_JOG_S), optional=True), name="jog",
             moves=True, while_faulted=True)
    def jog(self, direction: str, seconds: float | None = None) -> None:
        """sim jog open|close|off [S]: hold the front-panel jog switch (S seconds).

        It moves the jaws (MVJAWS drives them while the switch is held); it
        is the world's hand on the switch, so 'sim jog off' is accepted
        while the robot is faulted."""
        dur = None if seconds is None else int(seconds * 1e9)
        self._apply(self.plant.jog, direction, dur)

    @command(Arg("NAME", str.lower, choices=("limit", "jam", "encoder", "port", "none")),
             Arg("PORT", str.upper, optional=True), Arg("XX", str, optional=True),
             name="fault")
    def fault(self, what: str, port: str | None = None, value: str | None = None) -> str:
        """sim fault limit|jam|encoder|none, or sim fault port 2D|2E XX: inject a fault.

        limit (sensor dead), jam (motor), encoder (dead), port (a sensor port
        stuck at XX), none (clear them all).  Says what it did."""
        if what == "none":
            if port is not None:
                raise CommandError("sim fault none takes no more arguments")
            self._apply(self.plant.clear_faults)
            return "every injected fault cleared"
        if what == "port":
            if port is None or value is None:
                raise CommandError("sim fault port 2D|2E XX")
            byte = parse_hex(value, "stuck port value", 0xFF)
            self._apply(self.plant.inject, "port", byte, port)
            return f"port {port} stuck at {byte:02X}"
        if port is not None:
            raise CommandError(f"sim fault {what} takes no more arguments")
        self._apply(self.plant.inject, what)
        return _INJECTED[what] + "; 'sim fault none' clears it"


#: What ``sim fault NAME`` did, in the operator's words.
_INJECTED = {"limit": "limit sensor dead (it never fires, even at the open stop)",
             "jam": "motor jammed (the jaws do not move, whatever the drive)",
             "encoder": "encoder dead (its count stays where it is)"}


class GripperStation(Station):
    """Everything ``pyrt gripper`` runs, built by :func:`build_gripper`.

    ``boards``: the gripper's (:func:`~pyrt.boards.open_boards`), owned and
    closed by the station; ``plant``: the jaws behind in-process boards, or
    None.  Boards whose world runs elsewhere refuse a loop that does not run
    at real time (ConfigError).
    """

    def __init__(self, loop: Loop, boards: Boards, plant: JawPlant | None):
        super().__init__(loop)
        self.attach_boards(boards)  # first in the tick: this tick's inputs
        self.board = boards["gripper"]
        self.cpu = cpu = self.board.cpu
        self.plant = plant
        cal = JawCalibration()
        if plant is not None:  # the simulated mechanism's own numbers
            p = plant.p
            cal = JawCalibration(p.closed, p.open_mm, p.gain, p.deadband)
        ctl = GripperController(cpu, calibration=cal)
        self.name = ctl.name
        self.controller = ctl
        if plant is not None:
            self.attach_world(plant.step, "jaws")
        ctl.attach(loop, register=False)
        register_tasks(ctl.queue, ctl)  # every task the tree declares
        ctl.motion = self.motion

        def motion_done(motion: MotionType) -> None:
            reason = motion.stop_reason or ""
            if reason.startswith("refused"):
                ctl.say(f"move {reason}", "warning")
                return
            if reason == "stop command":
                ctl.move_ended(reason)
            self.end_move(*self._outcome())

        def motion_error(cause: str, motion: MotionType) -> None:
            self.trip(cause, source="P move")

        self.executor = MotionExecutor(ctl, self.motion.get, motion_done, motion_error)
        loop.attach(self.executor.poll, name="motion")
        extras: list[Component] = []
        if plant is not None:
            extras.append(GripperSim(plant))
        else:  # the world runs elsewhere: what its back end tells of it
            extras.append(BoardWorld(boards))
        self.adopt(ctl, queues=[ctl.queue], executors=[self.executor], extras=extras,
                   where=self._where, ended=self._ended, status=self._status)
        self.profile = gripper_profile(ctl)
        ctl.power_up()

    # -- what the operator reads ----------------------------------------------------------

    def busy(self) -> bool:
        """A move, jog, init or calibration runs, or a move waits.  The move
        watch asks every tick: its one executor and motion queue are looked at
        here directly (what :meth:`Station.busy` would look at)."""
        ctl = self.controller
        job = ctl.job
        return (ctl.moving or (job is not None and not job.done) or len(self.motion) > 0
                or self.executor.current is not None)

    def _where(self) -> str:
        """Where the jaws are: position, opening, target, error."""
        ctl = self.controller
        pos, tgt = ctl.word(ENCODER_CNT), ctl.word(COMMAND_CNT)
        err = _signed(pos) - _signed(tgt)
        mm = ctl.calibration.mm
        return (f"position {pos:04X} ({mm(_signed(pos)):.1f} mm), target {tgt:04X} "
                f"({mm(_signed(tgt)):.1f} mm), error {err:+d}")

    def _ended(self) -> tuple[str, list[str]]:
        """The robot went idle: how the job (I, C, a jog) ended, unless a P move's
        end has said it already."""
        if self.moves_this_period:
            return "", []
        return self._outcome()

    def _outcome(self) -> tuple[str, list[str]]:
        """How the move ended: at target, stopped short (and why), or the fault."""
        ctl = self.controller
        err = _signed(ctl.word(ENCODER_CNT)) - _signed(ctl.word(COMMAND_CNT))
        if self.fault is not None:
            why = f"fault: {self.fault.cause}"
        elif abs(err) <= AT_TARGET_COUNTS:
            why = "at target"
        else:
            travel = _signed(ctl.word(COMMAND_CNT)) - ctl.move_from  # the move's direction
            side = "past" if err * travel > 0 else "short of"
            why = f"stopped {side} the target by {abs(err)} counts ({ctl.last_stop or 'ended'})"
        return why, [f"{why}: {self.where()}"]

    def _status(self) -> str:
        """One line: position, target, error, state, drive current."""
        ctl = self.controller
        job = ctl.job
        state = ("fault" if self.fault is not None else job.name if ctl.busy and job is not None
                 else "moving" if ctl.moving else "idle")
        return f"{self.where()}, {state}, drive {ctl.dac - 0x80:+d}"

    def stop(self) -> str:
        """The operator's stop, and where it left the jaws."""
        said = super().stop()
        self.controller.move_ended("stop command")
        return said

    def closing_note(self) -> str:
        """Where the jaws were left and the drive current, for the line said on the way out."""
        ctl = self.controller
        pos = ctl.word(ENCODER_CNT)
        return (f"; jaws at {pos:04X} ({ctl.calibration.mm(_signed(pos)):.1f} mm), "
                f"drive current {ctl.dac - 0x80:+d}")

    def status_fields(self) -> list[tuple[str, Signal, str]]:
        """STATUS: position, target, moving, busy, sensors, fault."""
        ctl = self.controller
        sig = {s.name: s for s in ctl.signals()}
        return [("position", sig["encoder"], "d"), ("target", sig["target"], "d"),
                ("moving", sig["moving"], "d"), ("busy", sig["busy"], "d"),
                ("sensors", sig["sensors"], "0x04X"), self.fault_field()]

    def shutdown(self) -> None:
        """Null the drive, stop the loop and close the timing log."""
        self.close()

    def snapshot_state(self) -> dict[str, Any]:
        """The controller (its RAM, supervision, monitor, encoder pulses) and the
        P move under way, for a black box that replays (:mod:`pyrt.station.snapshot`)."""
        return state_of(self._snapshot_objects())

    def restore_state(self, state: dict[str, Any]) -> None:
        """Put :meth:`snapshot_state` back."""
        restore_into(self._snapshot_objects(), state)

    def _snapshot_objects(self) -> dict[str, Any]:
        return {"gripper": self.controller, "executor": self.executor}


def gripper_profile(ctl: GripperController, power_up_init: bool = True) -> ShellProfile:
    """002's console: the ``CMD:`` letters and the monitor's (``* ``), the power-up
    ``I`` (drive the jaws wide open, zero the encoder; not with ``--no-init``)."""
    return ShellProfile(
        prompt="CMD: ", level=ctl, level_prompts={ctl.name: "CMD: ", ctl.monitor.name: "* "},
        startup_commands=("I",) if power_up_init else (), fault_prefix="fault",
        idle="nothing to wait for: jaws idle")


#: The jaws' start position when none is given, encoder counts.
DEFAULT_START = -0x0C00


def build_gripper(
    loop: Loop,
    *,
    boards: str | None = None,
    start: int | None = None,
    object_mm: float | None = None,
    faults: Iterable[str] = (),
) -> GripperStation:
    """Wire a gripper onto ``loop`` and power it up (not yet started: call
    ``station.start()``).

    ``boards``: the board URL (default ``sim:``, the cage in this process
    with simulated jaws behind it; ``tcp://HOST:PORT``: ``pyrt board-sim
    gripper``).  ``start``, ``object_mm`` and ``faults`` set up the
    in-process jaws; with boards whose world runs elsewhere they are
    refused, as is a loop not at real time.  Bad settings raise ConfigError;
    boards that cannot be reached, BoardError.
    """
    faults = list(faults)
    b = open_boards(boards, "gripper", GRIPPER_BOARDS)
    try:
        refuse_sim_options(b, [name for name, given in (
            ("the jaw start position (--start)", start is not None),
            ("an object (--object)", object_mm is not None),
            ("faults (--fault)", bool(faults))) if given])
        plant = None
        sim = b.simulated  # the world's side, when the world is in this process
        if sim is not None:
            try:
                plant = JawPlant(sim["gripper"], start=DEFAULT_START if start is None else start)
                plant.set_object(object_mm)
                for fault in faults:
                    plant.inject(fault)
            except ValueError as exc:
                raise ConfigError(str(exc)) from None
        return GripperStation(loop, b, plant)
    except BaseException:
        b.close()
        raise


# -- the factory: ``pyrt gripper`` ---------------------------------------------------------


def parse_counts(text: str) -> int:
    """A jaw position in encoder counts from wide open: hex, two's complement
    (F400) or negative (-0C00); ValueError naming the range if not."""
    t = text.strip()
    try:
        value = -int(t[1:], 16) if t.startswith("-") else int(t, 16)
    except ValueError:
        raise ValueError(f"expected hex encoder counts, got {text!r}") from None
    if value > 0x7FFF:
        value -= 0x10000
    if not -0x2A00 <= value <= 0:
        raise ValueError("start position must be 0000 (wide open) .. D600 (closed)")
    return value


def counts_type(text: str) -> int:
    try:
        return parse_counts(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def add_jaw_arguments(parser: argparse.ArgumentParser) -> None:
    """The simulated jaws' options (``sim:`` here, and ``pyrt board-sim gripper``)."""
    g = parser.add_argument_group("simulation (sim: boards only; board-sim takes the same options)")
    g.add_argument(
        "--object", type=float, metavar="MM",
        help=f"an object this wide between the jaws (0 < MM < {JawParameters().open_mm:g})",
    )
    g.add_argument(
        "--start", type=counts_type, metavar="HEX",
        help="jaw position at power-up, encoder counts from wide open, in hex as the "
             "console shows them (two's complement; a negative number is accepted too: "
             f"-0C00 is F400); default {DEFAULT_START & 0xFFFF:04X}",
    )
    g.add_argument(
        "--fault", action="append", choices=[f for f in FAULTS if f != "port"],
        help="inject a fault from the start: limit (sensor dead), jam (motor), encoder (dead)",
    )
    # "--start -0C00": argparse takes a word that starts with "-" for an
    # option unless it looks like a negative number; hexadecimal counts are
    # numbers here (no option of this command looks like one).
    parser._negative_number_matcher = re.compile(r"^-[0-9A-Fa-f]+$|^-\d*\.\d+$")


class GripperWorlds(WorldFactory):
    """The gripper's boards and world for ``pyrt board-sim gripper``: the cage
    (board ``gripper``) with the jaws behind it (:class:`GripperFactory` has them)."""

    name = "gripper"

    def board_kinds(self) -> dict[str, BoardKind]:
        return dict(GRIPPER_BOARDS)

    def add_world_arguments(self, parser: argparse.ArgumentParser) -> None:
        add_jaw_arguments(parser)

    def world(self, boards: Boards, args: argparse.Namespace) -> World:
        start = getattr(args, "start", None)
        return GripperWorld(boards=boards, object_mm=getattr(args, "object", None),
                            start=DEFAULT_START if start is None else start,
                            faults=getattr(args, "fault", None) or ())


class GripperFactory(GripperWorlds, StationFactory):
    """pyrt gripper: the 002 parallel-jaw gripper controller on simulated jaws.

At start the controller does what the 8031 does at power-up: it loads its
RAM variables, starts its three self-scheduling routines and runs I (drive
the jaws wide open, zero the encoder), then prompts CMD:.  The commands
are the report's (C E I M P S T W X; the monitor's C D I L N Q S),
hexadecimal, lower case accepted; type help.  Every P move is supervised
(settle and stall bounds from the distance, the speed and the schedule in
RAM; oscillation about the target): a move that fails them is a fault, the
drive nulled at once.  stop, Ctrl-C, SIGTERM and SIGHUP stop the jaws and
say where they are; wait says whether the move ended at the target, short
of it (and why) or in a fault.  Power-up scales 002's schedule values to
--tick-us.  Pipe a file in to run it as a script; with --speed max time
advances only while commands run, wait or sleep, so a script's output is
the same on every run.

With --boards tcp://HOST:PORT the controller drives the boards of a
'pyrt board-sim gripper' in another process (start it first; its first
line names the URL): the jaws move there at real time, so only --speed 1
is accepted and the simulation options are board-sim's.
"""

    name = "gripper"
    summary = ("run the 002 parallel-jaw gripper controller (CMD: and monitor) on simulated "
               "jaws (or on pyrt board-sim's, --boards tcp://...)")
    description = __doc__ or ""

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        add_jaw_arguments(parser)
        c = parser.add_argument_group("power-up")
        c.add_argument("--no-init", action="store_true", help="do not run I at power-up")

    def build(self, loop: Loop, args: argparse.Namespace) -> GripperStation:
        station = build_gripper(loop, boards=args.boards, start=args.start,
                                object_mm=args.object, faults=args.fault or ())
        station.profile = gripper_profile(station.controller, power_up_init=not args.no_init)
        return station

    def banner(self, station: Station, args: argparse.Namespace) -> str:
        speed = ("max (simulated time)" if args.speed is None
                 else f"{args.speed:g}x real time")
        boards = station.boards
        jaws = ("simulated jaws" if station.plant is not None or boards is None
                else f"boards at {boards.url}" + (f" ({boards.world})" if boards.world else ""))
        return (f"pyrt gripper: 002 parallel-jaw controller, {jaws}; tick {args.tick_us} µs, "
                f"speed {speed}; {self.next_step(args)}")


#: ``pyrt gripper`` (registered in the entry-point group ``pyrt.stations``).
GRIPPER = GripperFactory()
