"""A station as the server serves it, derived from its records.

:class:`ServedStation` is the one :class:`~pyrt.server.robot.ServedRobot`:
its STATUS fields are the station's :meth:`status_fields` (signals of the
component tree plus the fault flag), its shell is a
:class:`~pyrt.commands.RobotShell`, and what an unprivileged client may
give is what the command records say (``reads_only``, or ``anyone`` for
the stop).  No second table of commands exists here.
"""

from __future__ import annotations

import functools
import io
import logging
import logging.handlers
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

from pyrt.commands.robot import RobotShell
from pyrt.commands.show import data_lines, read_table, require_rows
from pyrt.component import Limits, Signal
from pyrt.errors import CommandError
from pyrt.scope import Source

__all__ = ["Limits", "PVField", "ServedStation", "StationState"]  # Limits: pyrt.component's

#: The states of the ``state`` field (an enum PV).
StationState = ("idle", "moving", "fault")


@dataclass(frozen=True)
class PVField:
    """One value served beside the STATUS fields (a PV): read in the loop
    thread through ``source``; ``kind`` is ``text`` (a string: at most
    ``length`` characters, 0 unbounded), ``enum`` (one of ``states``, the
    value its index), or ``""`` (a number from the units and format, as a
    signal)."""

    name: str
    units: str
    fmt: str
    source: Source
    kind: str = ""
    states: tuple[str, ...] = ()
    limits: Limits | None = None
    doc: str = ""
    length: int = 0

    @classmethod
    def of_signal(cls, name: str, sig: Signal) -> PVField:
        """The PV field of signal ``sig`` (a text signal: a string)."""
        if sig.is_text:
            return cls(name, sig.units, sig.fmt, Source.call(sig.read), "text", doc=sig.doc,
                       length=sig.length)
        return cls(name, sig.units, sig.fmt, sig.scope_source(), limits=sig.limits,
                   doc=sig.doc)


_PV_NAME = re.compile(r"^[A-Za-z0-9_]+$")


class ServedStation:
    """The server's view of a :class:`~pyrt.station.base.Station`."""

    def __init__(self, station: Any):
        self.station = station
        self.name = station.name
        self.fields = station.status_fields()
        self.status_names = tuple(name for name, _sig, _fmt in self.fields)
        self._probe = RobotShell(station, _Null())
        #: Every component's signals and the station's state, stop reason and
        #: target, for EPICS (sampled only while somebody serves them).
        self.extra_fields: list[PVField] = self._extra_fields()

    @classmethod
    def from_station(cls, station: Any) -> ServedStation:
        """The same as ``ServedStation(station)``."""
        return cls(station)

    def status_sources(self) -> list[Source]:
        return [sig.scope_source() for _name, sig, _fmt in self.fields]

    def format_status(self, values: Sequence[Any]) -> str:
        return " ".join(f"{name}={_fmt(v, fmt)}"
                        for (name, _sig, fmt), v in zip(self.fields, values, strict=True))

    def make_shell(self, runner: Any, stdout: TextIO, source: str = "remote") -> RobotShell:
        return RobotShell(self.station, stdout, runner=runner, source=source, audit=self.audit)

    def table(self, runner: Any, prefix: str = "") -> list[str]:
        """The rows ``show PREFIX`` lists, as data (``TABLE``: one JSON object a row,
        then one for the table), read through ``runner`` in one mailbox call;
        CommandError when the prefix matches nothing, as ``show`` says it."""
        table = read_table(self.station, prefix, runner=runner)
        return data_lines(require_rows(table))

    # -- the audit trail ------------------------------------------------------------------

    #: Largest size of the audit log before it is rotated, bytes; rotated copies kept.
    audit_max_bytes: int = 1_000_000
    audit_backups: int = 3
    _audit_logger: logging.Logger | None = None

    def audit(self, source: str, line: str) -> None:
        """A command that moves or changes the robot came from ``source`` (a
        DAQ client, EPICS CMD or STOP; any thread): a message of the station
        for the operator's console (``remote: SOURCE: LINE``) and a timestamped
        line in the audit log when one is open (:meth:`open_audit_log`)."""
        text = f"{source}: {line.strip()[:200]}"
        self.station.say(f"remote: {text}")
        logger = self._audit_logger
        if logger is not None:
            logger.info("%s", text)

    def audit_log_path(self) -> Path:
        """Where the audit log goes: beside the station's files (``audit.log`` in
        its :attr:`~pyrt.station.base.Station.directory`), else the working
        directory (``pyrt-NAME-audit.log``)."""
        directory = self.station.directory
        if directory is not None:
            return Path(directory) / "audit.log"
        return Path.cwd() / f"pyrt-{self.name}-audit.log"

    def open_audit_log(self, path: str | Path | None = None) -> Path:
        """Write the audit trail to ``path`` (default :meth:`audit_log_path`), rotated
        by size (:attr:`audit_max_bytes`, :attr:`audit_backups` copies); the path."""
        self.close_audit_log()
        where = Path(path) if path is not None else self.audit_log_path()
        handler = logging.handlers.RotatingFileHandler(
            where, maxBytes=self.audit_max_bytes, backupCount=self.audit_backups,
            encoding="utf-8", delay=True)  # the file appears with the first line
        handler.setFormatter(logging.Formatter("%(asctime)s %(message)s"))
        logger = logging.Logger(f"pyrt.audit.{self.name}")  # its own, not the root's tree
        logger.addHandler(handler)
        self._audit_logger = logger
        return where

    def close_audit_log(self) -> None:
        """Close the audit log, if one is open."""
        logger = self._audit_logger
        if logger is None:
            return
        self._audit_logger = None
        for h in list(logger.handlers):
            logger.removeHandler(h)
            h.close()

    def is_read_only(self, line: str) -> bool:
        """True when ``line`` only reads, or any client may give it (the stop)."""
        if not line.strip():
            return True
        return self._probe.anyone(line)

    def unknown(self, line: str) -> str | None:
        """Why ``line`` names no command of this robot (the console's words), or None."""
        try:
            self._probe.resolve(line)
        except CommandError as exc:
            return str(exc)
        return None

    def is_stop(self, line: str) -> bool:
        """True when ``line`` is a stop: a command any client may give that
        does more than read (served even in a reserved slot)."""
        try:
            _comp, rec, words, _rest = self._probe.resolve(line)
        except CommandError:
            return False
        return rec.anyone and not rec.only_reads(words)

    @property
    def stop_all(self) -> Callable[[], object]:
        """Stop every motor (called in the loop thread): the station's own ``stop``, so
        that a journal records the request as the station's, and a replay applies it."""
        return self.station.stop

    def release(self, shell: Any) -> None:
        """A privileged connection ended: leave a monitor level it entered."""
        if getattr(shell, "in_monitor", False):
            shell.onecmd("Q")


    # -- what EPICS serves beyond the STATUS fields -----------------------------------------

    def _extra_fields(self) -> list[PVField]:
        st = self.station
        fields = [
            PVField("state", "", "d", Source.call(self._state), "enum", StationState,
                    doc="idle, moving (a move runs or waits) or fault (until ack)"),
            PVField("stopReason", "", "s", Source.call(self._stop_reason), "text",
                    doc="how the last move ended"),
        ]
        robots = list(getattr(st, "robots", ()))
        if len(robots) > 1:  # a station of several robots: each robot's own state
            for robot in robots:
                if _PV_NAME.match(robot.name):
                    fields.append(PVField(
                        f"{robot.name}:state", "", "d",
                        Source.call(functools.partial(self._robot_state, robot)), "enum",
                        StationState,
                        doc=f"{robot.name}: idle, moving or fault (until ack {robot.name})"))
                    fields.append(PVField(
                        f"{robot.name}:fault_msg", "", "s",
                        Source.call(functools.partial(self._robot_fault, robot)), "text",
                        doc=f"{robot.name}: its fault, whole (empty: none)"))
        for sig in st.served_signals():
            fields.append(PVField.of_signal(sig.name, sig))
        for comp in st.components():  # a robot's root with the robot's text signals
            prefix = self.signal_prefix(comp)
            for sig in st.signals_of(comp):
                name = f"{prefix}{sig.name}"
                if not _PV_NAME.match(comp.name) or not _PV_NAME.match(sig.name):
                    continue
                fields.append(PVField.of_signal(name, sig))
        return fields

    def _state(self) -> int:
        st = self.station
        if st.fault is not None:
            return 2
        return 1 if st.busy() else 0

    def signal_prefix(self, comp: Any) -> str:
        """What ``comp``'s signals are served under: ``COMPONENT:``; in a station of
        several robots, a robot's component under the robot's prefix
        (``ROBOT:COMPONENT:``, its root ``ROBOT:``)."""
        st = self.station
        robot = st.robot_of(comp) if len(getattr(st, "robots", ())) > 1 else None
        if robot is None or not _PV_NAME.match(robot.name) \
                or comp.name.lower() == robot.name.lower():
            return f"{comp.name}:"
        return f"{robot.name}:{comp.name}:"

    @staticmethod
    def _robot_fault(robot: Any) -> str:
        return str(robot.fault.cause) if robot.fault is not None else ""

    @staticmethod
    def _robot_state(robot: Any) -> int:
        if robot.fault is not None:
            return 2
        return 1 if robot.busy() else 0

    def _stop_reason(self) -> str:
        return self.station.last_stop()  # the last move-ended event: any robot's last_stop


def _fmt(value: Any, fmt: str) -> str:
    if fmt == "0x04X":
        return f"0x{int(value):04X}"
    if fmt == "d":
        return str(int(value))
    return format(value, fmt)


class _Null(io.StringIO):
    """A text stream that keeps nothing written to it."""

    def write(self, text: str) -> int:
        return len(text)

    def flush(self) -> None:
        """Nothing is kept."""
