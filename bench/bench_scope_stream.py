"""What ``scope stream`` costs the tick.

* Loop side (SimClock, as fast as the CPU goes): a loop sampling 8 channels
  into a rolling scope, without a stream and streaming at 50 Hz and 1 kHz of
  loop time (1 ms ticks).  The stream's thread is held still here and its
  queue emptied every tick, so the figure is the loop's own share: one
  comparison a sample and, when a sample is due, a copy of its packed bytes
  onto the queue.
* At real time (WallClock, 1 kHz, 3 s each): the same scope with the stream
  off, at 50 Hz and at 1 kHz to a listener on loopback, its thread encoding
  and sending beside the loop: the scope handler's time per tick, the
  loop's lateness (p99, max) and overruns, and the stream's rate (objects
  sent a second).

Run: ``python -m pytest bench/bench_scope_stream.py --benchmark-only -s``.
"""

from __future__ import annotations

import socket

import pytest

from pyrt.scheduler import Loop, SimClock, WallClock
from pyrt.scope import Scope, Source, UdpStream

TICKS = 20_000
SECONDS = 3.0


class Plant:
    def __init__(self):
        self.a = self.b = self.c = self.d = 0.0

    def step(self, now_ns):
        self.a = now_ns * 1e-9
        self.b = self.a * 2


@pytest.fixture
def listener():
    """A UDP socket on loopback that takes the datagrams (read by nobody: the kernel
    keeps or drops them, as a busy PlotJuggler would)."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    yield sock.getsockname()[1]
    sock.close()


def _loop(clock, hz: int, port: int) -> tuple[Loop, Scope, UdpStream | None]:
    loop = Loop(clock, period_ns=1_000_000)
    plant = Plant()
    loop.attach(plant.step)
    scope = Scope(capacity=16_000)
    for k in range(8):
        scope.add(f"obj{k % 2}.c{k}", Source.attr(plant, "abcd"[k % 4]))
    scope.run("roll")
    loop.attach(scope.sample, name="scope")
    stream = None
    if hz:
        stream = UdpStream("127.0.0.1", port, hz)
        scope.start_stream(stream)
    return loop, scope, stream


@pytest.mark.benchmark(group="scope stream: the loop's share per tick")
@pytest.mark.parametrize("hz", [0, 50, 1000], ids=["no-stream", "50Hz", "1kHz"])
def test_loop_side_cost_per_tick(benchmark, listener, hz):
    """TICKS ticks on a SimClock; the stream's thread held still, its queue emptied."""
    loop, _scope, stream = _loop(SimClock(), hz, listener)
    if stream is not None:
        stream._stop.set()
        stream._thread.join(5)
        queue = stream._queue
        loop.attach(lambda now: queue.clear(), name="empty the queue")
    else:
        loop.attach(lambda now: None, name="empty the queue")
    try:
        benchmark(loop.run, TICKS)
    finally:
        if stream is not None:
            stream.close()
    per_tick_us = benchmark.stats.stats.mean / TICKS * 1e6
    benchmark.extra_info.update(ticks=TICKS, per_tick_us=round(per_tick_us, 3))
    print(f"\nloop side, stream {hz or 'off'}: {per_tick_us:.3f} µs a tick")


@pytest.mark.benchmark(group="scope stream at real time (1 kHz)")
@pytest.mark.parametrize("hz", [0, 50, 1000], ids=["no-stream", "50Hz", "1kHz"])
def test_real_time_tick_with_the_stream(benchmark, listener, hz):
    """SECONDS of a 1 kHz WallClock loop: the scope handler's time, lateness, overruns."""
    loop, _scope, stream = _loop(WallClock(), hz, listener)

    def run():
        loop.run(duration_ns=int(SECONDS * 1e9))

    try:
        benchmark.pedantic(run, rounds=1, iterations=1)
    finally:
        if stream is not None:
            stream.close()
    st = loop.statistics()
    sc = st.tasks["scope"]
    result = {
        "scope_mean_us": round(sc.mean_ns / 1e3, 2), "scope_p99_us": round(sc.p99_ns / 1e3, 1),
        "scope_max_us": round(sc.max_ns / 1e3, 1),
        "lateness_p99_us": round(st.lateness.p99_ns / 1e3, 1),
        "lateness_max_us": round(st.lateness.max_ns / 1e3, 1),
        "overruns": st.overruns, "ticks": st.ticks,
    }
    if stream is not None:  # the rate: objects sent a second of the run (loop time = wall)
        result.update(sent=stream.sent, rate_hz=round(stream.sent / SECONDS, 1),
                      lost=stream.lost, dropped=stream.dropped)
    benchmark.extra_info.update(result)
    print(f"\nreal time, stream {hz or 'off'}: {result}")
