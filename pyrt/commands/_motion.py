"""The ``motion`` word of both consoles: any registered motion type by name.

``motion TYPE [key=value ...]`` puts ``MotionRecord(TYPE, {key: value})`` on
the robot's motion queue (values are numbers where they parse as numbers,
else words); ``motion`` alone lists the station's types (those that drive
its robot, built-in and plug-in: :meth:`pyrt.station.base.Station.motion_types`).
"""

from __future__ import annotations

import inspect
import math
from collections.abc import Mapping

from pyrt.errors import CommandError
from pyrt.scheduler.motion import MotionRecord, MotionType

__all__ = ["motion_type_lines", "parse_motion", "parse_value"]


def parse_value(text: str) -> int | float | str:
    """An int if ``text`` is one, else a finite float, else the word itself."""
    try:
        return int(text)
    except ValueError:
        pass
    try:
        v = float(text)
    except ValueError:
        return text
    return v if math.isfinite(v) else text


def parse_motion(arg: str) -> MotionRecord | None:
    """``TYPE [key=value ...]`` as a record (None for an empty line);
    CommandError for a malformed name or parameter (whether the station
    runs the type is the station's to say)."""
    words = arg.split()
    if not words:
        return None
    name, rest = words[0], words[1:]
    if not name.isidentifier():
        raise CommandError(f"motion: {name!r} is not a motion type name; 'motion' lists them")
    params: dict[str, int | float | str] = {}
    for w in rest:
        key, eq, value = w.partition("=")
        if not eq or not key.isidentifier() or not value:
            raise CommandError(f"motion {name}: expected key=value, got {w!r}")
        if key in params:
            raise CommandError(f"motion {name}: {key} given twice")
        params[key] = parse_value(value)
    return MotionRecord(name.lower(), params)


def motion_type_lines(types: Mapping[str, type[MotionType]]) -> list[str]:
    """One line per motion type of ``types``: its name and the first line of its help
    (``  none`` when there is none)."""
    lines = []
    for name, cls in types.items():
        doc = inspect.getdoc(cls) or ""
        lines.append(f"  {name:<16} {_plain(doc.splitlines()[0]) if doc else ''}")
    return lines or ["  none"]


def _plain(text: str) -> str:
    """reST inline literals as the console shows them (no double backticks)."""
    return text.replace("``", "")
