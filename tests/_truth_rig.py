"""Manipulator stations that start with the source at a chosen point (the truth tests)."""

from __future__ import annotations

import math
import re
from pathlib import Path

from _manipulator_rig import TICK_NS

from pyrt.db import copy_station
from pyrt.scheduler.runner import Runner
from pyrt.station.manipulator import ManipulatorStation

#: A station's endpoint tolerance: END_ERROR of its packaged POLYAXIS.dat.
TOLERANCE = {"prototype": 0.5, "sno": 1.0}


def station_at(tmp: Path, name: str, position: tuple[float, float, float], **kw
               ) -> tuple[ManipulatorStation, Runner]:
    """A working copy of packaged station ``name`` with its POSITION (the world's
    start and the controller's) at ``position``, built and started."""
    directory = copy_station(name, tmp)
    path = directory / "POLYAXIS.dat"
    text = path.read_text()
    x, y, z = position
    text, n = re.subn(r"^POSITION:.*$", f"POSITION: {x!r} {y!r} {z!r} // start",
                      text, count=1, flags=re.M)
    assert n == 1
    path.write_text(text)
    station = ManipulatorStation(directory, tick_ns=kw.pop("tick_ns", TICK_NS), **kw)
    runner = station.start()
    runner.sleep(0.2)
    return station, runner


def motors_still(station: ManipulatorStation) -> bool:
    """Every motor stopped: not stepping, no velocity."""
    return not station.motors_running() and all(a.motor.velocity == 0.0 for a in station.axes)


def true_error(station: ManipulatorStation, point) -> float:
    """Distance of the simulated source (the world's truth) from ``point`` (cm)."""
    return math.dist(station.plant.position, point)
