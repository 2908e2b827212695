"""A station as the server serves it, derived from its records.

:class:`ServedStation` is the one :class:`~pyrt.server.robot.ServedRobot`:
its STATUS fields are the station's :meth:`status_fields` (signals of the
component tree plus the fault flag), its shell is a
:class:`~pyrt.commands.RobotShell`, and what an unprivileged client may
give is what the command records say (``reads_only``, or ``anyone`` for
the stop).  No second table of commands exists here.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, TextIO

from pyrt.commands.robot import RobotShell
from pyrt.errors import CommandError
from pyrt.scope import Source

__all__ = ["Limits", "PVField", "ServedStation", "StationState"]

INF = math.inf

#: The states of the ``state`` field (an enum PV).
StationState = ("idle", "moving", "fault")


@dataclass(frozen=True)
class Limits:
    """Display range and alarm limits of a value (an EPICS PV's HOPR/LOPR,
    HIHI/HIGH/LOW/LOLO).  An alarm limit at +-inf is off."""

    lopr: float
    hopr: float
    lolo: float = -INF
    low: float = -INF
    high: float = INF
    hihi: float = INF


@dataclass(frozen=True)
class PVField:
    """One value served beside the STATUS fields (a PV): read in the loop
    thread through ``source``; ``kind`` is ``text`` (a string), ``enum`` (one
    of ``states``, the value its index), or ``""`` (a number from the units
    and format, as a signal)."""

    name: str
    units: str
    fmt: str
    source: Source
    kind: str = ""
    states: tuple[str, ...] = ()
    limits: Limits | None = None
    doc: str = ""


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

    def make_shell(self, runner: Any, stdout: TextIO) -> RobotShell:
        return RobotShell(self.station, stdout, runner=runner)

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

    def stop_all(self) -> None:
        self.station.stop()

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
        pa = getattr(st, "polyaxis", None)
        if pa is not None:
            # Read-back of the running move's endpoint (NaN between moves);
            # a move is started only through CMD with the token.
            for k, c in enumerate("xyz"):
                fields.append(PVField(
                    f"target_{c}", "cm", ".2f",
                    Source.call(lambda k=k: _coord(pa.endpoint if pa.active else None, k)),
                    limits=self._limits(c, "cm"), doc=f"endpoint {c} of the move (NaN: none)"))
        for comp in st.components():
            for sig in comp.signals():
                name = f"{comp.name}:{sig.name}"
                if not _PV_NAME.match(comp.name) or not _PV_NAME.match(sig.name):
                    continue
                fields.append(PVField(name, sig.units, sig.fmt, sig.scope_source(),
                                      limits=self._limits(sig.name, sig.units, comp),
                                      doc=sig.doc))
        return fields

    def _state(self) -> int:
        st = self.station
        if st.fault is not None:
            return 2
        return 1 if st.busy() else 0

    def _stop_reason(self) -> str:
        return self.station.last_stop()

    def limits(self, name: str, units: str) -> Limits | None:
        """Display and alarm limits of the STATUS field ``name`` (None: none known)."""
        return self._limits(name, units)

    def _limits(self, name: str, units: str, comp: Any = None) -> Limits | None:
        """Limits from the station's database (the manipulator's tension
        limits, net-force limit, END_ERROR, vessel and rope geometry, motor
        speeds); None when the station gives none."""
        pa = getattr(self.station, "polyaxis", None)
        if pa is None:
            return None
        n = name.lower()
        if units == "N" and n.startswith("tension"):
            # LOLO/HIHI are the stops (LOW_TENSION 2 N, MAX_TENSION 200 N: a
            # MAJOR alarm); LOW/HIGH warn a little before them (1.5 x LOW_TENSION,
            # 90 % of MAX_TENSION: pyrt's choice, the documents give only the stops).
            lo, hi = pa.low_tension, pa.max_tension
            return Limits(0.0, hi, lolo=lo, low=1.5 * lo, high=0.9 * hi, hihi=hi)
        if units == "N" and n == "netforce":
            lim = pa.net_forcelimit  # NET_FORCELIMIT: the net-force stop (MAJOR); MINOR at 80 %
            return Limits(0.0, 2.0 * lim, high=0.8 * lim, hihi=lim)
        if units == "cm" and n == "disterr":
            # An estimate less consistent than END_ERROR cannot claim ENDPOINT: MINOR.
            return Limits(0.0, 4.0 * pa.end_error, high=pa.end_error)
        av = pa.av
        if units == "cm" and n in ("x", "y", "z"):
            k = "xyz".index(n)
            centre = av.vtog((0.0, 0.0, 0.0))
            top = max(av.neck_ring_position[k] + av.neck_length * av.neck_axis[k],
                      centre[k] + av.vessel_radius)
            return Limits(centre[k] - av.vessel_radius, top)
        if units == "cm" and n == "length":
            axis = self._axis_of(pa, comp)
            if axis is not None:
                # A rope reaches at most from its top pulley to the far side of the vessel.
                centre = av.vtog((0.0, 0.0, 0.0))
                return Limits(0.0, math.dist(axis.top, centre) + av.vessel_radius)
        if units == "cm/s":
            axis = self._axis_of(pa, comp)
            if axis is not None:
                v = axis.motor.cruise_speed  # CRUISE_SPEED of MOTOR.dat
                return Limits(-v, v)
        return None

    @staticmethod
    def _axis_of(pa: Any, comp: Any) -> Any:
        for axis in pa.axes:
            if comp is axis or comp in (axis.motor, axis.encoder, axis.loadcell):
                return axis
        return None


def _coord(point: Sequence[float] | None, k: int) -> float:
    return math.nan if point is None else float(point[k])


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
