"""AXES (axis-poll): every axis under standalone control polled; every move supervised.

The manipulator's second routine: :meth:`pyrt.robots.axis.Axis.poll` (the
STEP_MODE control of ``axis1 up 5`` and the like, the Motor, the Encoder)
for every axis that is not driven by its PolyAxis; an axis under PolyAxis
control is polled by polyaxis-poll instead.

Then, while any motor runs (a PolyAxis move, an axis move, a pattern, a
motion plug-in: whatever drives it), every axis is supervised
(:meth:`pyrt.robots.axis.Axis.supervise`: loadcell alive, length inside the
rope's physical range, encoder following the motor, tensions inside their
limits).  The first axis that objects fails the robot with its reason
(:meth:`pyrt.component.Component.fail`): the station stops every motor in
this tick.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol

__all__ = ["ADDRESS", "NAME", "POLYAXIS", "STANDALONE", "PolledAxis", "axis_poll", "supervise"]

#: The routine's address on the manipulator's ready queue, and its name there.
ADDRESS = 0x0101
NAME = "AXES"

#: An axis's ``mode``: driven by its PolyAxis, or on its own (Table 4 commands).
POLYAXIS = "polyaxis"
STANDALONE = "standalone"


class PolledAxis(Protocol):
    """An axis as axis-poll sees it."""

    mode: str
    motor: Any

    def poll(self, now_s: float) -> None: ...

    def supervise(self, now_s: float, standalone_move: bool) -> str | None: ...

    def fail(self, cause: str, source: str = "") -> None: ...


def axis_poll(axes: Sequence[PolledAxis], now_ns: int) -> None:
    """Poll every axis of ``axes`` not under PolyAxis control, then supervise
    every axis while a motor runs, at the tick time ``now_ns``."""
    now_s = now_ns * 1e-9
    for a in axes:
        if a.mode != POLYAXIS:
            a.poll(now_s)
    supervise(axes, now_s)


def supervise(axes: Sequence[PolledAxis], now_s: float) -> str | None:
    """Supervise every axis while any motor runs; the first objection fails the
    robot (every motor stopped) and is returned."""
    running = False
    standalone = False
    for a in axes:
        if a.motor.running:
            running = True
            if a.mode != POLYAXIS:
                standalone = True
    if not running:
        return None
    for a in axes:
        why = a.supervise(now_s, standalone)
        if why is not None:
            a.fail(why)
            return why
    return None
