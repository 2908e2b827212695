"""Test clocks shared by the scheduler tests."""

from __future__ import annotations

from pyrt.scheduler.clock import Clock
from pyrt.testing import StallClock  # noqa: F401  (virtual time that can stall: pyrt's own)

MS = 1_000_000


class WorkClock(Clock):
    """A deterministic real-time stand-in: time moves at deadlines and when a task 'works'.

    It is not virtual, so the loop measures lateness, work and overruns on it
    exactly as on a wall clock; task durations are measured on it too.
    """

    virtual = False

    def __init__(self):
        self.now = 0
        self.timer = self.now_ns

    def now_ns(self) -> int:
        return self.now

    def wait_until(self, deadline_ns: int) -> None:
        self.now = max(self.now, deadline_ns)

    def work(self, ns: int) -> None:
        self.now += ns

