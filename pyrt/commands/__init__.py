"""Command interpreters: one :class:`RobotShell` for every station."""

from pyrt.commands.gripper import parse_hex, parse_target
from pyrt.commands.robot import RobotShell
from pyrt.commands.shell import CommandShell

__all__ = ["CommandShell", "RobotShell", "parse_hex", "parse_target"]
