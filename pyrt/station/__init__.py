"""Assembling a runnable station: databases, boards, physics, devices, robots, tasks, loop."""

from pyrt.station.manipulator import (
    AXIS_POLL_S,
    POLL_S,
    TICK_NS,
    ManipulatorStation,
)

__all__ = ["AXIS_POLL_S", "POLL_S", "TICK_NS", "ManipulatorStation"]
