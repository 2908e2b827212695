"""A station: the six object database files of one manipulator, read together.

:func:`load_station` reads POLYAXIS.dat, AXIS.dat, MOTOR.dat, ENCODER.dat,
LOADCELL.dat and AV.dat from a directory, builds the typed records and
resolves every cross reference (PolyAxis -> Axis -> Motor/Encoder/Loadcell,
PolyAxis -> AV).  Anything wrong refuses to load with a
:class:`~pyrt.errors.ConfigError` naming the file and line.

:meth:`Station.write_back` rewrites values in place: only the characters of
the changed numbers change, comments, spacing and line endings stay, and
each file is replaced atomically.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import stat
import threading
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pyrt.db._schema import FILES, SCHEMAS, VERSIONS, build_record, format_value
from pyrt.db._text import ENCODING, ERRORS, DatFile, parse_text
from pyrt.db.records import (
    AVRecord,
    AxisRecord,
    EncoderRecord,
    LoadcellRecord,
    MotorRecord,
    PolyAxisRecord,
)
from pyrt.errors import ConfigError, PyrtError
from pyrt.fileio import atomic_write, disk_error

__all__ = [
    "MAX_DB_BYTES",
    "TYPES",
    "ObjectRef",
    "Station",
    "UnknownNameError",
    "load_station",
    "parse_file",
    "parse_records",
    "read_regular_file",
]

#: The object types of a station, in the order their files are read.
TYPES = ("POLYAXIS", "AXIS", "MOTOR", "ENCODER", "LOADCELL", "AV")

#: Sub-object suffixes of an Axis's compound names (``axis0Motor``, section 6).
_SUFFIXES = {"motor": "MOTOR", "encoder": "ENCODER", "loadcell": "LOADCELL"}


class UnknownNameError(PyrtError, LookupError):
    """No object of that name in the station."""

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""


@dataclass(frozen=True)
class ObjectRef:
    """What a code name (``prototype``, ``axis0``, ``axis0Motor``) refers to."""

    kind: str  # POLYAXIS, AXIS, MOTOR, ENCODER, LOADCELL or AV
    name: str  # the code name as the station spells it (axis0Motor)
    record: Any
    axis: str | None = None  # the Axis a sub-object belongs to


def parse_records(text: str, file: str, type_: str) -> tuple[DatFile, dict[str, Any]]:
    """Parse one file's text: its lines and its records keyed by lower-case name."""
    type_ = type_.upper()
    schema = SCHEMAS.get(type_)
    if schema is None:
        raise ConfigError(f"unknown object type {type_!r}; expected one of {', '.join(TYPES)}",
                          file)
    dat = parse_text(text, file, type_, VERSIONS[type_])
    records = {e.name.lower(): build_record(schema, e, file) for e in dat.entries}
    return dat, records


#: Longest database file read (bytes): a station's files are a few kB.
MAX_DB_BYTES = 1 << 20


def read_regular_file(path: str | Path, limit: int) -> bytes:
    """The bytes of ``path``, which must be a regular file of at most ``limit``
    bytes (ConfigError naming the file if not).  Never blocks on a FIFO or a
    device and never reads more than ``limit + 1`` bytes (a file that grows
    while it is read is refused too)."""
    p = str(path)
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0)
    fd = os.open(p, flags)
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise ConfigError("not a regular file", p)
        if st.st_size > limit:
            raise ConfigError(f"{st.st_size} bytes, more than the {limit} bytes allowed", p)
        chunks: list[bytes] = []
        got = 0
        while got <= limit:
            chunk = os.read(fd, limit + 1 - got)
            if not chunk:
                break
            chunks.append(chunk)
            got += len(chunk)
        if got > limit:
            raise ConfigError(f"grew past the {limit} bytes allowed while read", p)
        return b"".join(chunks)
    finally:
        os.close(fd)


def parse_file(path: str | Path, type_: str | None = None) -> tuple[DatFile, dict[str, Any]]:
    """Read one database file (type from the file name unless given)."""
    path = Path(path)
    if type_ is None:
        stem = path.stem.upper()
        if stem not in SCHEMAS:
            raise ConfigError(f"cannot tell the object type of {path.name}; expected one of "
                              f"{', '.join(FILES.values())}", str(path))
        type_ = stem
    try:
        data = read_regular_file(path, MAX_DB_BYTES)
    except FileNotFoundError:
        raise ConfigError(f"missing database file: expected {path.name} holding the "
                          f"{type_.upper()} entries", str(path)) from None
    except OSError as e:
        raise ConfigError(f"cannot read: {e.strerror}", str(path)) from None
    return parse_records(data.decode(ENCODING, ERRORS), str(path), type_)


class Station:
    """The records of one station directory, with case-insensitive lookups and
    in-place write-back.  Build it with :func:`load_station`.

    Records are immutable; a write-back replaces them.  All methods are
    thread-safe (one lock), so a writer thread may write back while the
    control loop reads records.
    """

    def __init__(self, directory: Path, files: dict[str, DatFile],
                 records: dict[str, dict[str, Any]]):
        self.directory = Path(directory)
        self._files = files
        self._records = records
        self._lock = threading.RLock()

    # -- lookups ---------------------------------------------------------

    def record(self, type_: str, name: str) -> Any:
        """The record of ``type_`` named ``name`` (case-insensitive)."""
        t = type_.upper()
        table = self._records.get(t)
        if table is None:
            raise UnknownNameError(f"unknown object type {type_!r}; expected one of "
                                   f"{', '.join(TYPES)}")
        r = table.get(name.lower())
        if r is None:
            known = ", ".join(x.name for x in table.values()) or "none"
            raise UnknownNameError(f"no {t} named {name!r} in {FILES[t]} (there are: {known})")
        return r

    def records(self, type_: str) -> tuple[Any, ...]:
        """Every record of ``type_``, in file order."""
        return tuple(self._records[type_.upper()].values())

    def polyaxis(self, name: str | None = None) -> PolyAxisRecord:
        """The PolyAxis ``name``; without a name, the only (or first) one."""
        if name is None:
            return self.records("POLYAXIS")[0]
        return self.record("POLYAXIS", name)

    def axis(self, name: str) -> AxisRecord:
        return self.record("AXIS", name)

    def motor(self, name: str) -> MotorRecord:
        return self.record("MOTOR", name)

    def encoder(self, name: str) -> EncoderRecord:
        return self.record("ENCODER", name)

    def loadcell(self, name: str) -> LoadcellRecord:
        return self.record("LOADCELL", name)

    def av(self, name: str) -> AVRecord:
        return self.record("AV", name)

    def axes_of(self, polyaxis: str | PolyAxisRecord | None = None) -> tuple[AxisRecord, ...]:
        """The Axis records of a PolyAxis in its order (index 0 first)."""
        p = polyaxis if isinstance(polyaxis, PolyAxisRecord) else self.polyaxis(polyaxis)
        return tuple(self.axis(a) for a in p.axes)

    def av_of(self, polyaxis: str | PolyAxisRecord | None = None) -> AVRecord:
        """The AV record a PolyAxis uses."""
        p = polyaxis if isinstance(polyaxis, PolyAxisRecord) else self.polyaxis(polyaxis)
        assert p.av is not None  # resolved at load
        return self.av(p.av)

    def motor_of(self, axis: str | AxisRecord) -> MotorRecord:
        a = axis if isinstance(axis, AxisRecord) else self.axis(axis)
        return self.motor(a.motor)

    def encoder_of(self, axis: str | AxisRecord) -> EncoderRecord:
        a = axis if isinstance(axis, AxisRecord) else self.axis(axis)
        return self.encoder(a.encoder)

    def loadcell_of(self, axis: str | AxisRecord) -> LoadcellRecord:
        a = axis if isinstance(axis, AxisRecord) else self.axis(axis)
        return self.loadcell(a.loadcell)

    def find(self, name: str) -> ObjectRef:
        """Resolve a code name: a PolyAxis, an Axis, an AV, or an Axis's
        sub-object by its compound name (``axis0Motor``, ``AXIS0encoder``,
        ``axis0Loadcell``; section 6).  Case-insensitive."""
        key = name.lower()
        for t in ("POLYAXIS", "AXIS", "AV"):
            r = self._records[t].get(key)
            if r is not None:
                return ObjectRef(t, r.name, r)
        for suffix, t in _SUFFIXES.items():
            if key.endswith(suffix) and len(key) > len(suffix):
                a = self._records["AXIS"].get(key[: -len(suffix)])
                if a is not None:
                    sub = self.record(t, getattr(a, t.lower()))
                    return ObjectRef(t, a.name + suffix.capitalize(), sub, axis=a.name)
        raise UnknownNameError(
            f"no object named {name!r}; expected one of {', '.join(self.object_names())}")

    def object_names(self) -> list[str]:
        """Every code name :meth:`find` resolves, PolyAxes first."""
        names = [p.name for p in self.records("POLYAXIS")]
        for a in self.records("AXIS"):
            names.append(a.name)
            names.extend(a.name + s.capitalize() for s in _SUFFIXES)
        names.extend(v.name for v in self.records("AV"))
        return names

    def writable(self, type_: str, key: str) -> bool:
        """Whether ``TYPE KEY`` is a value pyrt writes back."""
        schema = SCHEMAS.get(type_.upper())
        spec = schema.spec(key) if schema is not None else None
        return spec is not None and spec.writable

    def path(self, type_: str) -> Path:
        """The file holding ``type_`` entries."""
        return self.directory / FILES[type_.upper()]

    def text(self, type_: str) -> str:
        """The current text of ``type_``'s file as pyrt holds it."""
        with self._lock:
            return self._files[type_.upper()].text()

    # -- write-back ----------------------------------------------------------

    def update(self, type_: str, name: str, key: str, value: Any) -> Any:
        """Write one value back (atomically) and return the new record."""
        self.write_back({(type_, name, key): value})
        return self.record(type_, name)

    def write_back(self, changes: Mapping[tuple[str, str, str], Any]
                   | Iterable[tuple[tuple[str, str, str], Any]]) -> list[Path]:
        """Rewrite values in place: ``{(TYPE, name, KEY): value}`` in base units.

        Only the changed numbers' characters change (the unit text stays and
        the number is converted into it); each touched file is re-read from
        its new text (so a value a record would refuse is refused here) and
        replaced atomically.  Bad input raises ConfigError and writes
        nothing.  A file that cannot be written (a full disk) raises
        DiskError naming it and keeps its last good value.  Returns the files
        written (a value equal to the file's is no change).
        """
        items = list(changes.items()) if isinstance(changes, Mapping) else list(changes)
        with self._lock:
            by_type: dict[str, dict[tuple[str, str], Any]] = {}
            for (type_, name, key), value in items:
                t = type_.upper()
                if t not in SCHEMAS:
                    raise ConfigError(f"unknown object type {type_!r}; expected one of "
                                      f"{', '.join(TYPES)}")
                slot = (name.lower(), key.upper())
                if slot in by_type.setdefault(t, {}):
                    raise ConfigError(f"{t} {name} {key.upper()} is given twice in one "
                                      "write-back")
                by_type[t][slot] = value
            staged: list[tuple[str, DatFile, dict[str, Any], bytes]] = []
            # files in one order whatever the batch's (a failure names the same file)
            for t, values in sorted(by_type.items(), key=lambda kv: TYPES.index(kv[0])):
                staged_file = self._stage(t, values)
                if staged_file is not None:
                    staged.append((t, *staged_file))
            written = []
            for t, dat, records, data in staged:
                try:
                    atomic_write(self.path(t), data)
                except OSError as exc:  # the file keeps its last good value
                    raise disk_error("", self.path(t), exc) from None
                self._files[t] = dat
                self._records[t] = _keep_resolved(self._records[t], records)
                written.append(self.path(t))
            return written

    def _stage(self, t: str, values: dict[tuple[str, str], Any]
               ) -> tuple[DatFile, dict[str, Any], bytes] | None:
        dat = self._files[t]
        schema = SCHEMAS[t]
        file = str(self.path(t))
        entries = {e.name.lower(): e for e in dat.entries}
        lines = list(dat.lines)
        inserts: list[tuple[int, str, Any]] = []
        for (lname, key), value in values.items():
            entry = entries.get(lname)
            if entry is None:
                raise ConfigError(f"no {t} entry named {lname!r} to write back", file)
            spec = schema.spec(key)
            if spec is None or not spec.writable:
                writable = ", ".join(f.key for f in schema.fields if f.writable)
                raise ConfigError(f"{t} {key} is not written back; writable keys: {writable}",
                                  file, entry.line)
            raw = next((f for f in entry.fields if f.key == key), None)
            if raw is None and not spec.required and spec.kind == "text" and entry.end_line:
                inserts.append((entry.end_line, key, value))  # a new line before END;
                continue
            if raw is None:
                raise ConfigError(f"{t} entry {entry.name!r} has no {key}: line to rewrite",
                                  file, entry.line)
            try:
                new = format_value(spec, raw.value, value)
            except ValueError as e:
                raise ConfigError(f"cannot write {key} = {value!r}: {e}", file,
                                  raw.line) from None
            line = lines[raw.line - 1]
            lines[raw.line - 1] = line[: raw.start] + new + line[raw.end:]
        for end_line, key, value in sorted(inserts, key=lambda i: i[0], reverse=True):
            try:  # an optional key the entry did not have yet, in the file's line ending
                new = format_value(schema.spec(key), "", value)  # type: ignore[arg-type]
            except ValueError as e:
                raise ConfigError(f"cannot write {key} = {value!r}: {e}", file,
                                  end_line) from None
            end = lines[end_line - 1]
            eol = end[len(end.rstrip("\r\n")):] or "\n"
            lines.insert(end_line - 1, f"{key}: {new}{eol}")
        text = "".join(lines)
        if text == dat.text():
            return None
        new_dat, records = parse_records(text, file, t)
        return new_dat, records, new_dat.encode()


def _keep_resolved(old: dict[str, Any], new: dict[str, Any]) -> dict[str, Any]:
    """New records, keeping what loading resolved (a PolyAxis's AV)."""
    out = {}
    for k, r in new.items():
        prev = old.get(k)
        if isinstance(r, PolyAxisRecord) and r.av is None and prev is not None:
            r = dataclasses.replace(r, av=prev.av)
        out[k] = r
    return out


def load_station(directory: str | Path) -> Station:
    """Read the six database files of ``directory`` and resolve references."""
    directory = Path(directory)
    if not directory.is_dir():
        raise ConfigError("expected a station directory holding "
                          f"{', '.join(FILES.values())}", str(directory))
    _remove_stale_temp_files(directory)
    files: dict[str, DatFile] = {}
    records: dict[str, dict[str, Any]] = {}
    for t in TYPES:
        files[t], records[t] = parse_file(directory / FILES[t], t)
    _resolve(files, records)
    return Station(directory, files, records)


#: A temp file older than this is a crashed write's leftover (a write takes
#: milliseconds); younger ones may belong to a writer still running.
STALE_TEMP_S = 60.0


def _remove_stale_temp_files(directory: Path) -> None:
    """Delete ``.NAME.dat.*.tmp`` files that a killed write-back left behind."""
    now = time.time()
    for filename in FILES.values():
        for tmp in directory.glob(f".{filename}.*.tmp"):
            with contextlib.suppress(OSError):
                if now - tmp.stat().st_mtime > STALE_TEMP_S:
                    tmp.unlink()


def _field_lines(dat: DatFile, name: str, key: str) -> list[int]:
    for e in dat.entries:
        if e.name.lower() == name.lower():
            return [f.line for f in e.fields if f.key == key]
    return []  # pragma: no cover - records come from these entries


def _resolve(files: dict[str, DatFile], records: dict[str, dict[str, Any]]) -> None:
    """Check every reference; fill in a PolyAxis's AV when AV.dat has one entry."""
    if not records["POLYAXIS"]:
        raise ConfigError("expected at least one 'POLYAXIS: name' entry",
                          files["POLYAXIS"].file, 1)
    avs = records["AV"]
    for key, p in list(records["POLYAXIS"].items()):
        where = p.where
        if not p.axes:
            raise where.error(None, f"POLYAXIS {p.name!r} lists no axes; expected one "
                              "'AXIS: name' line per rope")
        lines = _field_lines(files["POLYAXIS"], p.name, "AXIS")
        for a, line in zip(p.axes, lines, strict=True):
            if a.lower() not in records["AXIS"]:
                raise ConfigError(f"AXIS {a!r} is not in {FILES['AXIS']} (there are: "
                                  f"{', '.join(x.name for x in records['AXIS'].values())})",
                                  where.file, line)
        if p.av is None:
            if len(avs) != 1:
                raise where.error(None, f"POLYAXIS {p.name!r} needs an 'AV: name' line: "
                                  f"{FILES['AV']} holds {len(avs)} entries")
            records["POLYAXIS"][key] = dataclasses.replace(p, av=next(iter(avs.values())).name)
        elif p.av.lower() not in avs:
            raise where.error("AV", f"AV {p.av!r} is not in {FILES['AV']} (there are: "
                              f"{', '.join(v.name for v in avs.values())})")
    for a in records["AXIS"].values():
        for t in ("MOTOR", "ENCODER", "LOADCELL"):
            ref = getattr(a, t.lower())
            if ref.lower() not in records[t]:
                raise a.where.error(t, f"{t} {ref!r} is not in {FILES[t]} (there are: "
                                    f"{', '.join(x.name for x in records[t].values()) or 'none'})")
    # Within one PolyAxis, no two ropes may share hardware.
    for p in records["POLYAXIS"].values():
        axes = [records["AXIS"][n.lower()] for n in p.axes]
        for t, attr in (("MOTOR", "channel"), ("ENCODER", "address"), ("LOADCELL", "channel")):
            used: dict[str, str] = {}
            hw: dict[int, str] = {}
            for a in axes:
                ref = getattr(a, t.lower()).lower()
                if ref in used:
                    raise a.where.error(t, f"{t} {ref!r} is used by both {used[ref]} and "
                                        f"{a.name} in POLYAXIS {p.name!r}")
                used[ref] = a.name
                r = records[t][ref]
                value = getattr(r, attr)
                if value in hw:
                    raise r.where.error(attr.upper(), f"{t} {r.name!r} has {attr.upper()} "
                                        f"{value}, as has {hw[value]!r} (both in POLYAXIS "
                                        f"{p.name!r})")
                hw[value] = r.name
