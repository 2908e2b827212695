"""What the tests of pyrt urdf share: one PUMA station on simulated time, a pose from
mm and degrees, and the wait for a move to end."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from pyrt.kinematics import transform
from pyrt.scheduler import Loop, SimClock
from pyrt.station.urdf import UrdfStation, build_urdf


def puma_station() -> Iterator[tuple[UrdfStation, object]]:
    """A PUMA station on simulated time, powered and holding its start pose (a
    fixture's body: ``yield from puma_station()``); closed afterwards."""
    station = build_urdf(Loop(SimClock()))
    runner = station.start()
    assert runner.wait_until(lambda: station.arm.powered and not station.busy(), 5.0)
    yield station, runner
    station.close()


def target(x, y, z, rx, ry, rz) -> np.ndarray:
    """The pose at (x, y, z) mm with URDF rpy (rx, ry, rz) degrees."""
    return transform(np.array([x, y, z]) * 1e-3, np.radians([rx, ry, rz]))


def settle(station, runner) -> None:
    """Wait (simulated time) until the station's move has ended."""
    assert runner.wait_until(lambda: not station.busy(), 60.0), "the move never ended"
