"""Register maps: where a station's declared board registers live on Modbus devices.

A map is a TOML file a user writes for a lab's I/O module, drive or PLC
(no code): one table per declared register, ``[BOARD.REGISTER]``, saying
which Modbus **unit** (device id), **table**, **address**, **width**,
**word order**, **signedness** and **scale** hold it::

    # the gripper cage on a Modbus I/O module
    unit = 1                      # the default unit of every register

    [gripper.pa]                  # board "gripper", register "pa"
    table = "input"               # coil | discrete | input | holding
    address = 0

    [gripper.up]
    table = "input"
    address = 3
    width = 32                    # 16 (default) or 32: two registers
    word_order = "big"            # 32 bits: "big" (high word first, default) or "little"

    [gripper.dac]
    table = "holding"
    address = 3
    signed = false                # default: the register's declaration
    scale = 1                     # pyrt value = Modbus value x scale (default 1)

The top level may also name the outputs' **owner**, ``owner = "10.0.0.5"``
(an IP address, ``localhost``, or a list of them): a device serving the
map (``pyrt board-sim --modbus``) then lets only a connection from there
own its outputs and write them; anyone may still read.  Without it, the
first connection that writes owns them (one controller at a time).

Keys of a register's table: ``table`` (required), ``address`` (required,
0..65535: the protocol address, counted from 0), ``unit`` (0..255; default
the top-level ``unit``, else 1), ``width`` (16 or 32 for the register
tables; 1, the default, for coils and discrete inputs), ``word_order``,
``signed``, ``scale`` (a non-zero number).  An array register
(``cnt[256]``) takes ``count`` consecutive places from ``address`` on (one
bit, one or two registers each).

Rules, checked when the back end opens (a map that breaks one is refused
with one line naming the file and line, ``FILE:LINE: ...``): every
register the station declares is placed, and nothing else; an output (the
controller writes it) is in a writable table (``coil`` or ``holding``);
a coil or discrete input holds a 1-bit register; a register's declared
width fits the width it is given; places of one unit and table do not
overlap.

Values.  A value read is decoded (the words joined in word order, then
two's complement if signed), multiplied by ``scale`` and rounded; an
unsigned value is kept to the register's declared width (a 24-bit counter
in a 32-bit place wraps as the counter does), a signed one is clamped to
its range.  A value written is divided by ``scale``, rounded and encoded
the other way round.  A server decodes a value written to it with
:meth:`Place.decode_write`, which refuses (ValueError) a value the register
cannot hold instead of keeping it to the width: 0x0100 written to an 8-bit
register is an illegal value, never 0.

Grouping.  :meth:`RegisterMap.read_groups` joins the inputs of one unit
and table whose places are contiguous into one request (at most 125
registers or 2000 bits, the protocol's limits); :meth:`RegisterMap.write_groups`
does the same for a set of output writes.
"""

from __future__ import annotations

import ipaddress
import re
import tomllib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pyrt.boards.registers import BoardKind, Register
from pyrt.errors import ConfigError

__all__ = [
    "COIL",
    "DISCRETE",
    "HOLDING",
    "INPUT_REG",
    "TABLES",
    "Group",
    "Place",
    "RegisterMap",
    "load_map",
    "parse_map",
]

COIL = "coil"
DISCRETE = "discrete"
INPUT_REG = "input"
HOLDING = "holding"
#: The four Modbus tables.
TABLES = (COIL, DISCRETE, INPUT_REG, HOLDING)
_BITS = (COIL, DISCRETE)
_WRITABLE = (COIL, HOLDING)
#: The most one read request may carry: registers, bits.
MAX_READ_WORDS = 125
MAX_READ_BITS = 2000
#: The most one write request may carry.
MAX_WRITE_WORDS = 123
MAX_WRITE_BITS = 1968

_KEYS = {"table", "address", "unit", "width", "word_order", "signed", "scale"}


@dataclass(frozen=True)
class Place:
    """Where one index of a declared register lives."""

    board: str
    register: Register
    index: int
    unit: int
    table: str
    address: int
    width: int
    word_order: str
    signed: bool
    scale: float

    @property
    def size(self) -> int:
        """How many protocol places it takes (bits or 16-bit registers)."""
        return 2 if self.width == 32 else 1

    @property
    def key(self) -> tuple[str, str, int]:
        """(board, register, index)."""
        return (self.board, self.register.name, self.index)

    def _value(self, words: list[int]) -> int:
        """The words joined, two's complement if signed, times ``scale`` (not kept
        to the register's range)."""
        if self.width == 1:
            raw = int(bool(words[0]))
        elif self.width == 16:
            raw = words[0] & 0xFFFF
        else:
            hi, lo = (words[0], words[1]) if self.word_order == "big" else (words[1], words[0])
            raw = ((hi & 0xFFFF) << 16) | (lo & 0xFFFF)
        if self.signed and raw >= 1 << (self.width - 1):
            raw -= 1 << self.width
        return raw if self.scale == 1 else round(raw * self.scale)

    def decode(self, words: list[int]) -> int:
        """The register value of the protocol values ``words`` (``size`` of them),
        as read: kept to the register's declared width (see the module text)."""
        value = self._value(words)
        reg = self.register
        if reg.signed:
            return min(max(value, reg.low), reg.high)
        return value & reg.high

    def decode_write(self, words: list[int]) -> int:
        """The register value a write of ``words`` asks for; ValueError if the
        register cannot hold it (a device answers exception 03 and writes nothing:
        a value is never wrapped or clamped into range)."""
        return self.register.check_value(self._value(words))

    def encode(self, value: int) -> list[int]:
        """The protocol values of the register value ``value``."""
        raw = value if self.scale == 1 else round(value / self.scale)
        if self.width == 1:
            return [1 if raw else 0]
        raw &= (1 << self.width) - 1
        if self.width == 16:
            return [raw]
        hi, lo = raw >> 16, raw & 0xFFFF
        return [hi, lo] if self.word_order == "big" else [lo, hi]


@dataclass(frozen=True)
class Group:
    """One request: ``count`` places of ``table`` on ``unit`` from ``address``,
    holding ``places`` (in address order)."""

    unit: int
    table: str
    address: int
    count: int
    places: tuple[Place, ...]


class RegisterMap:
    """A checked map (see the module text): every declared register's places."""

    def __init__(self, source: str, places: list[Place], owner: tuple[str, ...] = ()):
        self.source = source
        self.places = places
        #: The addresses a connection must come from to own the outputs (none named: any).
        self.owner = owner
        self.by_key = {p.key: p for p in places}
        self.inputs = [p for p in places if p.register.is_input]
        self.readable_outputs = [p for p in places
                                 if not p.register.is_input and p.register.readback]
        self._input_groups = _groups(self.inputs, write=False)
        self._output_groups = _groups(self.readable_outputs, write=False)

    def read_groups(self) -> list[Group]:
        """The fewest requests that read every input."""
        return self._input_groups

    def output_groups(self) -> list[Group]:
        """The fewest requests that read every readable output (on opening)."""
        return self._output_groups

    def may_own(self, host: str) -> bool:
        """Whether a connection from ``host`` (an IP address) may own the outputs."""
        if not self.owner:
            return True
        try:
            ip = ipaddress.ip_address(host.strip("[]").split("%")[0])
        except ValueError:
            return False
        if isinstance(ip, ipaddress.IPv6Address) and ip.ipv4_mapped is not None:
            ip = ip.ipv4_mapped
        return str(ip) in self.owner

    def write_groups(self, keys: Iterable[tuple[str, str, int]]) -> list[Group]:
        """The fewest requests that write the outputs ``keys`` (board, register, index)."""
        return _groups([self.by_key[k] for k in keys], write=True)


def _groups(places: list[Place], *, write: bool) -> list[Group]:
    out: list[Group] = []
    ordered = sorted(places, key=lambda p: (p.unit, TABLES.index(p.table), p.address))
    cur: list[Place] = []
    for p in ordered:
        if cur:
            first, last = cur[0], cur[-1]
            bits = p.table in _BITS
            limit = (MAX_WRITE_BITS if write else MAX_READ_BITS) if bits else \
                (MAX_WRITE_WORDS if write else MAX_READ_WORDS)
            if (p.unit, p.table) == (first.unit, first.table) \
                    and p.address == last.address + last.size \
                    and p.address + p.size - first.address <= limit:
                cur.append(p)
                continue
            out.append(_group(cur))
        cur = [p]
    if cur:
        out.append(_group(cur))
    return out


def _group(places: list[Place]) -> Group:
    first, last = places[0], places[-1]
    return Group(first.unit, first.table, first.address,
                 last.address + last.size - first.address, tuple(places))


# -- reading a map ------------------------------------------------------------------------


def load_map(path: str | Path, kinds: Mapping[str, BoardKind]) -> RegisterMap:
    """The map in the file ``path`` for the declared boards ``kinds``;
    ConfigError ``FILE:LINE: ...`` if it cannot be read or is not a good map."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{p}: cannot read the register map: "
                          f"{getattr(exc, 'strerror', None) or exc}") from None
    return parse_map(text, kinds, str(p))


def parse_map(text: str, kinds: Mapping[str, BoardKind], source: str = "<map>") -> RegisterMap:
    """The map in ``text`` (TOML) for ``kinds``; ConfigError ``SOURCE:LINE: ...``."""
    lines = text.splitlines()
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        m = re.search(r"line (\d+)", str(exc))
        line = m.group(1) if m else "1"
        raise ConfigError(f"{source}:{line}: not TOML: {exc}") from None

    def bad(line: int, message: str) -> ConfigError:
        return ConfigError(f"{source}:{line}: {message}")

    default_unit = doc.get("unit", 1)
    if not _is_int(default_unit) or not 0 <= default_unit <= 255:
        raise bad(_key_line(lines, None, "unit"), f"unit must be 0..255, got {default_unit!r}")
    owner = _owner(doc.get("owner", ()), lambda m: bad(_key_line(lines, None, "owner"), m))
    places: list[Place] = []
    for board, regs in doc.items():
        if board in ("unit", "owner"):
            continue
        if not isinstance(regs, dict):
            raise bad(_key_line(lines, None, board), f"{board!r} is not a board's table "
                                                     "([BOARD.REGISTER] tables)")
        kind = kinds.get(board)
        if kind is None:
            raise bad(_header_line(lines, board, None),
                      f"unknown board {board!r}; the station declares "
                      f"{', '.join(kinds) or 'none'}")
        for name, spec in regs.items():
            header = (board, name)
            if name not in kind:
                raise bad(_header_line(lines, board, name),
                          f"unknown register {board}.{name}; a {kind.name} board has "
                          f"{' '.join(r.name for r in kind.registers)}")
            if not isinstance(spec, dict):
                raise bad(_header_line(lines, board, name),
                          f"{board}.{name} must be a table ([{board}.{name}])")
            places += _places(kind.register(name), board, spec, default_unit,
                              lambda key, h=header: _key_line(lines, h, key), bad)
    missing = [f"{b}.{r.name}" for b, k in kinds.items() for r in k.registers
               if (b, r.name, 0) not in {p.key for p in places}]
    if missing:
        raise bad(len(lines) or 1, f"the map does not place {', '.join(missing)} "
                                   "(every declared register needs a place)")
    seen: dict[tuple[int, str, int], Place] = {}
    for p in places:
        for a in range(p.address, p.address + p.size):
            other = seen.get((p.unit, p.table, a))
            if other is not None:
                raise bad(_key_line(lines, (p.board, p.register.name), "address"),
                          f"{p.board}.{p.register.name}[{p.index}] overlaps "
                          f"{other.board}.{other.register.name}[{other.index}] at unit "
                          f"{p.unit} {p.table} address {a}")
            seen[(p.unit, p.table, a)] = p
    return RegisterMap(source, places, owner)


def _owner(value: Any, bad: Any) -> tuple[str, ...]:
    """The top-level ``owner``: IP addresses (``localhost``: the loopback ones)."""
    names = [value] if isinstance(value, str) else value
    if not isinstance(names, (list, tuple)) or not all(isinstance(v, str) for v in names):
        raise bad(f"owner must be an IP address or a list of them, got {value!r}")
    out: list[str] = []
    for name in names:
        if name.strip().lower() == "localhost":
            out += ["127.0.0.1", "::1"]
            continue
        try:
            out.append(str(ipaddress.ip_address(name.strip())))
        except ValueError:
            raise bad(f"owner: {name!r} is not an IP address (or localhost)") from None
    return tuple(out)


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _places(reg: Register, board: str, spec: dict[str, Any], default_unit: int,
            line_of: Any, bad: Any) -> list[Place]:
    what = f"{board}.{reg.name}"
    unknown = sorted(set(spec) - _KEYS)
    if unknown:
        raise bad(line_of(unknown[0]), f"{what}: unknown key {unknown[0]!r}; keys: "
                                       f"{', '.join(sorted(_KEYS))}")
    table = spec.get("table")
    if table not in TABLES:
        raise bad(line_of("table"), f"{what}: table must be one of {', '.join(TABLES)}, "
                                    f"got {table!r}")
    if not reg.is_input and table not in _WRITABLE:
        raise bad(line_of("table"), f"{what} is an output: it needs a writable table "
                                    f"(coil or holding), not {table}")
    address: Any = spec.get("address")
    if not _is_int(address) or not 0 <= address <= 0xFFFF:
        raise bad(line_of("address"), f"{what}: address must be 0..65535, got {address!r}")
    unit = spec.get("unit", default_unit)
    if not _is_int(unit) or not 0 <= unit <= 255:
        raise bad(line_of("unit"), f"{what}: unit must be 0..255, got {unit!r}")
    bits = table in _BITS
    width = spec.get("width", 1 if bits else 16)
    if bits:
        if width != 1:
            raise bad(line_of("width"), f"{what}: width out of range: a {table} holds 1 bit, "
                                        f"got {width!r}")
        if reg.width != 1:
            raise bad(line_of("table"), f"{what} is {reg.width} bits wide: a {table} holds "
                                        "1 bit (use input or holding registers)")
    elif width not in (16, 32):
        raise bad(line_of("width"), f"{what}: width out of range: 16 or 32 bits for a "
                                    f"{table} register, got {width!r}")
    elif reg.width > width:
        raise bad(line_of("width"), f"{what}: width out of range: the register is "
                                    f"{reg.width} bits wide, its place {width}")
    order = spec.get("word_order", "big")
    if order not in ("big", "little"):
        raise bad(line_of("word_order"), f"{what}: word_order must be big or little, "
                                         f"got {order!r}")
    signed = spec.get("signed", reg.signed)
    if not isinstance(signed, bool):
        raise bad(line_of("signed"), f"{what}: signed must be true or false, got {signed!r}")
    scale = spec.get("scale", 1)
    if isinstance(scale, bool) or not isinstance(scale, (int, float)) or scale == 0 \
            or scale != scale or abs(scale) == float("inf"):
        raise bad(line_of("scale"), f"{what}: scale must be a non-zero number, got {scale!r}")
    size = 2 if width == 32 else 1
    if address + size * reg.count - 1 > 0xFFFF:
        raise bad(line_of("address"), f"{what}: {reg.count} places from {address} run past "
                                      "address 65535")
    return [Place(board, reg, i, unit, table, address + i * size, width, order, signed,
                  scale) for i in range(reg.count)]


def _header_line(lines: list[str], board: str, name: str | None) -> int:
    """The line of ``[board.name]`` (or of the first header of ``board``)."""
    for n, line in enumerate(lines, 1):
        m = re.match(r"\s*\[\s*([A-Za-z0-9_\"'-]+)\s*(?:\.\s*([A-Za-z0-9_\"'-]+)\s*)?\]", line)
        if m and m.group(1).strip("\"'") == board \
                and (name is None or (m.group(2) or "").strip("\"'") == name):
            return n
    return 1


def _key_line(lines: list[str], header: tuple[str, str] | None, key: str) -> int:
    """The line of ``key = ...`` under ``header`` (None: the top level)."""
    start = 0 if header is None else _header_line(lines, *header)
    for n in range(start + 1 if header else 1, len(lines) + 1):
        line = lines[n - 1]
        if re.match(r"\s*\[", line):
            if header is None:
                break
            if n > start:
                break
        if re.match(rf"\s*{re.escape(key)}\s*=", line):
            return n
    return start or 1
