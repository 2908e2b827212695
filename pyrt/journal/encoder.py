"""The journal's tick records encoded a run of ticks at a time in C.

:class:`NativeBlockEncoder` writes the bytes :class:`~pyrt.journal.format.BlockEncoder`
writes (the reference: the tests hold one to the other), but its state
lives in C buffers (:class:`pyrt.native.TickEncoder`) and the records of
a run of ticks are delta-encoded in one C call, the interpreter lock
released: what the journal's writer thread holds the lock for is packing
each tick's Python integers into a row of 64-bit integers (``struct``) and
the rare output writes, commands and events.

Anything the C encoder does not take (a value beyond +-2**62, an input
that is not an integer, a record it refuses) moves the encoder, for the
rest of the journal, onto the Python reference, with the state C held:
the bytes stay the same, a refusal is the reference's.
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Sequence
from itertools import chain, compress, count
from operator import itemgetter, truth
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

_OUTPUTS = itemgetter(5)
_COMMANDS = itemgetter(6)
_EVENTS = itemgetter(7)

#: One tick as the journal hands it over: (tick, time_ns, lateness_ns, missed,
#: inputs, outputs, commands, events).
TickItem = tuple[Any, ...]


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
        refused: list[JournalError] = []
        if self._py is not None:
            self._add_python(items, 0, refused)
            return refused
        n = len(items)
        size = self._row.size
        buf = self._rows
        if len(buf) < n * size:
            buf = self._rows = bytearray(n * size)
        pack = self._row.pack_into
        off = 0
        try:
            for it in items:
                pack(buf, off, *it[:4], *it[4])
                off += size
            per: list[int] | None = None
            writes: list[int] | None = None
            if any(map(truth, map(_OUTPUTS, items))):
                per = [len(o) for o in map(_OUTPUTS, items)]
                rows = list(chain.from_iterable(map(_OUTPUTS, items)))
                if not all(len(w) == 3 and all(type(x) is int for x in w) for w in rows):
                    raise TypeError
                writes = list(chain.from_iterable(rows))
        except (struct.error, TypeError):
            # not 64-bit integers, or not as many as the header says: the reference
            self._to_python()
            self._add_python(items, 0, refused)
            return refused
        # the ticks with commands or events end a C call: their fields follow the record
        marks = sorted(set(compress(count(), map(truth, map(_COMMANDS, items))))
                       | set(compress(count(), map(truth, map(_EVENTS, items)))))
        k = 0
        for end in (*marks, n - 1):
            if end < k:
                continue
            stop = end + 1
            flags = 0
            extra = b""
            if end in marks:
                item = items[end]
                try:
                    flags, extra = _extras(item[0], item[6], item[7])
                except JournalError as exc:
                    # the tick is refused: those before it go, then those after
                    if end > k and not self._encode(items, k, end, buf, per, writes, 0, b"",
                                                    refused):
                        return refused
                    refused.append(exc)
                    k = stop
                    continue
            if not self._encode(items, k, stop, buf, per, writes, flags, extra, refused):
                return refused
            k = stop
        return refused

    def _encode(self, items: Sequence[TickItem], a: int, b: int, rows: bytearray,
                per: list[int] | None, writes: list[int] | None, flags: int, extra: bytes,
                refused: list[JournalError]) -> bool:
        """Records ``a..b-1`` in C (the last followed by ``extra``); False if C refused
        one (from there on, the Python reference has taken every record left)."""
        c = self._c
        assert c is not None
        sub_per = sub_writes = None
        if per is not None:
            w0 = 3 * sum(per[:a])
            sub_per = per[a:b]
            sub_writes = writes[w0:w0 + 3 * sum(sub_per)] if writes is not None else None
        try:
            c.encode(rows, a, b - a, sub_per, sub_writes, flags)
        except RecordRefused as exc:
            self._to_python()
            self._add_python(items, a + exc.index, refused)
            return False
        if extra:
            c.append(extra)
        return True

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
