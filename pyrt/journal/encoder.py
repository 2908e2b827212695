"""The journal's tick records encoded a run of ticks at a time in C.

:class:`NativeBlockEncoder` writes the bytes :class:`~pyrt.journal.format.BlockEncoder`
writes (the reference: the tests hold one to the other), but its state
lives in C buffers (:class:`pyrt.native.TickEncoder`) and the records of
a run of ticks are delta-encoded in one C call, the interpreter lock
released.  The ticks come as rows of 64-bit integers (:attr:`~NativeBlockEncoder.row`:
the journal's loop thread packs them into its ring as it hands them over;
:meth:`~NativeBlockEncoder.add_many` packs them here), with the rare output
writes, commands and events beside them.

Anything the C encoder does not take (a value beyond +-2**62, an input
that is not an integer, a record it refuses) moves the encoder, for the
rest of the journal, onto the Python reference, with the state C held:
the bytes stay the same, a refusal is the reference's.
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Sequence
from itertools import chain
from typing import Any

from pyrt.errors import NativeError
from pyrt.journal.format import (
    BLOCK,
    F_COMMANDS,
    F_EVENTS,
    KIND_TICKS,
    KIND_ZTICKS,
    BlockEncoder,
    Header,
    JournalError,
    frame,
    put_str,
    put_svarint,
    put_uvarint,
)
from pyrt.native import JOURNAL_CLOCK, RecordRefused, TickEncoder

__all__ = ["NativeBlockEncoder"]


#: One tick as the journal hands it over: (tick, time_ns, lateness_ns, missed,
#: inputs, outputs, commands, events).
TickItem = tuple[Any, ...]
#: What a packed row leaves out: (outputs, commands, events, the whole tick if it
#: could not be packed, else None).
Extra = tuple[Any, Any, Any, Any]
#: A row's first integer: its tick.
_TICK = struct.Struct("=q")
#: What every output write is: three fields, each an ``int`` (not a bool).
_THREE = {3}
_INT = {int}


def _extras(tick: int, commands: Sequence[tuple[str, str]],
            events: Sequence[tuple[str, int, str]]) -> tuple[int, bytes]:
    """The flags and bytes of a record's commands and events (after its outputs)."""
    for c in commands:
        if len(c) != 2 or not all(type(x) is str for x in c):
            raise JournalError(f"journal: tick {tick}: a command is (text, source), got {c!r}")
    for e in events:
        if len(e) != 3 or type(e[0]) is not str or type(e[1]) is not int \
                or type(e[2]) is not str:
            raise JournalError(f"journal: tick {tick}: an event is (name, id, message), "
                               f"got {e!r}")
    out = bytearray()
    flags = 0
    try:
        if commands:
            flags |= F_COMMANDS
            put_uvarint(out, len(commands))
            for text, source in commands:
                put_str(out, text)
                put_str(out, source)
        if events:
            flags |= F_EVENTS
            put_uvarint(out, len(events))
            for name, ident, message in events:
                put_str(out, name)
                put_svarint(out, ident)
                put_str(out, message)
    except (TypeError, ValueError):
        raise JournalError(f"journal: tick {tick}: a command or event that has no UTF-8 "
                           "text") from None
    return flags, bytes(out)


class NativeBlockEncoder:
    """Encodes tick records into blocks, as :class:`BlockEncoder` does, in C
    (see the module text).  Not thread-safe: one thread owns it."""

    def __init__(self, header: Header, compress: int = 6):
        self.header = header
        self.compress = compress
        self.n_inputs = len(header.inputs)
        self._c: TickEncoder | None = None
        self._py: BlockEncoder | None = None
        try:
            self._c = TickEncoder(self.n_inputs, len(header.outputs), header.period_ns,
                                  header.output_values)
        except (ValueError, NativeError):
            self._py = BlockEncoder(header, compress)
        #: One tick's row for C: tick, time, lateness, missed, every input.
        self._row = struct.Struct(f"={JOURNAL_CLOCK + self.n_inputs}q")
        self._rows = bytearray()

    @property
    def native(self) -> bool:
        """Whether the records are still encoded in C."""
        return self._py is None

    @property
    def count(self) -> int:
        """Records in the block being filled."""
        return self._py.count if self._py is not None else self._c.count  # type: ignore[union-attr]

    @property
    def last_time(self) -> int:
        """The last record's time, ns."""
        return self._py.last_time if self._py is not None else self._c.last_time  # type: ignore[union-attr]

    def _to_python(self) -> BlockEncoder:
        """Move onto the Python reference for good, with the state C holds."""
        c = self._c
        assert c is not None
        py = BlockEncoder(self.header, self.compress)
        py.inputs = tuple(c.previous_inputs()) if c.has_previous else None
        py.outputs = c.outputs()
        py.deadline = c.deadline
        py.tick = c.tick
        py.body = bytearray(c.body())
        py.count = c.count
        py.first_tick = c.first_tick
        py.first_time = c.first_time
        py.last_time = c.last_time
        self._py, self._c = py, None
        return py

    @property
    def row(self) -> struct.Struct:
        """The row of one tick that :meth:`add_rows` takes: tick, time_ns,
        lateness_ns, missed, every input, native 64-bit integers."""
        return self._row

    def add(self, tick: int, time_ns: int, lateness_ns: int, missed: int,
            inputs: Sequence[int], outputs: Sequence[tuple[int, int, int]] = (),
            commands: Sequence[tuple[str, str]] = (),
            events: Sequence[tuple[str, int, str]] = ()) -> None:
        """Append one tick record (JournalError if it is refused; nothing of it kept)."""
        refused = self.add_many([(tick, time_ns, lateness_ns, missed, inputs, outputs,
                                  commands, events)])
        if refused:
            raise refused[0]

    def add_many(self, items: Sequence[TickItem]) -> list[JournalError]:
        """Append a run of tick records (each as :meth:`add` takes it); the
        refusals, in order (a refused tick is not recorded, the others are)."""
        n = len(items)
        size = self._row.size
        buf = self._rows
        if len(buf) < n * size:
            buf = self._rows = bytearray(n * size)
        pack = self._row.pack_into
        extras: dict[int, Extra] = {}
        for i, it in enumerate(items):
            try:
                pack(buf, i * size, *it[:4], *it[4])
            except (struct.error, TypeError):
                extras[i] = (it[5], it[6], it[7], it)
                continue
            if it[5] or it[6] or it[7]:
                extras[i] = (it[5], it[6], it[7], None)
        return self.add_rows(buf, 0, n, extras)

    def add_rows(self, rows: bytearray, start: int, n: int,
                 extras: dict[int, Extra]) -> list[JournalError]:
        """Append the records of rows ``start .. start + n - 1`` of ``rows`` (each
        packed as :attr:`row`), ``extras[i]`` holding the outputs, commands and
        events of the run's tick ``i`` (from 0) if it has any, and the whole tick
        if it could not be packed; the refusals, in order."""
        refused: list[JournalError] = []
        if self._py is None and any(e[3] is not None for e in extras.values()):
            self._to_python()
        if self._py is not None:
            self._add_python(self._items(rows, start, n, extras), 0, refused)
            return refused
        per: list[int] | None = None
        writes: list[int] | None = None
        if any(e[0] for e in extras.values()):
            per = [0] * n
            flat: list[int] = []
            for i in sorted(extras):
                outs = extras[i][0]
                if outs:
                    # each (index, value, writer), integers: checked by C-level maps, not
                    # a Python loop (the writer's turns with the interpreter lock)
                    if not (set(map(len, outs)) == _THREE
                            and set(map(type, chain.from_iterable(outs))) == _INT):
                        # not (index, value, writer) integers: the reference refuses it
                        self._to_python()
                        self._add_python(self._items(rows, start, n, extras), 0, refused)
                        return refused
                    per[i] = len(outs)
                    flat.extend(chain.from_iterable(outs))
            writes = flat
        # the ticks with commands or events end a C call: their fields follow the record
        marks = sorted(i for i, e in extras.items() if e[1] or e[2])
        k = 0
        for end in (*marks, n - 1):
            if end < k:
                continue
            stop = end + 1
            flags = 0
            extra = b""
            if marks and end == marks[0]:
                marks.pop(0)
                e = extras[end]
                try:
                    tick = _TICK.unpack_from(rows, (start + end) * self._row.size)[0]
                    flags, extra = _extras(tick, e[1], e[2])
                except JournalError as exc:
                    # the tick is refused: those before it go, then those after
                    if end > k and not self._encode(rows, start, n, extras, k, end, per,
                                                    writes, 0, b"", refused):
                        return refused
                    refused.append(exc)
                    k = stop
                    continue
            if not self._encode(rows, start, n, extras, k, stop, per, writes, flags, extra,
                                refused):
                return refused
            k = stop
        return refused

    def _encode(self, rows: bytearray, start: int, n: int, extras: dict[int, Extra], a: int,
                b: int, per: list[int] | None, writes: list[int] | None, flags: int,
                extra: bytes, refused: list[JournalError]) -> bool:
        """The run's records ``a..b-1`` in C (the last followed by ``extra``); False if
        C refused one (from there on, the Python reference has taken every record left)."""
        c = self._c
        assert c is not None
        sub_per = sub_writes = None
        if per is not None and writes is not None:
            w0 = 3 * sum(per[:a])
            sub_per = per[a:b]
            sub_writes = writes[w0:w0 + 3 * sum(sub_per)]
        try:
            c.encode(rows, start + a, b - a, sub_per, sub_writes, flags)
        except RecordRefused as exc:
            self._to_python()
            self._add_python(self._items(rows, start, n, extras), a + exc.index, refused)
            return False
        if extra:
            c.append(extra)
        return True

    def _items(self, rows: bytearray, start: int, n: int,
               extras: dict[int, Extra]) -> list[TickItem]:
        """The run's ticks as :meth:`add` takes them (for the Python reference)."""
        unpack = self._row.unpack_from
        size = self._row.size
        items: list[TickItem] = []
        for i in range(n):
            e = extras.get(i)
            if e is not None and e[3] is not None:
                items.append(e[3])
                continue
            row = unpack(rows, (start + i) * size)
            items.append((*row[:4], row[4:], *(e[:3] if e is not None else ((), (), ()))))
        return items

    def _add_python(self, items: Sequence[TickItem], start: int,
                    refused: list[JournalError]) -> None:
        py = self._py
        assert py is not None
        for item in items[start:]:
            try:
                py.add(*item)
            except JournalError as exc:
                refused.append(exc)

    def reset(self) -> None:
        """Forget the previous record: the next one is a keyframe (after a gap)."""
        if self._py is not None:
            self._py.reset()
        else:
            self._c.reset()  # type: ignore[union-attr]

    def take(self) -> tuple[bytes, int, int, int, int, int] | None:
        """The current block as a frame, and ``(first tick, last tick, first time,
        last time, ticks)``; None when it is empty (as :meth:`BlockEncoder.take`)."""
        if self._py is not None:
            return self._py.take()
        c = self._c
        assert c is not None
        n = c.count
        if not n:
            return None
        first, last, t0, t1 = c.first_tick, c.tick, c.first_time, c.last_time
        body = c.take()
        head = BLOCK.pack(first, last, t0, t1, n)
        if self.compress:
            data = frame(KIND_ZTICKS, head + zlib.compress(body, self.compress))
        else:
            data = frame(KIND_TICKS, head + body)
        return data, first, last, t0, t1, n
