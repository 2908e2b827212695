"""DAQ server benchmarks: STATUS requests per second on loopback, and what they cost the loop.

Run: ``python -m pytest bench/bench_server.py --benchmark-only -s``.

The gripper runs on a real-time (WallClock, 1 ms) loop in this process; the
clients run in processes of their own at the lowest priority (they stand
for a DAQ on another computer), each connection keeping one request in
flight.  For 1 and 32 clients the benchmark reports requests per second
and, measured in alternating windows of the same run, the loop's p99 tick
lateness and overruns idle and under that load.  Target: at least 5,000
STATUS requests/s with 32 clients, with no rise in overruns.  The machine
is shared: read the lateness figures as approximate.
"""

from __future__ import annotations

import pytest
from _server_rig import run_load, served

TARGET_PER_S = 5000.0
WINDOW_S = 2.0
ROUNDS = 3


def _window(sv, clients: int | None) -> tuple[object, dict | None]:
    """One measuring window: statistics reset, then idle or under load."""
    loop = sv.rig.loop
    sv.runner.call(loop.reset_statistics)
    load = None
    if clients is None:
        sv.runner.sleep(WINDOW_S)
    else:
        load = run_load(sv.host, sv.port, clients, WINDOW_S, "STATUS",
                        procs=1 if clients == 1 else 2)
    return sv.runner.call(loop.statistics), load


@pytest.mark.benchmark(group="server")
@pytest.mark.parametrize("clients", [1, 32])
def test_status_requests_per_second(benchmark, clients):
    """STATUS/s with N clients, and the loop's lateness idle vs loaded (alternating windows)."""
    with served(wall=True) as sv:
        rows: list[tuple[str, float, float, int, int]] = []

        def measure() -> None:
            for _ in range(ROUNDS):
                for what in (None, clients):
                    stats, load = _window(sv, what)
                    rows.append(("idle" if what is None else "load",
                                 load["per_s"] if load else 0.0,
                                 stats.lateness.p99_ns / 1e3, stats.overruns,
                                 stats.lateness.count))
                    if load is not None:
                        assert load["errors"] == 0

        benchmark.pedantic(measure, rounds=1, iterations=1)
        idle = [r for r in rows if r[0] == "idle"]
        busy = [r for r in rows if r[0] == "load"]
        per_s = sorted(r[1] for r in busy)[len(busy) // 2]
        p99_idle = sorted(r[2] for r in idle)[len(idle) // 2]
        p99_busy = sorted(r[2] for r in busy)[len(busy) // 2]
        over_idle = sum(r[3] for r in idle)
        over_busy = sum(r[3] for r in busy)
        ticks_idle = sum(r[4] for r in idle)
        ticks_busy = sum(r[4] for r in busy)
        benchmark.extra_info.update(
            clients=clients, status_per_s=round(per_s), target_per_s=TARGET_PER_S,
            p99_lateness_idle_us=round(p99_idle, 1), p99_lateness_load_us=round(p99_busy, 1),
            overruns_idle=over_idle, overruns_load=over_busy,
            ticks_idle=ticks_idle, ticks_load=ticks_busy,
        )
        print(
            f"\n{clients} client(s): {per_s:,.0f} STATUS/s (median of {ROUNDS} windows of "
            f"{WINDOW_S:g} s; target {TARGET_PER_S:,.0f} with 32 clients: "
            f"{per_s / TARGET_PER_S:.1f}x); p99 tick lateness idle {p99_idle:.0f} µs, loaded "
            f"{p99_busy:.0f} µs (+{p99_busy - p99_idle:.0f} µs); overruns idle {over_idle} in "
            f"{ticks_idle} ticks, loaded {over_busy} in {ticks_busy} ticks"
        )
        for r in rows:
            print(f"  {r[0]:4s} {r[1]:8.0f}/s  p99 {r[2]:7.0f} µs  overruns {r[3]:3d} / {r[4]}")


#: The floor tests/test_server_load.py asserted before it became a figure of
#: the machine (a busy machine missed it): 32 clients, STATUS requests/s.
FLOOR_PER_S = 1000.0


@pytest.mark.benchmark(group="server")
def test_status_throughput_floor_32_clients(benchmark):
    """32 busy clients for 1.5 s against the real-time gripper: STATUS/s above the 1000/s floor, no error."""
    with served(wall=True) as sv:
        loads: list[dict] = []

        def measure() -> None:
            loads.append(run_load(sv.host, sv.port, 32, 1.5, "STATUS"))

        benchmark.pedantic(measure, rounds=1, iterations=1)
        (load,) = loads
        benchmark.extra_info.update(clients=32, status_per_s=round(load["per_s"]),
                                    floor_per_s=FLOOR_PER_S)
        print(f"\n32 clients: {load['per_s']:,.0f} STATUS/s (floor {FLOOR_PER_S:,.0f})")
        assert load["errors"] == 0
        assert load["per_s"] > FLOOR_PER_S


#: What one read of every EPICS per-device value may cost the loop: far under
#: a 1 ms tick (it happens once per 0.1 s, i.e. every 20th 5 ms tick).
EXTRAS_BUDGET_US = 200.0


@pytest.mark.benchmark(group="server-hub")
@pytest.mark.parametrize("extras", [False, True], ids=["status-only", "epics-extras"])
def test_hub_tick_cost_with_and_without_the_epics_values(benchmark, tmp_path, extras):
    """The server's handler in the manipulator's tick: the STATUS snapshot alone, and with EPICS's per-device values read (every signal of every component, STATE, STOP_REASON, TARGET)."""
    from pyrt.db import copy_station
    from pyrt.server import ServedStation
    from pyrt.server.hub import StatusHub
    from pyrt.station.manipulator import ManipulatorStation

    station = ManipulatorStation(copy_station("prototype", tmp_path / "p"), tick_ns=5_000_000)
    try:
        robot = ServedStation(station)
        hub = StatusHub(robot.status_names, robot.status_sources(),
                        extra_sources=[f.source for f in robot.extra_fields], extra_every=1)
        hub.extras_wanted = extras
        benchmark(hub, 0)
        mean_us = benchmark.stats.stats.mean * 1e6
        benchmark.extra_info.update(values=len(robot.extra_fields) if extras else 0,
                                    mean_us=round(mean_us, 2))
        print(f"\nhub tick {'with' if extras else 'without'} the {len(robot.extra_fields)} EPICS "
              f"values: {mean_us:.1f} µs (budget for the read {EXTRAS_BUDGET_US:g} µs, once per "
              "0.1 s)")
        assert mean_us < EXTRAS_BUDGET_US
    finally:
        station.close()
