"""Clocks the tick loop runs against.

A clock answers two questions: what time is it (``now_ns``), and "return
when this deadline has come" (``wait_until``).  Times are integers in
nanoseconds of the *loop's* time base, so the same control code runs on
virtual time (:class:`SimClock`) or real time (:class:`WallClock`).
"""

from __future__ import annotations

import time
from collections.abc import Callable

__all__ = ["Clock", "SimClock", "WallClock"]


class Clock:
    """Interface of the loop's clocks."""

    #: True when time only moves because the loop moves it.
    virtual: bool = False

    #: Measures execution times (ns) of tasks: the CPU's fastest monotonic counter.
    timer: Callable[[], int] = staticmethod(time.perf_counter_ns)

    def now_ns(self) -> int:  # pragma: no cover - interface
        """Current time in nanoseconds."""
        raise NotImplementedError

    def wait_until(self, deadline_ns: int) -> None:  # pragma: no cover - interface
        """Return once ``now_ns() >= deadline_ns``."""
        raise NotImplementedError


class SimClock(Clock):
    """Virtual time: it stands still until the loop moves it to a deadline.

    Deterministic and as fast as the CPU allows; every test of control
    behaviour runs on it.  Work done inside a tick takes no virtual time, so a
    SimClock loop never overruns.
    """

    virtual = True

    def __init__(self, start_ns: int = 0):
        self._now = int(start_ns)

    def now_ns(self) -> int:
        return self._now

    def wait_until(self, deadline_ns: int) -> None:
        if deadline_ns > self._now:
            self._now = deadline_ns

    def advance(self, dt_ns: int) -> None:
        """Move virtual time forward by ``dt_ns`` (never backward)."""
        if dt_ns < 0:
            raise ValueError(f"SimClock cannot go backward (dt_ns={dt_ns})")
        self._now += dt_ns


class WallClock(Clock):
    """Real time from ``time.monotonic_ns``, optionally scaled by ``speed``.

    ``wait_until`` sleeps to an *absolute* deadline and spins the last
    ``spin_ns`` (default 200 µs) so that the sleep's wake-up jitter does not
    become lateness.  With ``speed`` N the loop's time runs N times faster
    than the wall (``--speed N``): a 1 ms tick then lasts 1/N ms of real time.
    """

    virtual = False

    def __init__(self, speed: float = 1.0, spin_ns: int = 200_000):
        if not speed > 0:
            raise ValueError(f"speed must be positive, got {speed!r}")
        if spin_ns < 0:
            raise ValueError(f"spin_ns must be >= 0, got {spin_ns!r}")
        self.speed = float(speed)
        self.spin_ns = int(spin_ns)
        self._wall0 = time.monotonic_ns()
        self._scaled = self.speed != 1.0

    def now_ns(self) -> int:
        if self._scaled:
            return int((time.monotonic_ns() - self._wall0) * self.speed)
        return time.monotonic_ns() - self._wall0

    def wall_deadline(self, deadline_ns: int) -> int:
        """The ``time.monotonic_ns`` value at which loop time ``deadline_ns`` comes."""
        if self._scaled:
            return self._wall0 + int(deadline_ns / self.speed)
        return self._wall0 + deadline_ns

    def wait_until(self, deadline_ns: int) -> None:
        target = self.wall_deadline(deadline_ns)
        mono = time.monotonic_ns
        remaining = target - mono()
        if remaining > self.spin_ns:
            time.sleep((remaining - self.spin_ns) / 1e9)
        while mono() < target:
            pass
