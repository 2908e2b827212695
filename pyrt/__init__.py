"""pyrt: an embedded-style control runtime for Python.

A periodic timer ticks an 8031-style ready queue of self-scheduling tasks;
the numeric hot loops are C through cffi; Python handles commands, databases,
consoles and the network link.  See README.md and the ``pyrt`` command.
"""

from pyrt.errors import (
    CommandError,
    ConfigError,
    Fault,
    FaultError,
    MailboxTimeout,
    NativeError,
    PyrtError,
    PyrtInternalError,
    QueueFullError,
)

__version__ = "0.1.0"

__all__ = [
    "CommandError",
    "ConfigError",
    "Fault",
    "FaultError",
    "MailboxTimeout",
    "NativeError",
    "PyrtError",
    "PyrtInternalError",
    "QueueFullError",
    "__version__",
]
