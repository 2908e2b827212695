"""The journal's C tick encoder (csrc/journal.c) against the Python reference encoder."""

from __future__ import annotations

import io
import random
import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_journal import PERIOD, expected, header, run, same

from pyrt.journal import Journal, JournalError, JournalReader
from pyrt.journal.encoder import NativeBlockEncoder
from pyrt.journal.format import BlockEncoder
from pyrt.native import JOURNAL_VMAX, RecordRefused, TickEncoder


def blocks(encoder, recs, block: int, runs: list[int]) -> list[tuple]:
    """Every block ``encoder`` makes of ``recs`` (handed over in runs of the given
    lengths, cut at ``block`` ticks), and the refusals."""
    out, refused = [], []
    i = r = 0
    while i < len(recs):
        if encoder.count >= block:
            out.append(encoder.take())
        if isinstance(encoder, NativeBlockEncoder):
            m = min(block - encoder.count, runs[r % len(runs)])
            refused += [str(e) for e in encoder.add_many(recs[i:i + m])]
        else:
            m = 1
            try:
                encoder.add(*recs[i])
            except JournalError as exc:
                refused.append(str(exc))
        i += m
        r += 1
    out.append(encoder.take())
    return [out, refused]


@settings(max_examples=150, deadline=None)
@given(n_in=st.integers(0, 40), n_out=st.integers(1, 6), n=st.integers(1, 300),
       seed=st.integers(0, 100_000), block=st.integers(1, 300),
       runs=st.lists(st.integers(1, 80), min_size=1, max_size=5),
       compress=st.sampled_from([0, 6]), late=st.booleans())
def test_c_encoder_writes_the_reference_bytes(n_in, n_out, n, seed, block, runs, compress,
                                              late):
    """Random runs (inputs changing, output writes with writers, commands, events, missed
    deadlines, lateness) encode to the same blocks in C as in Python, however the ticks
    are handed over in runs."""
    recs = run(n, n_in, n_out, seed, late=late)
    h = header(n_in, n_out)
    native = NativeBlockEncoder(h, compress)
    assert blocks(native, recs, block, runs) == blocks(BlockEncoder(h, compress), recs, block,
                                                       [1])
    assert native.native


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 100_000), at=st.integers(0, 99),
       kind=st.sampled_from(["huge", "float", "index", "writer", "tick", "missed", "text",
                             "time"]))
def test_what_c_does_not_take_the_reference_does(seed, at, kind):
    """A tick C cannot take (a value beyond 2**62, a time beyond 2**61, a non-integer input, an
    output index or writer out of range, a tick not after the last, missed < 0, a command
    without UTF-8)
    is refused or taken exactly as the Python encoder does, and every tick after it too."""
    recs = run(100, 4, 2, seed)
    k, t, late, missed, ins, outs, cmds, evs = recs[at]
    if kind == "huge":
        ins = [v + JOURNAL_VMAX for v in ins]
    elif kind == "float":
        ins = [*ins[:3], 0.5]
    elif kind == "index":
        outs = ((2, 1, 0),)
    elif kind == "writer":
        outs = ((1, 1, -1),)
    elif kind == "tick":
        k = recs[at - 1][0] if at else -1
    elif kind == "missed":
        missed = -1
    elif kind == "text":
        cmds = (("\ud800", "console"),)
    recs[at] = (k, t, late, missed, ins, outs, cmds, evs)
    h = header(4, 2)
    if kind == "time":
        recs = [(k, t + 2**62 if j >= at else t, late, m, ins, o, c, e)
                for j, (k, t, late, m, ins, o, c, e) in enumerate(recs)]
    got = blocks(NativeBlockEncoder(h, 0), recs, 37, [13, 50])
    want = blocks(BlockEncoder(h, 0), recs, 37, [1])
    assert got[0] == want[0]
    assert len(got[1]) == len(want[1])


def test_c_refuses_a_bad_record_and_changes_nothing():
    """The C encoder refuses a tick that does not follow the last and names it; the records
    before it are kept and its state is as it was."""
    enc = TickEncoder(2, 1, PERIOD)
    rows = bytearray()
    row = struct.Struct("=6q")
    for values in ((0, 0, 0, 0, 5, 6), (1, PERIOD, 0, 0, 5, 7), (1, 2 * PERIOD, 0, 0, 9, 9)):
        rows += row.pack(*values)
    with pytest.raises(RecordRefused) as info:
        enc.encode(rows, 0, 3)
    assert info.value.index == 2
    assert enc.count == 2 and enc.tick == 1 and enc.previous_inputs() == [5, 7]
    with pytest.raises(ValueError):
        enc.encode(rows, 2, 2)  # rows beyond the buffer
    with pytest.raises(ValueError):
        enc.encode(rows, 0, 1, [1], [0, 1])  # a write needs three values


def test_a_block_of_many_writes_grows_the_body():
    """Ticks that each write many outputs outgrow the encoder's first body and are
    still encoded whole, as the Python encoder encodes them."""
    rng = random.Random(2)
    recs = [(k, k * PERIOD, 0, 0, [k], tuple((i, rng.randrange(-10**9, 10**9), 3)
                                             for i in range(64) for _ in range(3)), (), ())
            for k in range(120)]
    h = header(1, 64)
    assert blocks(NativeBlockEncoder(h, 0), recs, 250, [120]) == \
        blocks(BlockEncoder(h, 0), recs, 250, [1])


def test_the_ring_wraps_and_reads_back():
    """A journal whose ring of handed-over ticks is a few rows long (the writer taking
    them as the loop waits) records every tick, whatever the wrap."""
    recs = run(500, 5, 3, seed=11)
    buf = io.BytesIO()
    j = Journal(header(5, 3), buf, queue_ticks=7, block_ticks=16, lossless=True)
    for r in recs:
        assert j.record_tick(*r)
    j.close()
    same(list(JournalReader(buf.getvalue())), expected(recs, n_out=3))


def test_an_input_that_is_not_an_integer_is_refused_by_the_writer():
    """A tick whose input is not an integer is handed over whole, refused by the writer and
    named at close; the ticks around it are recorded."""
    recs = run(30, 3, 2, seed=3)
    recs[10] = (*recs[10][:4], [1, 2.5, 3], *recs[10][5:])
    buf = io.BytesIO()
    j = Journal(header(3, 2), buf, lossless=True)
    for r in recs:
        j.record_tick(*r)
    with pytest.raises(JournalError, match="1 tick"):
        j.close()
    assert [t.tick for t in JournalReader(buf.getvalue()).ticks()] == \
        [r[0] for k, r in enumerate(recs) if k != 10]
