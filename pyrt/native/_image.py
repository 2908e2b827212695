"""The process image's side of a tick in C (csrc/image.c).

:class:`InputGather` copies the inputs of in-process boards that keep them
in 64-bit integers into the image's flat array of inputs (the read phase's
exchange: one C call, one ``memcpy`` a board); :class:`RingRows` appends a
tick's row (its clock and every input) to the journal's ring;
:class:`TickHandOver` is the recorder's hand-over of a plain tick, one C
call made from the image's write phase with the tick's start time alone
(its state a C struct the journal's writer thread shares);
:func:`output_changes` is the change detection of a block of outputs.
Every array is bound once, when the object is made, and held by it: the
per-tick calls convert nothing.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from functools import partial
from typing import Any

from pyrt.native._errors import NativeInputError, raise_for_status
from pyrt.native._lib import ffi, lib

__all__ = ["HAND_OVER_DUE", "HAND_OVER_SLOW", "IMAGE_CLOCK", "IMAGE_TMAX", "InputGather",
           "RingRows", "TickHandOver", "int64_buffer", "output_changes"]

#: Fields of a tick's clock in a ring row: tick, time_ns, lateness_ns, missed.
IMAGE_CLOCK: int = lib.PYRT_IMAGE_CLOCK
#: :class:`TickHandOver`'s answers besides 0 (handed over, nothing due): nothing
#: handed over (the caller records the tick), and handed over with the tick
#: listeners due.
HAND_OVER_SLOW: int = lib.PYRT_IMAGE_SLOW
HAND_OVER_DUE: int = lib.PYRT_IMAGE_DUE
#: The largest magnitude of a plain tick's time, deadline, index or count.
IMAGE_TMAX: int = lib.PYRT_IMAGE_TMAX


def int64_buffer(obj: Any) -> memoryview | None:
    """``obj`` as a flat view of native 64-bit integers, if it exports one (an
    ``array('q')``, a numpy ``int64`` array, a ``memoryview`` of either), else
    None (a list, a tuple ...)."""
    if isinstance(obj, list | tuple):
        return None
    try:
        view = memoryview(obj)
    except TypeError:
        return None
    if view.itemsize != 8 or view.format.lstrip("@=<") not in ("q", "l") \
            or not view.c_contiguous:
        return None
    return view.cast("B").cast("q")


class InputGather:
    """The copy of every source into ``inputs`` (a writable buffer of native
    64-bit integers): ``sources`` are ``(buffer, at, count)``, each buffer a
    board's inputs in 64-bit integers (see :func:`int64_buffer`) copied to
    ``inputs[at:at + count]``.  Call it (no arguments) once a read phase."""

    __slots__ = ("_args", "_held", "_src")

    def __init__(self, inputs: Any, sources: Sequence[tuple[Any, int, int]]):
        dst = int64_buffer(inputs)
        if dst is None or dst.readonly:
            raise NativeInputError("image inputs: a writable buffer of 64-bit integers")
        self._held: list[Any] = [dst]
        self._src = ffi.new("pyrt_image_source[]", max(1, len(sources)))
        for k, (buf, at, count) in enumerate(sources):
            view = int64_buffer(buf)
            if view is None or len(view) < count:
                raise NativeInputError(f"image source {k}: {count} 64-bit integers expected")
            if not (at >= 0 and 0 <= count <= len(dst) - at):
                raise NativeInputError(f"image source {k}: inputs {at}..{at + count - 1} "
                                       f"outside the image's {len(dst)}")
            ptr = ffi.from_buffer("int64_t[]", view)
            self._held.append(ptr)
            self._src[k].values = ptr
            self._src[k].at = at
            self._src[k].count = count
        self._args = (ffi.from_buffer("int64_t[]", dst), len(dst), self._src, len(sources))
        self._held.append(self._args[0])
        raise_for_status(lib.pyrt_image_gather(*self._args), "image gather")

    def __call__(self) -> None:
        raise_for_status(lib.pyrt_image_gather(*self._args), "image gather")


class RingRows:
    """Rows of a ring of ``rows`` rows (``ring``: a ``bytearray`` or a writable buffer
    of 64-bit integers, of at least
    ``rows * (IMAGE_CLOCK + len(inputs))`` 64-bit integers), each a tick's
    clock and the current ``inputs`` (a buffer of 64-bit integers, read at
    every :meth:`put`)."""

    __slots__ = ("_held", "_inputs", "_n", "_ring", "rows")

    def __init__(self, ring: Any, rows: int, inputs: Any):
        src = int64_buffer(inputs)
        dst = int64_buffer(ring)
        if dst is None and isinstance(ring, bytearray) and len(ring) % 8 == 0:
            dst = memoryview(ring).cast("q")  # a ring of bytes, 8 an integer
        if src is None or dst is None or dst.readonly:
            raise NativeInputError("ring rows: buffers of 64-bit integers expected")
        if rows <= 0 or len(dst) < rows * (IMAGE_CLOCK + len(src)):
            raise NativeInputError(f"ring rows: {len(dst)} integers do not hold {rows} rows "
                                   f"of {IMAGE_CLOCK + len(src)}")
        self._ring = ffi.from_buffer("int64_t[]", dst)
        self._inputs = ffi.from_buffer("int64_t[]", src)
        self._n = len(src)
        self._held = (src, dst)
        self.rows = rows

    def put(self, slot: int, tick: int, time_ns: int, lateness_ns: int, missed: int) -> None:
        """Row ``slot``: the clock given, then the inputs as they are now."""
        raise_for_status(lib.pyrt_image_row(self._ring, self.rows, slot, tick, time_ns,
                                            lateness_ns, missed, self._inputs, self._n),
                         "ring row")

    def writer(self) -> Any:
        """``put`` as the bare C call ``(ring, rows, slot, tick, time_ns, lateness_ns,
        missed, inputs, n_inputs) -> status`` and its fixed arguments (ring, rows)
        and (inputs, n_inputs): the caller's per-tick path makes no Python frame."""
        return lib.pyrt_image_row, (self._ring, self.rows), (self._inputs, self._n)


class TickHandOver:
    """The recorder's hand-over of a plain tick into a ring of ``rows`` rows
    (``ring``: a ``bytearray`` or a writable buffer of 64-bit integers, of at
    least ``rows * (IMAGE_CLOCK + n_inputs)`` integers) at ``period_ns``
    (``csrc/image.h``, ``pyrt_image_hand_over``).

    :attr:`state` is the C struct both threads share, its fields read and
    written as attributes: ``put`` (ticks handed over; the loop thread),
    ``taken`` (ticks the journal's writer took; its thread), ``open``,
    ``slow``, ``tick`` and ``deadline_ns`` (the next plain tick's),
    ``late_lo``/``late_hi`` (a plain tick's lateness), ``listen_at``.  It
    starts open, ``slow`` (nothing handed over until the owner sets the
    expected tick and clears it), nothing due.  :attr:`call` is the bare C
    call ``call(now_ns) -> status`` (0, :data:`HAND_OVER_DUE`,
    :data:`HAND_OVER_SLOW`, or 1 for a refused state), usable once
    :meth:`bind` gave it the inputs: a caller's per-tick path makes no
    Python frame."""

    __slots__ = ("_held", "call", "n_inputs", "rows", "state")

    def __init__(self, ring: Any, rows: int, n_inputs: int, period_ns: int):
        dst = int64_buffer(ring)
        if dst is None and isinstance(ring, bytearray) and len(ring) % 8 == 0:
            dst = memoryview(ring).cast("q")  # a ring of bytes, 8 an integer
        if dst is None or dst.readonly:
            raise NativeInputError("tick hand-over: a writable ring of 64-bit integers")
        if rows <= 0 or n_inputs < 0 or len(dst) < rows * (IMAGE_CLOCK + n_inputs):
            raise NativeInputError(f"tick hand-over: {len(dst)} integers do not hold {rows} "
                                   f"rows of {IMAGE_CLOCK + n_inputs}")
        if not 0 < period_ns <= IMAGE_TMAX:
            raise NativeInputError(f"tick hand-over: period {period_ns} ns out of range")
        state = ffi.new("pyrt_image_handover *")
        ring_ptr = ffi.from_buffer("int64_t[]", dst)
        state.ring = ring_ptr
        state.rows = rows
        state.n_inputs = n_inputs
        state.period_ns = period_ns
        state.open = 1
        state.slow = 1
        state.listen_at = IMAGE_TMAX
        self._held: list[Any] = [dst, ring_ptr]
        self.state: Any = state
        self.rows = rows
        self.n_inputs = n_inputs
        self.call: Callable[[int], int] = partial(lib.pyrt_image_hand_over, state)

    def bind(self, inputs: Any) -> bool:
        """Read the inputs of every tick handed over from ``inputs`` (a buffer of
        ``n_inputs`` native 64-bit integers its owner refills in place); False
        (nothing bound) for anything else."""
        view = int64_buffer(inputs)
        if view is None or len(view) != self.n_inputs:
            return False
        ptr = ffi.from_buffer("int64_t[]", view) if len(view) else ffi.NULL
        self._held += [view, ptr]
        self.state.inputs = ptr
        return True

    def __call__(self, now_ns: int) -> int:
        """:attr:`call`, its refusal of a bad state raised (NativeInputError)."""
        status: int = self.call(now_ns)
        if status not in (0, HAND_OVER_SLOW, HAND_OVER_DUE):
            raise_for_status(status, "tick hand-over")
        return status


def output_changes(current: Any, values: Sequence[int], all_changed: bool = False
                   ) -> list[int]:
    """The indices of ``values`` that differ from ``current`` (a writable buffer of
    64-bit integers of the same length; every index if ``all_changed``), ``current``
    updated to ``values``."""
    cur = int64_buffer(current)
    if cur is None or cur.readonly:
        raise NativeInputError("output changes: a writable buffer of 64-bit integers")
    n = len(values)
    if n != len(cur):
        raise NativeInputError(f"output changes: {n} values for {len(cur)} outputs")
    vals = ffi.new("int64_t[]", list(values)) if n else ffi.NULL
    out = ffi.new("int32_t[]", max(1, n))
    count = ffi.new("int32_t *")
    raise_for_status(lib.pyrt_image_changes(ffi.from_buffer("int64_t[]", cur) if n else ffi.NULL,
                                            vals, n, 1 if all_changed else 0, out, count),
                     "output changes")
    return list(out[0:count[0]])
