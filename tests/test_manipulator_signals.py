"""The manipulator's signals sampled where the tick keeps them: each sampled value is its read()."""

from __future__ import annotations

import math
import struct

import pytest
from _manipulator_rig import make_station

from pyrt.scope import compile_sources
from pyrt.scope.sources import compile_sampler
from pyrt.station.blackbox import SignalRing


def _same(a: object, b: object) -> bool:
    return a == b or (isinstance(a, float) and isinstance(b, float)
                      and math.isnan(a) and math.isnan(b))


def _check(station) -> int:
    """In the loop thread: every numeric signal's scope source, compiled as the scope and
    the black box compile them, gives its read(); the black box's ring row too.
    The number of signals checked."""
    named = [(n, s) for n, s in station.signals() if not s.is_text]
    names = [n for n, _ in named]
    sources = [s.scope_source() for _, s in named]
    reads = [s.read() for _, s in named]
    got = compile_sources(sources)()
    bad = [(n, g, r) for n, g, r in zip(names, got, reads, strict=True) if not _same(g, r)]
    assert not bad, f"sampled != read(): {bad}"
    packer = struct.Struct("<q" + "d" * len(sources))
    buf = bytearray(packer.size)
    compile_sampler(sources, packer.pack_into)(buf, 0, 123)
    packed = packer.unpack(buf)
    assert packed[0] == 123
    bad = [n for n, p, r in zip(names, packed[1:], reads, strict=True)
           if not _same(p, float(r))]
    assert not bad, f"packed != float(read()): {bad}"
    # the black box's ring, its text signals left out of the window
    every = station.signals()
    ring = SignalRing(every, 1.0, station.loop.period_ns)
    ring.sample(456)
    t, v, cols = ring.window(ring.samples)
    assert list(t) == [456]
    row = {every[c][0]: x for c, x in zip(cols, v[0], strict=True)}
    assert set(row) == set(names)
    bad = [n for n, r in zip(names, reads, strict=True) if not _same(row[n], float(r))]
    assert not bad, f"black box row != read(): {bad}"
    return len(named)


@pytest.fixture
def proto(tmp_path):
    station, runner = make_station(tmp_path)
    yield station, runner
    station.close()


def test_every_signal_samples_its_read_at_rest(proto):
    """At rest every numeric signal (the estimate, the axes, the devices, the world's truth)
    samples exactly what its read() gives."""
    station, runner = proto
    n = runner.call(_check, station)
    names = {name for name, s in station.signals() if not s.is_text}
    assert n >= 40
    assert {"prototype.x", "axis0.tension", "axis0Motor.running", "axis0Encoder.length",
            "axis0Loadcell.tension", "sim.x", "sim.tension2"} <= names


def test_every_signal_samples_its_read_in_an_axis_move(proto):
    """During and after a standalone axis move (a motor stepping, the encoder counting)
    every sampled value is its read()."""
    station, runner = proto
    runner.call(station.find("axis0").cmd_down, 0.4)  # the central rope: 35 -> ~20 N
    for _ in range(6):
        runner.sleep(0.07)
        assert runner.call(lambda: station.axes[0].motor.running)
        runner.call(_check, station)
    assert runner.wait_until(lambda: not station.busy(), 60.0)
    runner.call(_check, station)


def test_every_signal_samples_its_read_in_a_polyaxis_move(proto):
    """During a PolyAxis move (every rope under velocity control, the error signals
    live) and when it has stopped, every sampled value is its read()."""
    station, runner = proto
    pa = station.polyaxis
    x, y, z = pa.position
    runner.call(pa.to, (x, y, z + 5.0))
    for _ in range(6):
        runner.sleep(0.21)
        assert runner.call(lambda: pa.active)
        runner.call(_check, station)
    runner.call(station.stop)
    runner.call(_check, station)
