"""``show [PREFIX]``: every signal and parameter of the station in one table,
as halcmd's ``show pin`` lists every pin.

One row per signal and per parameter of every component, in the tree's
order (a component's signals, then its parameters): ``OBJECT.NAME``, the
value as the console shows it (the gripper's radix, hexadecimal RAM
bytes), the units, the range (a signal's display range, a parameter's
checked range) and whether ``set`` may change it (signals are read, never
set).  ``PREFIX`` keeps the rows whose name starts with it, in any case
(the manipulator's ``show axis0`` is ``axis0``, ``axis0Motor`` ...; ``pyrt
urdf``'s ``show puma560.`` the root's rows alone).

The rows are picked in the shell's thread and their values read in one
mailbox call, every value of the table from the same tick.  At most
:data:`MAX_ROWS` rows are shown, and only those are read: a line after the
table says how many were left out and which prefixes narrow it, so a
station of thousands of signals neither floods a console nor costs the
loop a long tick.  A prefix that matches nothing is a
command error (``error: show: nothing matches ...``, naming the objects):
a script that asks for a row that is not there fails, and nothing changes.

The same :class:`Table` is what the DAQ link's ``TABLE [PREFIX]`` request
serves as data (:func:`data_lines`: one JSON object a row, then one for
the table), so a program reads exactly the rows the operator sees.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from pyrt.commands._lines import _did_you_mean
from pyrt.component import Arg, Param, Signal, command
from pyrt.errors import CommandError

__all__ = ["MAX_ROWS", "Row", "ShowWord", "Table", "data_lines", "read_table", "require_rows",
           "table_lines"]

#: The most rows one table shows (every built-in robot's whole table fits).
MAX_ROWS = 250
#: The widest a cell is shown; a longer one is cut with "...".
MAX_CELL = 40
#: The most objects the line that says nothing matches names.
MAX_OBJECTS = 16
#: The columns, as the header names them.
COLUMNS = ("name", "value", "units", "range", "writable")


@dataclass(frozen=True)
class Row:
    """One signal or parameter as ``show`` lists it."""

    #: ``OBJECT.NAME``.
    name: str
    #: ``signal`` or ``param``.
    kind: str
    #: The value read (a number, a flag, text), or None when it could not be read.
    value: Any
    #: The value as the console shows it.
    text: str
    units: str
    #: ``lo..hi`` ('' without a range); ``lo``/``hi`` the same as numbers (or None).
    range: str
    lo: float | None
    hi: float | None
    writable: bool

    def cells(self) -> tuple[str, ...]:
        """The row's cells in :data:`COLUMNS` order."""
        return (self.name, self.text, self.units or "-", self.range or "-",
                "yes" if self.writable else "no")

    def data(self) -> dict[str, Any]:
        """The row as a JSON object (no NaN or infinity: those are null)."""
        return {"name": self.name, "kind": self.kind, "value": _plain(self.value),
                "text": self.text, "units": self.units, "range": self.range,
                "lo": _plain(self.lo), "hi": _plain(self.hi), "writable": self.writable}


@dataclass(frozen=True)
class Table:
    """The rows of one ``show``: those shown, how many matched ``prefix``
    and how many the station has, and the objects whose rows were left out."""

    prefix: str
    rows: tuple[Row, ...]
    matched: int
    total: int
    #: ``(object, rows left out)`` in the tree's order.
    left_out: tuple[tuple[str, int], ...]
    #: The station's objects (for the line that says nothing matches).
    objects: tuple[str, ...]
    #: The most rows shown.
    limit: int = MAX_ROWS

    @property
    def omitted(self) -> int:
        """Rows that matched but are not shown."""
        return self.matched - len(self.rows)

    def note(self) -> str:
        """The line after the table: nothing matched, or what was left out and
        how to narrow it ('' when every row that matched is shown)."""
        if not self.total:
            return "show: the station has no signals or parameters"
        if not self.matched:
            shown = self.prefix[:40]
            hint = _did_you_mean(self.prefix.partition(".")[0], list(self.objects))
            objects = ", ".join(self.objects[:MAX_OBJECTS])
            if len(self.objects) > MAX_OBJECTS:
                objects += f", ... ({len(self.objects)} objects)"
            return (f"show: nothing matches {shown!r}{hint}; the {self.total} rows are named "
                    f"OBJECT.NAME, objects: {objects}")
        if not self.omitted:
            return ""
        where = ", ".join(f"{name} ({n})" for name, n in self.left_out[:8])
        more = ", ..." if len(self.left_out) > 8 else ""
        example = self.left_out[0][0]
        return (f"{self.omitted} of {self.matched} rows left out (at most {self.limit} are "
                f"shown): narrow with a prefix, e.g. show {example}; left out: {where}{more}")


def _plain(value: Any) -> Any:
    """``value`` as JSON takes it: numbers, flags and text as they are (numpy's
    as Python's), a non-finite number as None, anything else as its text."""
    if value is None or isinstance(value, bool | str | int):
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    item = getattr(value, "item", None)  # a numpy scalar
    if callable(item):
        try:
            plain = item()
        except (TypeError, ValueError):
            return str(value)
        if isinstance(plain, bool | int | float | str):
            return _plain(plain)
    return str(value)


def _cut(text: str) -> str:
    text = " ".join(str(text).split())  # one line
    return text if len(text) <= MAX_CELL else text[:MAX_CELL - 3] + "..."


#: A value read, or the error its read raised.
_Read = tuple[Any, BaseException | None]


def _read_all(items: list[Signal | Param]) -> list[_Read]:
    """Every item's value (loop thread: the one mailbox call of a table)."""
    out: list[_Read] = []
    for item in items:
        try:
            out.append((item.read(), None))
        except Exception as exc:  # one unreadable value must not hide the others
            out.append((None, exc))
    return out


def _signal_row(owner: str, s: Signal, value: Any, failed: BaseException | None) -> Row:
    name = f"{owner}.{s.name}"
    if failed is not None:
        return Row(name, "signal", None, _unreadable(failed), s.units, *_limits(s), False)
    text = s.format(value) if s.is_text else ""  # a text: as it is ('' when empty)
    if s.show is not None:
        try:
            text = s.show(value)
        except (TypeError, ValueError):
            text = ""
    return Row(name, "signal", value, text or _format(value, s.fmt), s.units, *_limits(s),
               False)


def _unreadable(exc: BaseException) -> str:
    return f"<unreadable: {type(exc).__name__}>"


def _limits(s: Signal) -> tuple[str, float | None, float | None]:
    lim = s.limits
    if lim is None:
        return "", None, None
    return f"{lim.lopr:g}..{lim.hopr:g}", lim.lopr, lim.hopr


def _format(value: Any, fmt: str) -> str:
    try:
        return format(value, fmt)
    except (TypeError, ValueError):
        return str(value)


def _param_row(owner: str, p: Param, value: Any, failed: BaseException | None) -> Row:
    text = _unreadable(failed) if failed is not None else p.text(value)
    lo = "" if p.lo is None else p.text(p.lo)
    hi = "" if p.hi is None else p.text(p.hi)
    if p.lo is not None and p.hi is not None:
        rng = f"{lo}..{hi}"
    elif p.lo is not None:
        rng = f">= {lo}"
    elif p.hi is not None:
        rng = f"<= {hi}"
    else:
        rng = ""
    return Row(f"{owner}.{p.name}", "param", value, text, p.units, rng, p.lo, p.hi, p.writable)


def read_table(station: Any, prefix: str = "", limit: int = MAX_ROWS,
               runner: Any = None) -> Table:
    """The rows of ``station`` whose ``OBJECT.NAME`` starts with ``prefix`` (any
    case), at most ``limit`` of them.  The rows are picked in the caller's
    thread; their values are read in **one** mailbox call of ``runner`` (so
    every value is of the same tick, and the loop pays only for the rows
    shown), or here when ``runner`` is None (the loop thread, or a station
    not started)."""
    key = prefix.strip().lower()
    picked: list[tuple[str, Signal | Param]] = []
    left: dict[str, int] = {}
    matched = total = 0
    objects: list[str] = []
    for comp in station.components():
        objects.append(comp.name)
        for item in [*station.signals_of(comp), *station.params_of(comp)]:
            total += 1
            if not f"{comp.name}.{item.name}".lower().startswith(key):
                continue
            matched += 1
            if len(picked) < limit:
                picked.append((comp.name, item))
            else:
                left[comp.name] = left.get(comp.name, 0) + 1
    items = [item for _owner, item in picked]
    if runner is None:
        values = _read_all(items)
    else:
        values = runner.call(_read_all, items, name="show", take_fault=False)
    rows = tuple(_signal_row(owner, item, *read) if isinstance(item, Signal)
                 else _param_row(owner, item, *read)
                 for (owner, item), read in zip(picked, values, strict=True))
    return Table(prefix.strip(), rows, matched, total, tuple(left.items()), tuple(objects),
                 limit)


def require_rows(table: Table) -> Table:
    """``table`` when its prefix matched a row (or the station has none at all);
    else CommandError saying that nothing matches and what there is (a
    read: nothing was changed)."""
    if not table.matched and table.total:
        raise CommandError(table.note())
    return table


def table_lines(table: Table) -> list[str]:
    """The table as the console shows it: a header and aligned columns, then
    :meth:`Table.note` when it says something."""
    if not table.rows:
        return [table.note()]
    cells = [tuple(_cut(c) for c in row.cells()) for row in table.rows]
    widths = [max(len(h), *(len(r[k]) for r in cells)) for k, h in enumerate(COLUMNS)]

    def line(parts: tuple[str, ...]) -> str:
        name, value, units, rng, writable = parts
        return "  ".join((name.ljust(widths[0]), value.rjust(widths[1]),
                          units.ljust(widths[2]), rng.ljust(widths[3]), writable)).rstrip()

    out = [line(COLUMNS), line(tuple("-" * w for w in widths))]  # type: ignore[arg-type]
    out += [line(r) for r in cells]
    note = table.note()
    if note:
        out.append(note)
    return out


def data_lines(table: Table) -> list[str]:
    """The same table as data (the DAQ link's ``TABLE``): one JSON object a row
    (:meth:`Row.data`), then one for the table: ``rows`` shown, ``matched``,
    ``total``, ``left_out`` and the ``note`` the console shows after it."""
    out = [json.dumps(row.data(), separators=(",", ":"), allow_nan=False) for row in table.rows]
    out.append(json.dumps({"rows": len(table.rows), "matched": table.matched,
                           "total": table.total, "left_out": table.omitted,
                           "note": table.note()}, separators=(",", ":")))
    return out


class ShowWord:
    """The ``show`` word of :class:`~pyrt.commands.RobotShell` (a part of it)."""

    if TYPE_CHECKING:  # the shell's, used here
        station: Any
        runner: Any

        def say(self, text: str = "") -> None: ...

    @command(Arg("PREFIX", str, optional=True), name="show", reads_only=True, console=True)
    def do_show(self, prefix: str = "") -> None:
        """show [PREFIX]: every signal and parameter: name, value, units, range, writable.

        PREFIX keeps the rows whose OBJECT.NAME starts with it, in any case:
        show axis0 (axis0, axis0Motor ...), show puma560. (the PUMA's own
        rows), show gripper.s.  A signal's range is its
        display range, a parameter's the range set checks; writable: yes
        for a parameter set OBJECT.FIELD VALUE may change (get says when),
        no for signals.  Every value comes from the same tick.  At most
        250 rows are shown; the line after the table says how many were
        left out and which prefixes narrow it.  A prefix that matches
        nothing is an error that says what there is (a read: nothing
        changed).  Over the DAQ link, TABLE [PREFIX] gives the same rows
        as JSON."""
        st = self.station
        table = read_table(st, prefix or "", runner=self.runner)
        for text in table_lines(require_rows(table)):
            self.say(text)
