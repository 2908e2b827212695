"""Units of the object databases: numbers with units to cm, kg, cm3, N."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pyrt.units import (
    BASE,
    UnitError,
    convert,
    factor,
    parse_number,
    parse_quantity,
    parse_value,
    quantity_of,
    split_quantity,
    units_of,
    value_grammar,
)


@pytest.mark.parametrize(
    ("text", "quantity", "expected"),
    [
        ("3.20 m", "length", 320.0),
        ("42.0 cm", "length", 42.0),
        ("42.0cm", "length", 42.0),
        ("27", "length", 27.0),
        ("5.3357 kg", "mass", 5.3357),
        ("500 g", "mass", 0.5),
        ("0.0 cm3", "volume", 0.0),
        ("2 cm**3", "volume", 2.0),
        ("3 cc", "volume", 3.0),
        ("1.5 l", "volume", 1500.0),
        ("0.001 m3", "volume", 1000.0),
        ("2 m**3", "volume", 2e6),
        ("1 m\u00b3", "volume", 1e6),
        ("50 lb", "force", 50 * 4.4482216152605),
        ("10 N", "force", 10.0),
        ("10 n", "force", 10.0),
        ("1.10 g/cm3", "density", 1.10),
        ("2.0 cm/s", "speed", 2.0),
        ("10 s", "time", 10.0),
    ],
)
def test_table_units_convert_to_base(text: str, quantity: str, expected: float) -> None:
    """Every unit the tables use converts to the base unit of its quantity."""
    assert parse_quantity(text, quantity) == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize(
    ("text", "quantity"),
    [
        ("3.20 furlong", "length"),
        ("5 kg", "length"),
        ("5 cm", "mass"),
        ("5 m", "volume"),
        ("", "length"),
        ("kg", "mass"),
        ("1.2.3 cm", "length"),
        ("nan", "length"),
        ("inf cm", "length"),
        ("1_000 cm", "length"),
        ("0x10", "length"),
        ("1e400", "length"),
        ("5 k g", "mass"),
    ],
)
def test_bad_quantities_are_refused(text: str, quantity: str) -> None:
    """Unknown units, wrong-quantity units and malformed numbers raise UnitError."""
    with pytest.raises(UnitError):
        parse_quantity(text, quantity)


def test_unit_required_refuses_bare_number() -> None:
    """Table 1's 'units required' refuses a bare number and names the units."""
    with pytest.raises(UnitError, match="with its unit"):
        parse_quantity("5.3357", "mass", unit_required=True)
    assert parse_quantity("5335.7 g", "mass", unit_required=True) == pytest.approx(5.3357)


def test_unknown_quantity_is_an_error() -> None:
    """Asking for a quantity pyrt does not know is an error, not a pass-through."""
    with pytest.raises(UnitError, match="unknown quantity"):
        convert(1.0, "cm", "colour")


def test_parse_number_forms() -> None:
    """The database number forms parse; Python-only forms do not."""
    assert parse_number("0.") == 0.0
    assert parse_number(".5") == 0.5
    assert parse_number("-482.535980") == -482.53598
    assert parse_number("+1e-3") == 0.001
    assert parse_number("1.") == 1.0
    for bad in ("", "e5", "1e", "--1", "1 2", "0b1", "Infinity", "nan", "1_0"):
        with pytest.raises(UnitError):
            parse_number(bad)


def test_split_quantity_keeps_unit_text() -> None:
    """split_quantity gives the number and the unit as written."""
    assert split_quantity(" 3.20 m ") == (3.2, "m")
    assert split_quantity("42") == (42.0, None)
    assert factor("M", "length") == 100.0
    assert "cm**3" in units_of("volume")


@settings(max_examples=300, deadline=None)
@given(
    value=st.floats(min_value=-1e12, max_value=1e12, allow_nan=False),
    quantity=st.sampled_from(sorted(BASE)),
    data=st.data(),
    space=st.sampled_from(["", " ", "  ", "\t"]),
)
def test_value_unit_roundtrip(value: float, quantity: str, data: st.DataObject,
                              space: str) -> None:
    """A number written with any accepted unit parses to number * factor."""
    unit = data.draw(st.sampled_from(units_of(quantity)))
    text = f"{value!r}{space}{unit}"
    assert parse_quantity(text, quantity) == pytest.approx(value * factor(unit, quantity),
                                                           rel=1e-12, abs=1e-300)


@settings(max_examples=400, deadline=None)
@given(text=st.text(max_size=30), quantity=st.sampled_from(sorted(BASE)))
def test_junk_raises_only_unit_error(text: str, quantity: str) -> None:
    """Any text either parses to a finite base-unit value or raises UnitError."""
    try:
        v = parse_quantity(text, quantity)
    except UnitError:
        return
    assert math.isfinite(v)


# -- the one number grammar of command arguments ------------------------------------------

#: The units command arguments are given in (Arg.units), with their quantities.
_ARG_UNITS = {"cm": "length", "mm": "length", "N": "force", "cm/s": "speed", "s": "time",
              "kg": "mass"}


@settings(max_examples=400, deadline=None)
@given(value=st.floats(min_value=-1e12, max_value=1e12, allow_nan=False),
       arg_unit=st.sampled_from(sorted(_ARG_UNITS)), data=st.data(),
       space=st.sampled_from(["", " "]))
def test_a_number_with_a_unit_of_the_arguments_quantity_converts(value, arg_unit, data, space):
    """Any accepted unit of the argument's quantity converts to the argument's unit; a bare
    number is in the argument's unit."""
    quantity = _ARG_UNITS[arg_unit]
    assert quantity_of(arg_unit) == quantity
    unit = data.draw(st.sampled_from(units_of(quantity)))
    want = value * factor(unit, quantity) / factor(arg_unit, quantity)
    assert parse_value(f"{value!r}{space}{unit}", arg_unit) == pytest.approx(
        want, rel=1e-12, abs=1e-300)
    assert parse_value(repr(value), arg_unit) == value


@settings(max_examples=200, deadline=None)
@given(value=st.floats(min_value=-1e6, max_value=1e6, allow_nan=False),
       arg_unit=st.sampled_from(sorted(_ARG_UNITS)), data=st.data())
def test_a_unit_of_another_quantity_is_refused_naming_the_units(value, arg_unit, data):
    """A unit of another quantity is refused, and the refusal lists the units the argument takes."""
    quantity = _ARG_UNITS[arg_unit]
    other = data.draw(st.sampled_from([u for q in BASE if q != quantity for u in units_of(q)
                                       if u not in units_of(quantity)]))
    with pytest.raises(UnitError) as err:
        parse_value(f"{value!r}{other}", arg_unit)
    assert ", ".join(units_of(quantity)) in str(err.value)


@settings(max_examples=300, deadline=None)
@given(left=st.integers(0, 999), right=st.integers(0, 999),
       unit=st.sampled_from(["", "cm", "N", "s", "mm"]), arg_unit=st.sampled_from(["", "cm", "N"]))
def test_underscores_are_refused_everywhere(left, right, unit, arg_unit):
    """Python's digit grouping (1_0) is refused by every argument, with a unit or without."""
    with pytest.raises(UnitError):
        parse_value(f"{left}_{right}{unit}", arg_unit)


@settings(max_examples=400, deadline=None)
@given(text=st.text(max_size=20), arg_unit=st.sampled_from(["", "cm", "N", "cm/s", "counts"]))
def test_any_text_is_a_finite_value_or_a_unit_error(text, arg_unit):
    """Whatever the text, the grammar gives a finite number or raises UnitError (nothing else)."""
    try:
        v = parse_value(text, arg_unit)
    except UnitError:
        return
    assert math.isfinite(v)


def test_the_grammars_edges():
    """Dimensionless takes a bare number only; a unit pyrt does not convert is taken as itself."""
    assert parse_value("  -1.5e1 ") == -15.0
    with pytest.raises(UnitError, match="expected a number, got"):
        parse_value("5cm")
    assert parse_value("7 counts", "counts") == 7.0
    with pytest.raises(UnitError):
        parse_value("7 cm", "counts")
    for bad in ("nan", "inf", "1e400", "0x10", "", "cm", "5 k g"):
        with pytest.raises(UnitError):
            parse_value(bad, "cm")
    assert value_grammar("N") == "a number with an optional force unit (kgf, kn, lb, lbf, lbs, n)"
