"""The journal writer: the loop thread hands over each tick; a thread encodes and writes."""

from __future__ import annotations

import contextlib
import errno
import os
import struct
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from concurrent.futures import Future
from typing import Any, BinaryIO

from pyrt.journal.encoder import NativeBlockEncoder
from pyrt.journal.format import (
    END,
    KIND_END,
    KIND_GAP,
    KIND_HEADER,
    KIND_NAMES,
    Gap,
    Header,
    JournalError,
    frame,
    gap_payload,
    names_payload,
)
from pyrt.journal.ring import BlackBox
from pyrt.native import TickHandOver, int64_buffer

__all__ = ["DEFAULT_BLOCK_TICKS", "DEFAULT_QUEUE_TICKS", "Journal"]

#: Ticks per block (frame), each beginning with a keyframe.
DEFAULT_BLOCK_TICKS = 250
#: Ticks the loop may hand over before the writer takes them; beyond, a gap.
DEFAULT_QUEUE_TICKS = 4096

def _reason(exc: BaseException) -> str:
    """The system's reason for a failed write, in words (a full disk said so)."""
    if isinstance(exc, OSError) and exc.strerror:
        full = exc.errno in (errno.ENOSPC, getattr(errno, "EDQUOT", errno.ENOSPC))
        return exc.strerror + (" (the disk is full)" if full else "")
    return str(exc) or type(exc).__name__


_GAP = object()
_NAMES = object()
_DUMP = object()
_FLUSH = object()
#: Integers the writer encodes in one C call at most; a run is at most a block's
#: ticks.
BATCH_VALUES = 1 << 16
#: The most bytes of the ring of ticks handed over and not yet written (beyond
#: :data:`DEFAULT_QUEUE_TICKS` rows, a tick of many inputs has fewer rows).
RING_BYTES = 8 << 20


class Journal:
    """Records a run (see :mod:`pyrt.journal.format` for what and how).

    ``target``: a path (created or truncated), an open binary stream (``write``;
    ``flush`` and ``fileno`` used when it has them) or None (a black box only).
    ``black_box``: a :class:`BlackBox` fed with the same frames, or None.
    ``block_ticks``: ticks per block; each block is one frame and begins with a
    keyframe, so a run killed with ``kill -9`` loses at most the block being
    filled (and a block is written at the latest ``max_delay_s`` of wall time
    after its first tick).  ``compress``: zlib level of the blocks (0: none).
    ``queue_ticks``: how many ticks may wait for the writer thread (each a row
    of 64-bit integers in a ring of at most 8 MiB: fewer for ticks of very many
    inputs); when that many wait, :meth:`record_tick` drops the tick and the
    journal records a gap instead of blocking; with ``lossless`` (a run on
    virtual time, where waiting costs nothing) it waits for room instead.
    ``warn`` is called (in the writer thread) with one line for each gap, write
    error and refused tick.

    The loop thread calls :meth:`record_tick` once per tick (and
    :meth:`writer_index` to name a new writer); any thread may call
    :meth:`dump_black_box`; :meth:`close` flushes, fsyncs and ends the file.
    """

    def __init__(self, header: Header, target: str | os.PathLike[str] | BinaryIO | None = None,
                 *, black_box: BlackBox | None = None, block_ticks: int = DEFAULT_BLOCK_TICKS,
                 compress: int = 6, queue_ticks: int = DEFAULT_QUEUE_TICKS,
                 max_delay_s: float = 0.5, poll_s: float = 0.02, lossless: bool = False,
                 warn: Callable[[str], None] | None = None):
        if not isinstance(header, Header):
            raise JournalError(f"journal: header must be a Header, got {type(header).__name__}")
        for name, v, lo in (("block_ticks", block_ticks, 1), ("queue_ticks", queue_ticks, 1),
                            ("compress", compress, 0)):
            if isinstance(v, bool) or not isinstance(v, int) or v < lo:
                raise JournalError(f"journal: {name} must be an integer >= {lo}, got {v!r}")
        if compress > 9:
            raise JournalError(f"journal: compress is a zlib level 0..9, got {compress!r}")
        if target is None and black_box is None:
            raise JournalError("journal: nothing to write to (no file and no black box)")
        self.header = header
        self.black_box = black_box
        self.block_ticks = block_ticks
        self.max_delay_ns = int(max_delay_s * 1e9)
        self.poll_s = poll_s
        self.warn = warn
        self.path: str | None = None
        self._fh: Any = None
        self._owned = False
        if target is not None:
            if isinstance(target, str | os.PathLike):
                self.path = os.fspath(target)
                try:
                    self._fh = open(self.path, "wb", buffering=0)  # noqa: SIM115
                except OSError as exc:
                    raise JournalError(f"journal {self.path}: {exc.strerror or exc}") from None
                self._owned = True
            elif callable(getattr(target, "write", None)):
                self._fh = target
                self.path = getattr(target, "name", "<stream>")
            else:
                raise JournalError(f"journal: target must be a path or a binary stream, "
                                   f"got {type(target).__name__}")
        self._n_inputs = len(header.inputs)
        self._writers = list(header.writers)
        self._encoder = NativeBlockEncoder(header, compress)
        row = self._encoder.row
        self._pack = row.pack_into
        self._row_size = row.size
        #: Ticks handed over and not yet taken, at most (the ring's rows).
        self._capacity = min(queue_ticks, max(1, RING_BYTES // row.size))
        #: The ring of ticks handed over: a row each (tick, time, lateness, missed,
        #: every input), tick ``s`` in row ``s % capacity``.
        self._ring = bytearray(self._capacity * row.size)
        self._ring_words = memoryview(self._ring).cast("q")
        self._row_words = row.size // 8
        self._clock = struct.Struct("=4q").pack_into
        #: What a tick's row leaves out, in the order handed over: (its number,
        #: (outputs, commands, events, the whole tick if it could not be packed)).
        self._extras: deque[tuple[int, tuple[Any, Any, Any, Any]]] = deque()
        #: Entries that are not ticks (gaps, names, dumps, flushes), each after the
        #: ticks handed over before it: ``(number of ticks before it, kind, ...)``.
        self._queue: deque[tuple[Any, ...]] = deque()
        #: The one-C-call hand-over (:meth:`hand_over`); its state holds ``put`` (ticks
        #: handed over: the loop thread's), ``taken`` (encoded: the writer's), ``open``
        #: (not closed nor in a gap) and ``slow`` (set by the writer on a write error).
        self._hand = TickHandOver(self._ring, self._capacity, self._n_inputs,
                                  header.period_ns)
        self._st = self._hand.state
        self._gap_first: int | None = None
        self._gap_last = 0
        self._gap_count = 0
        self._closed = False
        self._wake = threading.Event()
        self._room = threading.Event()
        self._waiting = False
        self.lossless = lossless
        self._stop = False
        #: Gaps so far (as the loop thread knows them: a gap is listed when it ends).
        self.gaps: list[Gap] = []
        #: Ticks dropped into gaps (:attr:`recorded`: those handed over).
        self.dropped = 0
        #: Bytes written to the file so far (writer thread).
        self.bytes_written = 0
        #: The first write error (the file is no longer written; the black box is).
        #: A station's recorder reads it every tick: a journal that cannot be
        #: written is a fault of the station (:class:`~pyrt.station.recording.Recorder`).
        self.error: str | None = None
        self._fail: BaseException | None = None
        #: Ticks the writer refused (not integers, an output index out of range ...)
        #: and the first refusal's message.
        self.refused = 0
        self.refusal: str | None = None
        self._block_started = 0
        # The header is written here, not by the thread: a file that cannot be
        # written (a full disk) refuses the journal, and the run, before it starts.
        self._write(frame(KIND_HEADER, self.header.encode()), warn=False)
        if self.error is not None:
            if self._owned:
                with contextlib.suppress(OSError):
                    self._fh.close()
            raise JournalError(f"journal {self.path}: {self.error}")
        self._thread = threading.Thread(target=self._run, name="pyrt-journal", daemon=True)
        self._thread.start()

    # -- the loop thread ---------------------------------------------------------------------

    def record_tick(self, tick: int, time_ns: int, lateness_ns: int, missed: int,
                    inputs: Sequence[int], outputs: Sequence[tuple[int, int, int]] = (),
                    commands: Sequence[tuple[str, str]] = (),
                    events: Sequence[tuple[str, int, str]] = ()) -> bool:
        """Hand over one tick: its index, clock time, lateness, deadlines missed
        since the previous tick, every input (declared order; copied into the
        journal's ring: a buffer of 64-bit integers, such as an ``array('q')``,
        whole, a list integer by integer), the changed outputs written ``(index, value, writer
        index)`` in the order written, the mailbox commands applied ``(text,
        source)`` and named events ``(name, id, message)`` (these sequences are
        kept, not copied: pass new ones).  Never blocks.  Returns False if the
        tick was dropped into a gap (the writer is behind)."""
        st = self._st
        put = st.put
        if put - st.taken < self._capacity and st.open:
            row = put % self._capacity
            try:
                if type(inputs) is list:
                    self._pack(self._ring, row * self._row_size, tick, time_ns, lateness_ns,
                               missed, *inputs)
                else:
                    # a buffer of 64-bit integers (``array('q')``): copied whole
                    self._clock(self._ring, row * self._row_size, tick, time_ns, lateness_ns,
                                missed)
                    at = row * self._row_words + 4
                    self._ring_words[at:at + self._n_inputs] = inputs  # type: ignore[call-overload]
            except (struct.error, TypeError, ValueError, NotImplementedError):
                return self._record_slowly(tick, time_ns, lateness_ns, missed, inputs,
                                           outputs, commands, events)
            if outputs or commands or events:
                self._extras.append((put, (outputs, commands, events, None)))
            st.put = put + 1
            return True
        return self._record_slowly(tick, time_ns, lateness_ns, missed, inputs, outputs,
                                   commands, events)

    #: The same call (a tick's inputs are copied into the ring either way).
    record_owned = record_tick

    def hand_over(self, inputs: Any) -> TickHandOver | None:
        """The one-C-call hand-over of a plain tick (:class:`~pyrt.native.TickHandOver`:
        its owner keeps the expected tick, the lateness bounds and ``slow``; the ring
        full, a gap, a close or a write error refuse it, and :meth:`record_tick`
        decides), reading ``inputs``: a buffer of the header's inputs in native 64-bit
        integers its owner refills every tick; else None.  Loop thread only."""
        return self._hand if self._hand.bind(inputs) else None

    def _record_slowly(self, tick: int, time_ns: int, lateness_ns: int, missed: int,
                       inputs: Sequence[int], outputs: Sequence[tuple[int, int, int]],
                       commands: Sequence[tuple[str, str]],
                       events: Sequence[tuple[str, int, str]]) -> bool:
        if self._closed:
            raise JournalError("journal: record_tick after close")
        if len(inputs) != self._n_inputs:
            raise JournalError(f"journal: {len(inputs)} inputs, the header declares "
                               f"{self._n_inputs}")
        st = self._st
        if st.put - st.taken >= self._capacity:
            if not self.lossless:
                if self._gap_first is None:
                    self._gap_first = tick
                    st.open = 0
                self._gap_last = tick
                self._gap_count += 1
                self.dropped += 1
                return False
            self._wait_for_room()
        if self._gap_first is not None:
            self._end_gap()
        put = st.put
        row = put % self._capacity
        try:
            words = int64_buffer(inputs)
            if words is not None:
                # a buffer of 64-bit integers (an image that keeps its inputs so): copied
                # whole, not integer by integer
                self._clock(self._ring, row * self._row_size, tick, time_ns, lateness_ns,
                            missed)
                at = row * self._row_words + 4
                self._ring_words[at:at + self._n_inputs] = words
            else:
                self._pack(self._ring, row * self._row_size, tick, time_ns, lateness_ns,
                           missed, *inputs)
        except (struct.error, TypeError):
            # not 64-bit integers: the tick goes whole (the writer refuses or takes it)
            self._extras.append((put, (outputs, commands, events,
                                       (tick, time_ns, lateness_ns, missed, tuple(inputs),
                                        outputs, commands, events))))
        else:
            if outputs or commands or events:
                self._extras.append((put, (outputs, commands, events, None)))
        st.put = put + 1
        return True

    def _wait_for_room(self) -> None:
        # wait until half the queue is free: one hand-over per half queue, not per tick
        st = self._st
        while st.put - st.taken > self._capacity // 2:
            if not self._thread.is_alive():
                raise JournalError(f"journal {self.path}: the writer has stopped")
            self._room.clear()
            self._waiting = True
            self._wake.set()
            self._room.wait(self.poll_s)
        self._waiting = False

    def _end_gap(self) -> None:
        assert self._gap_first is not None
        gap = Gap(self._gap_first, self._gap_last, self._gap_count,
                  "the journal's writer fell behind")
        self.gaps.append(gap)
        self._queue.append((self._st.put, _GAP, gap))
        self._gap_first = None
        self._st.open = 0 if self._closed else 1
        self._gap_count = 0

    def writer_index(self, name: str) -> int:
        """The index of writer (task) ``name`` in the name table, added if new."""
        try:
            return self._writers.index(name)
        except ValueError:
            pass
        if not isinstance(name, str):
            raise JournalError(f"journal: a writer's name is a string, got {name!r}")
        self._writers.append(name)
        index = len(self._writers) - 1
        self._queue.append((self._st.put, _NAMES, index, name))
        self._wake.set()
        return index

    @property
    def recorded(self) -> int:
        """Ticks handed over (not those dropped into gaps)."""
        return int(self._st.put)

    @property
    def writers(self) -> list[str]:
        """The writer name table (a copy)."""
        return list(self._writers)

    @property
    def pending(self) -> int:
        """Ticks handed over that the writer has not taken yet."""
        return int(self._st.put - self._st.taken)

    # -- any thread --------------------------------------------------------------------------

    def dump_black_box(self, target: str | os.PathLike[str] | BinaryIO) -> Future[int]:
        """Write the black box (with every tick handed over so far) as a journal file, in
        the writer thread (at once, after :meth:`close`); the future gives the number
        of tick records written, or raises JournalError."""
        if self.black_box is None:
            raise JournalError("journal: no black box to dump")
        fut: Future[int] = Future()
        if self._closed:
            self._thread.join()
            self._dump(target, fut)
            return fut
        self._queue.append((self._st.put, _DUMP, target, fut))
        self._wake.set()
        return fut

    def flush(self, timeout: float | None = None) -> bool:
        """Wait until every tick handed over so far is written (the block being
        filled included); False if ``timeout`` seconds passed first.  Not for the
        loop thread of a real-time run: it waits for the disk."""
        if self._closed:
            return True
        done = threading.Event()
        self._queue.append((self._st.put, _FLUSH, done))
        self._wake.set()
        return done.wait(timeout)

    def close(self) -> None:
        """Write what is pending, end the file, flush and fsync it, stop the thread.
        Call it after the last :meth:`record_tick` (in the loop thread, or once the
        loop has stopped).  Raises JournalError if the file could not be written in
        full or ticks were refused; the file holds what could be written."""
        if self._closed:
            return
        if self._gap_first is not None:
            self._end_gap()
        self._closed = True
        self._st.open = 0
        self._stop = True
        self._wake.set()
        self._thread.join()
        if self._fail is not None:
            raise JournalError(f"journal {self.path}: the writer failed: {self._fail!r}") \
                from self._fail
        if self.error is not None:
            raise JournalError(f"journal {self.path}: {self.error}")
        if self.refusal is not None:
            raise JournalError(f"journal {self.path}: {self.refused} tick(s) not recorded; "
                               f"the first: {self.refusal}")

    def __enter__(self) -> Journal:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- the writer thread -------------------------------------------------------------------

    def _header_payload(self) -> bytes:
        return _with_writers(self.header, self._writers).encode()

    def _write(self, data: bytes, warn: bool = True) -> None:
        fh = self._fh
        if fh is None or self.error is not None:
            return
        try:
            view = memoryview(data)
            while view:
                n = fh.write(view)
                if n is None:
                    raise OSError("the stream would block")
                view = view[n:]
            flush = getattr(fh, "flush", None)
            if flush is not None:
                flush()
            self.bytes_written += len(data)
        except (OSError, ValueError) as exc:
            self._set_error(f"write failed after {self.bytes_written} bytes: {_reason(exc)}")
            if self.warn is not None and warn:
                self.warn(f"journal {self.path}: {self.error}; the file ends there")

    def _set_error(self, error: str) -> None:
        # the error, then the mark: the recorder clears the mark, then reads the error
        self.error = error
        self._st.slow = 1

    def _emit(self, data: bytes, first_time: int, last_time: int, ticks: int) -> None:
        if self.black_box is not None:
            self.black_box.add(data, first_time, last_time, ticks)
        self._write(data)

    def _dump(self, target: Any, fut: Future[int]) -> None:
        assert self.black_box is not None
        try:
            fut.set_result(self.black_box.dump(target, self._header_payload()))
        except JournalError as exc:
            fut.set_exception(exc)

    def _flush_block(self) -> None:
        taken = self._encoder.take()
        if taken is not None:
            data, _first, _last, t0, t1, n = taken
            self._emit(data, t0, t1, n)

    def _run(self) -> None:
        try:
            self._loop()
        except BaseException as exc:
            self._fail = exc
            self._set_error(self.error or f"the writer failed: {exc!r}")
            if self.warn is not None:
                self.warn(f"journal {self.path}: the writer failed: {exc!r}")
            # keep taking records so the loop thread never fills the queue for nothing
            while not self._stop:
                self._drain_discard()
                self._room.set()
                self._wake.wait(self.poll_s)
                self._wake.clear()
            self._drain_discard()
        finally:
            self._finish()

    def _drain_discard(self) -> None:
        q = self._queue
        while q:
            item = q.popleft()
            if item[1] is _DUMP:
                item[3].set_exception(JournalError("journal: the writer failed"))
            elif item[1] is _FLUSH:
                item[2].set()
        self._extras.clear()
        self._st.taken = self._st.put

    def _loop(self) -> None:
        q = self._queue
        enc = self._encoder
        block = self.block_ticks
        cap = self._capacity
        ring = self._ring
        extras = self._extras
        wait = self._wake.wait
        clear = self._wake.clear
        sleep = time.sleep
        mono = time.monotonic_ns
        yield_gil = not self.lossless
        most = max(1, BATCH_VALUES // (4 + self._n_inputs))
        st = self._st
        drained = mono()
        while True:
            stopping = self._stop
            while True:
                put = st.put
                limit = min(put, q[0][0]) if q else put
                taken = st.taken
                if taken < limit:
                    # a run of ticks, contiguous in the ring, at most to the block's end
                    # and the next entry that is not a tick: one C call, the
                    # interpreter lock released while it encodes
                    start = taken % cap
                    n = min(limit - taken, block - enc.count, most, cap - start)
                    mine: dict[int, tuple[Any, Any, Any, Any]] = {}
                    end = taken + n
                    while extras and extras[0][0] < end:
                        s, extra = extras.popleft()
                        mine[s - taken] = extra
                    if enc.count == 0:
                        # at real time, the earliest its first tick came (the ring empty)
                        self._block_started = mono() if self.lossless else drained
                    for exc in enc.add_rows(ring, start, n, mine):
                        self._refused(exc)
                    st.taken = taken + n
                    if enc.count >= block:
                        self._flush_block()
                    if self._waiting and st.put - st.taken <= cap // 2:
                        self._room.set()
                    if yield_gil and st.put > st.taken:
                        # more to encode: a real-time loop thread waking now gets the
                        # interpreter at once (on virtual time this would only slow
                        # both threads); with nothing more, the wait below lets go of
                        # it, and a yield here would be one more wake-up for nothing
                        sleep(0)
                    continue
                if not q or q[0][0] > taken:
                    break
                item = q.popleft()
                head = item[1]
                if head is _GAP:
                    self._flush_block()
                    enc.reset()
                    gap: Gap = item[2]
                    self._emit(frame(KIND_GAP, gap_payload(gap)), enc.last_time, enc.last_time, 0)
                    if self.warn is not None:
                        self.warn(f"journal {self.path}: ticks {gap.first}..{gap.last} not "
                                  f"recorded ({gap.cause}); not replayable past tick "
                                  f"{gap.first}")
                elif head is _NAMES:
                    self._emit(frame(KIND_NAMES, names_payload(item[2], [item[3]])),
                               enc.last_time, enc.last_time, 0)
                elif head is _FLUSH:
                    self._flush_block()
                    item[2].set()
                else:  # _DUMP
                    self._flush_block()
                    self._dump(item[2], item[3])
            if self._waiting:
                self._room.set()
            if enc.count and (stopping or mono() - self._block_started > self.max_delay_ns):
                self._flush_block()
            if stopping:
                return
            drained = mono()
            cut_in = self._block_started + self.max_delay_ns - drained \
                if enc.count and not self.lossless else None
            wait(_wait_s(self.poll_s, cut_in))
            clear()

    def _refused(self, exc: JournalError) -> None:
        self.refused += 1
        if self.refused == 1:
            self.refusal = exc.message
            if self.warn is not None:
                self.warn(f"journal {self.path}: {exc.message}; the tick is not recorded")

    def _finish(self) -> None:
        if self._fail is None:
            self._write(frame(KIND_END, END.pack(self.recorded, self.dropped)))
        if self._fh is not None:
            self.error = _sync_and_close(self._fh, self._owned, self.error)


def _wait_s(poll_s: float, cut_in_ns: int | None) -> float:
    """How long the writer waits for ticks: a poll, or less when a block being filled
    is to be cut in ``cut_in_ns`` (at real time: woken then, not a poll later)."""
    return poll_s if cut_in_ns is None else min(poll_s, max(1e-3, cut_in_ns / 1e9))


def _with_writers(h: Header, writers: list[str]) -> Header:
    """``h`` with the writer name table ``writers`` (``h`` itself if it has it)."""
    if list(h.writers) == writers:
        return h
    return Header(station=h.station, period_ns=h.period_ns, inputs=h.inputs,
                  outputs=h.outputs, version=h.version, databases=h.databases,
                  seeds=h.seeds, writers=writers, output_values=h.output_values,
                  metadata=h.metadata)


def _sync_and_close(fh: Any, owned: bool, error: str | None) -> str | None:
    """Sync a journal's file (unless ``error``: it was not written in full) and close
    it if the journal opened it; the error, or the first of the sync or the close."""
    try:
        fileno = getattr(fh, "fileno", None)
        if fileno is not None and error is None:
            try:
                os.fsync(fileno())
            except (OSError, ValueError, AttributeError) as exc:
                if not isinstance(exc, ValueError | AttributeError) and owned:
                    error = f"fsync failed: {exc}"
    finally:
        if owned:
            try:
                fh.close()
            except OSError as exc:
                error = error or f"close failed: {exc}"
    return error

