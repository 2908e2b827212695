"""The process image's C side (csrc/image.c): its kernels against Python references,
an image over boards that keep their inputs in 64-bit integers, and the journal's
one-call hand-over of a plain tick (against its Python reference)."""

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
from pyrt.journal import Journal, JournalError
from pyrt.native import (
    HAND_OVER_DUE,
    HAND_OVER_SLOW,
    IMAGE_CLOCK,
    IMAGE_TMAX,
    InputGather,
    NativeInputError,
    RingRows,
    TickHandOver,
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


def hand_over_reference(state: dict, ring: list[list[int]], inputs: list[int],
                        now: int) -> int:
    """What pyrt_image_hand_over does to ``state`` (its fields) and ``ring`` (a list of
    rows), and its answer: the C side's specification, in Python."""
    tmax = IMAGE_TMAX
    if state["rows"] <= 0 or state["put"] < 0 or not 0 < state["period_ns"] <= tmax:
        return 1  # PYRT_EINVAL
    if state["slow"] or not state["open"]:
        return HAND_OVER_SLOW
    put, taken = state["put"], state["taken"]
    if taken < 0 or taken > put or put - taken >= state["rows"] or put >= tmax:
        return HAND_OVER_SLOW
    if not (0 <= state["tick"] < tmax and -tmax <= now <= tmax
            and -tmax <= state["deadline_ns"] <= tmax):
        return HAND_OVER_SLOW
    late = now - state["deadline_ns"]
    if not state["late_lo"] <= late <= state["late_hi"]:
        return HAND_OVER_SLOW
    tick = state["tick"]
    ring[put % state["rows"]] = [tick, now, late, 0, *inputs]
    state["put"] = put + 1
    state["tick"] = tick + 1
    state["deadline_ns"] += state["period_ns"]
    return HAND_OVER_DUE if tick >= state["listen_at"] else 0


FIELDS = ("put", "taken", "tick", "deadline_ns", "late_lo", "late_hi", "listen_at", "open",
          "slow")
T61 = st.integers(-(2**61) - 2, 2**61 + 2)


@settings(max_examples=300, deadline=None)
@given(n=st.integers(0, 12), rows=st.integers(1, 6), period=st.integers(1, 2**20),
       data=st.data())
def test_the_hand_over_of_a_plain_tick_is_its_python_reference(n, rows, period, data):
    """Over runs of calls from random states (slow or not, open or not, the ring full or
    not, ticks on time, late, early or skipped, listeners due or not), the one-call
    hand-over answers, writes rows and moves its state as the Python reference does."""
    inputs = array("q", data.draw(st.lists(I64, min_size=n, max_size=n)))
    ring = bytearray(b"\x5a" * (8 * rows * (IMAGE_CLOCK + n)))
    hand = TickHandOver(ring, rows, n, period)
    assert hand.bind(inputs)
    c = hand.state
    state = {"rows": rows, "period_ns": period}
    put = data.draw(st.integers(0, 2**40))
    for name, value in (
            ("put", put), ("taken", put - data.draw(st.integers(-1, rows + 1))),
            ("tick", data.draw(st.integers(-1, 2**62))), ("deadline_ns", data.draw(T61)),
            ("late_lo", 0), ("late_hi", data.draw(st.sampled_from([0, period // 2]))),
            ("listen_at", data.draw(st.integers(0, 2**62))),
            ("open", data.draw(st.sampled_from([1, 1, 0]))),
            ("slow", data.draw(st.sampled_from([0, 0, 1])))):
        state[name] = value
        setattr(c, name, value)
    row = struct.Struct(f"={IMAGE_CLOCK + n}q")
    want = [list(row.unpack_from(ring, k * row.size)) for k in range(rows)]
    for _ in range(data.draw(st.integers(1, 8))):
        step = data.draw(st.sampled_from([0, 0, 1, period // 2, period, -1]))
        now = state["deadline_ns"] + step if data.draw(st.booleans()) else data.draw(T61)
        if data.draw(st.booleans()):  # the writer takes a tick meanwhile
            state["taken"] = min(state["put"], state["taken"] + 1)
            c.taken = state["taken"]
        assert hand(now) == hand_over_reference(state, want, list(inputs), now)
        for name in FIELDS:
            assert getattr(c, name) == state[name], name
        got = [list(row.unpack_from(ring, k * row.size)) for k in range(rows)]
        assert got == want


def test_a_refused_hand_over_state_raises_and_changes_nothing():
    """A state the C side cannot use (no rows, a negative count, a period of 0) is
    refused: an error, nothing written, nothing moved."""
    inputs = array("q", [1, 2])
    ring = bytearray(8 * 2 * (IMAGE_CLOCK + 2))
    hand = TickHandOver(ring, 2, 2, 1000)
    assert hand.bind(inputs)
    c = hand.state
    c.slow = 0
    for name, bad in (("put", -1), ("period_ns", 0), ("rows", 0)):
        old = getattr(c, name)
        setattr(c, name, bad)
        with pytest.raises(NativeInputError):
            hand(0)
        setattr(c, name, old)
        assert c.put == 0 and c.tick == 0 and ring == bytearray(len(ring))
    assert hand(0) == 0 and c.put == 1
    with pytest.raises(NativeInputError):
        TickHandOver(bytearray(8 * 5), 1, 2, 1000)
    with pytest.raises(NativeInputError):
        TickHandOver(ring, 2, 2, 0)
    assert not hand.bind([1, 2]) and not hand.bind(array("q", [1, 2, 3]))


@settings(max_examples=60, deadline=None)
@given(n_in=st.integers(0, 30), n=st.integers(1, 400), seed=st.integers(0, 10_000),
       queue=st.integers(1, 64), block=st.integers(1, 100))
def test_the_one_call_hand_over_writes_the_bytes_record_tick_writes(n_in, n, seed, queue,
                                                                     block):
    """A journal fed by the C hand-over (plain ticks, the state set again as the
    recorder sets it after every other) and by record_tick (ticks with outputs, late or
    skipped ones, and whenever the ring is full) writes the very bytes of one fed by
    record_tick alone."""
    rnd = random.Random(seed)
    period = 1_000_000
    inputs = array("q", bytes(8 * n_in))
    ticks = []
    deadline = 0
    for k in range(n):
        for i in range(n_in):
            if rnd.random() < 0.3:
                inputs[i] = rnd.randrange(-(2**40), 2**40)
        deadline += period * (1 + (rnd.random() < 0.05))  # now and then a deadline skipped
        late = rnd.choice((0, 0, rnd.randrange(0, period // 2), rnd.randrange(0, period)))
        outs = ((rnd.randrange(2), rnd.randrange(100), 0),) if rnd.random() < 0.1 else ()
        ticks.append((k, deadline + late, late, 0, inputs.tolist(), outs))
    h = header(n_in, 2)
    want, got = io.BytesIO(), io.BytesIO()
    a = Journal(h, want, lossless=True, queue_ticks=queue, block_ticks=block)
    for tk in ticks:
        a.record_tick(*tk)
    a.close()
    b = Journal(h, got, lossless=True, queue_ticks=queue, block_ticks=block)
    hand = b.hand_over(inputs)
    assert hand is not None
    c = hand.state
    c.late_lo, c.late_hi = 0, period // 2
    for tk in ticks:
        for i, v in enumerate(tk[4]):
            inputs[i] = v
        if tk[5]:
            c.slow = 1  # what the recorder's tap does
        if hand(tk[1]) == 0:
            continue
        b.record_tick(*tk)
        c.slow, c.tick, c.deadline_ns = 0, tk[0] + 1, tk[1] - tk[2] + period
    b.close()
    assert got.getvalue() == want.getvalue()
    assert b.recorded == n


def test_the_hand_over_needs_the_headers_inputs_in_64_bit_integers():
    """A list of inputs, or a buffer of another count, has no one-call hand-over."""
    j = Journal(header(3, 1), io.BytesIO())
    try:
        assert j.hand_over([0, 0, 0]) is None
        assert j.hand_over(array("q", [0, 0])) is None
        assert j.hand_over(array("q", [0, 0, 0])) is not None
    finally:
        j.close()


def test_a_closed_journal_or_a_write_error_refuses_the_hand_over():
    """Closing the journal, or a write the writer could not make, makes the hand-over
    answer "slow" (nothing handed over): the recorder's own path then decides."""

    class Full(io.RawIOBase):
        def __init__(self):
            self.fail = False

        def writable(self):
            return True

        def write(self, b):
            if self.fail:
                raise OSError(28, "No space left on device")
            return len(b)

    inputs = array("q", [5])
    sink = Full()
    j = Journal(header(1, 1), sink, block_ticks=1)
    hand = j.hand_over(inputs)
    c = hand.state
    c.slow, c.tick, c.deadline_ns = 0, 0, 0
    assert hand(0) == 0 and j.recorded == 1
    sink.fail = True
    assert j.flush(5)
    assert j.error is not None and c.slow == 1
    assert hand(1_000_000) == HAND_OVER_SLOW and j.recorded == 1
    with pytest.raises(JournalError):
        j.close()
    c.slow = 0
    assert c.open == 0 and hand(1_000_000) == HAND_OVER_SLOW


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
