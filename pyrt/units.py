"""Units of the object databases: values with units to pyrt's base units.

Base units: length cm, mass kg, volume cm3, force N.  The document's tables
write ``3.20 m``, ``42.0 cm``, ``500 g``, ``2 l``; a bare number is taken in
the base unit of its quantity.
"""

from __future__ import annotations

from pyrt.errors import PyrtError

__all__ = ["UnitError", "convert", "parse_quantity"]


class UnitError(PyrtError, ValueError):
    """A unit that is unknown, or not one of the quantity asked for."""


_LB_N = 4.4482216152605  # pound-force in newtons

#: quantity -> {unit spelling (lower case): factor to the base unit}
_UNITS: dict[str, dict[str, float]] = {
    "length": {"cm": 1.0, "m": 100.0, "mm": 0.1, "in": 2.54, "inch": 2.54, "ft": 30.48},
    "mass": {"kg": 1.0, "g": 1e-3, "gm": 1e-3, "mg": 1e-6, "lb": 0.45359237, "lbs": 0.45359237},
    "volume": {
        "cm3": 1.0, "cm**3": 1.0, "cm^3": 1.0, "cc": 1.0, "ml": 1.0,
        "l": 1000.0, "liter": 1000.0, "litre": 1000.0,
        "m3": 1e6, "m**3": 1e6, "m^3": 1e6,
    },
    "force": {"n": 1.0, "kn": 1000.0, "lb": _LB_N, "lbs": _LB_N, "lbf": _LB_N, "kgf": 9.80665},
    "speed": {"cm/s": 1.0, "m/s": 100.0, "mm/s": 0.1},
    "density": {"g/cm3": 1.0, "g/cc": 1.0, "kg/m3": 1e-3, "kg/l": 1.0},
}

BASE = {"length": "cm", "mass": "kg", "volume": "cm3", "force": "N", "speed": "cm/s", "density": "g/cm3"}


def convert(value: float, unit: str | None, quantity: str) -> float:
    """``value`` in ``unit`` expressed in the base unit of ``quantity``."""
    table = _UNITS.get(quantity)
    if table is None:
        raise UnitError(f"unknown quantity {quantity!r}; expected one of {', '.join(_UNITS)}")
    if unit is None or unit == "":
        return float(value)
    factor = table.get(unit.strip().lower())
    if factor is None:
        raise UnitError(
            f"unknown {quantity} unit {unit!r}; expected one of {', '.join(sorted(table))}"
        )
    return float(value) * factor


def parse_quantity(text: str, quantity: str) -> float:
    """Parse ``"3.20 m"`` / ``"42.0cm"`` / ``"500"`` as ``quantity`` in base units."""
    s = text.strip()
    if not s:
        raise UnitError(f"expected a {quantity}, got nothing")
    i = len(s)
    # The number is the longest prefix that parses as a float.
    while i > 0:
        try:
            number = float(s[:i])
            break
        except ValueError:
            i -= 1
    else:
        raise UnitError(f"expected a {quantity} such as '3.2 {BASE.get(quantity, '')}', got {text!r}")
    if number != number or number in (float("inf"), float("-inf")):
        raise UnitError(f"expected a finite {quantity}, got {text!r}")
    return convert(number, s[i:].strip() or None, quantity)
