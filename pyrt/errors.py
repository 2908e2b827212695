"""The exceptions pyrt raises, and the rule for raising them.

One root, :class:`PyrtError`, which is never raised itself; a handful of
subclasses that say what kind of thing went wrong; and
:class:`PyrtInternalError` for the case where pyrt itself is at fault.
Messages say what was wrong and what was expected.

The rule (one translation, at the boundary):

* **Pure functions** (parsers of a value, unit conversion, the rope model,
  formulas) know nothing of commands or files.  Bad input is a
  ``ValueError`` (:class:`pyrt.units.UnitError` is one); a question whose
  answer "no" is ordinary (may the source be here? may this target be
  reached?) returns the reason as a string, or None.
* **The command boundary** translates once: the argument grammar of the
  command records (:class:`pyrt.component.Arg`, ``finite``; the one number
  grammar, :func:`pyrt.units.parse_value`) turns a ``ValueError`` into a
  :class:`CommandError` naming the command and the argument; a handler that
  refuses raises :class:`CommandError` itself, with the pure function's
  reason, and says that nothing changed.
* **Configuration** (a database, a constructor's settings) is a
  :class:`ConfigError` naming the file and line where there is one; a
  constructor turns a kernel's :class:`NativeError` about its settings into
  one.
* **C kernels** raise :class:`NativeError`; a running robot's trouble is
  never raised at the operator: it is a fault, reported through
  :meth:`pyrt.component.Component.fail` (:class:`FaultError` at the
  application's next call).
* An exception that is none of these reaching the operator is a bug
  (:class:`PyrtInternalError` when pyrt notices it itself).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

__all__ = [
    "BoardError",
    "CommandError",
    "ConfigError",
    "DiskError",
    "Fault",
    "FaultError",
    "MailboxTimeout",
    "NativeError",
    "PyrtError",
    "PyrtInternalError",
    "QueueFullError",
    "UsageError",
]


class PyrtError(Exception):
    """Root of every exception pyrt raises on purpose.  Never raised itself."""


class ConfigError(PyrtError):
    """A configuration or database file is wrong; names the file and line.

    ``str(err)`` reads ``FILE:LINE: message`` (or ``FILE: message`` when the
    line is unknown) so an editor can jump to the place.
    """

    def __init__(self, message: str, file: str | None = None, line: int | None = None):
        self.message = message
        self.file = file
        self.line = line
        super().__init__(self._format())

    def _format(self) -> str:
        if self.file is None:
            return self.message
        if self.line is None:
            return f"{self.file}: {self.message}"
        return f"{self.file}:{self.line}: {self.message}"


class UsageError(ConfigError):
    """A command line that cannot be used: an option's value out of its range,
    an option that needs another, a name that is no choice.  Found before
    anything runs; the ``pyrt`` program ends it as argparse ends its own
    (``pyrt CMD: error: ...``, exit status 2), where a run that fails is 1."""


class DiskError(PyrtError):
    """A file pyrt writes could not be written (the disk is full, a write or
    an fsync failed).  A running robot's write error is a fault like any other;
    ``path`` is the file (or None), ``errno`` the system's error number (or None).
    """

    def __init__(self, message: str, path: str | None = None, errno: int | None = None):
        self.message = message
        self.path = path
        self.errno = errno
        super().__init__(message)


class BoardError(PyrtError):
    """A board back end could not carry out a register access (connection
    refused, reset or timed out; the board refused the request).

    ``str(err)`` reads ``board URL: what happened`` so that the robot can be
    faulted with it; ``url`` is the back end's URL.
    """

    def __init__(self, url: str, message: str):
        self.url = url
        self.message = message
        super().__init__(f"board {url}: {message}")


class CommandError(PyrtError):
    """A command was malformed or refused; nothing was changed."""


class QueueFullError(PyrtError):
    """A bounded queue (the ready queue, the motion queue) had no free slot."""


class MailboxTimeout(PyrtError):
    """The control loop did not take a mailbox command within its timeout."""


class NativeError(PyrtError):
    """A C kernel refused its input or could not produce an answer."""


@dataclass(frozen=True)
class Fault:
    """What the control loop recorded when it stopped a robot.

    ``time_ns`` is the loop clock's time, ``tick`` the tick index, ``source``
    the task or check that failed, ``cause`` one line saying why, and
    ``traceback`` the formatted traceback when an exception was the cause.
    """

    robot: str
    cause: str
    source: str = ""
    tick: int = -1
    time_ns: int = 0
    traceback: str = ""
    details: dict[str, Any] = field(default_factory=dict, compare=False)
    #: The fault event's number on its loop (1, 2, ...; 0: not published):
    #: everything that shows faults shows each id once.
    id: int = 0

    def __str__(self) -> str:
        where = f" in {self.source}" if self.source else ""
        when = f"tick {self.tick} ({self.time_ns / 1e9:.6f} s)"
        return f"{self.robot}: fault{where} at {when}: {self.cause}"


class FaultError(PyrtError):
    """A robot was stopped by its control loop; carries the :class:`Fault`.

    Raised to the application at its next call into the loop, exactly once
    per fault.  The robot refuses motion until the fault is acknowledged.
    """

    def __init__(self, fault: Fault):
        self.fault = fault
        super().__init__(str(fault))


class PyrtInternalError(PyrtError):
    """pyrt broke one of its own invariants: this is a bug, please report it."""
