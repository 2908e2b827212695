"""AXES (axis-poll): every axis under standalone control, polled.

The manipulator's second routine: :meth:`pyrt.robots.axis.Axis.poll` (the
STEP_MODE control of ``axis1 up 5`` and the like, the Motor, the Encoder)
for every axis that is not driven by its PolyAxis; an axis under PolyAxis
control is polled by polyaxis-poll instead.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Protocol

__all__ = ["ADDRESS", "NAME", "POLYAXIS", "STANDALONE", "PolledAxis", "axis_poll"]

#: The routine's address on the manipulator's ready queue, and its name there.
ADDRESS = 0x0101
NAME = "AXES"

#: An axis's ``mode``: driven by its PolyAxis, or on its own (Table 4 commands).
POLYAXIS = "polyaxis"
STANDALONE = "standalone"


class PolledAxis(Protocol):
    """An axis as axis-poll sees it."""

    mode: str

    def poll(self, now_s: float) -> None: ...


def axis_poll(axes: Iterable[PolledAxis], now_ns: int) -> None:
    """Poll every axis of ``axes`` not under PolyAxis control, at the tick time ``now_ns``."""
    now_s = now_ns * 1e-9
    for a in axes:
        if a.mode != POLYAXIS:
            a.poll(now_s)
