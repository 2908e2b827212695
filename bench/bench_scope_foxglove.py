"""What ``scope foxglove`` costs the tick, at real time.

A 1 kHz WallClock loop for SECONDS, 8 channels sampled into a rolling scope,
served at 50 Hz and at 1 kHz of loop time on a Foxglove server on loopback
(its thread encoding the samples as JSON and logging them beside the loop),
with no client and with one client subscribed to every channel (a plain
WebSocket reader, as the tests have it): the scope handler's time per tick
and the loop's lateness (p99, max) and overruns, against the scope alone.
The loop's own share is the UDP stream's (the same offer: a comparison a
sample and, when one is due, its packed bytes onto a bounded queue;
``bench_scope_stream.py``).

Run: ``python -m pytest bench/bench_scope_foxglove.py --benchmark-only -s``.
"""

from __future__ import annotations

import sys
import threading
from pathlib import Path

import pytest

from pyrt.scheduler import Loop, WallClock
from pyrt.scope import Scope, Source

pytest.importorskip("foxglove")
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from _wsclient import FoxgloveClient

from pyrt.scope.foxglove import FoxgloveServer

SECONDS = 3.0


class Plant:
    def __init__(self):
        self.a = self.b = self.c = self.d = 0.0

    def step(self, now_ns):
        self.a = now_ns * 1e-9
        self.b = self.a * 2


@pytest.mark.benchmark(group="scope foxglove at real time (1 kHz)")
@pytest.mark.parametrize(("hz", "client"), [(0, False), (50, False), (50, True),
                                            (1000, True)],
                         ids=["no-server", "50Hz", "50Hz-client", "1kHz-client"])
def test_real_time_tick_with_the_server(benchmark, hz, client):
    """SECONDS of a 1 kHz loop: the scope handler's time, lateness, overruns."""
    loop = Loop(WallClock(), period_ns=1_000_000)
    plant = Plant()
    loop.attach(plant.step)
    scope = Scope(capacity=16_000)
    for k in range(8):
        scope.add(f"obj{k % 2}.c{k}", Source.attr(plant, "abcd"[k % 4]))
    scope.run("roll")
    loop.attach(scope.sample, name="scope")
    server = reader = None
    stop = threading.Event()
    if hz:
        server = FoxgloveServer(0, hz)
        scope.start_foxglove(server)
    if client and server is not None:
        reader = FoxgloveClient("127.0.0.1", server.port)

        def read() -> None:
            while not stop.is_set():
                try:
                    reader.until(lambda c: stop.is_set(), timeout_s=SECONDS * 3,
                                 subscribe=["/scope/obj0", "/scope/obj1"])
                except (TimeoutError, OSError):
                    return

        t = threading.Thread(target=read, daemon=True)
        t.start()

    def run():
        loop.run(duration_ns=int(SECONDS * 1e9))

    try:
        benchmark.pedantic(run, rounds=1, iterations=1)
    finally:
        stop.set()
        if reader is not None:
            reader.close()
        if server is not None:
            server.close()
    st = loop.statistics()
    sc = st.tasks["scope"]
    result = {
        "scope_mean_us": round(sc.mean_ns / 1e3, 2), "scope_p99_us": round(sc.p99_ns / 1e3, 1),
        "lateness_p99_us": round(st.lateness.p99_ns / 1e3, 1),
        "lateness_max_us": round(st.lateness.max_ns / 1e3, 1),
        "overruns": st.overruns, "ticks": st.ticks,
    }
    if server is not None:
        result.update(sent=server.sent, dropped=server.dropped)
    if reader is not None:
        result.update(received=sum(len(v) for v in reader.messages.values()))
    benchmark.extra_info.update(result)
    print(f"\nreal time, server {hz or 'off'}{' + client' if client else ''}: {result}")
