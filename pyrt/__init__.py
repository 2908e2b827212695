"""pyrt: an embedded-style control runtime for Python.

A periodic timer ticks an 8031-style ready queue of self-scheduling tasks;
the numeric hot loops are C through cffi; Python handles commands, databases,
consoles and the network link.  See README.md and the ``pyrt`` command.

The public API for a station of one's own is importable from here (see
docs/writing-a-robot.md)::

    from pyrt import Arg, Component, Signal, Station, StationFactory, Task, command

Names are imported when first used, so ``import pyrt`` stays cheap.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from pyrt._version import __version__
from pyrt.errors import (
    BoardError,
    CommandError,
    ConfigError,
    Fault,
    FaultError,
    MailboxTimeout,
    NativeError,
    PyrtError,
    PyrtInternalError,
    QueueFullError,
    UsageError,
)

if TYPE_CHECKING:
    from pyrt.boards import INPUT, OUTPUT, BoardKind, Boards, Register, RegisterBoard, open_boards
    from pyrt.cli._station import run_station
    from pyrt.component import (
        Arg,
        Command,
        Component,
        Limits,
        Message,
        Signal,
        Switch,
        command,
        finite,
        word,
    )
    from pyrt.robots.trajectory import JointRobot, JointTrajectory, RangedJointRobot
    from pyrt.scheduler import (
        Job,
        Loop,
        RateGroup,
        ReadyQueue,
        SimClock,
        Task,
        WallClock,
        install,
    )
    from pyrt.scheduler.motion import MotionExecutor, MotionRecord, MotionType
    from pyrt.scope import Source
    from pyrt.scope.joints import JointStates
    from pyrt.sim.world import World, WorldFactory
    from pyrt.station.base import BoardWorld, Station
    from pyrt.station.factory import StationFactory
    from pyrt.station.moves import MoveEnded
    from pyrt.station.profile import ShellProfile

#: Public name -> the module that defines it (imported on first use).
_LAZY = {
    "Arg": "pyrt.component",
    "BoardKind": "pyrt.boards",
    "BoardWorld": "pyrt.station.base",
    "Boards": "pyrt.boards",
    "Command": "pyrt.component",
    "Component": "pyrt.component",
    "INPUT": "pyrt.boards",
    "Job": "pyrt.scheduler",
    "JointRobot": "pyrt.robots.trajectory",
    "JointStates": "pyrt.scope.joints",
    "JointTrajectory": "pyrt.robots.trajectory",
    "Limits": "pyrt.component",
    "Loop": "pyrt.scheduler",
    "Message": "pyrt.component",
    "MotionExecutor": "pyrt.scheduler.motion",
    "MotionRecord": "pyrt.scheduler.motion",
    "MotionType": "pyrt.scheduler.motion",
    "MoveEnded": "pyrt.station.moves",
    "OUTPUT": "pyrt.boards",
    "RangedJointRobot": "pyrt.robots.trajectory",
    "RateGroup": "pyrt.scheduler",
    "ReadyQueue": "pyrt.scheduler",
    "Register": "pyrt.boards",
    "RegisterBoard": "pyrt.boards",
    "ShellProfile": "pyrt.station.profile",
    "Signal": "pyrt.component",
    "SimClock": "pyrt.scheduler",
    "Source": "pyrt.scope",
    "Station": "pyrt.station.base",
    "StationFactory": "pyrt.station.factory",
    "Switch": "pyrt.component",
    "Task": "pyrt.scheduler",
    "WallClock": "pyrt.scheduler",
    "World": "pyrt.sim.world",
    "WorldFactory": "pyrt.sim.world",
    "command": "pyrt.component",
    "finite": "pyrt.component",
    "install": "pyrt.scheduler",
    "open_boards": "pyrt.boards",
    "run_station": "pyrt.cli._station",
    "word": "pyrt.component",
}


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'pyrt' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))


__all__ = [
    "INPUT",
    "OUTPUT",
    "Arg",
    "BoardError",
    "BoardKind",
    "BoardWorld",
    "Boards",
    "Command",
    "CommandError",
    "Component",
    "ConfigError",
    "Fault",
    "FaultError",
    "Job",
    "JointRobot",
    "JointStates",
    "JointTrajectory",
    "Limits",
    "Loop",
    "MailboxTimeout",
    "Message",
    "MotionExecutor",
    "MotionRecord",
    "MotionType",
    "MoveEnded",
    "NativeError",
    "PyrtError",
    "PyrtInternalError",
    "QueueFullError",
    "RangedJointRobot",
    "RateGroup",
    "ReadyQueue",
    "Register",
    "RegisterBoard",
    "ShellProfile",
    "Signal",
    "SimClock",
    "Source",
    "Station",
    "StationFactory",
    "Switch",
    "Task",
    "UsageError",
    "WallClock",
    "World",
    "WorldFactory",
    "__version__",
    "command",
    "finite",
    "install",
    "open_boards",
    "run_station",
    "word",
]
