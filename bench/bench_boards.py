"""Board back-end benchmarks: the register round trip over tcp://, and the gripper's tick with it.

Run: ``python -m pytest bench/bench_boards.py --benchmark-only -s``.

``pyrt board-sim`` runs in a process of its own on 127.0.0.1 (its world
stepping every 1 ms of real time), the controller's side in this one.  Each
round-trip benchmark times one register access per round (no per-tick copy:
``max_age=0``, so every read is on the wire) and reports the median and the
99th percentile twice: from pytest-benchmark's rounds, and from a separate
list of ``perf_counter_ns`` samples.  The tick benchmark runs the 002
controller on a 1 ms wall-clock loop through the tcp:// board (power-up
``I``, then a ``P`` move) and reports the time ``poll`` takes per tick (one
``SNAPX`` round trip: this loop runs no write phase, so nothing streams;
``bench_boards_station.py`` runs a station's whole tick, the stream with it)
and the whole tick's work, against the 1 ms tick.  The machine is shared:
read the tails as approximate.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import pytest

from pyrt.boards import open_boards
from pyrt.boards.gripper import DAC, LED_LO, P8155_PA
from pyrt.robots.gripper import GripperController
from pyrt.scheduler import Loop, WallClock
from pyrt.sim.world import GRIPPER_BOARDS, MANIPULATOR_BOARDS

ROUNDS = 3000
SAMPLES = 3000
TICK_NS = 1_000_000


def _quantile(samples: list[float], q: float) -> float:
    s = sorted(samples)
    return s[min(len(s) - 1, int(q * len(s)))]


def _samples(fn: Callable[[], object], n: int = SAMPLES) -> list[int]:
    """``n`` timings of ``fn`` in ns (perf_counter_ns around each call)."""
    clock = time.perf_counter_ns
    out = []
    for _ in range(n):
        t = clock()
        fn()
        out.append(clock() - t)
    return out


def _report(benchmark, label: str) -> None:
    data = benchmark.stats.stats.data  # one timing per round (iterations=1), s
    median, p99 = benchmark.stats.stats.median, _quantile(data, 0.99)
    own = _samples(benchmark._pyrt_fn)
    own_median, own_p99 = _quantile(own, 0.5), _quantile(own, 0.99)
    benchmark.extra_info.update(
        median_us=round(median * 1e6, 1), p99_us=round(p99 * 1e6, 1),
        samples_median_us=round(own_median / 1e3, 1), samples_p99_us=round(own_p99 / 1e3, 1),
    )
    print(f"\n{label}: median {median * 1e6:.1f} µs, p99 {p99 * 1e6:.1f} µs "
          f"({len(data)} rounds); own samples: median {own_median / 1e3:.1f} µs, "
          f"p99 {own_p99 / 1e3:.1f} µs ({len(own)})")


def _bench(benchmark, fn: Callable[[], object], label: str) -> None:
    benchmark._pyrt_fn = fn
    benchmark.pedantic(fn, rounds=ROUNDS, iterations=1, warmup_rounds=200)
    _report(benchmark, label)


@pytest.mark.benchmark(group="boards-tcp")
@pytest.mark.parametrize("access", ["read PA", "write LED", "poll (SNAPX)"])
def test_gripper_register_round_trip(benchmark, gripper_url, access):
    """One gripper register access over tcp:// (read, write, or a read phase asked for in one round trip, SNAPX)."""
    with open_boards(gripper_url, "gripper", GRIPPER_BOARDS, max_age=0) as boards:
        board = boards["gripper"]
        fn = {
            "read PA": lambda: board.read(P8155_PA),
            "write LED": lambda: board.write(LED_LO, 0xFF),
            "poll (SNAPX)": lambda: boards.poll(0),
        }[access]
        _bench(benchmark, fn, f"gripper {access} round trip")


@pytest.mark.benchmark(group="boards-tcp")
@pytest.mark.parametrize("access", ["pulses", "poll (SNAPX, 3 counters)"])
def test_manipulator_register_round_trip(benchmark, manipulator_url, access):
    """One manipulator register access over tcp:// (a TIO10 read, or a read phase asked for in one round trip, SNAPX)."""
    with open_boards(manipulator_url, "prototype", MANIPULATOR_BOARDS, max_age=0) as boards:
        tio, dc = boards["tio10"], boards["dc"]
        for address in (168, 169, 170):  # the prototype's encoders ride along in SNAPX
            dc.read_counter(address)
        fn = {
            "pulses": lambda: tio.pulses(7),
            "poll (SNAPX, 3 counters)": lambda: boards.poll(0),
        }[access]
        _bench(benchmark, fn, f"manipulator {access} round trip")


@pytest.mark.benchmark(group="boards-tick")
def test_gripper_tick_budget_over_tcp(benchmark, gripper_url):
    """The 002 controller on a 1 ms wall-clock loop through tcp://: poll time per tick and the
    tick's work (p50/p99/max) while it runs I and a P move, against the 1 ms tick."""
    result: dict[str, object] = {}

    def run() -> None:
        with open_boards(gripper_url, "gripper", GRIPPER_BOARDS) as boards:
            polls: list[int] = []
            clock = time.perf_counter_ns

            def timed_poll(now_ns: int) -> None:
                t = clock()
                boards.poll(now_ns)
                polls.append(clock() - t)

            ctl = GripperController(boards["gripper"].cpu)
            loop = Loop(WallClock(), period_ns=TICK_NS)
            loop.attach(timed_poll, name="board")
            ctl.attach(loop)
            ctl.power_up()
            job = ctl.start_init()
            loop.run(until=lambda: job.done, duration_ns=20_000_000_000)
            assert job.done and job.value().ok
            ctl.move(-0x0800)
            loop.run(duration_ns=2_000_000_000)
            ctl.drive(0x80)
            boards["gripper"].write(DAC, 0x80)
            stats = loop.statistics()
            result.update(polls=polls, stats=stats)

    benchmark.pedantic(run, rounds=1, iterations=1)
    polls, stats = result["polls"], result["stats"]
    p50, p99 = _quantile(polls, 0.5), _quantile(polls, 0.99)
    work = stats.work
    benchmark.extra_info.update(
        ticks=stats.ticks, poll_median_us=round(p50 / 1e3, 1), poll_p99_us=round(p99 / 1e3, 1),
        work_p50_us=round(work.p50_ns / 1e3, 1), work_p99_us=round(work.p99_ns / 1e3, 1),
        work_max_us=round(work.max_ns / 1e3, 1), overruns=stats.overruns,
    )
    print(f"\ngripper tick over tcp:// ({stats.ticks} ticks of 1 ms): poll median "
          f"{p50 / 1e3:.1f} µs, p99 {p99 / 1e3:.1f} µs ({p50 / TICK_NS:.1%} / {p99 / TICK_NS:.1%}"
          f" of the tick); tick work p50 <= {work.p50_ns / 1e3:.0f} µs, p99 <= "
          f"{work.p99_ns / 1e3:.0f} µs, max {work.max_ns / 1e3:.0f} µs; overruns "
          f"{stats.overruns}")
