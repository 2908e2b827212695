"""The real-time side: mailbox round trips against a 1 kHz wall-clock loop,
and the cost the scope adds per tick with 8 channels.

Run: ``python -m pytest bench/bench_runtime.py --benchmark-only -s``.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

from pyrt.scheduler import Loop, ReadyQueue, SimClock, WallClock
from pyrt.scheduler.runner import Runner
from pyrt.scope import Scope, Source

TICKS = 20_000


class Plant:
    def __init__(self):
        self.values = [0.0] * 8
        self.a = self.b = self.c = self.d = 0.0

    def step(self, now_ns):
        self.a = now_ns * 1e-9


def _loop_with_scope(channels: int, running: bool) -> Loop:
    loop = Loop(SimClock())
    plant = Plant()
    loop.attach(plant.step)
    if channels:
        scope = Scope(capacity=16_000)
        for k in range(channels):
            scope.add(f"c{k}", Source.attr(plant, "abcd"[k % 4]))
        if running:
            scope.run("roll")
        scope.attach_to(loop)  # as a station attaches it: sampling only while it acquires
    return loop


@pytest.mark.benchmark(group="scope per tick")
@pytest.mark.parametrize(
    ("channels", "running"), [(0, False), (8, False), (8, True), (16, True)],
    ids=["no-scope", "8ch-stopped", "8ch-roll", "16ch-roll"],
)
def test_scope_cost_per_tick(benchmark, channels, running):
    """TICKS ticks of a loop with a trivial plant, with and without the scope sampling."""
    loop = _loop_with_scope(channels, running)
    benchmark.extra_info["ticks"] = TICKS
    benchmark(loop.run, TICKS)


@pytest.mark.benchmark(group="mailbox round trip")
def test_mailbox_round_trip_at_1khz(benchmark):
    """Round-trip latency of runner.call against a 1 kHz WallClock loop in its own thread."""
    loop = Loop(WallClock(), period_ns=1_000_000)
    queue = ReadyQueue(divisor=4)
    for i, p in enumerate((0x0C, 0x0A, 0x01)):
        queue.add_periodic(0x100 + i, f"T{i}", lambda: None, p)
        queue.schedule(0x100 + i, p)
    loop.attach(queue)
    runner = Runner(loop)
    samples: list[float] = []

    def measure():
        with runner:
            for _ in range(2000):
                t0 = time.perf_counter_ns()
                runner.call(lambda: None)
                samples.append(time.perf_counter_ns() - t0)
                time.sleep(0.0003)  # do not phase-lock with the tick

    benchmark.pedantic(measure, rounds=1, iterations=1)
    arr = np.array(samples) / 1e6
    result = {
        "median_ticks": round(float(np.median(arr)), 3),
        "p99_ticks": round(float(np.percentile(arr, 99)), 3),
        "max_ticks": round(float(arr.max()), 3),
        "overruns": loop.statistics().overruns,
    }
    benchmark.extra_info.update(result)
    print(f"\nmailbox round trip at 1 kHz (in ticks of 1 ms): {result}")
