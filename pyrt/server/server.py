"""The DAQ link (000 section 15): a TCP line-protocol command and status server.

000's Server was to "allow a privileged client to send commands to the
manipulator control code and make them look like they came from the
keyboard" and return status to the DAQ; it never worked inside the control
program.  Here it runs **outside** the control loop and meets it only where
every application does: through the runner's mailbox (commands) and
through values the loop hands on without waiting (the status snapshot,
subscriptions and faults of :class:`~pyrt.server.hub.StatusHub`).

Threads, and why:

* one **I/O thread** owns every socket (``selectors``: accept, read, split
  lines, write): a slow or dead peer can only fill its own bounded output
  buffer, and is dropped when that is full, so nothing it does can stall
  another client, the commands or the loop.  The cheap requests (``STATUS``
  from the snapshot, ``AUTH``, ``SUBSCRIBE``) are answered right there,
  without a thread hop: that is what a DAQ polls thousands of times a second;
* one **worker thread per connection**, started at its first console
  command, runs its commands in order through a
  :class:`~pyrt.commands.CommandShell` of its own: console commands block
  (a mailbox round trip, a ``wait`` of minutes), and a blocking command
  must hold up only the client that sent it.  A worker pool would let one
  client's long ``wait`` starve everybody else's reads; an asyncio loop
  would still need threads for the blocking shell.

Replies to one client come back in the order of its requests: while a
connection has commands waiting in its worker, its server verbs queue
behind them.

Sharing one interpreter with a real-time loop: the loop thread must get the
interpreter lock the moment its deadline comes.  So on a wall clock the
server's threads *stand aside* between requests from just before each tick
until the tick has run (they read the tick's phase from the hub), run at a
lower OS priority, serve at most ``max_rate`` requests a second (pipelined
lines beyond it wait in their buffer, reading pauses), and the interpreter's
switch interval is cut to 0.2 ms, bounding what any wait for the lock can
cost the loop.  ``bench/bench_server.py`` measures the effect.

Robust by construction: request lines are bounded (:data:`MAX_LINE`; longer
gets ``ERR too-long`` and the connection closes), as are the number of
clients, each client's queued requests (reading pauses, TCP pushes back)
and each client's output (a reader that falls that far behind is dropped).
A subscriber is never idle (it is reading); any other connection is closed
when idle: the privileged one after ``idle_timeout_s`` (10 min), an
unprivileged one after ``guest_idle_s`` (30 s), and one that has sent no
request at all after ``greeting_timeout_s`` (5 s).  A line that is not text
(invalid UTF-8: ``ERR utf8``; control characters: ``ERR text``) is refused
with one line and ignored; a half line left when a peer disconnects is
discarded, never run.  Nothing a client sends reaches a motor unless it is a
complete, privileged command, or a stop.

Nobody can starve the operator of a slot.  Connections from one address
that have sent nothing are at most ``max_fresh_per_address`` (loopback
exempt, see :data:`~pyrt.server.limits.MAX_FRESH_PER_ADDRESS`).  When the
``max_clients`` slots are taken, a newcomer takes the slot of the oldest
connection that has sent nothing (that one gets ``ERR full``), else of an
unprivileged, unsubscribed client idle for ``EVICT_IDLE_S``; when none can
be freed it gets one of ``reserved_slots`` more, where it may only ``AUTH``
(the operator) or give a stop (anyone): so the operator and a stop always
get in, however many silent or busy connections there are.

The parts, one module each: :mod:`~pyrt.server.limits` (the bounds and the
manners toward the loop), :mod:`~pyrt.server.connection` (a connection's
state), :mod:`~pyrt.server.ioloop` (the selector loop of the I/O thread),
:mod:`~pyrt.server.framing` (bytes into request lines),
:mod:`~pyrt.server.session` (verbs, privilege, the worker and its shell);
this module holds :class:`Server`, which puts them together, its life cycle
and what it reports.
"""

from __future__ import annotations

import contextlib
import logging
import os
import selectors
import socket
import sys
import threading
import time
from collections import deque
from typing import Any

from pyrt.errors import ConfigError
from pyrt.scope.spew import MAX_SPEW_HZ
from pyrt.server.connection import Connection
from pyrt.server.framing import FramingMixin
from pyrt.server.guard import FailureGuard, check_token
from pyrt.server.hub import StatusHub
from pyrt.server.ioloop import IOLoopMixin
from pyrt.server.limits import (
    EVICT_IDLE_S,
    GREETING_TIMEOUT_S,
    GUEST_IDLE_S,
    IDLE_TIMEOUT_S,
    MAX_CLIENTS,
    MAX_FRESH_PER_ADDRESS,
    MAX_OUTPUT,
    MAX_PENDING,
    MAX_RATE,
    MAX_SUBSCRIPTION_RATE,
    NICE,
    RATE_WINDOW_S,
    RESERVED_SLOTS,
    SWITCH_INTERVAL_S,
    WRITE_STALL_S,
    is_loopback,
)
from pyrt.server.protocol import MAX_LINE
from pyrt.server.robot import ObserverRunner, ServedRobot
from pyrt.server.session import SessionMixin, run_shell

__all__ = ["Server", "is_loopback", "run_shell"]

log = logging.getLogger("pyrt.server")

#: How often the extra values (EPICS's per-device PVs) are read, while served.
EXTRA_PERIOD_NS = 100_000_000


class Server(IOLoopMixin, FramingMixin, SessionMixin):
    """Serve ``robot`` through ``runner`` on ``host:port`` (port 0: any free port).

    Build it before the loop runs (it attaches its :class:`StatusHub`);
    :meth:`start` binds and starts the I/O thread; :meth:`close` stops.
    ``token``: the privilege token (None: nobody is privileged, the server
    only reports).  Serving on a non-loopback address without a token is a
    :class:`~pyrt.errors.ConfigError`.
    """

    def __init__(
        self,
        runner: Any,
        robot: ServedRobot,
        host: str = "127.0.0.1",
        port: int = 0,
        *,
        token: str | None = None,
        max_clients: int = MAX_CLIENTS,
        idle_timeout_s: float = IDLE_TIMEOUT_S,
        guest_idle_s: float = GUEST_IDLE_S,
        greeting_timeout_s: float = GREETING_TIMEOUT_S,
        max_fresh_per_address: int = MAX_FRESH_PER_ADDRESS,
        reserved_slots: int = RESERVED_SLOTS,
        exempt_loopback: bool = True,
        max_line: int = MAX_LINE,
        max_output: int = MAX_OUTPUT,
        max_pending: int = MAX_PENDING,
        command_timeout_s: float = 5.0,
        snapshot_every: int = 1,
        max_rate: float = MAX_RATE,
        max_subscription_rate: float = MAX_SUBSCRIPTION_RATE,
        nice: int = NICE,
        switch_interval_s: float | None = SWITCH_INTERVAL_S,
        evict_idle_s: float = EVICT_IDLE_S,
        write_stall_s: float = WRITE_STALL_S,
        guard: FailureGuard | None = None,
    ):
        if token is not None and not token:
            raise ConfigError("the token is empty")
        if token is not None and not is_loopback(host):
            check_token(token)  # reachable from the network: a token that is not guessed
        if token is None and not is_loopback(host):
            raise ConfigError(
                f"refusing to serve on {host!r} without a token: anybody who can reach it "
                "could connect; give --token-file or PYRT_TOKEN, or serve on 127.0.0.1"
            )
        if not 0 <= port <= 65535:
            raise ConfigError(f"port must be 0..65535, got {port}")
        for what, value in (("max_clients", max_clients), ("max_line", max_line),
                            ("max_output", max_output), ("max_pending", max_pending),
                            ("max_fresh_per_address", max_fresh_per_address)):
            if value < 1:
                raise ConfigError(f"{what} must be >= 1, got {value}")
        if reserved_slots < 0:
            raise ConfigError(f"reserved_slots must be >= 0, got {reserved_slots}")
        for what, secs in (("idle_timeout_s", idle_timeout_s), ("guest_idle_s", guest_idle_s),
                           ("greeting_timeout_s", greeting_timeout_s),
                           ("evict_idle_s", evict_idle_s), ("write_stall_s", write_stall_s)):
            if not secs > 0:
                raise ConfigError(f"{what} must be > 0 s, got {secs}")
        self.runner = runner
        self.robot = robot
        self.host = host
        self.port = port
        self._token = token.encode("utf-8") if token is not None else None
        self.max_clients = max_clients
        self.idle_timeout_s = float(idle_timeout_s)
        # No connection waits longer than the privileged one may.
        self.guest_idle_s = min(float(guest_idle_s), self.idle_timeout_s)
        self.greeting_timeout_s = min(float(greeting_timeout_s), self.guest_idle_s)
        self.max_fresh_per_address = int(max_fresh_per_address)
        self.reserved_slots = int(reserved_slots)
        self.exempt_loopback = bool(exempt_loopback)
        self.max_line = max_line
        self.max_output = max_output
        self.max_pending = max_pending
        self.command_timeout_s = command_timeout_s
        self.max_rate = float(max_rate)
        self.max_subscription_rate = float(max_subscription_rate)
        self.nice = int(nice)
        self.switch_interval_s = switch_interval_s
        self.evict_idle_s = float(evict_idle_s)
        self.write_stall_s = float(write_stall_s)
        self.max_hz = min(1e9 / runner.loop.period_ns, MAX_SPEW_HZ)
        #: Failed AUTH (and, through EPICS, refused writes): back-off and
        #: bounded audit lines, per address and overall.
        self.guard = guard if guard is not None else FailureGuard(self._audit)
        #: The I/O thread's failure, if it has died (the station is tripped).
        self.crashed: BaseException | None = None
        #: A master without a connection (EPICS CMD) holding the privilege, and until when.
        self._lease_who: str | None = None
        self._lease_until = 0.0
        extras = robot.extra_fields
        self.hub = StatusHub(robot.status_names, robot.status_sources(),
                             snapshot_every=snapshot_every,
                             extra_sources=[f.source for f in extras],
                             extra_every=max(1, round(EXTRA_PERIOD_NS / runner.loop.period_ns)))
        runner.loop.attach(self.hub, name="server")
        runner.loop.fault_listeners.append(self.hub.on_fault)
        station = robot.station  # the end of each move and each message, pushed once
        self._unsubscribe = (station.subscribe_moves(self.hub.on_move),
                             station.subscribe(self.hub.on_message))
        self.observer = ObserverRunner(runner)
        clock = runner.loop.clock
        #: The tick in wall-clock ns (None on a SimClock: nothing to stand aside for).
        self._period_wall_ns: int | None = (
            None if clock.virtual
            else int(runner.loop.period_ns / float(getattr(clock, "speed", 1.0)))
        )
        self.counters = {
            "accepted": 0, "refused_full": 0, "requests": 0, "status": 0, "denied": 0,
            "auth_failed": 0, "too_long": 0, "utf8": 0, "text": 0, "idle": 0,
            "dropped_slow": 0, "evicted": 0, "reserve": 0, "refused_address": 0,
            "auth_backoff": 0, "internal": 0,
        }
        self._conns: dict[int, Connection] = {}
        self._next_id = 1
        self._lock = threading.Lock()
        self._privileged: Connection | None = None
        self._dirty: deque[Connection] = deque()
        self._backlog: list[Connection] = []
        self._budget = max(1, int(self.max_rate * RATE_WINDOW_S))
        self._window_start = 0
        self._sel: selectors.BaseSelector | None = None
        self._listener: socket.socket | None = None
        self._wake_r = self._wake_w = -1
        self._thread: threading.Thread | None = None
        self._stopping = False
        self.address: tuple[str, int] | None = None

    # -- life cycle ----------------------------------------------------------------

    def bind(self) -> tuple[str, int]:
        """Bind and listen (nothing is served until :meth:`start`); returns
        ``(host, port)`` bound; ConfigError (a taken port ...) saying why.  A
        station binds before it says anything, so that a port it cannot have
        is its first and only word."""
        if self._listener is not None:
            assert self.address is not None
            return self.address
        try:
            infos = socket.getaddrinfo(self.host or None, self.port, type=socket.SOCK_STREAM,
                                       flags=socket.AI_PASSIVE)
        except OSError as exc:
            raise ConfigError(f"cannot resolve {self.host!r}: {exc}") from None
        family, stype, proto, _, addr = infos[0]
        listener = socket.socket(family, stype, proto)
        try:
            listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            listener.bind(addr)
            listener.listen(min(self.max_clients, 128))
        except OSError as exc:
            listener.close()
            raise ConfigError(f"cannot serve on {self.host}:{self.port}: {exc.strerror}") from None
        listener.setblocking(False)
        self._listener = listener
        self.address = listener.getsockname()[:2]
        return self.address

    def start(self) -> tuple[str, int]:
        """Bind (unless :meth:`bind` has), listen and start the I/O thread; returns
        ``(host, port)`` bound."""
        if self._thread is not None:
            raise ConfigError("the server is already running")
        self.bind()
        listener = self._listener
        assert listener is not None and self.address is not None
        self._wake_r, self._wake_w = os.pipe()
        os.set_blocking(self._wake_r, False)
        os.set_blocking(self._wake_w, False)
        sel = selectors.DefaultSelector()
        sel.register(listener, selectors.EVENT_READ, None)
        sel.register(self._wake_r, selectors.EVENT_READ, "wake")
        self._sel = sel
        self._stopping = False
        if self.switch_interval_s is not None and sys.getswitchinterval() > self.switch_interval_s:
            sys.setswitchinterval(self.switch_interval_s)
        self._thread = threading.Thread(target=self._io_main, name="pyrt-server-io", daemon=True)
        self._thread.start()
        log.debug("serving %s on %s:%d", self.robot.name, *self.address)
        return self.address

    def close(self, timeout_s: float = 2.0) -> None:
        """Stop serving: close every connection and the listener, stop the threads."""
        for unsubscribe in self._unsubscribe:
            unsubscribe()
        self._unsubscribe = ()
        if self._thread is None:
            if self._listener is not None:  # bound, never started
                self._listener.close()
                self._listener = None
            return
        conns = list(self._conns.values())
        self._stopping = True
        self._wake()
        self._thread.join(timeout_s)
        self._thread = None
        self.guard.flush(force=True)
        for conn in list(self._conns.values()):
            self._finish(conn)
        deadline = time.monotonic() + timeout_s
        for conn in conns:
            if conn.worker is not None:
                conn.worker.join(max(0.0, deadline - time.monotonic()))
        self._conns.clear()
        if self._sel is not None:
            self._sel.close()
            self._sel = None
        if self._listener is not None:
            self._listener.close()
            self._listener = None
        for fd in (self._wake_r, self._wake_w):
            with contextlib.suppress(OSError):
                os.close(fd)
        self._wake_r = self._wake_w = -1
        log.info("server stopped")

    def __enter__(self) -> Server:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _audit(self, who: str, line: str) -> None:
        """An audit line of the served station (its console and audit log)."""
        self.robot.audit(who, line)

    @property
    def alive(self) -> bool:
        """The I/O thread is serving (False before start, after close, or if it died)."""
        return self._thread is not None and self._thread.is_alive() and self.crashed is None

    @property
    def clients(self) -> int:
        """Connections open now."""
        return len(self._conns)

    @property
    def has_token(self) -> bool:
        """A token is configured (a client can become privileged)."""
        return self._token is not None

    @property
    def privileged_client(self) -> str | None:
        """Who holds the privilege (``host:port``), or None."""
        conn = self._privileged
        return None if conn is None else f"{conn.peer[0]}:{conn.peer[1]}"
