"""The process image at 1 kHz: the gripper station over tcp:// and modbus://, and pymodbus's clients.

Run: ``python -m pytest bench/bench_image.py --benchmark-only -s``.

``pyrt board-sim gripper`` (``--listen``, and ``--modbus``) runs in a
process of its own on 127.0.0.1; this process builds the station as
``pyrt gripper --boards URL`` does on a 1 ms wall-clock loop, runs ``I``
and ``P-1B86`` with ``wait``, and reports per tick: the read phase
(``io:read``: one ``SNAP``, or one Modbus read of input registers 0..6),
the write phase (``io:write``: the changed outputs, one request), the
whole tick's work (p50/p99) and the overruns (% of ticks).  ``sim:`` (no
I/O phase) is the in-process baseline.

``test_modbus_exchange_cost`` times one grouped read of the gripper's
inputs (read input registers 0..6 of unit 1) with pymodbus's sync client
and with its async client driven from a synchronous caller (the loop
thread hands the coroutine to the client's event loop thread and waits),
and, for reference, the async client awaited inside its own loop.  The
machine has two cores and is shared: read the tails as approximate.
"""

from __future__ import annotations

import asyncio
import io
import re
import subprocess
import sys
import threading
import time
from collections.abc import Iterator

import pytest

from pyrt.commands import RobotShell
from pyrt.scheduler import Loop, WallClock
from pyrt.station.gripper import build_gripper

TICK_NS = 1_000_000


def _quantile(samples: list[int], q: float) -> int:
    s = sorted(samples) or [0]
    return s[min(len(s) - 1, int(q * len(s)))]


@pytest.fixture(scope="module")
def modbus_url() -> Iterator[str]:
    """A gripper board-sim --modbus in a subprocess."""
    proc = subprocess.Popen([sys.executable, "-m", "pyrt", "board-sim", "gripper", "--modbus",
                             "127.0.0.1:0", "--watchdog", "5"], stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        m = re.search(r" on (modbus://\S+) ", proc.stdout.readline())
        assert m, "board-sim did not say where it serves"
        yield m.group(1)
    finally:
        proc.kill()
        proc.wait(10)


@pytest.mark.benchmark(group="image")
@pytest.mark.parametrize("backend", ["sim", "tcp", "modbus"])
def test_gripper_station_phases(benchmark, gripper_url, modbus_url, backend):
    """I, P-1B86 and wait at 1 kHz: io:read and io:write p50/p99, tick work, overrun %."""
    url = {"sim": "sim:", "tcp": gripper_url, "modbus": modbus_url}[backend]
    result: dict[str, object] = {}

    def run() -> None:
        station = build_gripper(Loop(WallClock(), period_ns=TICK_NS), boards=url)
        reads: list[int] = []
        writes: list[int] = []
        clock = time.perf_counter_ns
        boards = station.boards

        def timed(fn, samples):
            def phase(now_ns: int) -> None:
                t = clock()
                try:
                    fn(now_ns)
                finally:
                    samples.append(clock() - t)
            return phase

        boards.poll = timed(boards.poll, reads)
        boards.flush = timed(boards.flush, writes)
        shell = RobotShell(station, out := io.StringIO())
        station.start()
        try:
            station.loop.reset_statistics()
            for line in ("I", "P-1B86", "wait"):
                shell.onecmd(line)
            stats = station.runner.statistics()
        finally:
            station.close()
        assert "target E47A" in out.getvalue(), out.getvalue()
        assert station.fault is None, station.fault
        result.update(reads=reads, writes=writes, stats=stats)

    benchmark.pedantic(run, rounds=1, iterations=1)
    reads, writes, stats = result["reads"], result["writes"], result["stats"]
    work = stats.work
    pct = 100.0 * stats.overruns / max(1, stats.ticks)
    info = {
        "ticks": stats.ticks,
        "read_p50_us": round(_quantile(reads, 0.5) / 1e3, 1),
        "read_p99_us": round(_quantile(reads, 0.99) / 1e3, 1),
        "write_p50_us": round(_quantile(writes, 0.5) / 1e3, 1),
        "write_p99_us": round(_quantile(writes, 0.99) / 1e3, 1),
        "work_p50_us": round(work.p50_ns / 1e3, 1), "work_p99_us": round(work.p99_ns / 1e3, 1),
        "overruns": stats.overruns, "overrun_pct": round(pct, 2),
    }
    benchmark.extra_info.update(info)
    print(f"\ngripper station on {backend}: {info}")


@pytest.mark.benchmark(group="image")
def test_modbus_exchange_cost(benchmark, modbus_url):
    """One grouped read of the gripper's inputs: sync client, async client from a sync caller,
    async client awaited in its loop (p50/p99 over 2000 reads each)."""
    from pymodbus.client import AsyncModbusTcpClient, ModbusTcpClient

    port = int(re.search(r":(\d+)\?", modbus_url).group(1))
    n = 2000
    out: dict[str, list[int]] = {}

    def run() -> None:
        clock = time.perf_counter_ns
        sync = ModbusTcpClient("127.0.0.1", port=port, retries=0)
        assert sync.connect()
        samples = []
        for _ in range(n):
            t = clock()
            sync.read_input_registers(0, count=7, device_id=1)
            samples.append(clock() - t)
        sync.close()
        out["sync"] = samples

        loop = asyncio.new_event_loop()
        thread = threading.Thread(target=loop.run_forever, daemon=True)
        thread.start()
        async def make() -> AsyncModbusTcpClient:
            c = AsyncModbusTcpClient("127.0.0.1", port=port, retries=0)
            assert await c.connect()
            return c

        client = asyncio.run_coroutine_threadsafe(make(), loop).result(5)
        samples = []
        for _ in range(n):
            t = clock()
            asyncio.run_coroutine_threadsafe(
                client.read_input_registers(0, count=7, device_id=1), loop).result(5)
            samples.append(clock() - t)
        out["async from the loop thread"] = samples

        async def inside() -> list[int]:
            got = []
            for _ in range(n):
                t = clock()
                await client.read_input_registers(0, count=7, device_id=1)
                got.append(clock() - t)
            return got

        out["async awaited in its loop"] = asyncio.run_coroutine_threadsafe(
            inside(), loop).result(60)
        client.close()
        loop.call_soon_threadsafe(loop.stop)
        thread.join(5)

    benchmark.pedantic(run, rounds=1, iterations=1)
    for name, samples in out.items():
        p50, p99 = _quantile(samples, 0.5) / 1e3, _quantile(samples, 0.99) / 1e3
        benchmark.extra_info[f"{name} p50_us"] = round(p50, 1)
        benchmark.extra_info[f"{name} p99_us"] = round(p99, 1)
        print(f"\npymodbus {name}: one grouped read p50 {p50:.1f} µs, p99 {p99:.1f} µs")
