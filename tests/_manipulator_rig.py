"""A manipulator station on simulated time for the PolyAxis and console tests."""

from __future__ import annotations

from pathlib import Path

from pyrt.db import copy_station
from pyrt.scheduler.runner import Runner
from pyrt.station.manipulator import ManipulatorStation

#: The tests' base tick: 5 ms (the physics at 200 Hz, the 50 ms control poll
#: is 10 ticks); see pyrt/station/manipulator.py (ManipulatorFactory) for why this keeps the numbers.
TICK_NS = 5_000_000


def make_station(tmp: Path, name: str = "prototype", **kw) -> tuple[ManipulatorStation, Runner]:
    """A working copy of packaged station ``name`` in ``tmp``, built and started."""
    directory = copy_station(name, tmp / name)
    station = ManipulatorStation(directory, tick_ns=kw.pop("tick_ns", TICK_NS), **kw)
    runner = station.start()
    runner.sleep(0.2)
    return station, runner


def read_log(path: Path) -> dict[str, list[list[str]]]:
    """The log's lines grouped by their first word."""
    out: dict[str, list[list[str]]] = {}
    for line in path.read_text().splitlines():
        parts = line.split()
        if parts and not parts[0].startswith("#"):
            out.setdefault(parts[0], []).append(parts)
    return out


def move(station: ManipulatorStation, runner: Runner, target, timeout_s: float = 900.0):
    """``to`` and wait for the move to end; returns the stop record."""
    runner.call(station.polyaxis.to, target)
    assert runner.wait_until(lambda: not station.polyaxis.active, timeout_s)
    return station.polyaxis.last_stop
