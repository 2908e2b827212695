"""What each object type's entry holds: keys, kinds, units, defaults, checks.

Turns a :class:`~pyrt.db._text.RawEntry` into a typed record (refusing
unknown, duplicate, malformed and missing keys at their line), and formats
a new value into an existing value's text for write-back.
"""

from __future__ import annotations

import builtins
import difflib
import math
import re
from collections.abc import Callable
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

from pyrt.db._text import RawEntry, RawField
from pyrt.db.records import (
    AVRecord,
    AxisRecord,
    EncoderRecord,
    LoadcellRecord,
    Location,
    MotorRecord,
    PolyAxisRecord,
)
from pyrt.errors import ConfigError
from pyrt.units import NUMBER_PATTERN, UnitError, factor, parse_number, parse_quantity

__all__ = [
    "FILES",
    "SCHEMAS",
    "VERSIONS",
    "FieldSpec",
    "Schema",
    "build_record",
    "defaults",
    "format_value",
]

#: Object type -> database file name.
FILES = {
    "POLYAXIS": "POLYAXIS.dat",
    "AXIS": "AXIS.dat",
    "MOTOR": "MOTOR.dat",
    "ENCODER": "ENCODER.dat",
    "LOADCELL": "LOADCELL.dat",
    "AV": "AV.dat",
}

#: Object type -> the VERSION this code reads (local to each type, section 5).
VERSIONS = {t: "1.00" for t in FILES}

#: Kinds that are not unit quantities.
_PLAIN = {"name", "text", "int", "number", "vector", "angles"}

#: Fewest decimals a rewritten fixed-point number gets (the document's
#: rewritten values carry 6 to 13); more if the original had more.
MIN_DECIMALS = 6

_NUMBER_TOKEN = re.compile(rf"(?<![\w.+\-])({NUMBER_PATTERN})(?![\w.])")
_INT = re.compile(r"[+-]?[0-9]+")  # ASCII digits only, as every number
_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.\-]*")
_NUMBER = re.compile(NUMBER_PATTERN)
_LEADING_NUMBER = re.compile(rf"({NUMBER_PATTERN})")


@dataclass(frozen=True)
class FieldSpec:
    """One key of an entry.

    ``kind`` is ``name`` (a reference to another entry), ``text``, ``int``,
    ``number`` (a plain number), ``vector`` (three lengths, optional trailing
    unit), ``angles`` (three plain numbers) or a unit quantity of
    :mod:`pyrt.units` (``length``, ``mass``, ``volume``, ``force``, ``speed``,
    ``density``, ``time``).
    """

    key: str
    kind: str
    required: bool = True
    default: Any = None
    unit_required: bool = False
    repeat: bool = False
    writable: bool = False
    check: Callable[[Any], str | None] | None = None
    #: record field name when it is not the lower-cased key (AXIS -> axes)
    field_name: str | None = None

    @property
    def attr(self) -> str:
        return self.field_name or self.key.lower()


@dataclass(frozen=True)
class Schema:
    type: str
    record: builtins.type[Any]  # (``type`` here is the field above)
    fields: tuple[FieldSpec, ...]
    #: prefix of free-form numeric keys kept as a mapping (AXIS: FUZZY_)
    mapping_prefix: str | None = None
    mapping_attr: str | None = None
    check: Callable[[Any], tuple[str, str] | None] | None = None

    def spec(self, key: str) -> FieldSpec | None:
        key = key.upper()
        for f in self.fields:
            if f.key == key:
                return f
        return None


def _positive(v: float) -> str | None:
    return None if v > 0 else f"expected a value > 0, got {v:g}"


def _nonnegative(v: float) -> str | None:
    if v == 0 and math.copysign(1.0, v) < 0:  # "-0": a sign slip more likely than a zero
        return "expected a value >= 0, got -0 (a minus sign on a value that cannot be negative)"
    return None if v >= 0 else f"expected a value >= 0, got {v:g}"


def _nonzero(v: float) -> str | None:
    return None if v != 0 else "expected a non-zero value, got 0"


def _motor_channel(v: int) -> str | None:
    # TIO10: two AM9513 chips of five channels, 0..9; channels 4 and 5 carry
    # the real-time clock and are refused, as 000's Motor code does.
    if v in (4, 5):
        return f"channel {v} is reserved for the real-time clock (channels 4 and 5)"
    if not 0 <= v <= 9:
        return f"expected a TIO10 channel 0..9 (not 4 or 5), got {v}"
    return None


def _speed_range(v: float) -> str | None:
    if not 0.07 <= v <= 7.0:
        return f"expected a speed between 0.07 and 7.0 cm/s (the limits 000 enforces), got {v:g}"
    return None


def _at_least_one(v: int) -> str | None:
    return None if v >= 1 else f"expected an integer >= 1, got {v}"


def _motor_check(r: MotorRecord) -> tuple[str, str] | None:
    if r.start_speed > r.cruise_speed:
        return ("START_SPEED", f"START_SPEED {r.start_speed:g} cm/s is above CRUISE_SPEED "
                f"{r.cruise_speed:g} cm/s")
    return None


def _polyaxis_check(r: PolyAxisRecord) -> tuple[str, str] | None:
    if r.low_tension >= r.max_tension:
        return ("LOW_TENSION", f"LOW_TENSION {r.low_tension:g} N must be below MAX_TENSION "
                f"{r.max_tension:g} N")
    seen: dict[str, str] = {}
    for a in r.axes:
        if a.lower() in seen:
            return ("AXIS", f"axis {a!r} is listed twice")
        seen[a.lower()] = a
    return None


SCHEMAS: dict[str, Schema] = {
    "POLYAXIS": Schema("POLYAXIS", PolyAxisRecord, (
        FieldSpec("AXIS", "name", repeat=True, field_name="axes"),
        FieldSpec("POSITION", "vector", writable=True),
        FieldSpec("SOURCE_MASS", "mass", unit_required=True, check=_positive, writable=True),
        FieldSpec("SOURCE_VOLUME", "volume", unit_required=True, check=_nonnegative,
                  writable=True),
        FieldSpec("AV", "name", required=False, default=None),
        FieldSpec("END_ERROR", "length", required=False, default=1.0, check=_positive),
        FieldSpec("LOW_TENSION", "force", required=False, default=2.0, check=_nonnegative),
        FieldSpec("MAX_TENSION", "force", required=False, default=200.0, check=_positive),
        FieldSpec("NET_FORCELIMIT", "force", required=False, default=25.0, check=_positive),
        FieldSpec("OFFSIDE_TENSION", "force", required=False, default=10.0, check=_positive),
        FieldSpec("HARE_SPEED", "speed", required=False, default=2.0, check=_positive),
        FieldSpec("HARE_RAMP", "length", required=False, default=20.0, check=_positive),
        FieldSpec("STUCK_TIME", "time", required=False, default=10.0, check=_positive),
        FieldSpec("FIND_TOLERANCE", "length", required=False, default=0.1, check=_positive),
        FieldSpec("D2O_DENSITY", "density", required=False, default=1.10, check=_positive),
        FieldSpec("DIST_ERR_LIMIT", "length", required=False, default=0.5, check=_positive),
        FieldSpec("TENSION_MARGIN", "force", required=False, default=5.0, check=_nonnegative),
    ), check=_polyaxis_check),
    "AXIS": Schema("AXIS", AxisRecord, (
        FieldSpec("MOTOR", "name"),
        FieldSpec("LOADCELL", "name"),
        FieldSpec("ENCODER", "name"),
        FieldSpec("LENGTH", "length", check=_nonnegative, writable=True),
        FieldSpec("DEADLENGTH", "length", check=_nonnegative),
        FieldSpec("OFFSET", "vector"),
        FieldSpec("TOP", "vector"),
        FieldSpec("BOTTOM", "vector", required=False, default=None),
        FieldSpec("STRETCH", "number", required=False, default=2.0e-5, check=_nonnegative),
    ), mapping_prefix="FUZZY_", mapping_attr="fuzzy"),
    "MOTOR": Schema("MOTOR", MotorRecord, (
        FieldSpec("CHANNEL", "int", check=_motor_channel),
        FieldSpec("START_SPEED", "speed", check=_speed_range),
        FieldSpec("CRUISE_SPEED", "speed", check=_speed_range),
        FieldSpec("STEPS_PER_CM", "number", required=False, default=40.0, check=_positive),
        FieldSpec("DV_LIMIT", "speed", required=False, default=0.5, check=_positive),
        FieldSpec("RAMP_DECREMENT", "int", required=False, default=10, check=_at_least_one),
    ), check=_motor_check),
    "ENCODER": Schema("ENCODER", EncoderRecord, (
        FieldSpec("SLOPE", "number", check=_nonzero),
        FieldSpec("ADDRESS", "int", check=_nonnegative),
        FieldSpec("ZEROLENGTH", "length", writable=True),
        FieldSpec("DATE", "text", writable=True),
    )),
    "LOADCELL": Schema("LOADCELL", LoadcellRecord, (
        FieldSpec("MAXLOAD", "force", check=_positive),
        FieldSpec("SLOPE", "number", check=_nonzero, writable=True),
        FieldSpec("OFFSET", "number", writable=True),
        FieldSpec("CHANNEL", "int", check=_nonnegative),
        FieldSpec("DATE", "text", writable=True),
        # 000's calibrationPoint: the points of the last calibration, "ADC N; ..."
        FieldSpec("CALIBRATIONPOINT", "text", required=False, default="", writable=True,
                  field_name="calibration_points"),
    )),
    "AV": Schema("AV", AVRecord, (
        FieldSpec("NECK_RING_STATIC_POSITION", "vector"),
        FieldSpec("NECK_RING_RADIUS", "length", check=_positive),
        FieldSpec("NECK_RADIUS", "length", check=_positive),
        FieldSpec("NECK_LENGTH", "length", check=_nonnegative),
        FieldSpec("VESSEL_RADIUS", "length", check=_positive),
        FieldSpec("POSITION", "vector", required=False, default=(0.0, 0.0, 0.0)),
        FieldSpec("ORIENTATION", "angles", required=False, default=(0.0, 0.0, 0.0)),
    )),
}


# -- values ---------------------------------------------------------------


def _describe(spec: FieldSpec) -> str:
    if spec.kind == "vector":
        return "three numbers x y z (cm, or a length unit after them)"
    if spec.kind == "angles":
        return "three numbers (degrees)"
    if spec.kind == "int":
        return "an integer"
    if spec.kind == "number":
        return "a number"
    if spec.kind == "name":
        return "a name"
    if spec.kind == "text":
        return "some text"
    unit = "with its unit" if spec.unit_required else "with an optional unit"
    return f"a {spec.kind} {unit}"


def parse_value(spec: FieldSpec, text: str) -> Any:
    """The value of ``text`` for ``spec`` in base units; ``ValueError`` if malformed."""
    kind = spec.kind
    if kind == "text":
        return text
    if kind == "name":
        if not _NAME.fullmatch(text):
            raise ValueError(f"expected a name (letters, digits, _ . -), got {text!r}")
        return text
    if kind == "int":
        if not _INT.fullmatch(text):
            raise ValueError(f"expected an integer, got {text!r}")
        return int(text)
    if kind == "number":
        return parse_number(text)
    if kind in ("vector", "angles"):
        parts = text.split()
        scale = 1.0
        if kind == "vector" and len(parts) == 4 and not _NUMBER.fullmatch(parts[3]):
            scale = factor(parts[3], "length")
            parts = parts[:3]
        if len(parts) != 3:
            raise ValueError(f"expected {_describe(spec)}, got {text!r}")
        return tuple(parse_number(p) * scale for p in parts)
    return parse_quantity(text, kind, unit_required=spec.unit_required)


def _location(entry: RawEntry, file: str) -> Location:
    keys: dict[str, int] = {}
    for f in entry.fields:
        keys.setdefault(f.key, f.line)
    return Location(file, entry.line, MappingProxyType(keys))


def build_record(schema: Schema, entry: RawEntry, file: str) -> Any:
    """The typed record of ``entry``; ConfigError at the offending line."""
    values: dict[str, Any] = {}
    seen: dict[str, RawField] = {}
    mapping: dict[str, float] = {}
    mapping_lines: dict[str, int] = {}
    repeats: dict[str, list[Any]] = {}
    for raw in entry.fields:
        spec = schema.spec(raw.key)
        if spec is None:
            if schema.mapping_prefix and raw.key.startswith(schema.mapping_prefix) and \
                    len(raw.key) > len(schema.mapping_prefix):
                name = raw.key[len(schema.mapping_prefix):].lower()
                if name in mapping:
                    raise ConfigError(
                        f"duplicate key {raw.key} in {schema.type} entry {entry.name!r} "
                        f"(first at line {mapping_lines[name]})", file, raw.line)
                try:
                    mapping[name] = parse_number(raw.value)
                except UnitError as e:
                    raise ConfigError(f"{raw.key}: {e}", file, raw.line) from None
                mapping_lines[name] = raw.line
                continue
            raise ConfigError(_unknown_key(schema, raw.key), file, raw.line)
        if raw.key in seen and not spec.repeat:
            raise ConfigError(
                f"duplicate key {raw.key} in {schema.type} entry {entry.name!r} (first at line "
                f"{seen[raw.key].line})", file, raw.line)
        seen.setdefault(raw.key, raw)
        try:
            value = parse_value(spec, raw.value)
        except ValueError as e:  # UnitError is a ValueError
            raise ConfigError(f"{raw.key}: {e}; expected {_describe(spec)}",
                              file, raw.line) from None
        if spec.check is not None:
            problem = spec.check(value)
            if problem:
                raise ConfigError(f"{raw.key}: {problem}", file, raw.line)
        if spec.repeat:
            repeats.setdefault(spec.attr, []).append(value)
        else:
            values[spec.attr] = value
    for spec in schema.fields:
        if spec.key in seen:
            continue
        if spec.required:
            raise ConfigError(
                f"{schema.type} entry {entry.name!r} has no {spec.key}: key; expected "
                f"'{spec.key}: ' followed by {_describe(spec)} before 'END;'", file, entry.line)
        values[spec.attr] = spec.default
    for attr, items in repeats.items():
        values[attr] = tuple(items)
    if schema.mapping_attr:
        values[schema.mapping_attr] = MappingProxyType(mapping)
    where = _location(entry, file)
    record = schema.record(name=entry.name, where=where, **values)
    if schema.check is not None:
        failed = schema.check(record)
        if failed:
            key, message = failed
            raise where.error(key, message)
    return record


def _unknown_key(schema: Schema, key: str) -> str:
    known = [f.key for f in schema.fields]
    close = difflib.get_close_matches(key, known, n=1)
    hint = f"; did you mean {close[0]}?" if close else ""
    extra = f" or {schema.mapping_prefix}<NAME>" if schema.mapping_prefix else ""
    return (f"unknown key {key} in a {schema.type} entry{hint} (expected one of "
            f"{', '.join(known)}{extra})")


# -- write-back formatting ----------------------------------------------------


def _format_like(value: float, original: str) -> str:
    """``value`` written in the style of the number text ``original``."""
    mantissa, e, _ = original.lower().partition("e")
    decimals = len(mantissa.partition(".")[2])
    if e:
        text = f"{value:.{max(decimals, MIN_DECIMALS)}e}"
        if "E" in original:
            text = text.upper()
    else:
        text = f"{value:.{max(decimals, MIN_DECIMALS)}f}"
    if float(text) == 0.0 and text.startswith("-"):
        text = text[1:]
    if original.startswith("+") and not text.startswith("-"):
        text = "+" + text
    return text


def format_value(spec: FieldSpec, old_text: str, value: Any) -> str:
    """The value text to write in place of ``old_text`` for the new ``value``.

    Numbers keep the original's style (fixed or exponent, at least as many
    decimals, at least :data:`MIN_DECIMALS`) and the unit text stays; the
    number is converted back into that unit.
    """
    kind = spec.kind
    if kind == "text":
        text = str(value)
        if not text.strip() or "\n" in text or "\r" in text or "//" in text:
            raise ValueError(f"expected one line of text without '//', got {text!r}")
        return text.strip()
    if kind == "name" or spec.repeat:
        raise ValueError(f"{spec.key} names another object and is not written back")
    if kind == "int":
        if isinstance(value, bool) or not isinstance(value, int):
            raise ValueError(f"expected an integer, got {value!r}")
        return str(value)
    if kind in ("vector", "angles"):
        comps = tuple(value)
        if len(comps) != 3:
            raise ValueError(f"expected three numbers, got {value!r}")
        parts = old_text.split()
        scale = 1.0
        if kind == "vector" and len(parts) == 4:
            scale = factor(parts[3], "length")
        numbers = list(_NUMBER_TOKEN.finditer(old_text))[:3]
        new = [_finite(c) / scale for c in comps]
        return _replace_numbers(old_text, numbers, new)
    v = _finite(value)
    if kind == "number":
        numbers = list(_NUMBER_TOKEN.finditer(old_text))[:1]
        return _replace_numbers(old_text, numbers, [v])
    # unit quantity: keep the unit text, convert back into it
    m = _LEADING_NUMBER.match(old_text)
    if m is None:  # pragma: no cover - the text parsed as this kind
        raise ValueError(f"cannot find the number in {old_text!r}")
    unit = old_text[m.end():].strip() or None
    return _replace_numbers(old_text, [m], [v / factor(unit, kind)])


def _finite(v: Any) -> float:
    if isinstance(v, bool):
        raise ValueError(f"expected a number, got {v!r}")
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise ValueError(f"expected a number, got {v!r}") from None
    if not math.isfinite(f):
        raise ValueError(f"expected a finite number, got {v!r}")
    return f


def _replace_numbers(text: str, matches: list[re.Match[str]], values: list[float]) -> str:
    out = []
    pos = 0
    for m, v in zip(matches, values, strict=True):
        original = m.group(1)
        new = original if float(original) == v else _format_like(v, original)
        out.append(text[pos:m.start(1)])
        out.append(new)
        pos = m.end(1)
    out.append(text[pos:])
    return "".join(out)


def defaults(type_: str) -> dict[str, Any]:
    """The default of every optional field of an entry of ``type_`` (``POLYAXIS``,
    ``AXIS``, ...) by record field name: the one home of each default (records
    get it from :func:`build_record`, constructors from here)."""
    return {f.attr: f.default for f in SCHEMAS[type_].fields if not f.required}
