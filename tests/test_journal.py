"""The flight recorder's journal: format, writer thread, reader, black box."""

from __future__ import annotations

import dataclasses
import io
import os
import random
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pyrt._version import __version__
from pyrt.journal import (
    DEFAULT_BLOCK_TICKS,
    BlackBox,
    Command,
    Event,
    Gap,
    Header,
    Journal,
    JournalError,
    JournalReader,
    Tick,
)
from pyrt.journal.format import (
    HEADER_SIZE,
    KIND_HEADER,
    BlockEncoder,
    _Cursor,
    frame,
    put_svarint,
    put_uvarint,
)

PERIOD = 1_000_000


def header(n_in: int = 4, n_out: int = 2, **kw) -> Header:
    kw.setdefault("writers", ("sensors", "jaw-move"))
    return Header(station="test", period_ns=PERIOD, inputs=[f"in{i}" for i in range(n_in)],
                  outputs=[f"out{i}" for i in range(n_out)], version=__version__, **kw)


def run(n: int, n_in: int = 4, n_out: int = 2, seed: int = 0, start: int = 0,
        late: bool = True, changing: int | None = None) -> list[tuple]:
    """A synthetic run: per tick (tick, time, lateness, missed, inputs, outputs, commands, events)."""
    rng = random.Random(seed)
    inputs = [rng.randrange(-5000, 5000) for _ in range(n_in)]
    changing = n_in if changing is None else changing
    deadline = start * PERIOD
    recs = []
    for k in range(start, start + n):
        missed = 1 if rng.random() < 0.02 else 0
        deadline += PERIOD * (1 + missed)
        lateness = rng.randrange(0, 90_000) if late else 0
        for i in range(changing):
            if rng.random() < 0.7:
                inputs[i] += rng.randrange(-3, 4)
        outs = tuple((i, rng.randrange(-2000, 2000), rng.randrange(2))
                     for i in range(n_out) if rng.random() < 0.5)
        cmds = (Command("S", "console"),) if rng.random() < 0.01 else ()
        evs = (Event("fault", k, "jaw jammed"),) if rng.random() < 0.005 else ()
        recs.append((k, deadline + lateness, lateness, missed, list(inputs), outs, cmds, evs))
    return recs


def expected(recs: list[tuple], accepted: list[bool] | None = None, n_out: int = 2,
             gaps: list[Gap] = ()) -> list[Tick | Gap]:
    """What a reader must give back for the records handed over (dropped ones left out)."""
    out: list[Tick | Gap] = []
    state = [0] * n_out
    prev = None
    gaps = list(gaps)
    for j, (k, t, late, missed, inputs, outs, cmds, evs) in enumerate(recs):
        if accepted is not None and not accepted[j]:
            continue
        if gaps and gaps[0].last < k:
            out.append(gaps.pop(0))
            prev = None
        for i, v, _w in outs:
            state[i] = v
        changed = tuple(range(len(inputs))) if prev is None else \
            tuple(i for i, (a, b) in enumerate(zip(inputs, prev, strict=True)) if a != b)
        out.append(Tick(k, t, late, missed, tuple(inputs), changed, tuple(outs), tuple(state),
                        tuple(cmds), tuple(evs)))
        prev = inputs
    return out + gaps


def same(got: list[Tick | Gap], want: list[Tick | Gap]) -> None:
    """Equal records, ignoring which ticks happen to be keyframes."""
    assert [dataclasses.replace(r, keyframe=False) if isinstance(r, Tick) else r
            for r in got] == want


def write(recs, target, hdr: Header | None = None, **kw) -> Journal:
    kw.setdefault("lossless", True)
    j = Journal(hdr or header(len(recs[0][4]) if recs else 4), target, **kw)
    for r in recs:
        j.record_tick(*r)
    j.close()
    return j


def journal_bytes(recs, **kw) -> bytes:
    buf = io.BytesIO()
    write(recs, buf, **kw)
    return buf.getvalue()


def frame_offsets(data: bytes) -> list[int]:
    """The offsets of the frames of an undamaged journal."""
    offs, pos = [], 0
    while pos < len(data):
        offs.append(pos)
        pos += HEADER_SIZE + int.from_bytes(data[pos + 5:pos + 9], "little")
    return offs


class StalledSink(io.RawIOBase):
    """A sink that stalls once the journal has started: its first write (the header, which
    the journal writes when it is made) goes through, every later one waits until released
    (at most 30 s: ``timed_out`` counts the writes that gave up waiting)."""

    def __init__(self):
        self.release = threading.Event()
        self.data = bytearray()
        self.timed_out = 0
        self.writes = 0

    def writable(self) -> bool:
        return True

    def write(self, b) -> int:
        self.writes += 1
        if self.writes > 1 and not self.release.wait(30):
            self.timed_out += 1
        self.data += bytes(b)
        return len(b)


# -- the encoding ------------------------------------------------------------------------------


@given(st.integers(min_value=-(1 << 200), max_value=1 << 200))
def test_varints_round_trip(v):
    """Signed and unsigned varints of any size decode to the integer encoded."""
    out = bytearray()
    put_svarint(out, v)
    put_uvarint(out, abs(v))
    r = _Cursor(bytes(out))
    assert (r.svarint(), r.uvarint(), r.pos) == (v, abs(v), len(out))


def test_header_round_trips_databases_seeds_and_metadata():
    """The header keeps the databases' bytes, seeds of any size, names and metadata."""
    hdr = header(databases={"prototype.dat": b"VERSION1.00\n\x00\xff", "b.dat": b""},
                 seeds={"plant": 2**100 + 7, "noise": -3}, output_values=(5, -6),
                 metadata={"url": "sim:", "speed": 1.0})
    reader = JournalReader(journal_bytes(run(3), hdr=hdr))
    assert reader.header == hdr
    assert reader.complete and reader.ended_early is None


@pytest.mark.parametrize("kw, what", [
    ({"period_ns": 0}, "period_ns"),
    ({"inputs": "abc"}, "inputs"),
    ({"output_values": (1,)}, "output values"),
    ({"seeds": {"a": 1.5}}, "seeds"),
    ({"databases": {"a": "text"}}, "databases"),
    ({"metadata": {"a": object()}}, "metadata"),
])
def test_bad_header_is_refused(kw, what):
    """A header with a bad field is refused with an error naming it."""
    args = {"station": "s", "period_ns": PERIOD, "inputs": ("a",), "outputs": ("b", "c")} | kw
    with pytest.raises(JournalError, match=what):
        Header(**args)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(n_in=st.integers(0, 6), n_out=st.integers(1, 4), n=st.integers(1, 80),
       seed=st.integers(0, 10_000), block=st.integers(1, 9), compress=st.sampled_from([0, 6]),
       big=st.booleans())
def test_random_runs_round_trip(n_in, n_out, n, seed, block, compress, big):
    """Any run (inputs, outputs with writers, commands, events, missed ticks, lateness, values
    of any size) reads back equal, whatever the block size and compression."""
    recs = run(n, n_in, n_out, seed)
    if big:
        recs = [(k, t, late, m, [v * 2**40 for v in ins], tuple((i, -v * 2**33, w)
                 for i, v, w in outs), c, e) for k, t, late, m, ins, outs, c, e in recs]
    data = journal_bytes(recs, hdr=header(n_in, n_out), block_ticks=block, compress=compress)
    reader = JournalReader(data)
    same(list(reader), expected(recs, n_out=n_out))
    s = reader.summary()
    assert (s.ticks, s.first_tick, s.last_tick, s.gaps, s.complete) == \
        (n, 0, n - 1, (), True)
    assert s.duration_ns == recs[-1][1] - recs[0][1]


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 10_000), stall_at=st.integers(0, 150), capacity=st.integers(1, 40))
def test_round_trip_with_gaps(seed, stall_at, capacity):
    """Ticks dropped while the writer is stalled come back as gaps; every tick handed over
    reads back equal, with the gap in its place."""
    recs = run(300, 3, 2, seed)
    sink = StalledSink()
    j = Journal(header(3, 2), sink, queue_ticks=capacity, block_ticks=16)
    accepted = []
    for idx, r in enumerate(recs):
        if idx == stall_at + 100:
            sink.release.set()
            assert j.flush(30)
        accepted.append(j.record_tick(*r))
    sink.release.set()
    j.close()
    assert accepted[:capacity] == [True] * capacity and not accepted[capacity]
    reader = JournalReader(bytes(sink.data))
    assert reader.gaps == j.gaps
    assert sum(g.ticks for g in j.gaps) == accepted.count(False) == j.dropped
    same(list(reader), expected(recs, accepted, gaps=j.gaps))


def test_seek_starts_mid_block():
    """seek(tick) gives the same ticks as reading from the start, from that tick on."""
    recs = run(500, 5, 2, seed=3)
    reader = JournalReader(journal_bytes(recs, block_ticks=37))
    ticks = list(reader.ticks())
    for at in (0, 1, 36, 37, 38, 250, 499):
        got = [t for t in reader.seek(at) if isinstance(t, Tick)]
        assert [(t.tick, t.inputs, t.output_values) for t in got] == \
            [(t.tick, t.inputs, t.output_values) for t in ticks[at:]]
    assert list(reader.seek(500)) == []


def test_seek_into_a_gap_gives_the_gap_first():
    """seek() to a tick the journal did not record gives the gap, then the ticks after it."""
    sink = StalledSink()
    j = Journal(header(), sink, queue_ticks=30, block_ticks=8)
    recs = run(100, seed=8)
    for r in recs[:60]:
        j.record_tick(*r)
    sink.release.set()
    assert j.flush(30)
    for k, r in enumerate(recs[60:]):
        assert j.record_tick(*r)
        if k % 20 == 19:
            assert j.flush(30)
    j.close()
    assert j.gaps == [Gap(30, 59, 30, "the journal's writer fell behind")]
    reader = JournalReader(bytes(sink.data))
    for at in (30, 45, 59):
        got = list(reader.seek(at))
        assert got[0] == j.gaps[0] and [t.tick for t in got[1:]] == list(range(60, 100))
    got = list(reader.seek(29))
    assert got[0].tick == 29 and got[1] == j.gaps[0] and got[2].tick == 60


def test_size_per_minute_of_a_moving_gripper():
    """A minute at 1 kHz with 10 changing inputs (of 40), 3 outputs written every tick and
    wall-clock lateness encodes to at most 1 MB with the default blocks."""
    rng = random.Random(7)
    inputs = [rng.randrange(4000) for _ in range(40)]
    enc = BlockEncoder(header(40, 8), compress=6)
    size = 0
    for k in range(60_000):
        for i in range(10):
            inputs[i] += rng.randrange(-2, 4)
        late = rng.randrange(20_000, 80_000)
        enc.add(k, k * PERIOD + late, late, 0, tuple(inputs),
                tuple((i, 1000 + (k // 7) % 50 + i, i % 2) for i in range(3)), (), ())
        if enc.count >= DEFAULT_BLOCK_TICKS:
            size += len(enc.take()[0])
    assert size <= 1_000_000


# -- damage and truncation -------------------------------------------------------------------


SMALL = run(120, 3, 2, seed=11)
SMALL_DATA = journal_bytes(SMALL, block_ticks=20)
SMALL_TICKS = expected(SMALL)


def test_truncated_at_every_offset_reads_to_its_last_complete_frame():
    """A journal cut at any byte of its last frames reads every tick of its complete frames,
    and says where it ends early."""
    offs = frame_offsets(SMALL_DATA)
    ends = [*offs[1:], len(SMALL_DATA)]
    for cut in range(offs[-4], len(SMALL_DATA)):
        reader = JournalReader(SMALL_DATA[:cut])
        n = 20 * sum(1 for i in range(1, len(offs) - 1) if ends[i] <= cut)
        same(list(reader), SMALL_TICKS[:n])
        assert not reader.complete
        assert (reader.ended_early is None) == (cut in offs), cut
        if reader.ended_early:
            assert f"offset {max(o for o in offs if o <= cut)}" in reader.ended_early


def test_truncated_inside_the_header_is_an_error():
    """A file cut inside its header frame cannot be read: the error says so."""
    with pytest.raises(JournalError, match="no header"):
        JournalReader(SMALL_DATA[:30])


@settings(max_examples=200, deadline=None)
@given(pos=st.integers(0, len(SMALL_DATA) - 1), mask=st.integers(1, 255))
def test_a_flipped_byte_is_reported_with_its_offset(pos, mask):
    """A byte changed anywhere raises a JournalError naming the frame that holds it and its
    offset, after only unchanged ticks; salvage yields only unchanged ticks and a gap."""
    data = bytearray(SMALL_DATA)
    data[pos] ^= mask
    offs = frame_offsets(SMALL_DATA)
    frame = max(i for i, o in enumerate(offs) if o <= pos)
    got = []
    with pytest.raises(JournalError) as err:
        got.extend(JournalReader(bytes(data)))
    assert err.value.offset == offs[frame] and err.value.frame == frame
    assert f"offset {offs[frame]}" in str(err.value)
    same(got, SMALL_TICKS[:len(got)])
    if frame == 0:
        return
    reader = JournalReader(bytes(data), salvage=True)
    records = list(reader)
    ticks = [r for r in records if isinstance(r, Tick)]
    want = {t.tick: t for t in SMALL_TICKS}
    for t in ticks:
        assert (t.time_ns, t.inputs, t.outputs, t.output_values, t.commands, t.events) == \
            (want[t.tick].time_ns, want[t.tick].inputs, want[t.tick].outputs,
             want[t.tick].output_values, want[t.tick].commands, want[t.tick].events)
    assert reader.damage and reader.damage[0].offset == offs[frame]
    if len(ticks) < len(SMALL):
        assert any(isinstance(r, Gap) and "damaged" in r.cause for r in records)


def test_salvage_skips_a_damaged_block_and_names_the_lost_ticks():
    """In salvage mode a damaged block becomes a gap of exactly its ticks; reading goes on."""
    offs = frame_offsets(SMALL_DATA)
    data = bytearray(SMALL_DATA)
    data[offs[2] + 40] ^= 0x55            # the second block: ticks 20..39
    reader = JournalReader(bytes(data), salvage=True)
    records = list(reader)
    gaps = [r for r in records if isinstance(r, Gap)]
    assert [(g.first, g.last) for g in gaps] == [(20, 39)]
    assert [t.tick for t in records if isinstance(t, Tick)] == \
        list(range(20)) + list(range(40, 120))
    assert reader.summary().damage[0].offset == offs[2]


def test_not_a_journal():
    """A file that is not a journal is refused, naming the offset."""
    with pytest.raises(JournalError, match="offset 0"):
        JournalReader(b"VERSION1.00\nthis is a database, not a journal\n")


def test_killed_writer_leaves_a_readable_journal(tmp_path):
    """A process killed with SIGKILL while writing leaves a journal that reads up to its
    last complete frame, every tick as it was handed over."""
    path = tmp_path / "killed.pj"
    src = textwrap.dedent(f"""
        import sys
        from pyrt.journal import Header, Journal
        h = Header(station="t", period_ns={PERIOD}, inputs=["a", "b", "c"], outputs=["o"])
        j = Journal(h, sys.argv[1], block_ticks=10, lossless=True)
        k = 0
        while True:
            j.record_tick(k, k * {PERIOD}, k % 7, 0, [k, -k, k // 3], ((0, k % 11, 0),))
            k += 1
            if k == 500:
                j.flush()
                print("ready", flush=True)
    """)
    proc = subprocess.Popen([sys.executable, "-c", src, str(path)], stdout=subprocess.PIPE,
                            text=True)
    try:
        assert proc.stdout.readline() == "ready\n"
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait(30)
    assert proc.returncode == -signal.SIGKILL
    reader = JournalReader(path)
    ticks = list(reader.ticks())
    assert len(ticks) >= 500 and not reader.complete
    for i, t in enumerate(ticks):
        assert (t.tick, t.time_ns, t.lateness_ns, t.inputs, t.output_values) == \
            (i, i * PERIOD, i % 7, (i, -i, i // 3), (i % 11,))
    assert reader.summary().ticks == len(ticks)


# -- the writer thread -------------------------------------------------------------------------


def test_a_stalled_disk_never_blocks_record_tick():
    """With the sink stalled, record_tick returns at once, drops ticks into a gap and says so."""
    sink = StalledSink()
    warnings = []
    j = Journal(header(), sink, queue_ticks=50, warn=warnings.append)
    recs = run(2000, seed=5)
    assert j.record_tick(*recs[0])
    # tick 0's block to the sink: the writer is then stuck in the stalled write, so that
    # however the machine schedules the threads, no tick leaves the queue meanwhile
    assert not j.flush(0.01)
    for _ in range(3000):
        if sink.writes >= 2:
            break
        time.sleep(0.01)
    assert sink.writes == 2, "the writer never reached the sink"
    results = [j.record_tick(*r) for r in recs[1:1001]]
    # a record_tick that waited for the sink would have waited out a stalled write
    assert sink.timed_out == 0 and not sink.release.is_set()
    assert results[:50] == [True] * 50 and results[50:] == [False] * 950
    assert j.dropped == 950 and j.gaps == []
    sink.release.set()
    assert j.flush(30)
    assert j.record_tick(*recs[1001])
    assert j.gaps == [Gap(51, 1000, 950, "the journal's writer fell behind")]
    j.close()
    reader = JournalReader(bytes(sink.data))
    assert reader.gaps == j.gaps
    assert [r.tick if isinstance(r, Tick) else "gap" for r in reader] == \
        [*range(51), "gap", 1001]
    assert any("ticks 51..1000 not recorded" in w and "not replayable past tick 51" in w
               for w in warnings)


def test_bad_ticks_are_refused():
    """A tick with the wrong number of inputs is refused at once and nothing is recorded;
    a malformed output write is refused by the writer and named at close."""
    buf = io.BytesIO()
    j = Journal(header(), buf)
    with pytest.raises(JournalError, match="3 inputs, the header declares 4"):
        j.record_tick(0, 0, 0, 0, [1, 2, 3])
    assert j.recorded == 0
    j.record_tick(0, 0, 0, 0, [1, 2, 3, 4])
    j.record_tick(1, PERIOD, 0, 0, [1, 2, 3, 4], ((7, 1, 0),))
    j.record_tick(2, 2 * PERIOD, 0, 0, [1, 2, 3, 5])
    with pytest.raises(JournalError, match=r"1 tick\(s\) not recorded.*output write"):
        j.close()
    assert [t.tick for t in JournalReader(buf.getvalue()).ticks()] == [0, 2]
    with pytest.raises(JournalError, match="after close"):
        j.record_tick(3, 3 * PERIOD, 0, 0, [1, 2, 3, 4])


class Full(io.RawIOBase):
    """A sink that takes ``room`` bytes, then fails as a full disk does."""

    def __init__(self, room: int = 0):
        self.room = room

    def writable(self):
        return True

    def write(self, b):
        if len(b) > self.room:
            raise OSError(28, "No space left on device")
        self.room -= len(b)
        return len(b)


def test_a_failing_disk_is_reported_at_close_not_in_the_loop():
    """A sink that fails after the header: record_tick goes on, the journal's error, the
    warning and close() name the failure."""
    warnings = []
    j = Journal(header(), Full(room=len(frame(KIND_HEADER, header().encode()))),
                warn=warnings.append, lossless=True)
    for r in run(600):
        j.record_tick(*r)
    with pytest.raises(JournalError, match="No space left"):
        j.close()
    assert any("No space left" in w for w in warnings)
    assert "No space left on device (the disk is full)" in j.error


def test_a_journal_whose_header_cannot_be_written_is_refused_at_once():
    """A full disk from the first byte: the Journal is refused when made (before any
    tick), naming the file and the reason; no thread is left behind."""
    before = threading.active_count()
    with pytest.raises(JournalError, match=r"write failed after 0 bytes: No space left on "
                                           r"device \(the disk is full\)"):
        Journal(header(), Full())
    assert threading.active_count() == before


def test_writer_names_added_during_the_run():
    """Writers named during the run are in the reader's name table, indices kept."""
    buf = io.BytesIO()
    j = Journal(header(), buf, block_ticks=4)
    recs = run(10)
    for r in recs[:5]:
        j.record_tick(*r)
    assert j.writer_index("jaw-move") == 1
    w = j.writer_index("jaw-watch")
    assert w == 2
    j.record_tick(*recs[5][:5], ((0, 9, w),))
    j.close()
    reader = JournalReader(buf.getvalue())
    assert reader.writers == ["sensors", "jaw-move", "jaw-watch"]
    assert next(t for t in reader.ticks() if t.tick == 5).outputs == ((0, 9, 2),)


def test_journal_to_a_path(tmp_path):
    """A journal written to a path is complete, fsynced at close and reads back."""
    recs = run(1000, seed=9)
    path = tmp_path / "run.pj"
    j = write(recs, path)
    assert path.stat().st_size == j.bytes_written
    reader = JournalReader(path)
    same(list(reader), expected(recs))
    lines = reader.summary().lines()
    assert lines[0].startswith("station test: 1000 ticks (0..999)")


def test_unwritable_path_is_refused(tmp_path):
    """A journal path that cannot be created is refused with the path named."""
    with pytest.raises(JournalError, match="nodir"):
        Journal(header(), tmp_path / "nodir" / "x.pj")


# -- the black box ---------------------------------------------------------------------------


class WatchedBox(BlackBox):
    """A black box that remembers its largest size."""

    most = 0

    def add(self, *args) -> None:
        super().add(*args)
        self.most = max(self.most, self.nbytes)
        assert self.nbytes <= self.budget_bytes


@pytest.mark.parametrize("budget", [64 << 10, 8 << 20])
def test_black_box_stays_within_budget_over_ten_minutes(budget, tmp_path):
    """Over a simulated 10-minute run at 1 kHz the black box never exceeds its byte budget,
    keeps at least its seconds when the budget allows, and dumps a journal readable alone."""
    box = WatchedBox(seconds=10.0, budget_bytes=budget)
    j = Journal(header(4, 1), None, black_box=box, lossless=True)
    rng = random.Random(1)
    a = b = 0
    for k in range(600_000):
        a += rng.randrange(3)
        b -= 1
        j.record_tick(k, k * PERIOD, 0, 0, (a, b, 7, k >> 10), ((0, k >> 4, 0),))
    path = tmp_path / "box.pj"
    assert j.dump_black_box(path).result(60) == box.ticks
    j.close()
    assert box.most <= budget and box.dropped > 0
    reader = JournalReader(path)
    ticks = list(reader.ticks())
    assert ticks[0].keyframe and ticks[-1].tick == 599_999
    assert [t.tick for t in ticks] == list(range(ticks[0].tick, 600_000))
    assert ticks[-1].inputs == (a, b, 7, 599_999 >> 10)
    if budget == 8 << 20:
        assert 10e9 <= reader.summary().duration_ns <= 10e9 + DEFAULT_BLOCK_TICKS * PERIOD


def test_black_box_dump_on_demand_includes_the_last_tick(tmp_path):
    """A dump during the run holds every tick up to the last one handed over, the writers
    named so far, and the fault event."""
    box = BlackBox(seconds=1.0)
    j = Journal(header(), tmp_path / "run.pj", black_box=box, block_ticks=100)
    recs = run(3000, seed=2)
    for r in recs[:2499]:
        j.record_tick(*r)
    j.writer_index("reflex")
    k, t, late, m, ins, _outs, _c, _e = recs[2499]
    j.record_tick(k, t, late, m, ins, ((0, 0, 2),), (), (Event("fault", 4, "jaw jammed"),))
    fut = j.dump_black_box(tmp_path / "box.pj")
    for r in recs[2500:]:
        j.record_tick(*r)
    assert fut.result(30) >= 1000
    j.close()
    reader = JournalReader(tmp_path / "box.pj")
    assert reader.complete and reader.writers == ["sensors", "jaw-move", "reflex"]
    ticks = list(reader.ticks())
    assert ticks[-1].tick == 2499 and ticks[-1].events == (Event("fault", 4, "jaw jammed"),)
    assert ticks[0].keyframe and ticks[-1].time_ns - ticks[0].time_ns >= 1e9
    full = {t.tick: t for t in JournalReader(tmp_path / "run.pj").ticks()}
    assert all(t.inputs == full[t.tick].inputs for t in ticks)


def test_black_box_refuses_bad_settings():
    """A black box with no seconds or a tiny budget is refused."""
    with pytest.raises(JournalError, match="seconds"):
        BlackBox(seconds=0)
    with pytest.raises(JournalError, match="budget"):
        BlackBox(budget_bytes=100)


def test_journal_needs_somewhere_to_write():
    """A journal with neither a file nor a black box is refused."""
    with pytest.raises(JournalError, match="nothing to write"):
        Journal(header(), None)


def test_journal_imports_nothing_above_the_scheduler_layer():
    """pyrt.journal imports only the standard library, pyrt.errors, pyrt._version, the C
    kernels' wrappers (pyrt.native: the tick encoder) and itself."""
    import ast

    import pyrt.journal

    allowed = ("pyrt.errors", "pyrt._version", "pyrt.native", "pyrt.journal")
    offenders = []
    for path in Path(pyrt.journal.__file__).parent.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
                [node.module or ""] if isinstance(node, ast.ImportFrom) else []
            for n in names:
                top = n.split(".")[0]
                if top not in sys.stdlib_module_names and not n.startswith(allowed):
                    offenders.append(f"{path.name}: {n}")
    assert offenders == []


def test_a_block_is_written_within_its_delay_without_more_ticks():
    """A block not yet full is written once max_delay_s has passed, so a slow or paused
    loop loses at most that much on a kill."""

    class Watched(io.RawIOBase):
        def __init__(self):
            self.data = bytearray()
            self.block = threading.Event()

        def writable(self):
            return True

        def write(self, b):
            self.data += bytes(b)
            if bytes(b)[4:5] in (b"T", b"Z"):
                self.block.set()
            return len(b)

    sink = Watched()
    j = Journal(header(), sink, max_delay_s=0.0, poll_s=0.005)
    for r in run(3):
        j.record_tick(*r)
    assert sink.block.wait(30)
    reader = JournalReader(bytes(sink.data))
    assert [t.tick for t in reader.ticks()] == [0, 1, 2] and not reader.complete
    j.close()


def test_black_box_dump_after_close_and_without_a_box(tmp_path):
    """The black box can still be dumped after close; a journal without one refuses."""
    box = BlackBox()
    j = Journal(header(), None, black_box=box, lossless=True)
    for r in run(700):
        j.record_tick(*r)
    j.close()
    assert j.dump_black_box(tmp_path / "after.pj").result(30) == 700
    assert [t.tick for t in JournalReader(tmp_path / "after.pj").ticks()] == list(range(700))
    plain = Journal(header(), io.BytesIO())
    with pytest.raises(JournalError, match="no black box"):
        plain.dump_black_box(tmp_path / "none.pj")
    plain.close()


def test_a_refused_tick_changes_nothing_that_follows():
    """A tick refused mid-encoding (a command that is not UTF-8) leaves the output and input
    state as it was: the ticks after it read back exactly."""
    buf = io.BytesIO()
    j = Journal(header(), buf, lossless=True)
    recs = run(40, seed=4)
    for k, r in enumerate(recs):
        if k == 20:
            r = (*r[:4], [v + 5 for v in r[4]], ((0, 12345, 0), (1, -1, 1)),
                 (("\ud800", "console"),), ())
        j.record_tick(*r)
    with pytest.raises(JournalError, match="1 tick"):
        j.close()
    accepted = [k != 20 for k in range(40)]
    same(list(JournalReader(buf.getvalue())), expected(recs, accepted))


def test_a_block_being_filled_at_real_time_is_cut_on_time_whatever_the_poll(tmp_path):
    """At real time the writer wakes to cut a block ``max_delay_s`` after its first tick
    even when its poll is far longer: the block is in the file well before the poll."""
    from pyrt.journal.format import KIND_HEADER, KIND_NAMES, frame, names_payload

    h = header(2, 1)
    j = Journal(h, tmp_path / "run.pj", lossless=False, poll_s=60.0, max_delay_s=0.05,
                block_ticks=1000)
    try:
        for k in range(3):
            j.record_tick(k, k * 1_000_000, 0, 0, [k, -k])
        index = j.writer_index("mover")  # wakes the writer: it begins the block
        before = len(frame(KIND_HEADER, h.encode())) + len(
            frame(KIND_NAMES, names_payload(index, ["mover"])))
        # bounded: the block is due 0.05 s after the writer began it; a poll is 60 s
        end = time.monotonic() + 20
        while j.bytes_written <= before and time.monotonic() < end:
            time.sleep(0.01)
        assert j.bytes_written > before and j.pending == 0
    finally:
        j.close()
    assert [t.tick for t in JournalReader(tmp_path / "run.pj").ticks()] == [0, 1, 2]
