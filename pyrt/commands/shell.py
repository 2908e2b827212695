"""The base of pyrt's command interpreter: output and the one way a line fails.

All output goes through ``self.stdout``; the interpreter never reads input
itself, so the same object serves a terminal, a piped script, a test with
StringIO or a network connection.  :meth:`CommandShell.onecmd` runs one
line and returns True when the session should end; :meth:`guarded` turns
every failure into one line.  What a line means comes from the command
records (:class:`~pyrt.commands.robot.RobotShell`), not from method names.
"""

from __future__ import annotations

import sys
import traceback
from collections.abc import Callable
from typing import TextIO

from pyrt.errors import CommandError, FaultError, MailboxTimeout, PyrtError, PyrtInternalError
from pyrt.units import UnitError, parse_value

__all__ = ["MAX_SLEEP_S", "CommandShell", "parse_number", "parse_seconds"]

#: The longest wait or sleep a console accepts (one hour).
MAX_SLEEP_S = 3600.0


class CommandShell:
    """Output, errors and the guard around each line (see the module text)."""

    #: The prompt shown before each line.
    prompt = "> "

    def __init__(self, stdout: TextIO, stderr: TextIO | None = None):
        self.stdout = stdout
        #: Where the traceback of a bug in pyrt goes (None: ``sys.stderr`` at the time).
        self.stderr = stderr
        #: How many times a line failed (a refused command, a fault shown, a bug):
        #: a script's console reads it to fail loudly (docs/scripts.md).
        self.failures = 0

    # -- output -----------------------------------------------------------------

    def say(self, text: str = "") -> None:
        """Write ``text`` and a newline to the session's stdout."""
        self.stdout.write(text + "\n")

    def error(self, text: str) -> None:
        """Report a refused or malformed command: one line, nothing changed."""
        self.failures += 1
        self.say(f"error: {text}")

    def internal_error(self, exc: BaseException) -> None:
        """Report a bug in pyrt (not the operator's mistake): one line on the
        session's output, the traceback on its error stream."""
        self.say(f"internal error: {type(exc).__name__}: {exc} "
                 "(a bug in pyrt; please report it with this traceback)")
        err = self.stderr if self.stderr is not None else sys.stderr
        try:
            err.write("".join(traceback.format_exception(exc)))
            err.flush()
        except (OSError, ValueError):  # a closed error stream must not end the session
            pass

    # -- dispatch ---------------------------------------------------------------

    def fault(self, exc: FaultError) -> None:
        """Report a fault raised by the loop at this command (robots say more)."""
        self.failures += 1
        self.say(f"FAULT: {exc.fault.cause}; give 'ack' to acknowledge")

    def guarded(self, dispatch: Callable[[str], bool], line: str) -> bool:
        """Run ``dispatch(line)``, turning every failure into one line of
        output: a fault, a loop that did not answer, a refused command
        (``error: ...``), or a bug in pyrt (``internal error: ...`` with the
        traceback on the error stream; it must not end the operator's session)."""
        try:
            return bool(dispatch(line))
        except FaultError as exc:
            self.fault(exc)
        except MailboxTimeout as exc:
            self.error(f"the control loop did not answer: {exc}")
        except PyrtInternalError as exc:  # pyrt's own invariant broken: a bug too
            self.internal_error(exc)
        except PyrtError as exc:
            self.error(str(exc))
        except Exception as exc:
            self.internal_error(exc)
        return False

    def onecmd(self, line: str) -> bool:
        """Run one line; return True when the session should end (the robot's
        shell says how: :class:`~pyrt.commands.robot.RobotShell`)."""
        raise NotImplementedError


def parse_number(text: str, what: str) -> float:
    """A finite number in the one grammar of arguments (:func:`pyrt.units.parse_value`),
    or CommandError naming ``what``."""
    try:
        return parse_value(text)
    except UnitError:
        raise CommandError(f"{what} {text!r} is not a number") from None


def parse_seconds(text: str, what: str) -> float:
    """A time of 0..MAX_SLEEP_S seconds for ``wait``/``sleep``-like words."""
    value = parse_number(text.strip(), f"{what} time")
    if not 0 <= value <= MAX_SLEEP_S:
        raise CommandError(f"{what} time must be 0..{MAX_SLEEP_S:g} seconds")
    return value
