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
A connection idle longer than the idle timeout is closed (a subscriber is
never idle: it is reading).  Invalid UTF-8 gets ``ERR utf8``; a half line
left when a peer disconnects is discarded, never run.  Nothing a client
sends reaches a motor unless it is a complete, privileged command.
"""

from __future__ import annotations

import contextlib
import hmac
import io
import ipaddress
import logging
import math
import os
import selectors
import socket
import sys
import threading
import time
from collections import deque
from typing import Any

from pyrt import __version__
from pyrt.errors import ConfigError
from pyrt.server.hub import StatusHub
from pyrt.server.protocol import MAX_LINE, format_error, format_reply, split_verb
from pyrt.server.robot import ObserverRunner, ServedRobot

__all__ = ["Server", "is_loopback", "run_shell"]

log = logging.getLogger("pyrt.server")

#: Defaults of the bounds (all overridable per server).
MAX_CLIENTS = 64
IDLE_TIMEOUT_S = 600.0
MAX_OUTPUT = 256 * 1024
MAX_PENDING = 32
MAX_AUTH_FAILURES = 3
#: How long a closing connection waits for its peer to take the last reply.
LINGER_S = 1.0
#: How often the I/O thread hands subscription samples on, seconds.
PUMP_S = 0.005
#: Requests per second the server serves at most (all clients together);
#: beyond it the I/O thread pauses, so the network cannot take the CPU
#: the loop needs.  Twice the DAQ target of 5,000 STATUS requests/s.
MAX_RATE = 10_000
#: STATUS lines per second all subscriptions together may ask for: each
#: sample is read in the loop thread, so their sum is bounded.
MAX_SUBSCRIPTION_RATE = 20_000
#: The budget is kept per window of this many seconds.
RATE_WINDOW_S = 0.01
#: Niceness added to the server's threads (Linux: per thread), so that the
#: loop thread wins the CPU when both want it.
NICE = 5
#: Real time: the server's threads pause from this long before the loop's
#: next tick until the tick has run, so that the loop thread never waits
#: for the interpreter lock at its deadline (the loop's spin is 200 µs).
GUARD_NS = 450_000
#: How long a standing-aside thread sleeps between looks at the loop.
GUARD_POLL_S = 0.0001
#: Longest the loop thread waits for the interpreter lock while a server
#: thread holds it (``sys.setswitchinterval``; CPython's default is 5 ms,
#: five ticks).  Set when the server starts, never raised.
SWITCH_INTERVAL_S = 0.0002


def _lower_priority(nice: int) -> None:
    """Make the calling thread ``nice`` steps nicer (Linux; elsewhere nothing)."""
    if nice <= 0 or not hasattr(os, "setpriority"):
        return
    with contextlib.suppress(OSError, AttributeError):
        tid = threading.get_native_id()
        os.setpriority(os.PRIO_PROCESS, tid, min(19, os.getpriority(os.PRIO_PROCESS, tid) + nice))


_VERBS = frozenset({"AUTH", "QUIT", "STATUS", "SUBSCRIBE", "UNSUBSCRIBE"})


def _denied(line: str) -> str:
    return format_error("denied", f"{line.strip()[:60]!r} changes the robot: AUTH first")


def run_shell(shell: Any, line: str, extra: list[str] | None = None) -> tuple[str, bool]:
    """Run ``line`` in a console ``shell``, its output captured; the framed reply
    and whether the shell asked to end the session.

    What the shell reports through ``error()`` makes the reply ``ERR command``;
    a bug in pyrt (its ``internal_error()``) ``ERR internal``, the traceback
    to the server's log; a fault it meets (a :class:`~pyrt.errors.FaultError`, handed to its
    ``fault()``) ``ERR fault``, with what the command then said as the lines.
    """
    out = io.StringIO()
    errors: list[str] = []
    faults: list[Any] = []
    bugs: list[BaseException] = []
    shell.stdout = out
    shell.error = errors.append
    shell.fault = faults.append
    shell.internal_error = bugs.append
    end = bool(shell.onecmd(line))
    lines = out.getvalue().splitlines() + list(extra or [])
    if bugs:
        exc = bugs[0]
        log.error("a bug in pyrt running %r", line[:60], exc_info=exc)
        return format_error("internal", f"{type(exc).__name__}: {exc} (a bug in pyrt; the "
                            "server log has the traceback)", lines), end
    if errors:
        return format_error("command", "; ".join(errors), lines), end
    if faults:
        return format_error("fault", f"{faults[0].fault}; every motor stopped; nothing "
                            "moves until you type ack", lines), end
    return format_reply(lines), end


def is_loopback(host: str) -> bool:
    """True when every address ``host`` resolves to is a loopback address."""
    if host in ("", "0.0.0.0", "::"):
        return False
    try:
        infos = socket.getaddrinfo(host, None, type=socket.SOCK_STREAM)
    except OSError:
        return False
    addrs = {info[4][0] for info in infos}
    return bool(addrs) and all(ipaddress.ip_address(a.split("%")[0]).is_loopback for a in addrs)


class _Conn:
    """One client connection (state shared by the I/O thread and its worker)."""

    def __init__(self, cid: int, sock: socket.socket, peer: Any):
        self.id = cid
        self.sock = sock
        self.peer = peer
        self.inbuf = bytearray()
        self.out = bytearray()
        self.lock = threading.Lock()
        self.cv = threading.Condition(self.lock)
        self.requests: deque[tuple[bool, str]] = deque()  # (ready-made reply?, text)
        self.pending = 0  # requests handed to the worker and not yet answered
        self.worker: threading.Thread | None = None
        self.shell: Any = None
        self.shell_privileged = False
        self.privileged = False
        self.subscribed = 0.0
        self.auth_failures = 0
        self.last_active = time.monotonic()
        self.paused = False  # too many requests queued: read no more for now
        self.backlogged = False  # over the server's rate: lines wait in inbuf
        self.writing = False
        self.dirty = False
        self.closing = False  # read nothing more; flush, then close
        self.stop_requests = False  # run no more of its queued requests
        self.eof = False  # the peer has closed its end
        self.events = 0  # selector events registered
        self.linger_until = 0.0
        self.drop: str | None = None  # close at once (slow reader ...)
        self.closed = False
        #: Set once the connection holds no privilege any more (its worker has
        #: released its session, or it never had one): an AUTH waits for it.
        self.released = threading.Event()

    def __repr__(self) -> str:
        return f"client {self.id} {self.peer}"


class Server:
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
        max_line: int = MAX_LINE,
        max_output: int = MAX_OUTPUT,
        max_pending: int = MAX_PENDING,
        command_timeout_s: float = 5.0,
        snapshot_every: int = 1,
        max_rate: float = MAX_RATE,
        max_subscription_rate: float = MAX_SUBSCRIPTION_RATE,
        nice: int = NICE,
        switch_interval_s: float | None = SWITCH_INTERVAL_S,
    ):
        if token is not None and not token:
            raise ConfigError("the token is empty")
        if token is None and not is_loopback(host):
            raise ConfigError(
                f"refusing to serve on {host!r} without a token: anybody who can reach it "
                "could connect; give --token-file or PYRT_TOKEN, or serve on 127.0.0.1"
            )
        if not 0 <= port <= 65535:
            raise ConfigError(f"port must be 0..65535, got {port}")
        for what, value in (("max_clients", max_clients), ("max_line", max_line),
                            ("max_output", max_output), ("max_pending", max_pending)):
            if value < 1:
                raise ConfigError(f"{what} must be >= 1, got {value}")
        self.runner = runner
        self.robot = robot
        self.host = host
        self.port = port
        self._token = token.encode("utf-8") if token is not None else None
        self.max_clients = max_clients
        self.idle_timeout_s = float(idle_timeout_s)
        self.max_line = max_line
        self.max_output = max_output
        self.max_pending = max_pending
        self.command_timeout_s = command_timeout_s
        self.max_rate = float(max_rate)
        self.max_subscription_rate = float(max_subscription_rate)
        self.nice = int(nice)
        self.switch_interval_s = switch_interval_s
        self.max_hz = 1e9 / runner.loop.period_ns
        self.hub = StatusHub(robot.status_names, robot.status_sources(),
                             snapshot_every=snapshot_every)
        runner.loop.attach(self.hub, name="server")
        runner.loop.fault_listeners.append(self.hub.on_fault)
        self.observer = ObserverRunner(runner)
        clock = runner.loop.clock
        #: The tick in wall-clock ns (None on a SimClock: nothing to stand aside for).
        self._period_wall_ns: int | None = (
            None if clock.virtual
            else int(runner.loop.period_ns / float(getattr(clock, "speed", 1.0)))
        )
        self.counters = {
            "accepted": 0, "refused_full": 0, "requests": 0, "status": 0, "denied": 0,
            "auth_failed": 0, "too_long": 0, "utf8": 0, "idle": 0, "dropped_slow": 0,
        }
        self._conns: dict[int, _Conn] = {}
        self._next_id = 1
        self._lock = threading.Lock()
        self._privileged: _Conn | None = None
        self._dirty: deque[_Conn] = deque()
        self._backlog: list[_Conn] = []
        self._budget = max(1, int(self.max_rate * RATE_WINDOW_S))
        self._window_start = 0
        self._sel: selectors.BaseSelector | None = None
        self._listener: socket.socket | None = None
        self._wake_r = self._wake_w = -1
        self._thread: threading.Thread | None = None
        self._stopping = False
        self.address: tuple[str, int] | None = None

    # -- life cycle ----------------------------------------------------------------

    def start(self) -> tuple[str, int]:
        """Bind, listen and start the I/O thread; returns ``(host, port)`` bound."""
        if self._thread is not None:
            raise ConfigError("the server is already running")
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
        if self._thread is None:
            return
        conns = list(self._conns.values())
        self._stopping = True
        self._wake()
        self._thread.join(timeout_s)
        self._thread = None
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

    def _wake(self) -> None:
        with contextlib.suppress(OSError):  # a full pipe is already a wake-up
            os.write(self._wake_w, b"\0")

    # -- the I/O thread --------------------------------------------------------------

    def _io_main(self) -> None:
        _lower_priority(self.nice)
        sel = self._sel
        assert sel is not None
        next_check = 0.0
        window_end = 0.0
        while not self._stopping:
            now = time.monotonic()
            if now >= window_end:
                window_end = now + RATE_WINDOW_S
                self._window_start = self.counters["requests"]
                backlog, self._backlog = self._backlog, []
                for conn in backlog:
                    conn.backlogged = False
                    if not conn.closed:
                        self._parse(conn)
                        self._set_events(conn)
            elif self._over_budget():
                # Over the rate: let the loop (and everything else) have the CPU.
                time.sleep(window_end - now)
                continue
            busy = self.hub.subscribers or self.hub.events
            try:
                events = sel.select(PUMP_S if busy else 0.25)
            except OSError:  # pragma: no cover - EINTR is retried by select
                continue
            for key, mask in events:
                self._stand_aside()
                data = key.data
                if data is None:
                    self._accept()
                elif data == "wake":
                    with contextlib.suppress(OSError):
                        while os.read(self._wake_r, 4096):
                            pass
                else:
                    if mask & selectors.EVENT_READ:
                        self._on_readable(data)
                    if mask & selectors.EVENT_WRITE and not data.closed:
                        self._flush(data)
            if self.hub.events:
                self._pump()
            self._service_dirty()
            now = time.monotonic()
            if now >= next_check:
                next_check = now + 0.1
                self._check_timeouts(now)
        for conn in list(self._conns.values()):
            self._finish(conn)

    def _over_budget(self) -> bool:
        return self.counters["requests"] - self._window_start >= self._budget

    def _stand_aside(self) -> None:
        """Real time: if the loop's next tick is near, wait until it has run.

        The loop thread must take the interpreter lock the moment its
        deadline comes; a server thread in the middle of a request would make
        it wait up to the switch interval.  Between requests the server looks
        at the tick phase (the hub's stamp) and sleeps through the tick.
        A loop that is not ticking (stopped, or far behind) is not waited for.
        """
        period = self._period_wall_ns
        if period is None:
            return
        hub = self.hub
        last = hub.tick_wall_ns
        now = time.monotonic_ns()
        due = last + period
        if now < due - GUARD_NS or now > due + 2 * period:
            return
        limit = due + period
        while hub.tick_wall_ns == last and now < limit:
            time.sleep(GUARD_POLL_S)
            now = time.monotonic_ns()

    def _accept(self) -> None:
        assert self._listener is not None
        while True:
            try:
                sock, peer = self._listener.accept()
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:  # out of descriptors: leave it in the backlog
                log.warning("accept failed: %s", exc)
                return
            if len(self._conns) >= self.max_clients:
                self.counters["refused_full"] += 1
                with contextlib.suppress(OSError):
                    sock.setblocking(False)
                    sock.send(format_error("full", f"{self.max_clients} clients already").encode())
                sock.close()
                log.warning("refused %s: %d clients already", peer, self.max_clients)
                continue
            sock.setblocking(False)
            with contextlib.suppress(OSError):
                sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            conn = _Conn(self._next_id, sock, peer)
            self._next_id += 1
            self._conns[conn.id] = conn
            self.counters["accepted"] += 1
            assert self._sel is not None
            self._sel.register(sock, selectors.EVENT_READ, conn)
            conn.events = selectors.EVENT_READ
            who = "AUTH to command" if self._token is not None else "no token: status only"
            self._output(conn, format_reply(
                [f"pyrt {__version__} {self.robot.name} server; {who}; HELP lists the commands"]
            ))
            log.info("%r connected", conn)

    def _on_readable(self, conn: _Conn) -> None:
        try:
            data = conn.sock.recv(65536)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            self._drop(conn, "connection reset")
            return
        if not data:
            # End of input: a half line is discarded, never run; what was
            # received complete is answered, then the connection closes.
            conn.inbuf.clear()
            conn.eof = conn.closing = True
            self._set_events(conn)
            return
        if conn.closing:  # closing: discard what still comes in
            return
        conn.inbuf += data
        self._parse(conn)

    def _parse(self, conn: _Conn) -> None:
        buf = conn.inbuf
        while not conn.paused and not conn.closing:
            if self._over_budget():
                if not conn.backlogged:  # the rest waits for the next window
                    conn.backlogged = True
                    self._backlog.append(conn)
                    self._set_events(conn)
                return
            i = buf.find(b"\n")
            if i < 0:
                if len(buf) > self.max_line:
                    self._too_long(conn)
                return
            raw = bytes(buf[:i])
            del buf[: i + 1]
            if raw.endswith(b"\r"):
                raw = raw[:-1]
            if len(raw) > self.max_line:
                self._too_long(conn)
                return
            self._stand_aside()
            self._request(conn, raw)

    def _too_long(self, conn: _Conn) -> None:
        self.counters["too_long"] += 1
        conn.inbuf.clear()
        self._output(conn, format_error("too-long", f"request lines are at most {self.max_line} "
                                        "bytes; closing"))
        self._close_after_flush(conn)

    def _request(self, conn: _Conn, raw: bytes) -> None:
        self.counters["requests"] += 1
        conn.last_active = time.monotonic()
        try:
            line = raw.decode("utf-8")
        except UnicodeDecodeError as exc:
            self.counters["utf8"] += 1
            self._reply(conn, format_error(
                "utf8", f"invalid UTF-8 at byte {exc.start}; request ignored"))
            return
        verb, rest = split_verb(line)
        if verb in _VERBS:
            if conn.pending == 0 and not (verb == "AUTH" and self._held_by_a_closing(conn)):
                self._output(conn, self._verb(conn, verb, rest))
            else:  # in order behind its commands, or waiting for a release (worker)
                self._enqueue(conn, line)
            return
        if not verb:
            self._reply(conn, format_reply([]))
            return
        # Behind queued requests (an AUTH among them, perhaps) the worker decides.
        if conn.pending == 0 and verb != "HELP" and not (
            conn.privileged or self.robot.is_read_only(line)
        ):
            self.counters["denied"] += 1
            self._output(conn, _denied(line))
            return
        self._enqueue(conn, line)

    def _reply(self, conn: _Conn, text: str) -> None:
        """A reply produced in the I/O thread, kept in order behind queued commands."""
        if conn.pending:
            self._enqueue(conn, text, ready=True)
        else:
            self._output(conn, text)

    def _enqueue(self, conn: _Conn, line: str, ready: bool = False) -> None:
        with conn.lock:
            conn.requests.append((ready, line))
            conn.pending += 1
            if conn.pending >= self.max_pending:
                conn.paused = True  # stop reading: TCP pushes back on the client
            conn.cv.notify()
        if conn.paused:
            self._set_events(conn)
        if conn.worker is None:
            conn.worker = threading.Thread(
                target=self._work, args=(conn,), name=f"pyrt-server-{conn.id}", daemon=True
            )
            conn.worker.start()

    def _set_events(self, conn: _Conn) -> None:
        """Register the events ``conn`` needs now; close it when it is done (I/O thread)."""
        sel = self._sel
        if conn.closed or sel is None:
            return
        if conn.closing and not conn.out and conn.pending == 0:
            if conn.eof:
                self._finish(conn)
                return
            if not conn.linger_until:
                # Everything answered and sent: half-close, then wait (a
                # little) for the peer's end so the last reply is not lost
                # to a reset.
                with contextlib.suppress(OSError):
                    conn.sock.shutdown(socket.SHUT_WR)
                conn.linger_until = time.monotonic() + LINGER_S
        ev = 0
        if not conn.eof and (conn.closing or not (conn.paused or conn.backlogged)):
            ev |= selectors.EVENT_READ
        if conn.out:
            ev |= selectors.EVENT_WRITE
        if ev == conn.events:
            return
        if conn.events == 0:
            sel.register(conn.sock, ev, conn)
        elif ev == 0:
            sel.unregister(conn.sock)
        else:
            sel.modify(conn.sock, ev, conn)
        conn.events = ev

    def _output(self, conn: _Conn, text: str) -> None:
        """Queue ``text`` for ``conn`` (any thread); a full buffer drops the client."""
        data = text.encode("utf-8")
        with conn.lock:
            if conn.closed or conn.drop:
                return
            if len(conn.out) + len(data) > self.max_output:
                conn.drop = f"slow reader: more than {self.max_output} bytes unread"
                conn.out.clear()
            else:
                conn.out += data
            if conn.dirty:
                return
            conn.dirty = True
        self._dirty.append(conn)
        if threading.current_thread() is not self._thread:
            self._wake()

    def _service_dirty(self) -> None:
        dirty = self._dirty
        while dirty:
            conn = dirty.popleft()
            with conn.lock:
                conn.dirty = False
                drop = conn.drop
                resume = conn.paused and conn.pending < self.max_pending // 2 + 1
                if resume:
                    conn.paused = False
            if conn.closed:
                continue
            if drop:
                self._drop(conn, drop)
                self.counters["dropped_slow"] += drop.startswith("slow")
                continue
            self._flush(conn)
            if resume and not conn.closed:
                self._parse(conn)
                self._set_events(conn)

    def _flush(self, conn: _Conn) -> None:
        with conn.lock:
            if conn.out:
                try:
                    n = conn.sock.send(conn.out)
                except (BlockingIOError, InterruptedError):
                    n = 0
                except OSError:
                    n = -1
                if n > 0:
                    del conn.out[:n]
            else:
                n = 0
        if n < 0:
            self._drop(conn, "connection reset")
            return
        self._set_events(conn)

    def _pump(self) -> None:
        """Hand subscription samples and faults on to the subscribers."""
        fmt = self.robot.format_status
        conns = self._conns
        for n, (kind, key, t_ns, payload) in enumerate(self.hub.drain()):
            if n & 63 == 63:
                self._stand_aside()
            if kind == "sample":
                conn = conns.get(key)
                if conn is not None and conn.subscribed:
                    self._output(conn, f"STATUS t={t_ns / 1e9:.6f} {fmt(payload)}\n")
            else:
                line = f"STATUS FAULT {payload}\n".replace("\r", " ")
                for conn in list(conns.values()):
                    if conn.subscribed:
                        self._output(conn, line)

    def _check_timeouts(self, now: float) -> None:
        for conn in list(self._conns.values()):
            if conn.closed:
                continue
            if conn.linger_until:
                if now >= conn.linger_until:
                    self._finish(conn)
                continue
            if conn.closing or conn.subscribed or conn.pending:
                continue
            if now - conn.last_active > self.idle_timeout_s:
                self.counters["idle"] += 1
                self._output(conn, format_error(
                    "idle", f"no request for {self.idle_timeout_s:g} s; closing"))
                self._close_after_flush(conn)

    def _close_after_flush(self, conn: _Conn) -> None:
        self._end(conn)
        self._touch(conn)

    def _touch(self, conn: _Conn) -> None:
        """Have the I/O thread look at ``conn`` again (after the current request)."""
        with conn.lock:
            if conn.dirty or conn.closed:
                return
            conn.dirty = True
        self._dirty.append(conn)
        if threading.current_thread() is not self._thread:
            self._wake()

    def _end(self, conn: _Conn) -> None:
        """Read and run nothing more from ``conn``; close once its replies are out."""
        with conn.lock:
            conn.closing = conn.stop_requests = True
            conn.pending -= len(conn.requests)  # queued, not started: never run
            conn.requests.clear()

    def _drop(self, conn: _Conn, why: str) -> None:
        log.info("%r dropped: %s", conn, why)
        self._end(conn)
        self._finish(conn)

    def _finish(self, conn: _Conn) -> None:
        """Close ``conn`` now and give up what it held (I/O thread or close())."""
        with conn.lock:
            if conn.closed:
                return
            conn.closed = True
            conn.out.clear()
            conn.cv.notify_all()
        if self._sel is not None and conn.events:
            with contextlib.suppress(KeyError, ValueError, OSError):
                self._sel.unregister(conn.sock)
            conn.events = 0
        with contextlib.suppress(OSError):
            conn.sock.close()
        self._conns.pop(conn.id, None)
        with self._lock:
            self.hub.unsubscribe(conn.id)
            conn.subscribed = 0.0
            if conn.worker is None or conn.shell is None:  # no session to release
                if self._privileged is conn:
                    self._privileged = None
                conn.released.set()
        log.info("%r closed", conn)

    # -- the server's verbs (I/O thread, or a worker when queued behind commands) ----

    def _verb(self, conn: _Conn, verb: str, rest: str) -> str:
        if verb == "STATUS":
            if rest:
                return format_error("syntax", "STATUS takes no argument")
            self.counters["status"] += 1
            t_ns, _tick, values = self.hub.snapshot
            if values is None:
                return format_error("timeout", "no status yet: the control loop has not run")
            return format_reply([f"t={t_ns / 1e9:.6f} {self.robot.format_status(values)}"])
        if verb == "AUTH":
            return self._auth(conn, rest)
        if verb == "SUBSCRIBE":
            try:
                hz = float(rest)
            except ValueError:
                hz = math.nan
            if not 0 < hz <= self.max_hz:
                return format_error(
                    "syntax", f"SUBSCRIBE needs a rate 0 < hz <= {self.max_hz:g}, got {rest!r}")
            with self._lock:
                if conn.closed:
                    return format_reply([])
                others = sum(c.subscribed for c in list(self._conns.values()) if c is not conn)
                if others + hz > self.max_subscription_rate:
                    return format_error(
                        "limit", f"subscriptions would total {others + hz:g} samples/s; "
                        f"the server serves at most {self.max_subscription_rate:g}")
                self.hub.subscribe(conn.id, hz)
                conn.subscribed = hz
            return format_reply(
                [f"subscribed at {hz:g} Hz: t {' '.join(self.robot.status_names)}"])
        if verb == "UNSUBSCRIBE":
            if rest:
                return format_error("syntax", "UNSUBSCRIBE takes no argument")
            with self._lock:
                had = self.hub.unsubscribe(conn.id)
                conn.subscribed = 0.0
            return format_reply(["unsubscribed" if had else "not subscribed"])
        if verb == "QUIT":
            self._close_after_flush(conn)
            return format_reply(["bye"])
        return format_error("internal", f"no verb {verb!r}")  # pragma: no cover

    def _held_by_a_closing(self, conn: _Conn) -> bool:
        """The privilege is held by another connection that is closing (its
        session not yet released): an AUTH of ``conn`` waits for it in ``conn``'s worker."""
        holder = self._privileged
        return holder is not None and holder is not conn and (holder.closing or holder.closed)

    def _auth(self, conn: _Conn, given: str) -> str:
        holder = self._privileged
        if (holder is not None and holder is not conn and (holder.closing or holder.closed)
                and threading.current_thread() is not self._thread):
            # A privileged client that has gone: its worker releases the
            # session (leaves the monitor ...) and then the privilege.  Wait
            # for that, so that "disconnect, reconnect, AUTH" never sees busy.
            holder.released.wait(self.command_timeout_s)
        with self._lock:
            if conn.privileged:
                return format_reply(["already privileged"])
            if self._token is None:
                self.counters["auth_failed"] += 1
                return format_error("auth", "no token is configured: this server only reports")
            if not given or not hmac.compare_digest(given.encode("utf-8"), self._token):
                self.counters["auth_failed"] += 1
                conn.auth_failures += 1
                if conn.auth_failures >= MAX_AUTH_FAILURES:
                    self._close_after_flush(conn)
                    return format_error("auth", "wrong token; too many failures, closing")
                return format_error("auth", "wrong token")
            holder = self._privileged
            if holder is not None and holder is not conn:
                return format_error("busy", "another client is privileged (one at a time)")
            self._privileged = conn
            conn.privileged = True
        log.info("%r is privileged", conn)
        return format_reply(["privileged: every console command is accepted"])

    # -- the worker thread of a connection -------------------------------------------

    def _work(self, conn: _Conn) -> None:
        _lower_priority(self.nice)
        while True:
            with conn.lock:
                while not conn.requests and not conn.closed:
                    conn.cv.wait()
                if conn.closed:
                    break
                ready, line = conn.requests.popleft()
            self._stand_aside()
            if ready:
                reply = line
            else:
                try:
                    reply = self._execute(conn, line)
                except Exception as exc:  # a bug must not end the service
                    log.exception("%r: %s failed", conn, line[:60])
                    reply = format_error("internal", f"{type(exc).__name__}: {exc}")
            self._output(conn, reply)
            with conn.lock:
                conn.pending -= 1
            if conn.paused or conn.closing:  # the I/O thread resumes reading, or closes
                self._touch(conn)
        self._release(conn)

    def _release(self, conn: _Conn) -> None:
        if conn.privileged and conn.shell is not None and conn.shell_privileged:
            try:
                self.robot.release(conn.shell)
            except Exception:
                log.exception("%r: release failed", conn)
        with self._lock:
            if self._privileged is conn:
                self._privileged = None
        conn.released.set()

    def _execute(self, conn: _Conn, line: str) -> str:
        verb, rest = split_verb(line)
        if verb in _VERBS:
            return self._verb(conn, verb, rest)
        if verb != "HELP" and not (conn.privileged or self.robot.is_read_only(line)):
            self.counters["denied"] += 1
            return _denied(line)
        extra = self._help_lines(conn) if verb == "HELP" and not rest else []
        reply, end = run_shell(self._shell(conn), line, extra)
        if end:
            self._close_after_flush(conn)
        return reply

    def _shell(self, conn: _Conn) -> Any:
        if conn.shell is None or conn.shell_privileged != conn.privileged:
            runner = self.runner if conn.privileged else self.observer
            conn.shell = self.robot.make_shell(runner, io.StringIO())
            conn.shell_privileged = conn.privileged
        return conn.shell

    def _help_lines(self, conn: _Conn) -> list[str]:
        lines = [
            "server (any case): AUTH TOKEN | STATUS | SUBSCRIBE HZ | UNSUBSCRIBE | QUIT",
        ]
        if not conn.privileged:
            lines.append("read-only until AUTH: commands that change the robot get ERR denied")
        return lines
