"""Manipulator control benchmarks: one full control poll, and a whole move's real-time ratio.

Run: ``python -m pytest bench/bench_manipulator.py --benchmark-only -s``.

* ``poll``: one :meth:`PolyAxis.poll` during a move (tensions and lengths
  through the device objects, ring contacts, the prepared position finder,
  error signals, one batched fuzzy call, every Motor's velocity and poll,
  the stop conditions), for the 3-rope prototype and the 5-rope station;
  the physics is not stepped.  Target: under 30 µs for 5 ropes.  The
  numeric work is two C calls (csrc/polyctl.c); what is left in Python is
  the device objects (``device``: their share alone), the motion's step and
  the stop conditions.  The machine is shared, so the median and the
  minimum are both printed; compare runs made under the same load.

  Measured on the shared 2-core VM, eight alternating runs of this poll
  loop against the tree before the kernels (median of the runs' medians):
  before 48.0 µs (3 ropes) and 54.5 µs (5 ropes); after 19.2 µs and
  25.9 µs (0.86x the target); a quiet run of this file gave 19.9 / 26.7 µs
  with the devices alone 8.0 / 12.4 µs, so about half of what is left is
  the device objects (``Motor.poll`` about 2 µs a motor).
  Since the controller's neck model lets lower segments bear too (the
  world's), and the poll checks the estimate (distErr, encoders against
  motors): the two kernels measured the same with either segment mask
  (5.7 µs for 5 ropes, alternating, same process) and the estimate check
  costs 0.6-0.9 µs a poll; on the loaded VM (load average 4.4 on 2 cores)
  a run gave 30.6 / 40.5 µs, with and without the check alternating
  within noise of each other.
* ``kernels``: the two polyctl calls alone (the numeric share of a poll).
* ``move``: a complete ``to`` on ``--speed max`` (plant, ready queue,
  write-back, mailbox, all on a SimClock loop) at the manipulator's default
  5 ms tick and at a 1 ms tick; simulated seconds per wall second.
  Target: at least 20x real time.
"""

from __future__ import annotations

import time

import pytest
from _manipulator_rig import make_station

POLL_TARGET_US = 30.0
REALTIME_TARGET = 20.0
MOVES = {"prototype": (60.0, 0.0, 140.0), "sno": (80.0, 60.0, 100.0)}


@pytest.mark.benchmark(group="manipulator-control-poll")
@pytest.mark.parametrize("name", ["prototype", "sno"])
def test_control_poll(benchmark, tmp_path, name):
    """One control poll during a move, physics excluded (µs)."""
    station, runner = make_station(tmp_path, name)
    pa = station.polyaxis
    runner.call(pa.to, MOVES[name])
    runner.sleep(20.0)
    assert pa.active
    clock = [station.loop.now_ns * 1e-9]

    def poll():
        clock[0] += pa.poll_s
        pa.poll(clock[0])

    benchmark.pedantic(poll, rounds=2000, iterations=1, warmup_rounds=50)
    us = benchmark.stats.stats.median * 1e6
    low = benchmark.stats.stats.min * 1e6
    benchmark.extra_info.update(ropes=pa.n, median_us=round(us, 1), min_us=round(low, 1),
                                target_us=POLL_TARGET_US,
                                ratio_to_target=round(us / POLL_TARGET_US, 2))
    print(f"\n{name}: control poll {us:.1f} µs (min {low:.1f}) for {pa.n} ropes "
          f"(target {POLL_TARGET_US:g} µs: {us / POLL_TARGET_US:.2f}x the target)")
    station.close()


@pytest.mark.benchmark(group="manipulator-move")
@pytest.mark.parametrize("tick_ms", [5, 1])
@pytest.mark.parametrize("name", ["prototype", "sno"])
def test_complete_move(benchmark, tmp_path_factory, name, tick_ms):
    """A complete 'to' on --speed max: simulated seconds per wall second."""
    ratios = []

    def run():
        station, runner = make_station(tmp_path_factory.mktemp(name), name,
                                       tick_ns=tick_ms * 1_000_000)
        t0_sim = station.loop.now_ns
        w0 = time.perf_counter()
        runner.call(station.polyaxis.to, MOVES[name])
        assert runner.wait_until(lambda: not station.polyaxis.active, 600.0)
        wall = time.perf_counter() - w0
        sim = (station.loop.now_ns - t0_sim) * 1e-9
        ratios.append(sim / wall)
        assert station.polyaxis.last_stop.reason.value == "ENDPOINT_STOP"
        station.close()

    benchmark.pedantic(run, rounds=2, iterations=1)
    ratio = sorted(ratios)[len(ratios) // 2]
    benchmark.extra_info.update(tick_ms=tick_ms, realtime_ratio=round(ratio, 1),
                                target=REALTIME_TARGET)
    print(f"\n{name}: a complete move at a {tick_ms} ms tick runs {ratio:.1f}x real time "
          f"(target {REALTIME_TARGET:g}x: {ratio / REALTIME_TARGET:.2f}x the target)")


@pytest.mark.benchmark(group="manipulator-control-poll")
@pytest.mark.parametrize("name", ["prototype", "sno"])
def test_control_poll_device_share(benchmark, tmp_path, name):
    """The device part of a poll alone: every Loadcell and Encoder read, every Motor's
    velocity set and polled (the floor under the control poll's Python, µs)."""
    station, runner = make_station(tmp_path, name)
    pa = station.polyaxis
    runner.call(pa.to, MOVES[name])
    runner.sleep(20.0)
    axes = pa.axes

    def devices():
        for a in axes:
            a.loadcell.tension()
            a.encoder.length()
            m = a.motor
            m.set_desired_velocity(m.velocity)
            m.poll()

    benchmark.pedantic(devices, rounds=2000, iterations=1, warmup_rounds=50)
    us = benchmark.stats.stats.median * 1e6
    low = benchmark.stats.stats.min * 1e6
    benchmark.extra_info.update(ropes=pa.n, median_us=round(us, 1), min_us=round(low, 1))
    print(f"\n{name}: device reads and motor polls alone {us:.1f} µs (min {low:.1f}) "
          f"for {pa.n} ropes")
    station.close()


@pytest.mark.benchmark(group="manipulator-control-poll")
@pytest.mark.parametrize("name", ["prototype", "sno"])
def test_control_poll_kernels(benchmark, tmp_path, name):
    """The numeric share of a poll alone: the two polyctl C calls through their wrapper
    (lengths, ring contacts, solve, net force; error signals, fuzzy), µs."""
    station, runner = make_station(tmp_path, name)
    pa = station.polyaxis
    runner.call(pa.to, MOVES[name])
    runner.sleep(20.0)
    ctl = pa._ctl
    tens, raw = list(pa.tensions), list(pa.estimator.encoder_lengths)
    hare, vel = pa.hare_position, [a.motor.velocity for a in pa.axes]
    lengths, el, et, want, free = ([0.0] * pa.n for _ in range(5))

    def kernels():
        ctl.measure(tens, raw, lengths)
        ctl.drive(hare, vel, 20.0, el, et, want, free)

    benchmark.pedantic(kernels, rounds=2000, iterations=1, warmup_rounds=50)
    us = benchmark.stats.stats.median * 1e6
    benchmark.extra_info.update(ropes=pa.n, median_us=round(us, 1))
    print(f"\n{name}: the two polyctl calls alone {us:.1f} µs for {pa.n} ropes")
    station.close()
