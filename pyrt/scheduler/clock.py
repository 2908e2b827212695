"""Clocks the tick loop runs against.

A clock answers two questions: what time is it (``now_ns``), and "return
when this deadline has come" (``wait_until``).  Times are integers in
nanoseconds of the *loop's* time base, so the same control code runs on
virtual time (:class:`SimClock`) or real time (:class:`WallClock`).  The
loop starts every tick with :meth:`Clock.start_tick`: the clocks differ in
how they wait, never in what a tick does.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable

from pyrt.scheduler.rt import set_timer_slack

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

    def moving(self, busy: bool) -> None:
        """Whether a robot moves now (the station says so when it changes): a
        real-time clock may wait more precisely while one does.  Nothing here."""

    def start_tick(self, deadline_ns: int) -> int:
        """Wait for a tick's deadline; return the tick's start time (on real
        time, the moment the wait ended: the deadline plus the lateness)."""
        self.wait_until(deadline_ns)
        return self.now_ns()


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

    def start_tick(self, deadline_ns: int) -> int:
        """Move to the deadline (never backward); a tick starts exactly on it."""
        if deadline_ns > self._now:
            self._now = deadline_ns
        return deadline_ns

    def advance(self, dt_ns: int) -> None:
        """Move virtual time forward by ``dt_ns`` (never backward)."""
        if dt_ns < 0:
            raise ValueError(f"SimClock cannot go backward (dt_ns={dt_ns})")
        self._now += dt_ns


class WallClock(Clock):
    """Real time from ``time.monotonic_ns``, optionally scaled by ``speed``.

    ``wait_until`` sleeps to an *absolute* deadline, then spins the last
    stretch so that the sleep's wake-up error does not become lateness.  The
    spin window adapts to the wake-up error it measures (a decaying maximum
    of how late the sleeps woke, plus ``SPIN_MARGIN_NS``, within
    ``0..spin_ns``): short when the timer is accurate, so an idle loop costs
    little CPU, and as long as the timer needs when it is not.  A fixed
    window is ``adaptive=False`` (``spin_ns`` each tick, the old behaviour).

    ``timer_slack_ns`` (Linux): the loop thread's timer slack
    (``PR_SET_TIMERSLACK``; the kernel's default is 50 µs), set from the thread
    that waits, the first time it waits.  1 makes sleeps wake within a few
    µs, and the adaptive spin shrinks with it.

    ``spin`` says when the last stretch is spun: ``"moving"`` (the default)
    only while a robot moves (:meth:`moving`, which the station calls when its
    robots start and stop), sleeping to the deadline itself while they are
    all at rest, when a tick started a wake-up later costs nothing but keeps
    an idle controller from holding a core; ``"always"``; ``"never"``.

    With ``speed`` N the loop's time runs N times faster than the wall
    (``--speed N``): a 1 ms tick then lasts 1/N ms of real time.
    """

    #: The spin policies (see the class text).
    SPIN_POLICIES = ("moving", "always", "never")

    virtual = False

    #: Added to the measured wake-up error to make the spin window.
    SPIN_MARGIN_NS = 10_000
    #: Each sleep, the remembered wake-up error decays by this factor (a
    #: preemption's long wake-up is forgotten within a few hundred ticks).
    DECAY = 0.99

    def __init__(self, speed: float = 1.0, spin_ns: int = 200_000, *, adaptive: bool = True,
                 timer_slack_ns: int | None = None, spin: str = "moving"):
        if not speed > 0:
            raise ValueError(f"speed must be positive, got {speed!r}")
        if spin_ns < 0:
            raise ValueError(f"spin_ns must be >= 0, got {spin_ns!r}")
        if timer_slack_ns is not None and timer_slack_ns < 1:
            raise ValueError(f"timer_slack_ns must be >= 1, got {timer_slack_ns!r}")
        if spin not in self.SPIN_POLICIES:
            raise ValueError(f"spin must be one of {', '.join(self.SPIN_POLICIES)}, "
                             f"got {spin!r}")
        self.speed = float(speed)
        self.spin_ns = int(spin_ns)
        self.spin = spin
        #: Whether the waits spin now (the policy, and while "moving" whether one does).
        self.spinning = spin == "always"
        self.adaptive = adaptive
        self.timer_slack_ns = timer_slack_ns
        self._slack_set_in: int | None = None
        #: The wake-up error the spin window covers now (ns; decaying maximum).
        self.wake_error_ns = float(spin_ns)
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

    def moving(self, busy: bool) -> None:
        """A robot moves (``busy``) or every robot is at rest: under the
        ``"moving"`` policy the waits spin from the next one on, or stop spinning."""
        if self.spin == "moving":
            self.spinning = bool(busy)

    @property
    def spin_window_ns(self) -> int:
        """How long before a deadline the sleep ends and the spin begins (0 while
        the policy says not to spin now)."""
        if not self.spinning:
            return 0
        if not self.adaptive:
            return self.spin_ns
        return min(self.spin_ns, int(self.wake_error_ns) + self.SPIN_MARGIN_NS)

    def start_tick(self, deadline_ns: int) -> int:
        """Wait for a tick's deadline and return its start.  At rest (the
        policy does not spin now) this is one ``clock_nanosleep`` to the
        deadline between two reads of the clock, and the second read is the
        tick's start: an idle loop wakes once a tick and does nothing else
        to wait.  While it spins, :meth:`wait_until` (sleep, then spin)."""
        if self.spinning or (self.timer_slack_ns is not None
                             and self._slack_set_in != threading.get_ident()):
            self.wait_until(deadline_ns)
            return self.now_ns()
        mono = time.monotonic_ns
        target = self.wall_deadline(deadline_ns) if self._scaled else self._wall0 + deadline_ns
        now = mono()
        if now < target:
            time.sleep((target - now) / 1e9)
            now = mono()
            while now < target:  # a sleep never ends early; a rounding might
                now = mono()
            if self.adaptive:
                # what a spin would have had to cover, as wait_until keeps it
                error = now - target
                decayed = self.wake_error_ns * self.DECAY
                self.wake_error_ns = error if decayed < error <= self.spin_ns else decayed
        if self._scaled:
            return int((now - self._wall0) * self.speed)
        return now - self._wall0

    def wait_until(self, deadline_ns: int) -> None:
        if self.timer_slack_ns is not None and self._slack_set_in != threading.get_ident():
            self._slack_set_in = threading.get_ident()
            # where it cannot be set (not Linux) the option has said so at
            # start-up; the loop runs on with the default slack
            with contextlib.suppress(OSError):
                set_timer_slack(self.timer_slack_ns)
        target = self.wall_deadline(deadline_ns)
        mono = time.monotonic_ns
        spin = self.spin_window_ns
        wake = target - spin
        remaining = wake - mono()
        if remaining > 0:
            time.sleep(remaining / 1e9)
            if self.adaptive:
                error = mono() - wake
                decayed = self.wake_error_ns * self.DECAY
                # a wake-up later than the whole window is a preemption,
                # which no spin can hide: it does not widen the window
                if decayed < error <= self.spin_ns:
                    self.wake_error_ns = error
                else:
                    self.wake_error_ns = decayed
        while mono() < target:
            pass

