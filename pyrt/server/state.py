"""What the parts of :class:`~pyrt.server.Server` share: its attributes and
the methods one part calls in another.

:class:`~pyrt.server.Server` is put together from three parts
(:class:`~pyrt.server.ioloop.IOLoopMixin`,
:class:`~pyrt.server.framing.FramingMixin`,
:class:`~pyrt.server.session.SessionMixin`), each in a module of its own;
:class:`ServerState`, their common base, declares for the type checker what
each may use of the others.  At run time it adds nothing: the attributes
are set by ``Server.__init__`` and the methods are the parts' own.
"""

from __future__ import annotations

import selectors
import socket
import threading
from collections import deque
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from pyrt.server.connection import Connection
from pyrt.server.guard import FailureGuard

if TYPE_CHECKING:
    from pyrt.server.hub import StatusHub
    from pyrt.server.robot import ObserverRunner, ServedRobot

__all__ = ["ServerState"]


class ServerState:
    """The attributes and cross-part methods of :class:`~pyrt.server.Server`."""

    # -- set by Server.__init__ -------------------------------------------------
    runner: Any
    robot: ServedRobot
    observer: ObserverRunner
    hub: StatusHub
    counters: dict[str, int]
    max_clients: int
    idle_timeout_s: float
    guest_idle_s: float
    greeting_timeout_s: float
    max_fresh_per_address: int
    reserved_slots: int
    exempt_loopback: bool
    max_line: int
    max_output: int
    max_pending: int
    command_timeout_s: float
    max_rate: float
    max_subscription_rate: float
    max_hz: float
    nice: int
    evict_idle_s: float
    write_stall_s: float
    guard: FailureGuard
    crashed: BaseException | None
    _lease_who: str | None
    _lease_until: float
    _token: bytes | None
    _unsubscribe: tuple[Callable[[], None], ...]
    _period_wall_ns: int | None
    _conns: dict[int, Connection]
    _next_id: int
    _lock: threading.Lock
    _privileged: Connection | None
    _dirty: deque[Connection]
    _backlog: list[Connection]
    _budget: int
    _window_start: int
    _sel: selectors.BaseSelector | None
    _listener: socket.socket | None
    _wake_r: int
    _wake_w: int
    _thread: threading.Thread | None
    _stopping: bool

    if TYPE_CHECKING:
        # -- the I/O loop (ioloop.py) --------------------------------------------
        def _wake(self) -> None: ...
        def _over_budget(self) -> bool: ...
        def _stand_aside(self) -> None: ...
        def _set_events(self, conn: Connection) -> None: ...
        def _output(self, conn: Connection, text: str) -> None: ...
        def _close_after_flush(self, conn: Connection) -> None: ...
        def _touch(self, conn: Connection) -> None: ...
        def _drop(self, conn: Connection, why: str) -> None: ...
        def _finish(self, conn: Connection) -> None: ...
        def _client_failed(self, conn: Connection, exc: BaseException) -> None: ...

        # -- framing (framing.py) ------------------------------------------------
        def _on_readable(self, conn: Connection) -> None: ...
        def _parse(self, conn: Connection) -> None: ...

        # -- requests (session.py) -----------------------------------------------
        def _request(self, conn: Connection, raw: bytes) -> None: ...
        def _lease_text(self) -> str: ...
