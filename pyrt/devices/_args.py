"""Argument checking shared by the device commands: bad input is a CommandError."""

from __future__ import annotations

import math

from pyrt.errors import CommandError
from pyrt.units import UnitError
from pyrt.units import parse_number as _parse_number

__all__ = ["dispatch", "parse_number"]


def parse_number(value: object, command: str, what: str) -> float:
    """``value`` (a number or its text) as a finite float, or CommandError."""
    if isinstance(value, bool):
        raise CommandError(f"{command}: expected a {what}, got {value!r}")
    if isinstance(value, (int, float)):
        v = float(value)
    elif isinstance(value, str):
        try:
            v = _parse_number(value)
        except UnitError as exc:
            raise CommandError(f"{command}: expected a {what}, got {value!r}") from exc
    else:
        raise CommandError(f"{command}: expected a {what}, got {value!r}")
    if not math.isfinite(v):
        raise CommandError(f"{command}: expected a finite {what}, got {value!r}")
    return v


def dispatch(target: object, owner: str, commands: dict[str, tuple[str, int]], name: str,
             args: tuple[str, ...]) -> object:
    """Run command ``name`` (case-insensitive) of ``commands`` (command -> (method,
    argument count)) on ``target``; a wrong name or count is a CommandError."""
    key = name.lower()
    entry = next((v for k, v in commands.items() if k.lower() == key), None)
    if entry is None:
        raise CommandError(f"{owner}: unknown command {name!r}; expected one of "
                           f"{', '.join(commands)}")
    method, nargs = entry
    if len(args) != nargs:
        raise CommandError(f"{owner} {name}: takes {nargs} argument(s), got {len(args)}")
    return getattr(target, method)(*args)
