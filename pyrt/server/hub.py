"""The server's one handler in the loop: the status snapshot, subscriptions, faults.

The server runs outside the loop; the loop hands values on to it, as the
scope's spew does (004), and never waits for it:

* every ``snapshot_every`` ticks the hub reads the robot's status sources
  (one compiled getter) and publishes ``(time_ns, tick, values)`` as one
  immutable tuple; a ``STATUS`` request is answered from it, so a DAQ
  polling status thousands of times a second adds no mailbox traffic and
  no work to the tick beyond that one read;
* each ``SUBSCRIBE`` is a :class:`~pyrt.scope.Spew` whose callback appends
  the sample to a bounded deque (an atomic append, never a block);
* a fault is appended to the same deque the moment the loop records it,
  and so is the end of every move (the station's move-ended event) and
  every message of the station's components.

The server's I/O thread drains the deque and formats the lines.  The list
of spews is replaced whole (copy on write) by the server thread and read
once per tick by the loop thread: a reference swap, no lock in the tick.
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Sequence
from typing import Any

from pyrt.errors import Fault
from pyrt.scope import Source, Spew, compile_sources

__all__ = ["StatusHub"]

#: Events (samples and faults) waiting for the I/O thread; beyond this the
#: oldest are dropped (the I/O thread has stalled for seconds).
EVENT_CAPACITY = 65536

_mono = time.monotonic_ns


def _safe(source: Source) -> Any:
    try:
        return source.read()
    except Exception:
        return math.nan


class StatusHub:
    """Loop handler: publish status snapshots, run the subscriptions' spews.

    Attach it to the loop (``loop.attach(hub, name="server")``) before the
    loop runs, and add :meth:`on_fault` to ``loop.fault_listeners``.
    """

    def __init__(
        self,
        names: Sequence[str],
        sources: Sequence[Source],
        *,
        snapshot_every: int = 1,
        extra_sources: Sequence[Source] = (),
        extra_every: int = 100,
    ):
        if snapshot_every < 1 or extra_every < 1:
            raise ValueError(f"snapshot_every and extra_every must be >= 1, got "
                             f"{snapshot_every}, {extra_every}")
        if len(names) != len(sources):
            raise ValueError("one name per status source")
        self.names = tuple(names)
        self.sources = tuple(sources)
        self._read = compile_sources(self.sources)
        self.snapshot_every = int(snapshot_every)
        self._count = 0
        self._tick = 0
        #: ``(time_ns, tick, values)`` of the latest snapshot; values None before the first.
        self.snapshot: tuple[int, int, tuple | None] = (0, -1, None)
        #: ``("sample", key, time_ns, values)``, ``("fault", None, time_ns, fault)``,
        #: ``("stop", None, time_ns, move_ended)`` and ``("message", None, 0, message)``.
        self.events: deque[tuple[str, Any, int, Any]] = deque(maxlen=EVENT_CAPACITY)
        self._spews: tuple[tuple[Any, Spew], ...] = ()
        #: ``time.monotonic_ns()`` when the loop last ran this handler: where
        #: the server's threads read the loop's tick phase (to stand aside).
        self.tick_wall_ns = 0
        #: The latest fault the loop recorded (None before the first).
        self.last_fault: Fault | None = None
        #: The latest move-ended event (None before the first move ended).
        self.last_move: Any = None
        #: More values (EPICS's per-device PVs), read every ``extra_every``
        #: ticks only while :attr:`extras_wanted` (a bool the server side sets).
        self.extra_sources = tuple(extra_sources)
        self._read_extra = compile_sources(self.extra_sources) if self.extra_sources else None
        self.extra_every = int(extra_every)
        self.extras_wanted = False
        self._extra_count = 0
        #: ``(time_ns, values)`` of the latest extra sample; values None before the first.
        self.extra_snapshot: tuple[int, tuple | None] = (0, None)

    # -- the loop side -------------------------------------------------------------

    def __call__(self, now_ns: int) -> None:
        self.tick_wall_ns = _mono()
        tick = self._tick
        self._tick = tick + 1
        self._count += 1
        if self._count >= self.snapshot_every:
            self._count = 0
            self.snapshot = (now_ns, tick, self._read())
        for _key, spew in self._spews:
            spew(now_ns)
        if self.extras_wanted:
            self._extra_count -= 1
            if self._extra_count <= 0:
                self._extra_count = self.extra_every
                self.extra_snapshot = (now_ns, self._extras())

    def _extras(self) -> tuple | None:
        """Every extra value; one that cannot be read is NaN (the tick goes on)."""
        read = self._read_extra
        if read is None:
            return ()
        try:
            return read()
        except Exception:
            return tuple(_safe(s) for s in self.extra_sources)

    def on_fault(self, fault: Fault) -> None:
        """Fault listener (loop thread): push the fault to the subscribers."""
        self.last_fault = fault
        self.events.append(("fault", None, fault.time_ns, fault))

    def on_move(self, event: Any) -> None:
        """Move-ended listener (loop thread): push the end of the move, once."""
        self.last_move = event
        self.events.append(("stop", None, event.time_ns, event))

    def on_message(self, message: Any) -> None:
        """Message listener (loop thread): push a component's message."""
        self.events.append(("message", None, 0, message))

    # -- the server side -----------------------------------------------------------

    def subscribe(self, key: Any, hz: float) -> Spew:
        """Start a spew at ``hz`` for subscriber ``key`` (replacing its old one)."""
        events = self.events

        def hand_on(now_ns: int, values: tuple, _key: Any = key) -> None:
            events.append(("sample", _key, now_ns, values))

        spew = Spew(self.names, self.sources, hz, hand_on)
        self._spews = (*(s for s in self._spews if s[0] != key), (key, spew))
        return spew

    def unsubscribe(self, key: Any) -> bool:
        """Stop subscriber ``key``'s spew; False if it had none."""
        old = self._spews
        self._spews = tuple(s for s in old if s[0] != key)
        for k, spew in old:
            if k == key:
                spew.active = False
                return True
        return False

    @property
    def subscribers(self) -> int:
        """How many spews are running."""
        return len(self._spews)

    def drain(self) -> list[tuple[str, Any, int, Any]]:
        """Take every pending event, oldest first."""
        out = []
        pop = self.events.popleft
        try:
            while True:
                out.append(pop())
        except IndexError:
            return out
