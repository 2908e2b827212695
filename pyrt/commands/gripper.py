"""The gripper's command grammar (its records are the controller's: see
:mod:`pyrt.robots.gripper_commands`); kept here for the console's users."""

from pyrt.robots.gripper_commands import parse_hex, parse_target

__all__ = ["parse_hex", "parse_target"]
