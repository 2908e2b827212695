"""Command interpreters of the robots.

The gripper's CMD: level and monitor, the manipulator's object commands.
"""

from pyrt.commands.gripper import GripperShell, parse_hex, parse_target
from pyrt.commands.shell import CommandShell

__all__ = ["CommandShell", "GripperShell", "parse_hex", "parse_target"]
