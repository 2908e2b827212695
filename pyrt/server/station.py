"""A station as the server serves it, derived from its records.

:class:`ServedStation` is the one :class:`~pyrt.server.robot.ServedRobot`:
its STATUS fields are the station's :meth:`status_fields` (signals of the
component tree plus the fault flag), its shell is a
:class:`~pyrt.commands.RobotShell`, and what an unprivileged client may
give is what the command records say (``reads_only``, or ``anyone`` for
the stop).  No second table of commands exists here.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, TextIO

from pyrt.commands.robot import RobotShell
from pyrt.errors import CommandError
from pyrt.scope import Source

__all__ = ["ServedStation"]


class ServedStation:
    """The server's view of a :class:`~pyrt.station.base.Station`."""

    def __init__(self, station: Any):
        self.station = station
        self.name = station.name
        self.fields = station.status_fields()
        self.status_names = tuple(name for name, _sig, _fmt in self.fields)
        self._probe = RobotShell(station, _Null())

    @classmethod
    def from_station(cls, station: Any) -> ServedStation:
        """The same as ``ServedStation(station)``."""
        return cls(station)

    def status_sources(self) -> list[Source]:
        return [sig.scope_source() for _name, sig, _fmt in self.fields]

    def format_status(self, values: Sequence[Any]) -> str:
        return " ".join(f"{name}={_fmt(v, fmt)}"
                        for (name, _sig, fmt), v in zip(self.fields, values, strict=True))

    def make_shell(self, runner: Any, stdout: TextIO) -> RobotShell:
        return RobotShell(self.station, stdout, runner=runner)

    def is_read_only(self, line: str) -> bool:
        """True when ``line`` only reads, or any client may give it (the stop)."""
        if not line.strip():
            return True
        return self._probe.anyone(line)

    def is_stop(self, line: str) -> bool:
        """True when ``line`` is a stop: a command any client may give that
        does more than read (served even in a reserved slot)."""
        try:
            _comp, rec, words, _rest = self._probe.resolve(line)
        except CommandError:
            return False
        return rec.anyone and not rec.only_reads(words)

    def stop_all(self) -> None:
        self.station.stop()

    def release(self, shell: Any) -> None:
        """A privileged connection ended: leave a monitor level it entered."""
        if getattr(shell, "in_monitor", False):
            shell.onecmd("Q")


def _fmt(value: Any, fmt: str) -> str:
    if fmt == "0x04X":
        return f"0x{int(value):04X}"
    if fmt == "d":
        return str(int(value))
    return format(value, fmt)


class _Null:
    def write(self, text: str) -> int:
        return len(text)

    def flush(self) -> None:
        """Nothing is kept."""
