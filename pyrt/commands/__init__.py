"""Command interpreters: one :class:`RobotShell` for every station."""

from pyrt.commands.gripper import parse_hex, parse_target
from pyrt.commands.robot import RobotShell
from pyrt.commands.scope import SCOPE_HELP
from pyrt.commands.shell import CommandShell

# The scope word's help is kept with its sub-commands (pyrt.commands.scope):
# ``help scope`` (the record's help, read from the handler) prints all of them.
RobotShell.do_scope.__doc__ = SCOPE_HELP

__all__ = ["CommandShell", "RobotShell", "parse_hex", "parse_target"]
