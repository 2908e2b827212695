"""Reading a journal back: its header, its ticks (inputs reconstructed), gaps and damage."""

from __future__ import annotations

import bisect
import os
import zlib
from collections.abc import Iterator
from dataclasses import dataclass
from typing import NamedTuple

from pyrt.journal.format import (
    BLOCK,
    END,
    FRAME_HEADER,
    GAP,
    HEADER_SIZE,
    KIND_END,
    KIND_GAP,
    KIND_HEADER,
    KIND_NAMES,
    KIND_SNAPSHOT,
    KIND_TICKS,
    KIND_ZTICKS,
    KINDS,
    MAGIC,
    MAX_PAYLOAD,
    Gap,
    Header,
    JournalError,
    Tick,
    _Cursor,
    decode_block,
    read_snapshot_payload,
)

__all__ = ["Damage", "JournalReader", "Summary", "read_journal"]


class Damage(NamedTuple):
    """Bytes ``offset``..``end`` (exclusive) of a journal that hold no valid frame,
    beginning where frame ``frame`` was expected, and why."""

    offset: int
    end: int
    frame: int
    reason: str


@dataclass(frozen=True)
class Summary:
    """What a journal holds, in a few numbers."""

    station: str
    ticks: int
    first_tick: int | None
    last_tick: int | None
    duration_ns: int
    size: int
    frames: int
    gaps: tuple[Gap, ...]
    damage: tuple[Damage, ...]
    ended_early: str | None
    complete: bool

    def lines(self) -> list[str]:
        """The summary as text, one line each."""
        out = [f"station {self.station}: {self.ticks} ticks"
               + (f" ({self.first_tick}..{self.last_tick})" if self.ticks else "")
               + f", {self.duration_ns / 1e9:.3f} s, {self.size} bytes in {self.frames} frames"]
        out += [f"gap: ticks {g.first}..{'end' if g.last is None else g.last} not recorded "
                f"({g.cause})" for g in self.gaps]
        out += [f"damaged: bytes {d.offset}..{d.end} (frame {d.frame}): {d.reason}"
                for d in self.damage]
        if self.ended_early:
            out.append(self.ended_early)
        elif not self.complete and not self.damage:
            out.append("the journal has no end record")
        return out


class _Frame(NamedTuple):
    offset: int
    number: int
    kind: bytes
    payload: memoryview
    first_tick: int
    last_tick: int
    first_time: int
    last_time: int
    ticks: int


class JournalReader:
    """A journal file (a path or its bytes), checked frame by frame on opening.

    The header, the writer name table and the gaps are read at once; the ticks
    are decoded as they are iterated.  A file that ends early (the writer was
    killed) reads up to its last complete frame (:attr:`ended_early` says
    where it ends).  A damaged frame (a checksum that does not match, a bad
    frame header) is an error: iteration gives every tick before it, then
    raises :class:`JournalError` naming the frame and its offset.  With
    ``salvage`` the reader skips from the damage to the next valid frame
    instead and gives the ticks lost as a :class:`Gap` (and in :attr:`damage`).
    A damaged or missing header is an error in both modes.
    """

    def __init__(self, source: str | os.PathLike[str] | bytes, *, salvage: bool = False):
        if isinstance(source, bytes | bytearray | memoryview):
            data = bytes(source)
            self.path = "<bytes>"
        else:
            self.path = os.fspath(source)
            try:
                with open(self.path, "rb") as fh:
                    data = fh.read()
            except OSError as exc:
                raise JournalError(f"journal {self.path}: {exc.strerror or exc}") from None
        self.salvage = salvage
        self.size = len(data)
        self._bytes = data
        self._data = memoryview(data)
        #: Where the file ends early, or None.
        self.ended_early: str | None = None
        #: Damaged stretches found (strict: at most one; nothing after it is read).
        self.damage: list[Damage] = []
        #: Whether the file has its end record (a clean close).
        self.complete = False
        self._frames: list[_Frame | Damage] = []
        self._scan()
        first = self._frames[0] if self._frames else None
        if not isinstance(first, _Frame) or first.kind != KIND_HEADER:
            if isinstance(first, Damage):
                raise self._error(first)
            raise JournalError(f"journal {self.path}: no header frame", 0, 0)
        try:
            self.header = Header.decode(bytes(first.payload))
        except (JournalError, ValueError) as exc:
            raise JournalError(f"journal {self.path}: frame 0 at offset 0: bad header: {exc}",
                               0, 0) from None
        #: The writer (task) name table: the header's, then those added later.
        self.writers: list[str] = list(self.header.writers)
        self.gaps: list[Gap] = []
        #: The ``S`` frames: ``(tick, data)``, the controller's state before that tick.
        self.snapshots: list[tuple[int, bytes]] = []
        self._ticks: list[_Frame] = []
        last_tick: int | None = None
        for f in self._frames[1:]:
            if isinstance(f, Damage):
                if salvage:
                    self.gaps.append(self._damage_gap(f, last_tick))
                continue
            if f.kind in (KIND_TICKS, KIND_ZTICKS):
                self._ticks.append(f)
                last_tick = f.last_tick
            elif f.kind == KIND_NAMES:
                r = _Cursor(bytes(f.payload))
                start = r.uvarint()
                names = [r.str() for _ in range(r.uvarint())]
                del self.writers[start:]
                self.writers += names
            elif f.kind == KIND_GAP:
                self.gaps.append(_gap(f.payload))
            elif f.kind == KIND_END:
                self.complete = True
            elif f.kind == KIND_SNAPSHOT:
                try:
                    self.snapshots.append(read_snapshot_payload(f.payload))
                except JournalError as exc:
                    raise JournalError(f"journal {self.path}: frame {f.number} at offset "
                                       f"{f.offset}: {exc.message}", f.offset, f.number) from None
        self._starts = [f.first_tick for f in self._ticks]

    # -- scanning --------------------------------------------------------------------------

    def _error(self, d: Damage) -> JournalError:
        return JournalError(f"journal {self.path}: frame {d.frame} at offset {d.offset}: "
                            f"{d.reason}", d.offset, d.frame)

    def _check(self, pos: int) -> tuple[bytes, int] | str:
        """(kind, length) of a valid frame header at ``pos``, or why there is none."""
        data = self._data
        magic, kind, length, _crc = FRAME_HEADER.unpack_from(data, pos)
        if magic != MAGIC:
            return "bad magic (not the start of a frame)"
        hcrc = int.from_bytes(data[pos + 13:pos + 15], "little")
        if zlib.crc32(data[pos:pos + 13]) & 0xFFFF != hcrc:
            return "frame header checksum mismatch"
        if kind not in KINDS or length > MAX_PAYLOAD:
            return f"frame header names unknown kind {kind!r} or length {length}"
        return kind, length

    def _frame_at(self, pos: int, index: int) -> _Frame | str | None:
        """The valid frame at ``pos``, why there is none (damage), or None if the file
        ends inside it (ended early; :attr:`ended_early` set)."""
        data = self._data
        left = self.size - pos
        if left < HEADER_SIZE:
            if bytes(data[pos:pos + min(left, 4)]) == MAGIC[:min(left, 4)]:
                self.ended_early = (f"the journal ends early at offset {pos}: frame {index} "
                                    f"has {left} of its {HEADER_SIZE} header bytes")
                return None
            return "bad magic (not the start of a frame)"
        checked = self._check(pos)
        if isinstance(checked, str):
            return checked
        kind, length = checked
        end = pos + HEADER_SIZE + length
        if end > self.size:
            self.ended_early = (f"the journal ends early at offset {pos}: frame {index} "
                                f"needs {HEADER_SIZE + length} bytes, the file holds {left}")
            return None
        payload = data[pos + HEADER_SIZE:end]
        crc = int.from_bytes(data[pos + 9:pos + 13], "little")
        if zlib.crc32(payload) != crc:
            return f"payload checksum mismatch (bytes {pos + HEADER_SIZE}..{end})"
        ft = lt = t0 = t1 = n = 0
        if kind in (KIND_TICKS, KIND_ZTICKS):
            if length < BLOCK.size:
                return "tick block shorter than its head"
            ft, lt, t0, t1, n = BLOCK.unpack_from(payload, 0)
        elif kind == KIND_GAP and length < GAP.size:
            return "gap record shorter than its head"
        elif kind == KIND_END and length != END.size:
            return "end record of the wrong size"
        return _Frame(pos, index, kind, payload, ft, lt, t0, t1, n)

    def _resync(self, pos: int) -> int:
        """The offset of the next valid frame after ``pos``, or the file's size."""
        data = self._bytes
        start = pos + 1
        while True:
            nxt = data.find(MAGIC, start)
            if nxt < 0:
                return self.size
            saved = self.ended_early
            found = self._frame_at(nxt, -1)
            self.ended_early = saved
            if isinstance(found, _Frame):
                return nxt
            start = nxt + 1

    def _scan(self) -> None:
        pos = 0
        index = 0
        while pos < self.size:
            found = self._frame_at(pos, index)
            if found is None:
                break
            if isinstance(found, str):
                if not self.salvage or index == 0:
                    d = Damage(pos, self.size, index, found)
                    self.damage.append(d)
                    self._frames.append(d)
                    return
                nxt = self._resync(pos)
                d = Damage(pos, nxt, index, found)
                self.damage.append(d)
                self._frames.append(d)
                pos = nxt
            else:
                self._frames.append(found)
                pos = found.offset + HEADER_SIZE + len(found.payload)
            index += 1

    def _damage_gap(self, d: Damage, last_tick: int | None) -> Gap:
        after = [f for f in self._frames if isinstance(f, _Frame) and f.offset >= d.end
                 and f.kind in (KIND_TICKS, KIND_ZTICKS)]
        first = 0 if last_tick is None else last_tick + 1
        last = after[0].first_tick - 1 if after else None
        return Gap(first, last, None if last is None else max(0, last - first + 1),
                   f"damaged bytes at offset {d.offset}..{d.end}: {d.reason}")

    # -- reading ---------------------------------------------------------------------------

    def __iter__(self) -> Iterator[Tick | Gap]:
        """Every tick and gap after the header, in order (see the class text for damage)."""
        return self._records(0)

    def ticks(self) -> Iterator[Tick]:
        """Every tick, in order (gaps left out)."""
        for rec in self:
            if isinstance(rec, Tick):
                yield rec

    def seek(self, tick: int) -> Iterator[Tick | Gap]:
        """Ticks (and gaps) from ``tick`` on: decoding starts at the block that holds it
        (or the first block after it, if it is in a gap)."""
        i = bisect.bisect_right(self._starts, tick) - 1
        if i < 0:
            return self._records(0, tick)
        return self._records(self._frames.index(self._ticks[i]), tick)

    def _records(self, start: int, from_tick: int | None = None) -> Iterator[Tick | Gap]:
        prev_inputs: tuple[int, ...] | None = None
        last_tick: int | None = None
        header = self.header
        for f in self._frames[max(start, 1):]:
            if isinstance(f, Damage):
                if not self.salvage:
                    raise self._error(f)
                gap = self._damage_gap(f, last_tick)
                prev_inputs = None
                if from_tick is None or gap.last is None or gap.last >= from_tick:
                    yield gap
                continue
            if f.kind == KIND_GAP:
                gap = _gap(f.payload)
                prev_inputs = None
                if from_tick is None or gap.last is None or gap.last >= from_tick:
                    yield gap
            elif f.kind in (KIND_TICKS, KIND_ZTICKS):
                if from_tick is not None and f.last_tick < from_tick:
                    continue
                try:
                    ticks = decode_block(f.kind, f.payload, header, inputs_before=prev_inputs)
                except JournalError as exc:
                    raise JournalError(f"journal {self.path}: frame {f.number} at offset "
                                       f"{f.offset}: {exc.message}", f.offset, f.number) from None
                for t in ticks:
                    if from_tick is None or t.tick >= from_tick:
                        yield t
                if ticks:
                    prev_inputs = ticks[-1].inputs
                    last_tick = ticks[-1].tick

    def summary(self) -> Summary:
        """Ticks, gaps, size, duration, damage and how the file ends."""
        n = sum(f.ticks for f in self._ticks)
        return Summary(
            station=self.header.station, ticks=n,
            first_tick=self._ticks[0].first_tick if self._ticks else None,
            last_tick=self._ticks[-1].last_tick if self._ticks else None,
            duration_ns=(self._ticks[-1].last_time - self._ticks[0].first_time)
            if self._ticks else 0,
            size=self.size, frames=sum(isinstance(f, _Frame) for f in self._frames),
            gaps=tuple(self.gaps), damage=tuple(self.damage), ended_early=self.ended_early,
            complete=self.complete)


def _gap(payload: memoryview) -> Gap:
    first, last, count = GAP.unpack_from(payload, 0)
    cause = _Cursor(bytes(payload[GAP.size:])).str()
    return Gap(first, last, count, cause)


def read_journal(source: str | os.PathLike[str] | bytes, *,
                 salvage: bool = False) -> tuple[Header, list[Tick | Gap]]:
    """The header and every record of a journal (see :class:`JournalReader`)."""
    reader = JournalReader(source, salvage=salvage)
    return reader.header, list(reader)
