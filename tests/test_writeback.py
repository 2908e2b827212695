"""Database write-back task: cadence on simulated time, ZEROLENGTH semantics, writers."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pyrt.db import Station, UnknownNameError, copy_station, load_station
from pyrt.errors import ConfigError, QueueFullError
from pyrt.scheduler import Loop, ReadyQueue, SimClock
from pyrt.tasks import SyncWriter, ThreadWriter, WriteBack
from pyrt.tasks import __all__ as tasks_all

S = 1_000_000_000
MS = 1_000_000


@pytest.fixture
def station(tmp_path: Path) -> Station:
    return load_station(copy_station("prototype", tmp_path / "st"))


class Rope:
    """A stand-in value source: a length that moves at ``speed`` cm/s when moving."""

    def __init__(self, length: float):
        self.length = length
        self.moving = False
        self.speed = 0.0
        self.creep = 0.0  # change while "stationary" (settling), cm per step

    def step(self, dt_s: float) -> None:
        if self.moving:
            self.length += self.speed * dt_s
        else:
            self.length += self.creep

    def read(self) -> tuple[float, bool]:
        return self.length, self.moving


def _times(wb: WriteBack, key: str) -> list[float]:
    return [t / S for t, _, _, k, _ in wb.history if k == key]


def test_exports_sorted() -> None:
    """pyrt.tasks exports its names isort-style (as ruff keeps them)."""
    assert list(tasks_all) == sorted(tasks_all, key=lambda n: (
        0 if n.isupper() else 1 if n[0].isupper() else 2, n))


def test_length_written_every_second_moving_and_ten_seconds_stationary(
        station: Station) -> None:
    """LENGTH goes to the file every 1 s while moving and every 10 s while stationary."""
    rope = Rope(station.axis("axis0").length)
    wb = WriteBack(station, SyncWriter(station))
    wb.watch_length("axis0", rope.read)
    t = 0
    rope.moving, rope.speed = True, 2.0
    while t <= 5 * S:  # 10 ms polls for 5 s of moving
        wb.poll(t)
        t += 10 * MS
        rope.step(0.01)
    rope.moving, rope.creep = False, 1e-4
    while t <= 40 * S:
        wb.poll(t)
        t += 10 * MS
        rope.step(0.01)
    times = _times(wb, "LENGTH")
    # t = 0 holds the file's value (nothing to write); then once a second
    assert times[:5] == [1.0, 2.0, 3.0, 4.0, 5.0]
    # the last moving poll (5 s) scheduled the next at 6 s; from then 10 s apart
    assert times[5:] == [6.0, 16.0, 26.0, 36.0]
    on_disk = load_station(station.directory).axis("axis0").length
    assert on_disk == pytest.approx(wb.history[-1][4], abs=1e-9)


def test_unchanged_stationary_value_is_not_rewritten(station: Station) -> None:
    """A stationary rope whose length does not change costs no write at all."""
    before = station.path("AXIS").read_bytes()
    writer = SyncWriter(station)
    wb = WriteBack(station, writer)
    wb.watch_length("axis1", lambda: (station.axis("axis1").length, False))
    for t in range(0, 60 * S, 100 * MS):
        wb.poll(t)
    assert writer.batches == 0 and not wb.history
    assert station.path("AXIS").read_bytes() == before


def test_position_written_from_numpy_vector(station: Station) -> None:
    """POSITION accepts a numpy vector and is written with the file's decimals."""
    pos = np.array([-0.199943, 0.0, 95.569618419])
    state = {"moving": True}
    wb = WriteBack(station, SyncWriter(station))
    wb.watch_position("prototype", lambda: (pos, state["moving"]))
    wb.poll(0)  # equal to the file: nothing
    assert not wb.history
    pos[2] = 100.25
    wb.poll(1 * S)
    assert load_station(station.directory).polyaxis().position == (-0.199943, 0.0, 100.25)
    assert "POSITION: -0.199943 0.000000 100.250000000 // last known position" in \
        station.path("POLYAXIS").read_text()


def test_zerolength_follows_current_length_while_changing(station: Station) -> None:
    """ZEROLENGTH takes the encoder's current length once a second while it
    changes, and is not written while it stays put; a restart starts from it."""
    enc = {"length": 747.04541}
    wb = WriteBack(station, SyncWriter(station))
    wb.watch_zerolength("encoder0", lambda: enc["length"])
    t = 0
    while t <= 3 * S:  # paying out 1 cm/s for 3 s
        wb.poll(t)
        t += 10 * MS
        enc["length"] += 0.01
    moving_times = _times(wb, "ZEROLENGTH")
    assert moving_times == [1.0, 2.0, 3.0]  # t = 0 equals the file
    last = enc["length"]
    while t <= 30 * S:  # stopped
        wb.poll(t)
        t += 10 * MS
    assert _times(wb, "ZEROLENGTH") == [1.0, 2.0, 3.0, 4.0]  # picks up the final length
    restarted = load_station(station.directory).encoder("encoder0")
    assert restarted.zerolength == pytest.approx(last, abs=1e-6)


def test_loadcell_calibration_written_once(station: Station) -> None:
    """A calibration's SLOPE and OFFSET (and DATE) are written in one batch."""
    writer = SyncWriter(station)
    wb = WriteBack(station, writer)
    wb.loadcell_calibrated("LOADCELL2", 0.7, -490.5, date="22-11-2026")
    assert writer.batches == 1
    c = load_station(station.directory).loadcell("loadcell2")
    assert (c.slope, c.offset, c.date) == (0.7, -490.5, "22-11-2026")


def test_watch_refuses_unknown_and_unwritable(station: Station) -> None:
    """Watching a missing object, a key that is not written back, or one twice is refused."""
    wb = WriteBack(station, SyncWriter(station))
    with pytest.raises(UnknownNameError):
        wb.watch_length("axis9", lambda: (1.0, False))
    with pytest.raises(ValueError, match="not a written-back key"):
        wb.watch("AXIS", "axis0", "DEADLENGTH", lambda: (1.0, False), S, S)
    wb.watch_length("axis0", lambda: (1.0, False))
    with pytest.raises(ValueError, match="already watched"):
        wb.watch_length("AXIS0", lambda: (1.0, False))
    with pytest.raises(ValueError, match="positive"):
        WriteBack(station, SyncWriter(station), moving_period_ns=0)


def test_runs_as_ready_queue_routine_on_sim_clock(station: Station) -> None:
    """Scheduled on a ready queue in a SimClock loop, the task writes on the loop's time."""
    clock = SimClock()
    loop = Loop(clock, period_ns=1 * MS)
    rq = ReadyQueue(capacity=4, divisor=10, name="manipulator")
    rope = Rope(station.axis("axis1").length)
    rope.moving, rope.speed = True, -1.0
    loop.attach(lambda now: rope.step(0.001), name="plant")
    loop.attach(rq)
    wb = WriteBack(station, SyncWriter(station))
    wb.watch_length("axis1", rope.read)
    wb.attach(rq, 0x0100, period=10)  # every 10 checks of 10 ticks: 100 ms
    loop.run(ticks=3500)
    times = _times(wb, "LENGTH")
    # first run at the 10th check (100 ms), then once a simulated second
    assert times == pytest.approx([0.1, 1.1, 2.1, 3.1])
    assert load_station(station.directory).axis("axis1").length == pytest.approx(
        wb.history[-1][4], abs=1e-9)


def test_thread_writer_writes_off_the_tick_and_coalesces(station: Station) -> None:
    """The background writer puts the latest value of each key on disk."""
    writer = ThreadWriter(station)
    try:
        for i in range(50):
            writer.submit({("AXIS", "axis0", "LENGTH"): 300.0 + i})
        writer.flush(timeout=30)
        assert load_station(station.directory).axis("axis0").length == 349.0
        assert 1 <= writer.batches <= 50
    finally:
        writer.close()
    with pytest.raises(ConfigError, match="closed"):
        writer.submit({("AXIS", "axis0", "LENGTH"): 1.0})


def test_thread_writer_reports_failure_at_next_call(station: Station) -> None:
    """A write the thread could not do is raised at the next submit or flush."""
    writer = ThreadWriter(station)
    try:
        writer.submit({("AXIS", "axis0", "LENGTH"): float("nan")})
        with pytest.raises(ConfigError, match="write-back failed"):
            writer.flush(timeout=30)
        writer.submit({("AXIS", "axis0", "LENGTH"): 310.0})
        writer.flush(timeout=30)
        assert load_station(station.directory).axis("axis0").length == 310.0
    finally:
        writer.close()


def test_thread_writer_bounds_pending_keys(station: Station) -> None:
    """More distinct pending keys than the bound raises QueueFullError."""
    writer = ThreadWriter(station, max_pending=2)
    try:
        big: dict[Any, float] = {("AXIS", f"axis{i}", "LENGTH"): 1.0 for i in range(3)}
        with pytest.raises(QueueFullError):
            writer.submit(big)
    finally:
        writer.close()


def test_refused_value_raises_from_poll_and_is_retried(station: Station) -> None:
    """A value the database refuses raises from poll (the queue would fault)
    and is offered again when next due, once it is valid."""
    src = {"length": -1.0}
    wb = WriteBack(station, SyncWriter(station))
    wb.watch_length("axis0", lambda: (src["length"], True))
    with pytest.raises(ConfigError, match=">= 0"):
        wb.poll(0)
    assert not wb.history
    src["length"] = 250.0
    assert wb.poll(500 * MS) == 0  # not due yet
    assert wb.poll(1 * S) == 1
    assert load_station(station.directory).axis("axis0").length == 250.0
