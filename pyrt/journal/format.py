"""The journal file format (``pyrt-journal/2``): a specification, and its encoder and decoder.

A journal records everything that enters a controller during a run (the
mailbox commands, the inputs of the process image, the clock's decisions,
the random seeds) and the outputs it wrote, tick by tick, so that the run
can be replayed on virtual time and checked bit for bit.

Primitive encodings
===================

* ``uvarint``: an unsigned integer, 7 bits per byte, least significant
  group first, the high bit set on every byte but the last (LEB128).
  Integers of any size.
* ``svarint``: a signed integer, zigzag-mapped (``0, -1, 1, -2, ...`` to
  ``0, 1, 2, 3, ...``), then a uvarint.
* ``str``: a uvarint byte count, then that many bytes of UTF-8.
* ``bytes``: a uvarint byte count, then the bytes.
* ``u16``, ``u32``, ``u64``, ``i64``: fixed little-endian integers.

Frames
======

A journal file is a sequence of **frames**; nothing lies between them.
Each frame is a 15-byte frame header followed by its payload::

    offset  size  field
    0       4     magic       b"\\x89PJR"
    4       1     kind        one ASCII letter (below)
    5       4     length      u32, payload bytes (at most MAX_PAYLOAD)
    9       4     crc         u32, CRC-32 (zlib.crc32) of the payload
    13      2     header crc  u16, the low 16 bits of CRC-32 of bytes 0..12

The header CRC tells a damaged frame header (corruption) from a frame whose
payload the file does not hold in full (a file that ends early: the writer
was killed or the disk filled).  A reader reads up to the last complete,
checksum-valid frame; it reports a file that ends early with the offset of
the incomplete frame, and any checksum mismatch or bad magic with the offset
of the frame and its index (frames counted from 0, the header frame being
frame 0).  Nothing inside a damaged frame is ever used.  In salvage mode a
reader skips from a damaged frame to the next magic that begins a valid
frame and records the ticks it lost as a gap.

Frame kinds:

``H`` header (always frame 0, exactly once)::

    uvarint  format version (2; version 1, which has no ``S`` frames, is read too)
    str      station name
    str      pyrt version
    uvarint  tick period, ns
    uvarint  n, then n x (str name, bytes contents)   the station's database files,
                                                      as the run found them
    uvarint  n, then n x (str name, svarint seed)     every random seed
    uvarint  n, then n x str                          input register names, declared order
    uvarint  n, then n x str                          output register names, declared order
    uvarint  n, then n x svarint                      output values before the first tick
                                                      (n = 0: all 0, else n = outputs)
    uvarint  n, then n x str                          writer (task) name table
    str      metadata, a JSON object (free-form)

``T`` ticks, ``Z`` ticks compressed (a block of tick records)::

    u64   first tick index
    u64   last tick index
    i64   clock time of the first tick, ns
    i64   clock time of the last tick, ns
    u32   number of tick records
    ...   the tick records; for ``Z`` they are one zlib stream (zlib.compress)

    A block never refers to another: its first record is always a keyframe.
    A reader may therefore start at any ``T``/``Z`` frame.

``N`` writer names added after the header::

    uvarint  index of the first name (the size of the table before)
    uvarint  n, then n x str

``G`` gap: ticks the journal did not record (its writer fell behind)::

    u64   first tick not recorded
    u64   last tick not recorded
    u64   number of ticks not recorded
    str   cause

    A run is not replayable past the first tick of its first gap.  The block
    after a gap begins anew (with a keyframe).

``S`` snapshot (version 2; a black box writes one right after its header)::

    uvarint  tick: the controller's state is that before this tick
    bytes    the state, zlib-compressed ``pyrt-snapshot/1`` JSON
             (:mod:`pyrt.station.snapshot`), or why the station had none

    A replay of a journal that does not begin where its run began (a black
    box) resumes from it; the journal package stores it, the station reads it.

``E`` end (written by a clean close; a file without it ended early)::

    u64   tick records written
    u64   ticks not recorded (in gaps)

Tick records
============

Each record is a ``uvarint`` flags word, then the fields its flags select, in
this order:

=====  ==========  ==========================================================
bit    name        field(s)
=====  ==========  ==========================================================
0      KEY         keyframe: ``uvarint tick``, ``svarint time_ns``,
                   ``uvarint missed``, ``svarint lateness_ns``, every input
                   (``svarint`` each, declared order), every output as it
                   stood before this tick (``svarint`` each)
4      STEP        (not keyframes) ``uvarint tick - previous tick - 1``;
                   absent: the next tick
5      MISSED      (not keyframes) ``uvarint`` deadlines missed since the
                   previous record; absent: 0
6      SHIFT       (not keyframes) ``svarint deadline - predicted deadline``,
                   where deadline = time - lateness and the prediction is
                   previous deadline + period x (1 + missed); absent: 0
1      LATE        (not keyframes) ``svarint lateness_ns``; absent: 0
2      INPUTS      (not keyframes) ``uvarint n``, then n x
                   (``uvarint index - previous index - 1``, the first
                   previous index being -1; ``svarint new - old``): the
                   inputs that changed since the previous record
3      OUTPUTS     ``uvarint n``, then n x (``uvarint index``,
                   ``svarint new - old``, ``uvarint writer``): the outputs
                   written in this tick that changed, in the order written
7      COMMANDS    ``uvarint n``, then n x (``str text``, ``str source``):
                   the mailbox commands applied in this tick
8      EVENTS      ``uvarint n``, then n x (``str name``, ``svarint id``,
                   ``str message``): named events (a fault: name
                   ``"fault"``, its id and message)
=====  ==========  ==========================================================

The time of a record is its deadline plus its lateness; a keyframe gives it
whole.  An output's ``old`` value is the keyframe's, updated by every write
read since.  Values are integers of any size (registers are 1..32-bit
integers); a run on virtual time has lateness, shift and missed 0, and a tick
in which nothing changed costs one byte before compression.

A black-box dump (:class:`pyrt.journal.BlackBox`) is a journal in this same
format: a header (with the writer table as it stood at the dump), the frames
the ring held (the first a block, hence a keyframe), an end frame.

Size: blocks of 250 ticks compressed at zlib level 6 (the journal's defaults)
hold a 1 kHz gripper moving (10 of 40 inputs changing every tick, 3 outputs
written, wall-clock lateness) in about 0.7 MB per minute (bench/bench_journal.py).
"""

from __future__ import annotations

import json
import struct
import zlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from itertools import compress
from operator import ne
from typing import Any, NamedTuple

from pyrt.errors import PyrtError

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "MAGIC",
    "Command",
    "Event",
    "Gap",
    "Header",
    "JournalError",
    "Tick",
]

FORMAT = "pyrt-journal/2"
FORMAT_VERSION = 2
#: The versions this pyrt reads: 1 (no ``S`` frames) and 2.
READ_VERSIONS = (1, 2)
MAGIC = b"\x89PJR"
FRAME_HEADER = struct.Struct("<4scII")
HEADER_SIZE = FRAME_HEADER.size + 2  # 15
MAX_PAYLOAD = 1 << 28

KIND_HEADER = b"H"
KIND_TICKS = b"T"
KIND_ZTICKS = b"Z"
KIND_NAMES = b"N"
KIND_GAP = b"G"
KIND_END = b"E"
KIND_SNAPSHOT = b"S"
KINDS = frozenset((KIND_HEADER, KIND_TICKS, KIND_ZTICKS, KIND_NAMES, KIND_GAP, KIND_END,
                   KIND_SNAPSHOT))

BLOCK = struct.Struct("<QQqqI")
GAP = struct.Struct("<QQQ")
END = struct.Struct("<QQ")

F_KEY = 1
F_LATE = 2
F_INPUTS = 4
F_OUTPUTS = 8
F_STEP = 16
F_MISSED = 32
F_SHIFT = 64
F_COMMANDS = 128
F_EVENTS = 256


class JournalError(PyrtError):
    """A journal cannot be written or read as asked: bad arguments, a damaged or
    foreign file.  ``offset`` and ``frame`` say where, when a place is known."""

    def __init__(self, message: str, offset: int | None = None, frame: int | None = None):
        self.message = message
        self.offset = offset
        self.frame = frame
        super().__init__(message)


class Command(NamedTuple):
    """A mailbox command applied in a tick: its text and where it came from."""

    text: str
    source: str = ""


class Event(NamedTuple):
    """A named event of a tick (a fault: name ``"fault"``, its id and message)."""

    name: str
    id: int = 0
    message: str = ""


class Gap(NamedTuple):
    """Ticks ``first``..``last`` (inclusive; ``last`` None: to the end) that are
    not in the journal, how many ticks ran in that stretch if known, and why."""

    first: int
    last: int | None
    ticks: int | None
    cause: str


@dataclass(frozen=True)
class Header:
    """What a journal says about its run before the first tick (see the module text)."""

    station: str
    period_ns: int
    inputs: Sequence[str]
    outputs: Sequence[str]
    version: str = ""
    databases: Mapping[str, bytes] = field(default_factory=dict)
    seeds: Mapping[str, int] = field(default_factory=dict)
    writers: Sequence[str] = ()
    output_values: Sequence[int] = ()
    metadata: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        def bad(what: str) -> JournalError:
            return JournalError(f"journal header: {what}")

        if not isinstance(self.station, str):
            raise bad(f"station must be a string, got {self.station!r}")
        if isinstance(self.period_ns, bool) or not isinstance(self.period_ns, int) \
                or self.period_ns <= 0:
            raise bad(f"period_ns must be a positive integer, got {self.period_ns!r}")
        for what in ("inputs", "outputs", "writers"):
            names = getattr(self, what)
            if isinstance(names, str) or not all(isinstance(n, str) for n in names):
                raise bad(f"{what} must be a sequence of strings, got {names!r}")
            object.__setattr__(self, what, tuple(names))
        if self.output_values and len(self.output_values) != len(self.outputs):
            raise bad(f"{len(self.output_values)} output values for "
                      f"{len(self.outputs)} outputs")
        if not all(_is_int(v) for v in self.output_values):
            raise bad(f"output values must be integers, got {self.output_values!r}")
        object.__setattr__(self, "output_values", tuple(self.output_values))
        for name, data in self.databases.items():
            if not isinstance(name, str) or not isinstance(data, bytes | bytearray):
                raise bad(f"databases map names to bytes, got {name!r}: {type(data).__name__}")
        for name, seed in self.seeds.items():
            if not isinstance(name, str) or not _is_int(seed):
                raise bad(f"seeds map names to integers, got {name!r}: {seed!r}")
        try:
            json.dumps(dict(self.metadata))
        except (TypeError, ValueError) as exc:
            raise bad(f"metadata must be a JSON object: {exc}") from None
        try:
            self.encode()
        except UnicodeEncodeError as exc:
            raise bad(f"a name is not encodable as UTF-8: {exc}") from None

    def encode(self) -> bytes:
        """The payload of this header's ``H`` frame."""
        out = bytearray()
        put_uvarint(out, FORMAT_VERSION)
        put_str(out, self.station)
        put_str(out, self.version)
        put_uvarint(out, self.period_ns)
        put_uvarint(out, len(self.databases))
        for name, data in self.databases.items():
            put_str(out, name)
            put_bytes(out, bytes(data))
        put_uvarint(out, len(self.seeds))
        for name, seed in self.seeds.items():
            put_str(out, name)
            put_svarint(out, seed)
        for names in (self.inputs, self.outputs):
            put_uvarint(out, len(names))
            for n in names:
                put_str(out, n)
        put_uvarint(out, len(self.output_values))
        for v in self.output_values:
            put_svarint(out, v)
        put_uvarint(out, len(self.writers))
        for n in self.writers:
            put_str(out, n)
        put_str(out, json.dumps(dict(self.metadata), sort_keys=True, separators=(",", ":")))
        return bytes(out)

    @classmethod
    def decode(cls, payload: bytes) -> Header:
        """The header an ``H`` frame's payload holds (JournalError if it is not one)."""
        r = _Cursor(payload)
        version = r.uvarint()
        if version not in READ_VERSIONS:
            raise JournalError(f"journal format version {version}; this pyrt reads "
                               f"versions {', '.join(map(str, READ_VERSIONS))}")
        station = r.str()
        pyrt_version = r.str()
        period = r.uvarint()
        databases = {r.str(): r.bytes() for _ in range(r.uvarint())}
        seeds = {r.str(): r.svarint() for _ in range(r.uvarint())}
        inputs = tuple(r.str() for _ in range(r.uvarint()))
        outputs = tuple(r.str() for _ in range(r.uvarint()))
        values = tuple(r.svarint() for _ in range(r.uvarint()))
        writers = tuple(r.str() for _ in range(r.uvarint()))
        metadata = json.loads(r.str())
        if r.pos != len(payload):
            raise JournalError("journal header: bytes left over after the metadata")
        return cls(station=station, period_ns=period, inputs=inputs, outputs=outputs,
                   version=pyrt_version, databases=databases, seeds=seeds, writers=writers,
                   output_values=values, metadata=metadata)


@dataclass(frozen=True, slots=True)
class Tick:
    """One tick as a reader gives it back.

    ``inputs``: every input, reconstructed; ``changed``: the indices of the
    inputs that changed since the previous tick read (all of them at the
    first tick read and after a gap); ``outputs``: the changed outputs written
    in the tick, ``(index, value, writer)`` in the order written;
    ``output_values``: every output after the tick.
    """

    tick: int
    time_ns: int
    lateness_ns: int
    missed: int
    inputs: tuple[int, ...]
    changed: tuple[int, ...]
    outputs: tuple[tuple[int, int, int], ...]
    output_values: tuple[int, ...]
    commands: tuple[Command, ...] = ()
    events: tuple[Event, ...] = ()
    keyframe: bool = False


def _is_int(v: object) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


# -- primitives ----------------------------------------------------------------------------------


def put_uvarint(out: bytearray, v: int) -> None:
    """Append ``v`` (>= 0) as a uvarint."""
    while v > 0x7F:
        out.append((v & 0x7F) | 0x80)
        v >>= 7
    out.append(v)


def put_svarint(out: bytearray, v: int) -> None:
    """Append ``v`` as a zigzag svarint."""
    v = (v << 1) if v >= 0 else ((-v << 1) - 1)
    while v > 0x7F:
        out.append((v & 0x7F) | 0x80)
        v >>= 7
    out.append(v)


def put_str(out: bytearray, s: str) -> None:
    """Append a str (uvarint length, UTF-8)."""
    put_bytes(out, s.encode("utf-8"))


def put_bytes(out: bytearray, b: bytes) -> None:
    """Append bytes (uvarint length, the bytes)."""
    put_uvarint(out, len(b))
    out += b


class _Cursor:
    """Reads primitives from a payload; JournalError on a payload that ends too soon."""

    __slots__ = ("buf", "end", "pos")

    def __init__(self, buf: bytes | memoryview, pos: int = 0):
        self.buf = buf
        self.pos = pos
        self.end = len(buf)

    def uvarint(self) -> int:
        buf = self.buf
        pos = self.pos
        try:
            b = buf[pos]
            if b < 0x80:
                self.pos = pos + 1
                return b
            v = b & 0x7F
            shift = 7
            while True:
                pos += 1
                b = buf[pos]
                v |= (b & 0x7F) << shift
                if b < 0x80:
                    self.pos = pos + 1
                    return v
                shift += 7
        except IndexError:
            raise JournalError("journal record ends inside a number") from None

    def svarint(self) -> int:
        v = self.uvarint()
        return (v >> 1) if not v & 1 else -((v + 1) >> 1)

    def bytes(self) -> bytes:
        n = self.uvarint()
        if self.pos + n > self.end:
            raise JournalError("journal record ends inside a string")
        b = self.buf[self.pos:self.pos + n]
        self.pos += n
        return bytes(b)

    def str(self) -> str:
        try:
            return self.bytes().decode("utf-8")
        except UnicodeDecodeError:
            raise JournalError("journal record holds a string that is not UTF-8") from None


# -- frames --------------------------------------------------------------------------------------


def frame(kind: bytes, payload: bytes) -> bytes:
    """One frame: header (magic, kind, length, CRC, header CRC) and payload."""
    if len(payload) > MAX_PAYLOAD:
        raise JournalError(f"journal frame of {len(payload)} bytes; at most {MAX_PAYLOAD}")
    head = FRAME_HEADER.pack(MAGIC, kind, len(payload), zlib.crc32(payload))
    return head + (zlib.crc32(head) & 0xFFFF).to_bytes(2, "little") + payload


def gap_payload(gap: Gap) -> bytes:
    """The payload of a ``G`` frame."""
    out = bytearray(GAP.pack(gap.first, gap.first if gap.last is None else gap.last,
                             gap.ticks or 0))
    put_str(out, gap.cause)
    return bytes(out)


def snapshot_payload(tick: int, data: bytes) -> bytes:
    """The payload of an ``S`` frame: the controller's state before ``tick``."""
    out = bytearray()
    put_uvarint(out, tick)
    put_bytes(out, data)
    return bytes(out)


def read_snapshot_payload(payload: bytes | memoryview) -> tuple[int, bytes]:
    """``(tick, data)`` of an ``S`` frame's payload (JournalError if it is not one)."""
    r = _Cursor(bytes(payload))
    tick = r.uvarint()
    data = r.bytes()
    if r.pos != r.end:
        raise JournalError("journal snapshot: bytes left over after its data")
    return tick, data


def names_payload(first: int, names: Sequence[str]) -> bytes:
    """The payload of an ``N`` frame."""
    out = bytearray()
    put_uvarint(out, first)
    put_uvarint(out, len(names))
    for n in names:
        put_str(out, n)
    return bytes(out)


# -- tick records --------------------------------------------------------------------------------


class BlockEncoder:
    """Encodes tick records into blocks (``T``/``Z`` frame payloads); its state is the
    previous record's inputs, outputs and deadline.  Not thread-safe: one thread owns it."""

    def __init__(self, header: Header, compress: int = 6):
        self.period = header.period_ns
        self.n_inputs = len(header.inputs)
        self.n_outputs = len(header.outputs)
        self.compress = compress
        self.inputs: tuple[int, ...] | None = None
        self.outputs = list(header.output_values) or [0] * self.n_outputs
        self.deadline = 0
        self.tick = 0
        self.body = bytearray()
        self.count = 0
        self.first_tick = 0
        self.first_time = 0
        self.last_time = 0

    def add(self, tick: int, time_ns: int, lateness_ns: int, missed: int,
            inputs: tuple[int, ...], outputs: Sequence[tuple[int, int, int]],
            commands: Sequence[tuple[str, str]], events: Sequence[tuple[str, int, str]]) -> None:
        """Append one tick record to the current block (a keyframe if it is the block's first)."""
        n_out = self.n_outputs
        for w in outputs:
            i, v, wr = w
            if not (type(i) is int and 0 <= i < n_out and type(v) is int and type(wr) is int
                    and wr >= 0):
                raise JournalError(f"journal: tick {tick}: an output write is (index "
                                   f"0..{n_out - 1}, integer value, writer index), got {w!r}")
        for c in commands:
            if len(c) != 2 or not all(type(x) is str for x in c):
                raise JournalError(f"journal: tick {tick}: a command is (text, source), "
                                   f"got {c!r}")
        for e in events:
            if len(e) != 3 or type(e[0]) is not str or type(e[1]) is not int \
                    or type(e[2]) is not str:
                raise JournalError(f"journal: tick {tick}: an event is (name, id, message), "
                                   f"got {e!r}")
        out = self.body
        mark = len(out)
        try:
            self._record(tick, time_ns, lateness_ns, missed, inputs, outputs, commands, events)
        except (TypeError, ValueError):
            del out[mark:]
            raise JournalError(f"journal: tick {tick}: tick, time, lateness, missed and every "
                               f"input must be integers, missed >= 0, ticks increasing") from None

    def _record(self, tick: int, time_ns: int, lateness_ns: int, missed: int,
                inputs: tuple[int, ...], outputs: Sequence[tuple[int, int, int]],
                commands: Sequence[tuple[str, str]], events: Sequence[tuple[str, int, str]]
                ) -> None:
        out = self.body
        prev = self.inputs
        deadline = time_ns - lateness_ns
        flags = 0
        if outputs:
            flags |= F_OUTPUTS
        if commands:
            flags |= F_COMMANDS
        if events:
            flags |= F_EVENTS
        if self.count == 0 or prev is None:
            for v in inputs:
                if type(v) is not int:
                    raise TypeError
            put_uvarint(out, flags | F_KEY)
            put_uvarint(out, tick)
            put_svarint(out, time_ns)
            put_uvarint(out, missed)
            put_svarint(out, lateness_ns)
            for v in inputs:
                put_svarint(out, v)
            for v in self.outputs:
                put_svarint(out, v)
            self.first_tick = tick
            self.first_time = time_ns
        else:
            step = tick - self.tick - 1
            shift = deadline - (self.deadline + self.period * (1 + missed))
            if len(inputs) != len(prev):
                raise ValueError("the inputs changed in number")
            # the indices that changed, found at C speed (the writer thread's largest
            # share of a tick of many inputs)
            changes = list(compress(range(len(inputs)), map(ne, inputs, prev))) \
                if inputs != prev else ()
            if step:
                flags |= F_STEP
            if missed:
                flags |= F_MISSED
            if shift:
                flags |= F_SHIFT
            if lateness_ns:
                flags |= F_LATE
            if changes:
                flags |= F_INPUTS
            put_uvarint(out, flags)
            if step:
                put_uvarint(out, step)
            if missed:
                put_uvarint(out, missed)
            if shift:
                put_svarint(out, shift)
            if lateness_ns:
                put_svarint(out, lateness_ns)
            if changes:
                put_uvarint(out, len(changes))
                last = -1
                for i in changes:
                    put_uvarint(out, i - last - 1)
                    put_svarint(out, inputs[i] - prev[i])
                    last = i
        state = self.outputs
        if outputs:
            state = state.copy()  # kept only once the whole record is encoded
            put_uvarint(out, len(outputs))
            for i, v, w in outputs:
                put_uvarint(out, i)
                put_svarint(out, v - state[i])
                put_uvarint(out, w)
                state[i] = v
        if commands:
            put_uvarint(out, len(commands))
            for text, source in commands:
                put_str(out, text)
                put_str(out, source)
        if events:
            put_uvarint(out, len(events))
            for name, ident, message in events:
                put_str(out, name)
                put_svarint(out, ident)
                put_str(out, message)
        self.outputs = state
        self.inputs = inputs
        self.deadline = deadline
        self.tick = tick
        self.last_time = time_ns
        self.count += 1

    def reset(self) -> None:
        """Forget the previous record: the next one is a keyframe (after a gap)."""
        self.inputs = None

    def take(self) -> tuple[bytes, int, int, int, int, int] | None:
        """The current block as a frame, and ``(first tick, last tick, first time,
        last time, ticks)``; None when it is empty.  The next record starts a new block."""
        if not self.count:
            return None
        head = BLOCK.pack(self.first_tick, self.tick, self.first_time, self.last_time,
                          self.count)
        if self.compress:
            data = frame(KIND_ZTICKS, head + zlib.compress(bytes(self.body), self.compress))
        else:
            data = frame(KIND_TICKS, head + bytes(self.body))
        result = (data, self.first_tick, self.tick, self.first_time, self.last_time, self.count)
        self.body = bytearray()
        self.count = 0
        return result


def decode_block(kind: bytes, payload: bytes | memoryview, header: Header,
                 outputs_before: Sequence[int] | None = None,
                 inputs_before: tuple[int, ...] | None = None) -> list[Tick]:
    """The tick records of a ``T``/``Z`` payload.  ``inputs_before``: the inputs of the
    tick read just before (to tell which inputs a keyframe changed)."""
    first, last, _t0, _t1, count = BLOCK.unpack_from(payload, 0)
    body: bytes | memoryview = payload[BLOCK.size:]
    if kind == KIND_ZTICKS:
        try:
            body = zlib.decompress(body)
        except zlib.error as exc:
            raise JournalError(f"journal block does not decompress: {exc}") from None
    n_in = len(header.inputs)
    n_out = len(header.outputs)
    period = header.period_ns
    r = _Cursor(body)
    ticks: list[Tick] = []
    prev_inputs = inputs_before
    outputs = list(outputs_before) if outputs_before is not None else [0] * n_out
    tick = deadline = 0
    inputs: list[int] = []
    try:
        while r.pos < r.end:
            flags = r.uvarint()
            if flags & F_KEY:
                tick = r.uvarint()
                time_ns = r.svarint()
                missed = r.uvarint()
                lateness = r.svarint()
                inputs = [r.svarint() for _ in range(n_in)]
                outputs = [r.svarint() for _ in range(n_out)]
                deadline = time_ns - lateness
                if prev_inputs is None or len(prev_inputs) != n_in:
                    changed: tuple[int, ...] = tuple(range(n_in))
                else:
                    changed = tuple(i for i in range(n_in) if inputs[i] != prev_inputs[i])
            else:
                if not ticks:
                    raise JournalError("journal block does not begin with a keyframe")
                tick += 1 + (r.uvarint() if flags & F_STEP else 0)
                missed = r.uvarint() if flags & F_MISSED else 0
                deadline += period * (1 + missed) + (r.svarint() if flags & F_SHIFT else 0)
                lateness = r.svarint() if flags & F_LATE else 0
                time_ns = deadline + lateness
                inputs = list(inputs)
                if flags & F_INPUTS:
                    idx = -1
                    ch = []
                    for _ in range(r.uvarint()):
                        idx += r.uvarint() + 1
                        inputs[idx] += r.svarint()
                        ch.append(idx)
                    changed = tuple(ch)
                else:
                    changed = ()
            writes: tuple[tuple[int, int, int], ...] = ()
            if flags & F_OUTPUTS:
                ws = []
                for _ in range(r.uvarint()):
                    i = r.uvarint()
                    v = outputs[i] + r.svarint()
                    outputs[i] = v
                    ws.append((i, v, r.uvarint()))
                writes = tuple(ws)
            commands: tuple[Command, ...] = ()
            if flags & F_COMMANDS:
                commands = tuple(Command(r.str(), r.str()) for _ in range(r.uvarint()))
            events: tuple[Event, ...] = ()
            if flags & F_EVENTS:
                events = tuple(Event(r.str(), r.svarint(), r.str()) for _ in range(r.uvarint()))
            t_inputs = tuple(inputs)
            ticks.append(Tick(tick, time_ns, lateness, missed, t_inputs, changed, writes,
                              tuple(outputs), commands, events, bool(flags & F_KEY)))
            prev_inputs = t_inputs
    except IndexError:
        raise JournalError("journal record names a register the header does not have") \
            from None
    if len(ticks) != count or (ticks and (ticks[0].tick != first or ticks[-1].tick != last)):
        raise JournalError(f"journal block holds {len(ticks)} ticks, its head says {count} "
                           f"({first}..{last})")
    return ticks
