"""Units of the object databases: values with units to pyrt's base units.

Base units: length cm, mass kg, volume cm3, force N, speed cm/s, density
g/cm3.  The document's tables write ``3.20 m``, ``42.0 cm``, ``5.3357 kg``,
``0.0 cm3``, ``50 lb``; a bare number is taken in the base unit of its
quantity (unless the caller demands a unit, as Table 1 does for the source
mass and volume).

Numbers are written the way the database files write them: an optional
sign, ASCII digits with an optional decimal point (``0.``, ``.5``,
``95.569618``) and an optional exponent.  Python's extras (``nan``, ``inf``,
``1_000``, hexadecimal, the digits of other scripts such as ``\u0663\u0660``
or fullwidth ``\uff13``) are refused: a database value is a plain decimal
number.

The same grammar serves every numeric argument of every command (console,
network and EPICS ``CMD`` alike): :func:`parse_value` takes a number with an
optional unit of the argument's dimension (``50mm``, ``5 cm``, ``0.05m`` for
a length in cm; ``1000N`` or ``50lbf`` for a force in N; ``500ms`` for a
time in s) and converts it to the argument's unit, or refuses it naming the
units it takes.  Underscores are refused everywhere: an operator's ``1_0``
is more likely a slip than ten.
"""

from __future__ import annotations

import math
import re

from pyrt.errors import PyrtError

__all__ = [
    "BASE",
    "NUMBER_PATTERN",
    "UnitError",
    "convert",
    "factor",
    "parse_number",
    "parse_quantity",
    "parse_value",
    "quantity_of",
    "split_quantity",
    "units_of",
    "value_grammar",
]


class UnitError(PyrtError, ValueError):
    """A number or unit that is malformed, unknown, or not of the quantity asked for."""


#: A decimal number as the database files write it: ASCII digits only (Python's
#: ``\d`` and ``float()`` take any script's digits: ``"\u0663\u0660"`` would be 30).
NUMBER_PATTERN = r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?"
_NUMBER = re.compile(NUMBER_PATTERN)
_QUANTITY = re.compile(rf"\s*({NUMBER_PATTERN})\s*(\S*)\s*")

_LB_N = 4.4482216152605  # pound-force in newtons (exact definition)

#: quantity -> {unit spelling (lower case): factor to the base unit}
_UNITS: dict[str, dict[str, float]] = {
    "length": {"cm": 1.0, "m": 100.0, "mm": 0.1, "in": 2.54, "inch": 2.54, "ft": 30.48},
    "mass": {
        "kg": 1.0, "g": 1e-3, "gm": 1e-3, "mg": 1e-6, "lb": 0.45359237, "lbs": 0.45359237,
    },
    "volume": {
        "cm3": 1.0, "cm**3": 1.0, "cm^3": 1.0, "cm\u00b3": 1.0, "cc": 1.0, "ml": 1.0,
        "l": 1000.0, "liter": 1000.0, "litre": 1000.0,
        "m3": 1e6, "m**3": 1e6, "m^3": 1e6, "m\u00b3": 1e6,
    },
    "force": {"n": 1.0, "kn": 1000.0, "lb": _LB_N, "lbs": _LB_N, "lbf": _LB_N, "kgf": 9.80665},
    "speed": {"cm/s": 1.0, "m/s": 100.0, "mm/s": 0.1},
    "density": {
        "g/cm3": 1.0, "g/cm**3": 1.0, "g/cm^3": 1.0, "g/cm\u00b3": 1.0, "g/cc": 1.0,
        "kg/m3": 1e-3, "kg/m**3": 1e-3, "kg/m^3": 1e-3, "kg/l": 1.0, "g/ml": 1.0,
    },
    "time": {"s": 1.0, "ms": 1e-3, "min": 60.0},
}

#: quantity -> the spelling of its base unit
BASE = {
    "length": "cm",
    "mass": "kg",
    "volume": "cm3",
    "force": "N",
    "speed": "cm/s",
    "density": "g/cm3",
    "time": "s",
}


def _table(quantity: str) -> dict[str, float]:
    table = _UNITS.get(quantity)
    if table is None:
        raise UnitError(f"unknown quantity {quantity!r}; expected one of {', '.join(_UNITS)}")
    return table


def units_of(quantity: str) -> list[str]:
    """The unit spellings accepted for ``quantity`` (lower case, sorted)."""
    return sorted(_table(quantity))


def factor(unit: str | None, quantity: str) -> float:
    """How many base units of ``quantity`` one ``unit`` is (1.0 for no unit)."""
    table = _table(quantity)
    if unit is None or unit.strip() == "":
        return 1.0
    f = table.get(unit.strip().lower())
    if f is None:
        raise UnitError(
            f"unknown {quantity} unit {unit!r}; expected one of {', '.join(sorted(table))}"
        )
    return f


def convert(value: float, unit: str | None, quantity: str) -> float:
    """``value`` in ``unit`` expressed in the base unit of ``quantity``."""
    return float(value) * factor(unit, quantity)


def parse_number(text: str) -> float:
    """A finite decimal number such as ``"95.569618419"``, ``"0."`` or ``"-1e-3"``."""
    s = text.strip()
    if not _NUMBER.fullmatch(s):
        raise UnitError(f"expected a number such as 12.5, got {text!r}")
    value = float(s)
    if not math.isfinite(value):
        raise UnitError(f"expected a finite number, got {text!r}")
    return value


def split_quantity(text: str) -> tuple[float, str | None]:
    """``"3.20 m"`` -> ``(3.2, "m")``; ``"42"`` -> ``(42.0, None)``.  No conversion."""
    m = _QUANTITY.fullmatch(text)
    if m is None:
        raise UnitError(f"expected a number with an optional unit such as '3.2 m', got {text!r}")
    value = float(m.group(1))
    if not math.isfinite(value):
        raise UnitError(f"expected a finite number, got {text!r}")
    return value, (m.group(2) or None)


def parse_quantity(text: str, quantity: str, *, unit_required: bool = False) -> float:
    """Parse ``"3.20 m"`` / ``"42.0cm"`` / ``"500"`` as ``quantity`` in base units.

    With ``unit_required`` a bare number is refused (Table 1: "units required").
    """
    _table(quantity)
    s = text.strip()
    if not s:
        raise UnitError(f"expected a {quantity}, got nothing")
    try:
        value, unit = split_quantity(s)
    except UnitError:
        raise UnitError(
            f"expected a {quantity} such as '3.2 {BASE[quantity]}', got {text!r}"
        ) from None
    if unit is None and unit_required:
        raise UnitError(
            f"expected a {quantity} with its unit (one of {', '.join(units_of(quantity))}), "
            f"got the bare number {text.strip()!r}"
        )
    return convert(value, unit, quantity)


def quantity_of(unit: str) -> str | None:
    """The quantity ``unit`` measures (``"cm"`` -> ``"length"``, ``"N"`` ->
    ``"force"``), or None for a unit pyrt does not convert (``"counts"``)."""
    u = unit.strip().lower()
    for quantity, base in BASE.items():
        if base.lower() == u:
            return quantity
    for quantity, table in _UNITS.items():
        if u in table:
            return quantity
    return None


def value_grammar(unit: str = "") -> str:
    """What :func:`parse_value` takes for an argument in ``unit``, for messages:
    ``"a number"`` or ``"a number with an optional length unit (cm, ft, ...)"``."""
    quantity = quantity_of(unit) if unit else None
    if quantity is None:
        return f"a number (in {unit})" if unit else "a number"
    return f"a number with an optional {quantity} unit ({', '.join(units_of(quantity))})"


def parse_value(text: str, unit: str = "") -> float:
    """One numeric argument in ``unit``: a finite decimal number (as
    :func:`parse_number`), optionally followed, with or without a space, by a
    unit of the same quantity (converted to ``unit``); without ``unit``, or with
    one pyrt does not convert, a bare number (or, for the latter, the number
    followed by ``unit`` itself).  UnitError naming what it takes otherwise."""
    m = _QUANTITY.fullmatch(text)
    quantity = quantity_of(unit) if unit else None
    if m is None:
        raise UnitError(f"expected {value_grammar(unit)}, got {text.strip()[:40]!r}")
    value = float(m.group(1))
    if not math.isfinite(value):
        raise UnitError(f"expected a finite number, got {text.strip()[:40]!r}")
    given = m.group(2)
    if not given:
        return value
    if quantity is None or not given[0].isalpha():  # 1_0, 1.5.2: not a number and a unit
        if unit and quantity is None and given.lower() == unit.strip().lower():
            return value
        raise UnitError(f"expected {value_grammar(unit)}, got {text.strip()[:40]!r}")
    table = _UNITS[quantity]
    f = table.get(given.lower())
    if f is None:
        raise UnitError(f"{given!r} is not a {quantity} unit: expected {value_grammar(unit)}, "
                        f"got {text.strip()[:40]!r}")
    return value * (f / table[unit.strip().lower()])
