"""Interactive consoles: line editing and history on a terminal, plain lines from a pipe."""

from pyrt.console.base import Console, Interpreter

__all__ = ["Console", "Interpreter"]
