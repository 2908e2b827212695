"""Argument checking shared by the device commands: bad input is a CommandError."""

from __future__ import annotations

import math

from pyrt.errors import CommandError
from pyrt.units import UnitError
from pyrt.units import parse_number as _parse_number

__all__ = ["parse_number"]


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
