"""``pyrt urdf [FILE.urdf]``: any serial arm from its URDF, with no code of one's own.

The chain comes from the URDF (:meth:`pyrt.kinematics.Chain.from_urdf`); with
no file, the packaged PUMA 560 (:func:`pyrt.kinematics.puma.puma560`, with
Paul's closed form and RCCL's configuration names).  The boards are one
passive servo board (:func:`pyrt.boards.armservo.arm_servo_kind`: per joint
a DAC, an amplifier enable and an encoder counter, and the wrist
force/torque sensor); ``sim:`` puts the simulated arm behind it
(:mod:`pyrt.station._urdf_sim`: the chain's forward dynamics with gravity,
the URDF's damping and friction, torque limits from ``effort``, a DC motor
and an encoder per joint), ``tcp://HOST:PORT`` reaches the board that
``pyrt board-sim urdf [FILE.urdf]`` serves.

The component tree::

    NAME         the arm (the URDF's robot name): q1 .. qn, x y z rx ry rz;
                 NAME movej / moveto / movel / tool / coord / where
      JOINT ...  one per joint (the URDF's names): position, setpoint, error, torque, dac
    sim          the simulated arm's truth and its table (sim show, sim table)

Two rate groups, periods in time units whatever the tick (``--tick-us 500``
leaves them as they are): ``servo`` (1 kHz) and ``trajectory`` (100 Hz),
each with its task in a ready queue of the robot's name and its own overrun
accounting; see :mod:`pyrt.station._urdf_arm` for the control.  With ``--hardware a`` the
board is a motion-control board instead (:func:`pyrt.boards.armdrive.arm_drive_kind`,
board name ``drive``) that interpolates and servos on its own: the host has
only the ``trajectory`` group (:mod:`pyrt.station._urdf_drive`).  A following error
beyond 2 degrees or a joint beyond its limits trips the station: every
joint's DAC and enable are written 0 in that tick.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from pyrt.boards import Boards, open_boards
from pyrt.boards.armdrive import arm_drive_kind
from pyrt.boards.armservo import arm_servo_kind
from pyrt.boards.registers import BoardKind
from pyrt.component import Component
from pyrt.errors import ConfigError, PyrtError
from pyrt.kinematics import Chain
from pyrt.kinematics.puma import URDF as PUMA_URDF
from pyrt.kinematics.puma import PaulInverse
from pyrt.scheduler import Loop
from pyrt.sim.arm import (
    PUMA560_MOTORS,
    ArmWorld,
    DriveTuning,
    FTCalibration,
    Motor,
    default_motors,
)
from pyrt.sim.world import World
from pyrt.station._urdf_arm import (
    SERVO_PERIOD_NS,
    Drive,
    UrdfArm,
    snapshot_ready,
    snapshot_restored,
)
from pyrt.station._urdf_drive import DrivenArm
from pyrt.station._urdf_sim import UrdfPhysics, UrdfSim
from pyrt.station.base import BoardWorld, Station
from pyrt.station.factory import StationFactory
from pyrt.station.snapshot import restore_into, state_of

__all__ = ["HARDWARE", "PUMA_START_DEG", "URDF", "UrdfFactory", "UrdfStation", "arm_boards",
           "build_urdf", "load_arm"]

#: 004's two kinds of hardware, as ``--hardware`` names them: (a) a motion-control
#: board that takes setpoints at the trajectory rate and servos on the board, (b) a
#: passive servo board written at the servo rate.
HARDWARE = ("a", "b")

#: Where the simulated PUMA starts (deg): Corke's nominal pose, the wrist noflip.
PUMA_START_DEG = (0.0, 45.0, -180.0, 0.0, -45.0, 0.0)

#: The name the journal gives the URDF it keeps (pyrt replay rebuilds from it).
_JOURNAL_NAME = "arm.urdf"


def load_arm(path: str | Path | None) -> tuple[Chain, tuple[Motor, ...], str]:
    """The chain of the URDF at ``path`` (None: the packaged PUMA 560, with its
    closed form), its motors and the URDF's text; ConfigError naming the file."""
    source = Path(path) if path is not None else PUMA_URDF
    try:
        text = source.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"{source}: cannot read the URDF: {exc.strerror or exc}") from None
    chain = Chain.from_urdf(text)
    motors: tuple[Motor, ...] | None = None
    if chain.n == 6:
        with contextlib.suppress(ValueError):
            chain = chain.replace(closed_form=PaulInverse.for_chain(chain))
            if text == _packaged_puma():  # the packaged PUMA, wherever it was read from
                motors = PUMA560_MOTORS
    if motors is None:
        motors = default_motors(chain)
    return chain, motors, text


def _packaged_puma() -> str:
    global _PUMA_TEXT
    if _PUMA_TEXT is None:
        _PUMA_TEXT = PUMA_URDF.read_text(encoding="utf-8")
    return _PUMA_TEXT


_PUMA_TEXT: str | None = None


def _robot_name(chain: Chain) -> str:
    name = re.sub(r"[^A-Za-z0-9_-]", "_", chain.name).strip("_") or "arm"
    return name if name[0].isalpha() else f"arm_{name}"


def default_start(chain: Chain) -> np.ndarray:
    """Where a simulated arm starts (rad, m): the PUMA's nominal pose, or every
    joint at zero (brought inside its limits)."""
    if chain.closed_form is not None and chain.n == 6 and chain.name == "puma560":
        return np.radians(PUMA_START_DEG)
    lo = np.where(np.isfinite(chain.lower), chain.lower, -1e9)
    hi = np.where(np.isfinite(chain.upper), chain.upper, 1e9)
    return np.clip(np.zeros(chain.n), lo, hi)


def _drives(motors: Sequence[Motor]) -> tuple[Drive, ...]:
    return tuple(Drive(m.counts_per_joint_rev / (2.0 * math.pi), m.nm_per_count,
                       m.reflected_inertia) for m in motors)


def arm_boards(chain: Chain, hardware: str = "b") -> dict[str, BoardKind]:
    """The arm's board: ``servo`` (hardware (b), :func:`~pyrt.boards.armservo.arm_servo_kind`)
    or ``drive`` (hardware (a), :func:`~pyrt.boards.armdrive.arm_drive_kind`)."""
    if hardware not in HARDWARE:
        raise ConfigError(f"hardware: expected a or b, got {hardware!r}")
    if hardware == "a":
        return {"drive": arm_drive_kind(chain.n)}
    return {"servo": arm_servo_kind(chain.n)}


def _arm_board(boards: Boards) -> Any:
    return boards["drive"] if "drive" in boards else boards["servo"]


def arm_world(boards: Boards, chain: Chain, motors: Sequence[Motor],
              start: ArrayLike | None = None) -> World:
    """The simulated arm behind ``boards`` (in process; the board of either
    hardware, :func:`arm_boards`), starting at rest at ``start`` (rad, m;
    default :func:`default_start`)."""
    q0 = default_start(chain) if start is None else np.asarray(start, dtype=float)
    driven = "drive" in boards
    arm = ArmWorld(chain, motors=motors, board=_arm_board(boards), q0=q0,
                   drive=DriveTuning() if driven else None,
                   brake=[m.torque_limit for m in motors])  # a brake per joint
    return World("urdf", boards, UrdfPhysics(arm))


class UrdfStation(Station):
    """Everything ``pyrt urdf`` runs (see the module text), built by :func:`build_urdf`."""

    def __init__(self, loop: Loop, chain: Chain, motors: Sequence[Motor], boards: Boards,
                 world: World | None, urdf_text: str = "") -> None:
        super().__init__(loop)
        self.name = _robot_name(chain)
        self.chain = chain
        self.urdf_text = urdf_text
        self.attach_boards(boards)
        self.world = world
        self.board = _arm_board(boards)
        extras: list[Component] = []
        if world is not None:
            physics = world.plant
            assert isinstance(physics, UrdfPhysics)
            self.plant = physics.arm
            self.attach_world(physics.step_to, "physics")  # World.step: the same, a call more
            extras.append(UrdfSim(physics.arm))
        else:  # the world runs elsewhere: what its back end tells of it
            extras.append(BoardWorld(boards))
        ft = FTCalibration()  # the wrist sensor's data sheet: counts per N and per N m
        # hardware (a): the board servos, the host writes setpoints (pyrt.station._urdf_drive)
        arm_class = DrivenArm if self.board.kind.name == "arm-drive" else UrdfArm
        # the host's servo runs at its group's 1 kHz whatever the tick; (a) checks the tick
        period = loop.period_ns if arm_class is DrivenArm else SERVO_PERIOD_NS
        self.arm = arm = arm_class(self, self.name, chain, self.board, _drives(motors),
                                   period, wrench=ft.wrench)
        taken = {c.lower() for c in ("sim", *(j.name for j in arm.joints))}
        if self.name.lower() in taken:
            raise ConfigError(f"robot {self.name!r}: a joint of the URDF has the robot's name "
                              "(or 'sim'); the console names each once")
        #: The arm's rate groups (servo 1 kHz, trajectory 100 Hz; (a): trajectory alone).
        self.rate_groups = arm.rate_groups(self.name)
        for group in self.rate_groups:
            loop.attach(group)
        queues = [q for g in self.rate_groups for q in g.queues]
        self.adopt(arm, queues=queues, extras=extras, where=arm.where, ended=self._ended)

    # -- what the shell, the server and EPICS ask -----------------------------------------

    def busy(self) -> bool:
        """A move runs or the arm settles (the arm asked first: the move watch asks
        every tick, and while the arm moves its answer is the whole answer)."""
        return self.arm.busy() or super().busy()

    def _ended(self) -> tuple[str, list[str]]:
        """How the move that has just ended ended: the arm's words, or the fault."""
        if self.fault is not None:
            return f"fault: {self.fault.cause}", [f"FAULT: {self.fault.cause}; {self.where()}"]
        why = self.arm.last_stop or "ended"
        return why, [f"{why}: {self.where()}"]

    def stop(self) -> str:
        """The operator's stop: a move brakes along its path to rest and the servo
        holds the arm there (it carries its weight); idle, nothing changes."""
        said = self.arm.stop()
        if said:
            return f"{said}; {self.where()}"
        if self.arm.powered:
            return f"{self.name}: nothing moving; holding at {self.where()}"
        return super().stop()

    def snapshot_state(self) -> dict[str, Any]:
        """The controller (the arm: its servo's C state and board side, the
        motion under way in its evaluator, where it is, its joints), for a black
        box that replays (:mod:`pyrt.station.snapshot`); the chain is structure."""
        return state_of(self._snapshot_objects())

    def restore_state(self, state: dict[str, Any]) -> None:
        """Put :meth:`snapshot_state` back (the evaluator made first when the
        snapshot has one and the arm, not yet powered, has not)."""
        arm = self.arm
        snapshot_ready(arm, state.get("arm"))
        restore_into(self._snapshot_objects(), state)
        snapshot_restored(arm)

    def _snapshot_objects(self) -> dict[str, Any]:
        """The arm, and the moves' snapshots the loop took for commands being
        prepared in their callers' threads (a command's snapshot and its commit
        are two requests, a tick or more apart)."""
        return {"arm": self.arm, "prepared": self.__dict__.setdefault("_snapshots", {})}

    def journal_databases(self) -> dict[str, bytes]:
        """The URDF the arm was built from (a replay rebuilds the same arm)."""
        return {_JOURNAL_NAME: self.urdf_text.encode("utf-8")} if self.urdf_text else {}

    def close(self) -> None:
        """Every amplifier off (not braked: the loop stops), then pyrt's close."""
        runner = self.runner
        if runner is not None and runner.running:
            with contextlib.suppress(PyrtError):
                runner.call(self.reflex, "shutdown", take_fault=False, name="shutdown")
        super().close()


def build_urdf(loop: Loop, urdf: str | Path | None = None, *, boards: str | None = None,
               start: ArrayLike | None = None, hardware: str = "b") -> UrdfStation:
    """The arm of ``urdf`` (None: the packaged PUMA 560) on ``loop``, not yet
    started.  ``boards`` the board URL (default ``sim:``); ``start`` the
    simulated arm's joints (rad, m; in-process boards only); ``hardware``
    ``b`` (a passive servo board, the host's servo group at 1 kHz on a tick
    that divides 1 ms) or ``a`` (a motion-control board: the host writes setpoints at
    100 Hz, on a tick that divides 10 ms).  ConfigError for a bad file or
    setting; BoardError if the boards cannot be reached."""
    chain, motors, text = load_arm(urdf)
    kinds = arm_boards(chain, hardware)
    if hardware == "b" and SERVO_PERIOD_NS % loop.period_ns:
        raise ConfigError(f"a tick of {loop.period_ns / 1e3:g} µs: hardware b runs its servo "
                          "group at 1 kHz, on a tick that divides 1000 µs (1000, 500, 250 ...)")
    b = open_boards(boards, "urdf", kinds)
    try:
        world = None
        sim = b.simulated  # the world's side, when the world is in this process
        if sim is not None:
            world = arm_world(sim, chain, motors, start)
        elif start is not None:
            raise ConfigError(f"board URL {b.url!r}: the arm's start is an option of "
                              "'pyrt board-sim urdf' (the world runs there)")
        return UrdfStation(loop, chain, motors, b, world, text)
    except BaseException:
        b.close()
        raise


class UrdfFactory(StationFactory):
    """pyrt urdf [FILE.urdf]: any serial arm from its URDF (default: the PUMA 560).

Per joint a DC motor and an incremental encoder behind one passive servo
board; the simulated arm integrates the chain's forward dynamics with
gravity, the URDF's damping and friction, and torque limits from effort.
A 1 kHz servo (PID with gravity and dynamics feed-forward) and a 100 Hz
trajectory task.  Commands, on the arm named after the URDF's robot (NAME):
NAME movej Q1 .. Qn (degrees, mm for a prismatic joint), NAME moveto X Y Z
RX RY RZ [CONFIG] (mm, degrees: URDF rpy), NAME movel X Y Z RX RY RZ (a
straight line), NAME tool / coord (001's TOOL and COORD), NAME conveyor
VX VY VZ (COORD moving, mm/s: movel targets ride on it), NAME where;
queued moves blend.  OPTIONS: speed=F blend=MM force=N
buffer=aborting|buffered|blending, and on movel comply AXES N (a force
held along the tool's axes).  The servo's gains are parameters (get/set).
An unreachable pose or a target beyond a joint limit is refused, nothing
moves.  A following error above 2 degrees or a joint beyond its limits
stops every joint in the same tick; ack clears it.  The truth: sim show,
the signals sim.x sim.y sim.z.

With --boards tcp://HOST:PORT the controller drives the board of a
'pyrt board-sim urdf [FILE.urdf]' in another process, at real time.

--hardware a puts the arm behind a motion-control board instead (004's
hardware (a)): the host writes joint setpoints at 100 Hz and the board
interpolates and servos at 1 kHz; the host's tick may then be 10 ms
(--tick-us 10000).  board-sim takes --hardware too.
"""

    name = "urdf"
    summary = "run any serial arm from its URDF (default: the PUMA 560)"
    description = __doc__ or ""
    default_tick_us = 1000
    max_tick_us = 10000
    max_tick_why = "hardware (a) takes setpoints at 100 Hz; hardware (b) at most 1000 µs"

    @staticmethod
    def _hardware_of(text: str) -> str:
        """argparse's type of --hardware: a or b (checked; nothing kept: the options
        parsed say which, :meth:`board_kinds_of`)."""
        if text not in HARDWARE:
            raise argparse.ArgumentTypeError(f"expected a or b, got {text!r}")
        return text

    @staticmethod
    def _file(text: str) -> str:
        """argparse's type of FILE.urdf: read and checked now (a bad file is a usage
        error; nothing kept: the options parsed name it, :meth:`board_kinds_of`)."""
        try:
            load_arm(text)
        except ConfigError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
        return text

    def board_kinds(self) -> dict[str, BoardKind]:
        """The PUMA's board on hardware (b), the default (:meth:`board_kinds_of` for
        the options given)."""
        chain, _motors, _text = load_arm(None)
        return arm_boards(chain, "b")

    def board_kinds_of(self, args: argparse.Namespace) -> dict[str, BoardKind]:
        """The board of the URDF and the hardware the parsed options ``args`` name."""
        chain, _motors, _text = load_arm(getattr(args, "urdf", None))
        return arm_boards(chain, getattr(args, "hardware", "b") or "b")

    def add_world_arguments(self, parser: argparse.ArgumentParser) -> None:
        parser.add_argument("urdf", nargs="?", type=self._file, default=None,
                            metavar="FILE.urdf",
                            help="the arm's URDF (default: the packaged PUMA 560)")
        g = parser.add_argument_group("simulation (sim: boards only; board-sim takes the same)")
        g.add_argument("--start", type=_start, metavar="Q1,Q2,...", default=None,
                       help="the simulated arm's joints at start, degrees (mm for a prismatic "
                            "joint); default: the PUMA's nominal pose, or zero")
        parser.add_argument(
            "--hardware", type=self._hardware_of, default="b", metavar="a|b",
            help="the arm's board (004's hardware): b a passive servo board written at the "
                 "servo rate by the host's 1 kHz servo (default); a a motion-control board "
                 "that takes setpoints at 100 Hz and servos on the board (the host's tick "
                 "may then be --tick-us 10000)")

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        self.add_world_arguments(parser)

    def use_databases(self, args: argparse.Namespace, directory: str) -> None:
        """A replay: the URDF the journal kept."""
        path = Path(directory) / _JOURNAL_NAME
        if path.exists():
            args.urdf = str(path)

    def world(self, boards: Boards, args: argparse.Namespace) -> World:
        chain, motors, _text = load_arm(getattr(args, "urdf", None))
        return arm_world(boards, chain, motors, _start_of(chain, getattr(args, "start", None)))

    def build(self, loop: Loop, args: argparse.Namespace) -> UrdfStation:
        urdf = getattr(args, "urdf", None)
        start = getattr(args, "start", None)
        if start is not None:
            chain, _m, _t = load_arm(urdf)
            start = _start_of(chain, start)
        return build_urdf(loop, urdf, boards=args.boards, start=start,
                          hardware=getattr(args, "hardware", "b"))


def _start(text: str) -> tuple[float, ...]:
    try:
        q = tuple(float(p) for p in text.split(","))
    except ValueError:
        q = ()
    if not q or not all(math.isfinite(v) for v in q):
        raise argparse.ArgumentTypeError(f"expected Q1,Q2,... (degrees or mm), got {text!r}")
    return q


def _start_of(chain: Chain, start: Sequence[float] | None) -> np.ndarray | None:
    """``--start`` (operator units) in rad and m, checked against the chain."""
    if start is None:
        return None
    if len(start) != chain.n:
        raise ConfigError(f"--start: {chain.name} has {chain.n} joints, got {len(start)} values")
    k = np.array([1e-3 if j.kind == "prismatic" else math.pi / 180.0 for j in chain.joints])
    q = np.asarray(start, dtype=float) * k
    why = chain.limit_violation(q)
    if why:
        raise ConfigError(f"--start: {why}")
    return q


#: ``pyrt urdf`` (the entry point ``pyrt.station.urdf:URDF`` in ``pyrt.stations``).
URDF = UrdfFactory()
