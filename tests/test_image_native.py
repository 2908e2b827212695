"""The process image's C side (csrc/image.c): its kernels against Python references,
an image over boards that keep their inputs in 64-bit integers, and the journal's
one-call hand-over of a tick."""

from __future__ import annotations

import io
import random
import struct
from array import array

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_journal import header

from pyrt.boards.image import ImageRegisters, LocalImage, input_buffer
from pyrt.boards.registers import OUTPUT, BoardKind, Register, RegisterBoard
from pyrt.journal import Journal
from pyrt.native import (
    IMAGE_CLOCK,
    InputGather,
    NativeInputError,
    RingRows,
    int64_buffer,
    output_changes,
)

I64 = st.integers(-(2**63), 2**63 - 1)

# -- the kernels against their references ------------------------------------------------


def gather_reference(n: int, sources: list[tuple[list[int], int, int]]) -> list[int]:
    """The image's inputs after the gather: each source's values at its place."""
    out = [0] * n
    for values, at, count in sources:
        out[at:at + count] = values[:count]
    return out


@st.composite
def images(draw):
    """An image of n inputs and sources that tile parts of it."""
    n = draw(st.integers(0, 300))
    cuts = sorted(draw(st.lists(st.integers(0, n), max_size=6)))
    sources = []
    for a, b in zip([0, *cuts], [*cuts, n], strict=True):
        if draw(st.booleans()):
            sources.append((draw(st.lists(I64, min_size=b - a, max_size=b - a)), a, b - a))
    return n, sources


@settings(max_examples=200, deadline=None)
@given(images())
def test_gather_copies_each_source_to_its_place(image):
    """One C gather leaves the image's inputs as slice assignments of every source would."""
    n, sources = image
    inputs = array("q", bytes(8 * n))
    bufs = [(array("q", v), at, c) for v, at, c in sources]
    gather = InputGather(inputs, bufs)
    assert inputs.tolist() == gather_reference(n, sources)
    for buf, _at, _c in bufs:  # the boards change in place; the next call sees it
        for i in range(len(buf)):
            buf[i] = -buf[i] if buf[i] != -(2**63) else 0
    gather()
    assert inputs.tolist() == gather_reference(n, [(b.tolist(), a, c) for b, a, c in bufs])


@settings(max_examples=200, deadline=None)
@given(n=st.integers(0, 50), rows=st.integers(1, 8), data=st.data())
def test_a_ring_row_is_the_clock_and_the_inputs(n, rows, data):
    """A row the C side writes is the row ``struct`` packs: tick, time, lateness, missed,
    every input; the other rows are untouched."""
    slot = data.draw(st.integers(0, rows - 1))
    clock = data.draw(st.lists(I64, min_size=IMAGE_CLOCK, max_size=IMAGE_CLOCK))
    inputs = array("q", data.draw(st.lists(I64, min_size=n, max_size=n)))
    row = struct.Struct(f"={IMAGE_CLOCK + n}q")
    ring = bytearray(b"\x5a" * (rows * row.size))
    want = bytearray(ring)
    row.pack_into(want, slot * row.size, *clock, *inputs)
    RingRows(ring, rows, inputs).put(slot, *clock)
    assert ring == want


@settings(max_examples=200, deadline=None)
@given(data=st.data(), n=st.integers(0, 40), strobe=st.booleans())
def test_output_changes_are_the_slots_that_differ(data, n, strobe):
    """The change detection names the outputs whose value differs (every one for a
    write-only strobe), in order, and leaves the current values the new ones."""
    current = data.draw(st.lists(I64, min_size=n, max_size=n))
    values = [v if data.draw(st.booleans()) else data.draw(I64) for v in current]
    cur = array("q", current)
    got = output_changes(cur, values, strobe)
    assert got == [i for i in range(n) if strobe or values[i] != current[i]]
    assert cur.tolist() == values


def test_the_kernels_refuse_what_does_not_fit():
    """A source outside the image, a ring too small for its rows, a slot beyond them, a
    list where 64-bit integers are needed, or a count that is not the image's: refused."""
    inputs = array("q", bytes(8 * 4))
    with pytest.raises(NativeInputError):
        InputGather(inputs, [(array("q", [1, 2]), 3, 2)])
    with pytest.raises(NativeInputError):
        InputGather(inputs, [([1, 2], 0, 2)])
    with pytest.raises(NativeInputError):
        InputGather([0, 0], [])
    with pytest.raises(NativeInputError):
        RingRows(bytearray(8 * 7), 1, inputs)
    rows = RingRows(bytearray(8 * 8 * 2), 2, inputs)
    with pytest.raises(NativeInputError):
        rows.put(2, 0, 0, 0, 0)
    with pytest.raises(NativeInputError):
        output_changes(array("q", [1]), [1, 2])
    assert int64_buffer([1, 2]) is None and int64_buffer(array("i", [1])) is None
    assert int64_buffer(array("q", [1, 2])).tolist() == [1, 2]


# -- an image over boards that keep their inputs in 64-bit integers -----------------------

KIND = BoardKind("io", (
    Register("count", count=5, width=24),
    Register("adc", count=3, width=12),
    Register("dac", count=2, width=12, direction=OUTPUT),
    Register("rtc", width=16),
))


class SnapshotBoard(RegisterBoard):
    """A register file that offers no ``input_buffer()``: the image reads its
    inputs as the list its snapshot gives (the path of any other register view)."""

    input_buffer = None  # type: ignore[assignment]


def pair():
    """Two images of two boards each: over snapshots and over the boards' input buffers."""
    kinds = {"a": KIND, "b": KIND}
    plain = {n: SnapshotBoard(KIND) for n in kinds}
    native = {n: RegisterBoard(KIND) for n in kinds}
    images = []
    for boards in (plain, native):
        img = LocalImage("sim:", kinds, boards)
        img.open()
        img.set_tick(0.001)
        images.append(img)
    return images, plain, native


def set_both(plain, native, rnd: random.Random) -> None:
    for name in plain:
        for reg in KIND.inputs():
            for i in range(reg.count):
                if rnd.random() < 0.5:
                    v = rnd.randrange(reg.low, reg.high + 1)
                    plain[name].set_input(reg.name, v, i)
                    native[name].set_input(reg.name, v, i)


def test_an_image_over_int64_boards_reads_what_a_list_image_reads():
    """Tick after tick, an image gathering 64-bit register files in C answers every read,
    block read and snapshot as the image over list register files does."""
    (slow, fast), plain, native = pair()
    assert slow.native is None and fast.native is not None
    assert input_buffer(native["a"]) is not None and input_buffer(plain["a"]) is None
    rnd = random.Random(5)
    regs = [(ImageRegisters(slow, n), ImageRegisters(fast, n)) for n in ("a", "b")]
    blocks = [(r.block_reader("count"), s.block_reader("count")) for r, s in regs]
    readers = [(slow.reader(b, "adc", 2), fast.reader(b, "adc", 2)) for b in ("a", "b")]
    for tick in range(50):
        set_both(plain, native, rnd)
        slow.read_phase(tick)
        fast.read_phase(tick)
        assert list(fast.last_inputs) == slow.last_inputs
        for r, s in regs:
            assert r.snapshot() == s.snapshot() and type(s.snapshot()) is list
            assert r.read("rtc") == s.read("rtc")
        for r, s in blocks:
            assert r() == s() and type(s()) is list
        for r, s in readers:
            assert r() == s()
        slow.write_phase(tick)
        fast.write_phase(tick)


def test_a_cached_input_leaves_what_the_tick_read():
    """An input the tick sets in the image (a cleared counter) reads back at once, while
    the inputs the read phase brought (what a journal records) stay as read; the next
    read phase gathers into the native array again."""
    (_slow, fast), _plain, native = pair()
    native["a"].set_input("count", 77, 1)
    fast.read_phase(0)
    read = fast.reader("a", "count", 1)
    regs = ImageRegisters(fast, "a")
    assert read() == 77
    regs.set_cached("count", 0, 1)
    assert read() == 0 and fast.last_inputs[1] == 77
    fast.write_phase(0)
    fast.read_phase(1)
    assert read() == 77 and fast._values is fast.native


def test_a_board_without_an_int64_buffer_keeps_the_list_path():
    """One board of lists among native ones: the image reads every board as lists."""
    kinds = {"a": KIND, "b": KIND}
    img = LocalImage("sim:", kinds, {"a": RegisterBoard(KIND), "b": SnapshotBoard(KIND)})
    assert img.native is None


# -- the journal's hand-over of a plain tick ----------------------------------------------


@settings(max_examples=60, deadline=None)
@given(n_in=st.integers(0, 30), n=st.integers(1, 400), seed=st.integers(0, 10_000),
       queue=st.integers(1, 64), block=st.integers(1, 100))
def test_the_one_call_hand_over_writes_the_bytes_record_tick_writes(n_in, n, seed, queue,
                                                                     block):
    """A journal fed by the C hand-over (plain ticks) and by record_tick (the others, and
    whenever the ring is full) writes the very bytes of one fed by record_tick alone."""
    rnd = random.Random(seed)
    inputs = array("q", bytes(8 * n_in))
    ticks = []
    t = 0
    for k in range(n):
        for i in range(n_in):
            if rnd.random() < 0.3:
                inputs[i] = rnd.randrange(-(2**40), 2**40)
        t += 1_000_000
        late = rnd.choice((0, 0, rnd.randrange(0, 50_000)))
        outs = ((rnd.randrange(2), rnd.randrange(100), 0),) if rnd.random() < 0.1 else ()
        ticks.append((k, t + late, late, 0, inputs.tolist(), outs))
    h = header(n_in, 2)
    want, got = io.BytesIO(), io.BytesIO()
    a = Journal(h, want, lossless=True, queue_ticks=queue, block_ticks=block)
    for tk in ticks:
        a.record_tick(*tk)
    a.close()
    b = Journal(h, got, lossless=True, queue_ticks=queue, block_ticks=block)
    append = b.appender(inputs)
    assert append is not None
    for tk in ticks:
        for i, v in enumerate(tk[4]):
            inputs[i] = v
        if tk[5] or not append(tk[0], tk[1], tk[2]):
            b.record_tick(*tk)
    b.close()
    assert got.getvalue() == want.getvalue()


def test_the_hand_over_needs_the_headers_inputs_in_64_bit_integers():
    """A list of inputs, or a buffer of another count, has no one-call hand-over."""
    j = Journal(header(3, 1), io.BytesIO())
    try:
        assert j.appender([0, 0, 0]) is None
        assert j.appender(array("q", [0, 0])) is None
        assert j.appender(array("q", [0, 0, 0])) is not None
    finally:
        j.close()


def test_the_built_in_simulated_boards_are_gathered_in_c():
    """Register files of the built-in kinds put the image on its native path, values alike."""
    from pyrt.boards.armservo import arm_servo_kind
    from pyrt.boards.dataconcentrator import DATACONCENTRATOR
    from pyrt.boards.gripper import GRIPPER_CAGE

    kinds = {"g": GRIPPER_CAGE, "d": DATACONCENTRATOR, "s": arm_servo_kind(3)}
    boards = {n: RegisterBoard(k) for n, k in kinds.items()}
    img = LocalImage("sim:", kinds, boards)
    img.open()
    img.set_tick(0.001)
    assert img.native is not None
    rnd = random.Random(11)
    for n, board in boards.items():
        for reg in kinds[n].inputs():
            cells = board.cells(reg.name)
            for i in range(reg.count):
                cells[i] = rnd.randrange(reg.low, reg.high + 1)
    img.read_phase(0)
    want = [v for n in kinds for v in boards[n].snapshot()]
    assert list(img.native) == want
