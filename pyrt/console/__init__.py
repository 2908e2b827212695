"""Interactive consoles: line editing and history on a terminal, plain lines from a pipe."""

from pyrt.console.base import Console, Interpreter, ReaderGone, silence

__all__ = ["Console", "Interpreter", "ReaderGone", "silence"]
