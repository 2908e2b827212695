"""What the server needs of a robot, and the read-only view of the runner.

A robot plugs into the server through a :class:`ServedRobot`: its status
(the sources the loop reads, how a STATUS line shows them, the signals
behind them with their units and limits), the values served beside them,
a command shell per connection, the classification of its commands into
read-only and privileged, and the action that stops every motor.  Every
station is served through the one implementation,
:class:`pyrt.server.station.ServedStation`.

An unprivileged connection's shell gets an :class:`ObserverRunner` instead
of the runner: its mailbox calls leave a pending fault for the operator
(they neither consume nor acknowledge it), and it refuses everything that
would move time or the robot (waits, sleeps, jobs, motion records), a
second line of defence behind the command classification.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, Protocol, TextIO

from pyrt.errors import CommandError
from pyrt.scope import Source

__all__ = ["ObserverRunner", "ServedRobot", "Shell"]


class Shell(Protocol):
    """A console command interpreter (``pyrt.commands.CommandShell`` style)."""

    stdout: TextIO

    def onecmd(self, line: str) -> bool: ...

    def error(self, text: str) -> None: ...


class ServedRobot(Protocol):
    """A robot as the server sees it."""

    # Read-only to the server (properties here, so that a plain attribute of
    # a narrower type, a tuple or a list, serves).

    @property
    def name(self) -> str:
        """The robot's name (``gripper``, ``prototype``), shown in STATUS lines."""
        ...

    @property
    def status_names(self) -> Sequence[str]:
        """Names of the status fields, in the order of :meth:`status_sources`."""
        ...

    @property
    def fields(self) -> Sequence[tuple[str, Any, str]]:
        """The status fields ``(name, signal, format)``: units and limits for EPICS."""
        ...

    @property
    def extra_fields(self) -> Sequence[Any]:
        """Values served beside the status fields (EPICS PVs): ``PVField`` records."""
        ...

    @property
    def station(self) -> Any:
        """The station served (acknowledging its fault is its own act)."""
        ...

    def status_sources(self) -> list[Source]:
        """Where the loop reads each status field (sampled in the loop thread)."""
        ...

    def format_status(self, values: Sequence[Any]) -> str:
        """The ``key=value`` fields of a STATUS line for one sample."""
        ...

    def make_shell(self, runner: Any, stdout: TextIO, source: str = "remote") -> Shell:
        """A fresh command shell for one connection (``source`` names it in the
        audit trail), talking through ``runner``."""
        ...

    def table(self, runner: Any, prefix: str = "") -> list[str]:
        """``TABLE [PREFIX]``: the rows the console's ``show PREFIX`` lists, as data
        lines (one JSON object each), read through ``runner``; CommandError when
        the prefix matches nothing."""
        ...

    def is_read_only(self, line: str) -> bool:
        """True when ``line`` only reads (served without privilege)."""
        ...

    def is_stop(self, line: str) -> bool:
        """True when ``line`` is a stop (any client may give it, even in a reserved slot)."""
        ...

    def unknown(self, line: str) -> str | None:
        """Why ``line`` names no command of this robot, or None."""
        ...

    @property
    def stop_all(self) -> Callable[[], object]:
        """What stops every motor now: a call made in the loop thread (a method of
        the station itself, so that a journal records it as a request to the station)."""
        ...

    def audit(self, source: str, line: str) -> None:
        """A command that moves or changes the robot came from ``source``: shown on
        the operator's console and written to the audit log (any thread)."""
        ...

    def release(self, shell: Shell) -> None:
        """A privileged connection has ended: undo what only its session meant
        (leave a monitor level ...); called in a server thread."""
        ...


class ObserverRunner:
    """The runner as an unprivileged client may use it: reads only."""

    def __init__(self, runner: Any):
        self._runner = runner
        self.loop = runner.loop
        self.virtual = runner.virtual

    def call(
        self, fn: Callable[..., Any], *args: Any, timeout_s: float = 1.0, name: str = "",
        take_fault: bool = False,
    ) -> Any:
        """A mailbox call that leaves a pending fault for the operator (whatever
        ``take_fault`` asks: only the operator's session takes it)."""
        del take_fault
        return self._runner.call(fn, *args, timeout_s=timeout_s, name=name, take_fault=False)

    def statistics(self, timeout_s: float = 1.0) -> Any:
        """The loop's timing statistics, leaving a pending fault for the operator."""
        return self._runner.statistics(timeout_s, take_fault=False)

    def messages(self) -> list[str]:
        """The loop's asynchronous lines are the operator's: none here."""
        return []

    def take_fault(self, fault: Any) -> None:
        """A fault is the operator's to take: nothing here."""

    def take_faults(self) -> list[Any]:
        """Faults are the operator's to take: none here."""
        return []

    def poll(self, timeout_s: float = 1.0) -> None:
        """A no-op round trip that does not take the operator's fault."""
        self.call(lambda: None, timeout_s=timeout_s, name="poll")

    def _refuse(self, *args: Any, **kwargs: Any) -> Any:
        raise CommandError("denied: not a read-only command (AUTH first)")

    wait_until = sleep = spawn = run_job = submit_motion = _refuse
