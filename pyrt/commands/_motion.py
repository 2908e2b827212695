"""The ``motion`` word of both consoles: any registered motion type by name.

``motion TYPE [key=value ...]`` puts ``MotionRecord(TYPE, {key: value})`` on
the robot's motion queue (values are numbers where they parse as numbers,
else words); ``motion`` alone lists the registered types, built-in and
plug-in (the entry-point group ``pyrt.motion_types``).
"""

from __future__ import annotations

import inspect
import math

from pyrt.errors import CommandError
from pyrt.scheduler.motion import MotionRecord, get_motion_type, motion_type_names

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
    CommandError for an unknown type or a malformed parameter."""
    words = arg.split()
    if not words:
        return None
    name, rest = words[0], words[1:]
    if not name.isidentifier():
        raise CommandError(f"motion: {name!r} is not a motion type name; 'motion' lists them")
    get_motion_type(name)  # unknown: CommandError naming the known ones
    params: dict[str, int | float | str] = {}
    for w in rest:
        key, eq, value = w.partition("=")
        if not eq or not key.isidentifier() or not value:
            raise CommandError(f"motion {name}: expected key=value, got {w!r}")
        if key in params:
            raise CommandError(f"motion {name}: {key} given twice")
        params[key] = parse_value(value)
    return MotionRecord(name.lower(), params)


def motion_type_lines(names: list[str] | None = None) -> list[str]:
    """One line per registered motion type (or per one of ``names``): its
    name and the first line of its help."""
    lines = []
    for name in motion_type_names() if names is None else names:
        try:
            doc = inspect.getdoc(get_motion_type(name)) or ""
        except CommandError as exc:
            doc = str(exc)
        lines.append(f"  {name:<16} {doc.splitlines()[0] if doc else ''}")
    return lines
