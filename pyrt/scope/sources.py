"""Where a scope channel reads its value, compiled into one fast getter.

A robot resolves a channel name (``axis0.tension``, ``prototype.x``,
``ram:4A``) to a :class:`Source`; :func:`compile_sources` turns a list of
sources into a single function returning a tuple of floats, built once so
that sampling 8 channels costs one Python call and 8 attribute or item
loads rather than 8 calls.

The kinds, cheapest first: an attribute (``obj.name``), an item of a
sequence updated in place (``seq[i]``), an item of a sequence an attribute
holds (``obj.name[i]``, the attribute replaced or not), a little-endian RAM
word, a call (``fn()``), and an item of a call's result (``fn()[i]``): a
compiled read calls each such ``fn`` once, whatever number of its items it
reads (a vector a plant computes whole, read once a sample).
"""

from __future__ import annotations

import keyword
import struct
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

__all__ = ["Source", "compile_sampler", "compile_sources"]


@dataclass(frozen=True)
class Source:
    """One readable value: an attribute, an item, a little-endian RAM word or a call."""

    kind: str  # "attr" | "item" | "attritem" | "word" | "call" | "callitem"
    obj: Any
    key: Any = None
    signed: bool = False
    #: What the value is measured in (``cm``, ``N``, ``byte`` ...), for plots; "" unknown.
    units: str = ""
    #: How the robot writes the value (a format spec: ``02X`` for a hex byte), for plots.
    fmt: str = ""

    def described(self, units: str, fmt: str = "") -> Source:
        """The same source, with the units and format its plots show."""
        return replace(self, units=units, fmt=fmt)

    @classmethod
    def attr(cls, obj: Any, name: str) -> Source:
        """``obj.name``: ``name`` must be an attribute the object has."""
        if not name.isidentifier() or keyword.iskeyword(name):
            raise ValueError(f"not an attribute name: {name!r}")
        if not hasattr(obj, name):
            raise ValueError(f"{type(obj).__name__} has no attribute {name!r}")
        return cls("attr", obj, name)

    @classmethod
    def item(cls, seq: Any, index: int) -> Source:
        """``seq[index]`` for an integer index inside the sequence."""
        if not isinstance(index, int) or not -len(seq) <= index < len(seq):
            raise ValueError(f"index {index!r} outside 0..{len(seq) - 1}")
        return cls("item", seq, index)

    @classmethod
    def attr_item(cls, obj: Any, name: str, index: int) -> Source:
        """``obj.name[index]``: an item of the sequence the attribute holds when
        it is read (``name`` must be an attribute the object has, ``index`` an
        integer inside its sequence now)."""
        attr = cls.attr(obj, name)
        seq = getattr(obj, name)
        if isinstance(index, bool) or not isinstance(index, int) \
                or not -len(seq) <= index < len(seq):
            raise ValueError(f"index {index!r} outside 0..{len(seq) - 1}")
        return cls("attritem", attr.obj, (name, index))

    @classmethod
    def word(cls, mem: Any, address: int, signed: bool = False) -> Source:
        """The little-endian 16-bit word at ``mem[address]``, ``mem[address+1]``."""
        if not isinstance(address, int) or not 0 <= address < len(mem) - 1:
            raise ValueError(f"word address {address!r} outside 00..{len(mem) - 2:02X}")
        return cls("word", mem, address, signed)

    @classmethod
    def call(cls, fn: Callable[[], float | str]) -> Source:
        """Whatever ``fn()`` returns (the slowest kind: a call per sample): a
        number, or text for a value only served (never plotted) by the server."""
        if not callable(fn):
            raise ValueError(f"not callable: {fn!r}")
        return cls("call", fn)

    @classmethod
    def call_item(cls, fn: Callable[[], Sequence[Any]], index: int) -> Source:
        """Item ``index`` of what ``fn()`` returns; a compiled read calls ``fn``
        once for every source of this kind it holds that has the same ``fn``
        (equal: a bound method made twice counts as one)."""
        if not callable(fn):
            raise ValueError(f"not callable: {fn!r}")
        if isinstance(index, bool) or not isinstance(index, int):
            raise ValueError(f"index {index!r} is not an integer")
        return cls("callitem", fn, index)

    def read(self) -> float:
        """The value now (for one-off reads; sampling uses :func:`compile_sources`)."""
        return compile_sources([self])()[0]


def _expr(i: int, src: Source) -> str:
    o = f"o{i}"
    if src.kind == "attr":
        return f"{o}.{src.key}"
    if src.kind == "item":
        return f"{o}[{int(src.key)}]"
    if src.kind == "attritem":
        name, index = src.key
        if not str(name).isidentifier() or keyword.iskeyword(name):
            raise ValueError(f"not an attribute name: {name!r}")
        return f"{o}.{name}[{int(index)}]"
    if src.kind == "word":
        a = int(src.key)
        w = f"({o}[{a}] | ({o}[{a + 1}] << 8))"
        return f"(({w} ^ 0x8000) - 0x8000)" if src.signed else w
    if src.kind == "call":
        return f"{o}()"
    raise ValueError(f"unknown source kind {src.kind!r}")


def _compiled(sources: Sequence[Source]) -> tuple[str, list[str]]:
    """The statements a compiled read runs first (each shared call once, into a
    local ``cN``) and every source's expression, in order."""
    calls: list[tuple[Any, str]] = []  # (fn, its local): found by equality
    first: list[str] = []
    exprs: list[str] = []
    for i, src in enumerate(sources):
        if src.kind != "callitem":
            exprs.append(_expr(i, src))
            continue
        local = next((name for fn, name in calls if _same_call(fn, src.obj)), None)
        if local is None:
            local = f"c{i}"
            calls.append((src.obj, local))
            first.append(f"    {local} = o{i}()\n")
        exprs.append(f"{local}[{int(src.key)}]")
    return "".join(first), exprs


def _same_call(a: Any, b: Any) -> bool:
    if a is b:
        return True
    try:
        return bool(a == b)
    except Exception:
        return False


def compile_sources(sources: Sequence[Source]) -> Callable[[], tuple]:
    """One function reading every source, returning their values as a tuple."""
    first, exprs = _compiled(sources)
    body = ", ".join(exprs)
    # the sources are the function's globals (no defaults copied at each call)
    code = (f"def read():\n{first}"
            f"    return ({body}{',' if len(sources) == 1 else ''})\n")
    namespace: dict[str, Any] = {f"o{i}": s.obj for i, s in enumerate(sources)}
    # The code is built only from validated identifiers and integers.
    exec(compile(code, "<pyrt scope sources>", "exec"), namespace)
    return namespace["read"]


#: Arguments a generated ``pack_into`` call passes at most: a call of more than
#: 30 is compiled to build a list and a tuple of them first.
_PACK_ARGS = 29


def compile_sampler(sources: Sequence[Source], pack_into: Callable[..., None]) -> Callable:
    """One function ``sample(buf, offset, now_ns)`` that packs the time and every
    source's value straight into ``buf`` with ``pack_into`` (a ``struct.Struct``
    method for ``"<q" + "d" * len(sources)``): a few C calls, no tuple built.
    Given that struct's own ``pack_into``, the row is packed in pieces of at
    most :data:`_PACK_ARGS` arguments each (the same bytes; a read that fails
    leaves the row partly written, which the caller then does not keep)."""
    first, exprs = _compiled(sources)
    namespace: dict[str, Any] = {f"o{i}": s.obj for i, s in enumerate(sources)}
    n = len(sources)
    packer = getattr(pack_into, "__self__", None)
    if (isinstance(packer, struct.Struct) and packer.format == "<q" + "d" * n
            and getattr(pack_into, "__name__", "") == "pack_into"):
        # the time and the first values, then the rest in pieces
        first_n = min(n, _PACK_ARGS - 3)
        namespace["pack0"] = struct.Struct("<q" + "d" * first_n).pack_into
        lines = [f"    pack0(buf, offset, now_ns{''.join(f', {e}' for e in exprs[:first_n])})\n"]
        for c, j in enumerate(range(first_n, n, _PACK_ARGS - 2), start=1):
            part = exprs[j:j + _PACK_ARGS - 2]
            namespace[f"pack{c}"] = struct.Struct("<" + "d" * len(part)).pack_into
            lines.append(f"    pack{c}(buf, offset + {8 + 8 * j}, {', '.join(part)})\n")
    else:
        namespace["pack_into"] = pack_into
        lines = [f"    pack_into(buf, offset, now_ns{''.join(f', {e}' for e in exprs)})\n"]
    # the sources are the function's globals (no defaults copied at each call)
    code = "def sample(buf, offset, now_ns):\n" + first + "".join(lines)
    # The code is built only from validated identifiers and integers.
    exec(compile(code, "<pyrt scope sampler>", "exec"), namespace)
    return namespace["sample"]
