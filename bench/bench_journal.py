"""Journal benchmarks: what recording costs the loop thread, what the writer thread
spends encoding, and how large a minute of a 1 kHz gripper is.

Run: ``python -m pytest bench/bench_journal.py --benchmark-only -s``.  The figures
are in ``extra_info`` and on stdout.

* ``record_tick``: the loop thread's cost per tick (40 inputs of which 10 change,
  3 outputs written), the writer thread parked so that it takes no interpreter time
  while it is measured; target a few us, <= 5 % of the gripper's ~30 us tick work.
* ``record_tick at 1 kHz``: the same on a 1 kHz wall-clock loop with the writer
  thread running (encoding, compressing, writing a file): p50 and p99 of the call,
  and the loop's lateness with and without the journal.
* ``encode``: the writer thread's work per tick (off the loop thread).
* ``size``: bytes per minute at 1 kHz, idle and moving (10 inputs change every tick,
  3 outputs written, wall-clock lateness recorded); target <= 1 MB/min moving.
"""

from __future__ import annotations

import io
import random
import threading
import time

import pytest

from pyrt.journal import DEFAULT_BLOCK_TICKS, Header, Journal
from pyrt.journal.format import BlockEncoder

PERIOD = 1_000_000
N_IN = 40
TICKS = 20_000


def gripper_header() -> Header:
    return Header(station="gripper", period_ns=PERIOD,
                  inputs=[f"in{i}" for i in range(N_IN)], outputs=[f"out{i}" for i in range(8)],
                  writers=("sensors", "jaw-move", "jaw-watch"))


def moving(n: int, seed: int = 1, late: bool = True, changing: int = 10) -> list[tuple]:
    """A moving gripper: ``changing`` of 40 inputs change every tick (encoder counts,
    ADC readings), 3 outputs are written, lateness as a wall clock has it."""
    rng = random.Random(seed)
    inputs = [rng.randrange(4000) for _ in range(N_IN)]
    out = []
    for k in range(n):
        for i in range(changing):
            inputs[i] += rng.randrange(-2, 4)
        lat = rng.randrange(20_000, 80_000) if late else 0
        writes = tuple((i, 1000 + (k // 7) % 50 + i, i % 3) for i in range(3)) \
            if changing else ()
        out.append((k, k * PERIOD + lat, lat, 0, list(inputs), writes, (), ()))
    return out


class Parked(io.RawIOBase):
    """A sink that holds the writer thread in its first write until released."""

    def __init__(self):
        self.release = threading.Event()

    def writable(self) -> bool:
        return True

    def write(self, b) -> int:
        self.release.wait(60)
        return len(b)


@pytest.mark.benchmark(group="journal: loop thread")
def test_record_tick(benchmark):
    """record_tick per TICKS ticks, the writer thread parked (the loop thread's cost alone)."""
    recs = moving(TICKS)
    journals = []

    def setup():
        sink = Parked()
        j = Journal(gripper_header(), sink, queue_ticks=TICKS + 10)
        journals.append((j, sink))
        return (j,), {}

    def run(j):
        rec = j.record_tick
        for r in recs:
            rec(*r)

    benchmark.pedantic(run, setup=setup, rounds=5, iterations=1)
    for j, sink in journals:
        sink.release.set()
        j.close()
    per_tick_us = benchmark.stats.stats.median / TICKS * 1e6
    benchmark.extra_info["us_per_tick"] = round(per_tick_us, 3)
    benchmark.extra_info["percent_of_30us_tick"] = round(per_tick_us / 30 * 100, 1)
    print(f"\nrecord_tick: {per_tick_us:.3f} us per tick "
          f"({per_tick_us / 30 * 100:.1f} % of a 30 us tick)")


@pytest.mark.benchmark(group="journal: writer thread")
def test_encode(benchmark):
    """The writer thread's encoding (and zlib) per TICKS ticks of a moving gripper."""
    recs = [(k, t, late, m, tuple(ins), outs, c, e) for k, t, late, m, ins, outs, c, e
            in moving(TICKS)]

    def run():
        enc = BlockEncoder(gripper_header())
        for r in recs:
            enc.add(*r)
            if enc.count >= DEFAULT_BLOCK_TICKS:
                enc.take()

    benchmark.pedantic(run, rounds=3, iterations=1)
    per_tick_us = benchmark.stats.stats.median / TICKS * 1e6
    benchmark.extra_info["us_per_tick"] = round(per_tick_us, 2)
    print(f"\nencode (writer thread): {per_tick_us:.2f} us per tick")


@pytest.mark.parametrize("kind", ["idle", "moving"])
def test_size_per_minute(kind, benchmark):
    """Bytes of one minute at 1 kHz through a Journal with its defaults."""
    recs = moving(60_000, changing=10 if kind == "moving" else 0)
    buf = io.BytesIO()

    def run():
        buf.seek(0)
        buf.truncate()
        j = Journal(gripper_header(), buf, lossless=True)
        for r in recs:
            j.record_tick(*r)
        j.close()

    benchmark.pedantic(run, rounds=1, iterations=1)
    size = len(buf.getvalue())
    benchmark.extra_info["bytes_per_minute"] = size
    print(f"\n{kind}: {size / 1e6:.3f} MB per minute at 1 kHz")
    if kind == "moving":
        assert size <= 1_000_000


def _wall_loop(seconds: float, journal: Journal | None, recs: list[tuple]
               ) -> tuple[list[int], list[int]]:
    """A 1 kHz loop on the wall clock (sleep, then spin, to absolute deadlines) that
    hands each tick to ``journal``; the call durations and the lateness, ns."""
    calls, late = [], []
    now = time.monotonic_ns
    deadline = now() + PERIOD
    n = int(seconds * 1000)
    for k in range(n):
        while True:
            left = deadline - now()
            if left <= 0:
                break
            if left > 200_000:
                time.sleep((left - 150_000) / 1e9)
        start = now()
        late.append(start - deadline)
        if journal is not None:
            r = recs[k % len(recs)]
            journal.record_tick(k, start, start - deadline, 0, r[4], r[5])
            calls.append(now() - start)
        deadline += PERIOD
        if now() > deadline:
            deadline += ((now() - deadline) // PERIOD + 1) * PERIOD
    return calls, late


def _pct(xs: list[int], p: float) -> float:
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(p * len(xs)))] / 1e3


def test_record_tick_at_1khz(benchmark, tmp_path):
    """On a 1 kHz wall-clock loop with the writer running: record_tick p50/p99 and the
    loop's lateness p50/p99 with and without the journal (3 s each)."""
    recs = moving(3000)
    results = {}

    def run():
        _calls, base = _wall_loop(3.0, None, recs)
        j = Journal(gripper_header(), tmp_path / "bench.pj")
        calls, late = _wall_loop(3.0, j, recs)
        j.close()
        results.update(calls=calls, late=late, base=base, dropped=j.dropped,
                       size=j.bytes_written)

    benchmark.pedantic(run, rounds=1, iterations=1)
    info = {
        "record_tick_p50_us": _pct(results["calls"], 0.5),
        "record_tick_p99_us": _pct(results["calls"], 0.99),
        "record_tick_max_us": max(results["calls"]) / 1e3,
        "lateness_p50_us_without": _pct(results["base"], 0.5),
        "lateness_p99_us_without": _pct(results["base"], 0.99),
        "lateness_p50_us_with": _pct(results["late"], 0.5),
        "lateness_p99_us_with": _pct(results["late"], 0.99),
        "ticks_dropped": results["dropped"],
        "bytes": results["size"],
    }
    benchmark.extra_info.update(info)
    print("\n" + "\n".join(f"{k}: {v:.1f}" if isinstance(v, float) else f"{k}: {v}"
                           for k, v in info.items()))
