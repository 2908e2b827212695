"""The line grammar of a ``.dat`` object database file.

::

    VERSION1.00                      first line: the version of this object type
    // a comment line                 anywhere after the first line
    TYPE: name                        starts an entry (TYPE is the file's type)
    KEY: value // comment             a field of the entry
    END;                              ends the entry

Keys, types and names are case-insensitive; blank lines are free.  The file
is kept as its original lines (line endings included, undecodable bytes
carried through ``surrogateescape``), so joining the lines gives back the
exact bytes, and a write-back replaces characters inside one value only.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from pyrt.errors import ConfigError

__all__ = ["DatFile", "RawEntry", "RawField", "parse_text", "split_lines"]

ENCODING = "utf-8"
ERRORS = "surrogateescape"

_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.\-]*")
_FIELD = re.compile(r"\s*([A-Za-z_][A-Za-z0-9_]*)\s*:(.*)")
_LINES = re.compile(r"[^\n]*\n|[^\n]+")


@dataclass
class RawField:
    """``KEY: value`` as written: the value text sits at ``line_text[start:end]``."""

    key: str  # upper case
    value: str  # stripped, comment removed
    line: int  # 1-based
    start: int
    end: int


@dataclass
class RawEntry:
    """One ``TYPE: name`` ... ``END;`` entry."""

    type: str
    name: str
    line: int
    end_line: int = 0
    fields: list[RawField] = field(default_factory=list)


@dataclass
class DatFile:
    """A parsed file: its original lines and its entries in file order."""

    file: str
    type: str
    lines: list[str]
    entries: list[RawEntry]

    def text(self) -> str:
        return "".join(self.lines)

    def encode(self) -> bytes:
        return self.text().encode(ENCODING, ERRORS)


def split_lines(text: str) -> list[str]:
    """Lines with their ``\\n`` kept (only ``\\n`` ends a line; ``\\r`` stays in it)."""
    return _LINES.findall(text)


def _content(line: str) -> tuple[str, int]:
    """The line without its end and its ``//`` comment, and where that part ends."""
    body = line.rstrip("\n")
    if body.endswith("\r"):
        body = body[:-1]
    cut = body.find("//")
    if cut >= 0:
        body = body[:cut]
    return body, len(body)


def _show(text: str) -> str:
    text = text.strip()
    return repr(text if len(text) <= 60 else text[:57] + "...")


def parse_text(text: str, file: str, type_: str, version: str) -> DatFile:
    """Parse ``text`` as a file of ``type_`` entries that must carry ``VERSION<version>``."""
    type_ = type_.upper()
    lines = split_lines(text)
    if not lines:
        raise ConfigError(f"expected 'VERSION{version}' on the first line, got an empty file",
                          file, 1)
    first, _ = _content(lines[0])
    first = first.lstrip("\ufeff").strip()
    if first.upper() != f"VERSION{version}":
        if first.upper().startswith("VERSION") and first[7:8].isspace():
            raise ConfigError(
                f"expected 'VERSION{version}' (the string VERSION then the number, no "
                f"spaces), got {_show(first)}", file, 1)
        if first.upper().startswith("VERSION"):
            raise ConfigError(
                f"{type_} files of {first!r} are not read by pyrt: expected 'VERSION{version}' "
                "(the version is local to each object type)", file, 1)
        raise ConfigError(
            f"expected 'VERSION{version}' on the first line (the string VERSION then the "
            f"number, no spaces), got {_show(first)}", file, 1)

    entries: list[RawEntry] = []
    names: dict[str, RawEntry] = {}
    current: RawEntry | None = None
    for index in range(1, len(lines)):
        lineno = index + 1
        line = lines[index]
        body, _ = _content(line)
        stripped = body.strip()
        if not stripped:
            continue
        if stripped.upper() == "END;":
            if current is None:
                raise ConfigError(f"'END;' outside an entry: expected '{type_}: name' first",
                                  file, lineno)
            current.end_line = lineno
            current = None
            continue
        m = _FIELD.fullmatch(body)
        if m is None:
            what = "'KEY: value' or 'END;'" if current else f"'{type_}: name'"
            raise ConfigError(f"expected {what}, got {_show(body)}", file, lineno)
        key = m.group(1).upper()
        raw_value = m.group(2)
        value = raw_value.strip()
        start = m.start(2) + (len(raw_value) - len(raw_value.lstrip()))
        end = start + len(value)
        if current is None:
            if key != type_:
                raise ConfigError(
                    f"expected '{type_}: name' to start an entry, got {_show(body)} "
                    f"(a {type_} file holds {type_} entries only)", file, lineno)
            if not _NAME.fullmatch(value):
                raise ConfigError(
                    f"expected a name after '{type_}:' (letters, digits, _ . -), got "
                    f"{_show(value) if value else 'nothing'}", file, lineno)
            previous = names.get(value.lower())
            if previous is not None:
                raise ConfigError(
                    f"duplicate {type_} entry {value!r} (names are case-insensitive; the "
                    f"first is at line {previous.line})", file, lineno)
            current = RawEntry(type_, value, lineno)
            names[value.lower()] = current
            entries.append(current)
            continue
        if key == type_:
            raise ConfigError(
                f"expected 'END;' to close {type_} entry {current.name!r} (line {current.line}) "
                f"before the next entry", file, lineno)
        if not value:
            raise ConfigError(f"expected a value after '{m.group(1)}:'", file, lineno)
        current.fields.append(RawField(key, value, lineno, start, end))
    if current is not None:
        raise ConfigError(
            f"expected 'END;' to close {type_} entry {current.name!r} (line {current.line}) "
            "before the end of the file", file, current.line)
    return DatFile(file, type_, lines, entries)
