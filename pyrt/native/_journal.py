"""The journal's tick records encoded in C (csrc/journal.c).

:class:`TickEncoder` holds the encoder's state (the previous record's
inputs, every output as it stands, the block being filled) in buffers
allocated once; :meth:`TickEncoder.encode` appends a run of ticks given as
rows of native 64-bit integers, the interpreter lock released while C works.
The bytes are those of :class:`pyrt.journal.format.BlockEncoder` (the
reference the tests hold it to).
"""

from __future__ import annotations

from collections.abc import Sequence

from pyrt.native._errors import NativeInputError, raise_for_status
from pyrt.native._lib import ffi, lib

__all__ = ["JOURNAL_CLOCK", "JOURNAL_TMAX", "JOURNAL_VMAX", "JOURNAL_WRITE", "RecordRefused",
           "TickEncoder"]

#: Fields of a tick's clock row (tick, time_ns, lateness_ns, missed) and of a write.
JOURNAL_CLOCK: int = lib.PYRT_JOURNAL_CLOCK
JOURNAL_WRITE: int = lib.PYRT_JOURNAL_WRITE
#: The largest magnitude of a value, and of a time, the C encoder takes.
JOURNAL_VMAX: int = lib.PYRT_JOURNAL_VMAX
JOURNAL_TMAX: int = lib.PYRT_JOURNAL_TMAX
#: The flags of the fields a caller appends after a record (commands, events).
EXTRA_FLAGS = (lib.PYRT_JF_COMMANDS, lib.PYRT_JF_EVENTS)

class RecordRefused(NativeInputError):
    """The C encoder refused record ``index`` of a run (the records before it are
    encoded, nothing of it): a tick not after the last, missed < 0, an output
    index or writer out of range, or a value beyond its bounds."""

    def __init__(self, message: str, index: int):
        super().__init__(message)
        self.index = index


class TickEncoder:
    """The C encoder of one journal's tick records (see the module text).

    ``output_values``: every output before the first tick (empty: all 0).
    ``capacity``: the body's first size in bytes; it grows (doubles) when a
    record would not fit, which only the first blocks of a run should need.
    """

    __slots__ = ("_body", "_bound", "_cap", "_done", "_outs", "_pos", "_prev", "_st", "n_inputs",
                 "n_outputs")

    def __init__(self, n_inputs: int, n_outputs: int, period_ns: int,
                 output_values: Sequence[int] = (), capacity: int = 1 << 16):
        if output_values and len(output_values) != n_outputs:
            raise ValueError(f"{len(output_values)} output values for {n_outputs} outputs")
        if not 0 <= n_inputs < 1 << 24 or not 0 <= n_outputs < 1 << 24:
            raise ValueError(f"journal encoder: {n_inputs} inputs, {n_outputs} outputs")
        if any(not -JOURNAL_VMAX <= v <= JOURNAL_VMAX for v in output_values):
            raise NativeInputError("journal encoder: an output value beyond +-2**62")
        self.n_inputs = n_inputs
        self.n_outputs = n_outputs
        self._st = ffi.new("pyrt_journal_state *")
        raise_for_status(lib.pyrt_journal_init(self._st, period_ns, n_inputs, n_outputs),
                         f"journal encoder (period {period_ns} ns)")
        self._prev = ffi.new("int64_t[]", max(1, n_inputs))
        self._outs = ffi.new("int64_t[]", max(1, n_outputs))
        for i, v in enumerate(output_values):
            self._outs[i] = v
        self._bound = ffi.new("int64_t *")
        self._cap = max(capacity, 2 * self._record_bound(16))
        self._body = ffi.new("uint8_t[]", self._cap)
        self._pos = ffi.new("int64_t *")
        self._done = ffi.new("int32_t *")

    # -- state ---------------------------------------------------------------------------

    @property
    def count(self) -> int:
        """Records in the block being filled."""
        return int(self._st.count)

    @property
    def size(self) -> int:
        """Bytes of the block being filled."""
        return int(self._pos[0])

    @property
    def tick(self) -> int:
        """The last record's tick."""
        return int(self._st.tick)

    @property
    def first_tick(self) -> int:
        """The block's first tick."""
        return int(self._st.first_tick)

    @property
    def first_time(self) -> int:
        """The block's first tick's time, ns."""
        return int(self._st.first_time)

    @property
    def last_time(self) -> int:
        """The last record's time, ns."""
        return int(self._st.last_time)

    @property
    def deadline(self) -> int:
        """The last record's deadline, ns."""
        return int(self._st.deadline)

    @property
    def has_previous(self) -> bool:
        """Whether a record came before (False: the next is a keyframe)."""
        return bool(self._st.have_prev)

    def previous_inputs(self) -> list[int]:
        """The last record's inputs."""
        return list(self._prev[0:self.n_inputs])

    def outputs(self) -> list[int]:
        """Every output as it stands after the last record."""
        return list(self._outs[0:self.n_outputs])

    def body(self) -> bytes:
        """The records of the block being filled."""
        return ffi.buffer(self._body, self._pos[0])[:]

    # -- encoding ------------------------------------------------------------------------

    @property
    def row_bytes(self) -> int:
        """Bytes of one tick's row: tick, time_ns, lateness_ns, missed, every input
        (``struct`` format ``"<{4 + n_inputs}q"``)."""
        return 8 * (JOURNAL_CLOCK + self.n_inputs)

    def encode(self, rows: bytes | bytearray, start: int, n: int,
               n_writes: Sequence[int] | None = None, writes: Sequence[int] | None = None,
               extra: int = 0) -> None:
        """Append a record for each of rows ``start .. start + n - 1`` of ``rows``
        (native 64-bit integers, :attr:`row_bytes` a tick).  ``n_writes``: the
        output writes of each of those ticks (None: none), ``writes``: their
        ``index, value, writer`` flat, in the order written.  ``extra``: the flags
        of the commands and events the caller appends after the last record.
        :class:`RecordRefused` names the first record refused (counted from
        ``start``; those before it are encoded, nothing of it)."""
        if not isinstance(rows, bytes | bytearray):
            raise TypeError(f"rows must be bytes or a bytearray, got {type(rows).__name__}")
        if start < 0 or n < 0 or len(rows) < (start + n) * self.row_bytes:
            raise ValueError(f"rows {start}..{start + n - 1}: {len(rows)} bytes hold "
                             f"{len(rows) // self.row_bytes} rows")
        if extra & ~(EXTRA_FLAGS[0] | EXTRA_FLAGS[1]):
            raise ValueError(f"extra flags are commands and events only, got {extra!r}")
        if not n:
            return
        if n_writes is not None and any(n_writes):
            if len(n_writes) != n or min(n_writes) < 0:
                raise ValueError(f"writes per tick: {list(n_writes)!r} for {n} ticks")
            total = sum(n_writes)
            if writes is None or len(writes) != total * JOURNAL_WRITE:
                raise ValueError(f"{total} writes need {total * JOURNAL_WRITE} values")
            per = ffi.new("int32_t[]", list(n_writes))
            owner = ffi.new("int64_t[]", list(writes))  # held while C reads it
            w = owner
        else:
            per, owner, total = ffi.new("int32_t[]", n), None, 0
            w = ffi.NULL
        stride = JOURNAL_CLOCK + self.n_inputs
        r = ffi.from_buffer("int64_t[]", rows)
        try:
            k = 0
            while k < n:
                rc = lib.pyrt_journal_encode(self._st, self._prev, self._outs,
                                             r + (start + k) * stride, per + k, w, extra, n - k,
                                             self._body, self._cap, self._pos, self._done)
                done = int(self._done[0])
                try:
                    raise_for_status(rc, "journal encoder")
                except NativeInputError:
                    raise RecordRefused(f"journal: record {k + done} refused (a tick not "
                                        "after the last, missed < 0, an output index or "
                                        "writer out of range, a value beyond its bounds)",
                                        k + done) from None
                if done and total:
                    w = w + sum(per[k:k + done]) * JOURNAL_WRITE
                k += done
                if k < n:
                    self._grow(per[k])
        finally:
            ffi.release(r)  # the buffer is the caller's again at once
            del owner

    def _record_bound(self, n_writes: int) -> int:
        raise_for_status(lib.pyrt_journal_record_bound(self._st, n_writes, self._bound),
                         f"journal record bound ({n_writes} writes)")
        return int(self._bound[0])

    def _grow(self, n_writes: int) -> None:
        need = self._record_bound(n_writes)
        cap = self._cap
        while cap - self._pos[0] < need:
            cap *= 2
        body = ffi.new("uint8_t[]", cap)
        ffi.memmove(body, self._body, self._pos[0])
        self._body, self._cap = body, cap

    def append(self, data: bytes) -> None:
        """Append ``data`` to the block (a record's commands and events)."""
        pos = self._pos[0]
        if self._cap - pos < len(data):
            cap = self._cap
            while cap - pos < len(data):
                cap *= 2
            body = ffi.new("uint8_t[]", cap)
            ffi.memmove(body, self._body, pos)
            self._body, self._cap = body, cap
        ffi.memmove(self._body + pos, data, len(data))
        self._pos[0] = pos + len(data)

    def take(self) -> bytes:
        """The block's records; the next record starts a new block (a keyframe)."""
        data = ffi.buffer(self._body, self._pos[0])[:]
        self._pos[0] = 0
        self._st.count = 0
        return data

    def reset(self) -> None:
        """Forget the previous record: the next one is a keyframe (after a gap)."""
        self._st.have_prev = 0
