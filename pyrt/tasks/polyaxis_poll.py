"""POLYAXIS (polyaxis-poll): the PolyAxis's co-ordinated control poll (000, section 5).

A declared task and nothing more: the poll, its order and its steps are the
controller's (:meth:`pyrt.robots.polyaxis.PolyAxis.poll`; the order is in
:mod:`pyrt.robots.polyaxis`).  The routine reschedules itself with a period
in queue checks; the time it hands the poll is the queue's tick time.
"""

from __future__ import annotations

from typing import Protocol

__all__ = ["ADDRESS", "NAME", "PolledPolyAxis", "polyaxis_poll"]

#: The routine's address on the manipulator's ready queue, and its name there.
ADDRESS = 0x0100
NAME = "POLYAXIS"


class PolledPolyAxis(Protocol):
    """A PolyAxis as polyaxis-poll sees it: something that polls at a time."""

    def poll(self, now_s: float) -> None: ...


def polyaxis_poll(pa: PolledPolyAxis, now_ns: int) -> None:
    """The routine: one control poll of ``pa`` at the tick time ``now_ns``."""
    pa.poll(now_ns * 1e-9)
