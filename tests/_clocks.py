"""Test clocks shared by the scheduler tests."""

from __future__ import annotations

from pyrt.scheduler.clock import Clock, SimClock

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


class StallClock(SimClock):
    """Virtual time that can stall: :meth:`stall` makes the next tick start that much
    after its deadline and every later one with it (the deadlines passed meanwhile
    skipped, never run back to back), as a loop that stalled on a loaded machine.
    Deterministic like a SimClock; the handlers see the time that really passed."""

    offset = 0

    def stall(self, ns: int) -> None:
        """The loop stalls ``ns`` before its next tick."""
        self.offset += int(ns)

    def now_ns(self) -> int:
        return super().now_ns() + self.offset

    def start_tick(self, deadline_ns: int) -> int:
        return super().start_tick(deadline_ns) + self.offset
