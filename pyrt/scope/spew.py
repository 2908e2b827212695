"""Spew (004): hand the current values of some sources to a subscriber at a fixed rate."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

from pyrt.scope.sources import Source, compile_sources

__all__ = ["MAX_SPEW_HZ", "MIN_SPEW_HZ", "Spew"]

#: The slowest spew: one sample every 100 s (a slower one would wait for ever,
#: and its interval, in ns, would overflow long before the rate reaches 0).
MIN_SPEW_HZ = 0.01
#: The fastest spew.
MAX_SPEW_HZ = 10_000.0


class Spew:
    """A loop handler that calls ``callback(now_ns, values)`` every
    ``1/hz`` seconds of loop time with the values of ``sources``.

    The callback runs in the loop thread: it must only hand the values on
    (append to a bounded queue), never block.
    """

    def __init__(
        self,
        names: Sequence[str],
        sources: Sequence[Source],
        hz: float,
        callback: Callable[[int, tuple], None],
    ):
        if len(names) != len(sources):
            raise ValueError("one name per source")
        if not (isinstance(hz, (int, float)) and math.isfinite(hz)
                and MIN_SPEW_HZ <= hz <= MAX_SPEW_HZ):
            raise ValueError(f"spew rate must be {MIN_SPEW_HZ:g} <= hz <= {MAX_SPEW_HZ:g}, "
                             f"got {hz!r}")
        self.names = tuple(names)
        self.hz = float(hz)
        self.interval_ns = int(1e9 / hz)
        self._read = compile_sources(sources)
        self._callback = callback
        self._next: int | None = None
        self.active = True

    def __call__(self, now_ns: int) -> None:
        if not self.active:
            return
        if self._next is None:
            self._next = now_ns
        if now_ns >= self._next:
            # Never burst after a pause: the next one is a whole interval on.
            self._next = max(self._next + self.interval_ns, now_ns + 1)
            self._callback(now_ns, self._read())
