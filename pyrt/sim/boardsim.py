"""board-sim: simulated boards served over TCP, their world stepping at real time.

:class:`BoardServer` serves one :class:`~pyrt.sim.world.World` (any
station's: its boards' declared registers) on a TCP address with the wire
protocol of :mod:`pyrt.boards.wire`, so that a
controller in another process reaches the boards through the ``tcp://``
back end (:mod:`pyrt.boards.tcp`) exactly as it reaches the in-process
``sim:`` boards.  :class:`~pyrt.sim.modbusserver.ModbusBoardServer` serves
the same world over Modbus TCP; both are a :class:`LinkServer`, which does
what is common to them:

One thread does everything, in a selectors loop: it steps the world every
``step_ns`` of the monotonic clock (dt = now - last, so a late step moves
the world by the time that really passed), answers requests as they come
(every complete request in what arrived, so pipelined requests all get
their replies, in order), and keeps the watchdog.

One owner, any readers.  A board has one owning controller: the
connection that claims the outputs (``OWN`` on the wire; its first write
claims them too, on either protocol) while no other holds them.  Any other
connection may read (an HMI, a logger, a tool); its write is refused
(``ERR busy`` on the wire, exception 06 over Modbus) and changes nothing.
An owner that has been silent for longer than the watchdog time (its
outputs are off already) is displaced by the next connection that claims
them: a dead controller's half-open socket never keeps the next one out.

Watchdog, fed only by the owner.  Every register access of the owning
connection (its writes, and its reads: the keep-alive of its session)
feeds the watchdog; a reader's never does.  When the owner has made none
for ``watchdog_s`` the world's outputs are turned off
(:meth:`~pyrt.sim.world.World.outputs_off`); so they are at once when the
owner's connection closes, whether it said goodbye or its process died,
whoever else is connected and polling.

Connections.  At most ``max_clients`` are held: a newcomer when all are
taken closes the reader that has been idle longest (never the owner), so
a controller always gets in.  A connection that completes no request for
``idle_s`` (idle, or half-open: a client gone without a word, or one that
stopped in the middle of a request) is closed.  A client that leaves
:data:`MAX_PENDING_OUTPUT` of replies unread is dropped.  A bad request
gets an error reply; nothing a client sends stops the server.
"""

from __future__ import annotations

import contextlib
import selectors
import socket
import struct
import threading
import time
from collections.abc import Callable
from typing import Any

from pyrt.boards.wire import (
    MAX_LINE,
    NOT_ACCESSES,
    PUSH,
    Access,
    WireError,
    error_line,
    greeting_line,
    ok_line,
    parse_request,
    snapshot_line,
    snapshot_struct,
)
from pyrt.errors import ConfigError
from pyrt.sim.world import World

__all__ = [
    "DEFAULT_IDLE_S",
    "DEFAULT_MAX_CLIENTS",
    "DEFAULT_STEP_NS",
    "DEFAULT_WATCHDOG_S",
    "BoardServer",
    "Connection",
    "LinkServer",
]

DEFAULT_WATCHDOG_S = 0.5
DEFAULT_STEP_NS = 1_000_000
#: A connection that completes no request for this long is closed.
DEFAULT_IDLE_S = 30.0
#: The most connections held at once (the owner and the readers).
DEFAULT_MAX_CLIENTS = 8
#: A client that leaves this much of our output unread is dropped.
MAX_PENDING_OUTPUT = 1 << 20
#: How often idle connections are looked for.
_SWEEP_NS = 20_000_000
#: select() watches descriptors below this (FD_SETSIZE).
_SELECT_FDS = 1024


def _moved(old: selectors.BaseSelector, new: selectors.BaseSelector) -> selectors.BaseSelector:
    """``new`` watching what ``old`` did (``old`` closed)."""
    for key in list(old.get_map().values()):
        new.register(key.fileobj, key.events, key.data)
    old.close()
    return new


class Connection:
    """One client's connection: its socket, what came and what goes out."""

    __slots__ = ("addr", "discarding", "gone", "inbuf", "last_ns", "out", "quitting", "sock",
                 "stream", "stream_until", "told", "writing")

    def __init__(self, sock: socket.socket, addr: str, now: int):
        self.sock = sock
        self.addr = addr
        self.inbuf = bytearray()
        self.out = bytearray()
        #: When its last complete request came (or it connected): the idle timeout's start.
        self.last_ns = now
        self.discarding = False
        self.quitting = False
        self.writing = False
        self.gone = False
        #: Whether a refusal (busy) was said about it already (said once per connection).
        self.told = False
        #: Its stream (wire ``STREAM``): the boards pushed after every world step, until
        #: ``stream_until`` (the server's clock; 0: none).
        self.stream: tuple[str, ...] = ()
        self.stream_until = 0


class LinkServer:
    """What board-sim's servers share (see the module text): the socket loop, the
    world stepping, the owner and its watchdog, idle and surplus connections.

    A subclass gives :meth:`greeting` and :meth:`consume` (the requests in a
    connection's :attr:`Connection.inbuf`, replies appended to its ``out``),
    calling :meth:`claim` before a write and :meth:`feed` on every register
    access.
    """

    def __init__(
        self,
        world: World,
        host: str = "127.0.0.1",
        port: int = 0,
        *,
        watchdog_s: float = DEFAULT_WATCHDOG_S,
        step_ns: int = DEFAULT_STEP_NS,
        idle_s: float = DEFAULT_IDLE_S,
        max_clients: int = DEFAULT_MAX_CLIENTS,
        say: Callable[[str], None] | None = None,
        clock: Callable[[], int] = time.monotonic_ns,
    ):
        if not 0.001 <= watchdog_s <= 3600:
            raise ConfigError(f"watchdog time must be 0.001..3600 s, got {watchdog_s!r}")
        if not 50_000 <= step_ns <= 100_000_000:
            raise ConfigError(f"world step must be 50 µs..100 ms, got {step_ns} ns")
        if not 0.01 <= idle_s <= 86400:
            raise ConfigError(f"idle time must be 0.01..86400 s, got {idle_s!r}")
        if isinstance(max_clients, bool) or not isinstance(max_clients, int) \
                or not 2 <= max_clients <= 1024:
            raise ConfigError(f"the most clients must be 2..1024 (the owner and at least one "
                              f"reader), got {max_clients!r}")
        self.world = world
        #: The boards served (name -> kind) and their register views.
        self.kinds = dict(world.kinds)
        self.views = {name: world.registers(name) for name in self.kinds}
        self.watchdog_ns = int(watchdog_s * 1e9)
        self.idle_ns = int(idle_s * 1e9)
        self.max_clients = max_clients
        self.step_ns = int(step_ns)
        self.report = say
        self.clock = clock
        try:
            family = socket.AF_INET6 if ":" in host else socket.AF_INET
            self._listener = socket.create_server((host, port), family=family,
                                                  backlog=64)
        except OSError as exc:
            raise ConfigError(f"board-sim cannot listen on {host}:{port}: "
                              f"{exc.strerror or exc}") from None
        self._listener.setblocking(False)
        bound = self._listener.getsockname()
        self.host, self.port = bound[0], bound[1]
        self._wake_r, self._wake_w = socket.socketpair()
        self._wake_r.setblocking(False)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._conns: list[Connection] = []
        self._owner: Connection | None = None
        self._sel: selectors.BaseSelector | None = None
        self._last_access = 0
        self._fed = False
        self.t0 = clock()
        #: Counters: requests answered, error replies, watchdog trips, refused claims
        #: (busy), connections closed idle and to make room, world steps.
        self.requests = 0
        self.errors = 0
        self.watchdog_trips = 0
        self.refused = 0
        self.timed_out = 0
        self.evicted = 0
        self.steps = 0

    # -- what a subclass gives --------------------------------------------------------------

    def greeting(self) -> bytes:
        """What the server says first on a new connection (nothing by default)."""
        return b""

    def consume(self, conn: Connection) -> None:
        """Answer the complete requests in ``conn.inbuf`` (removing them), each
        reply appended to ``conn.out``; call :meth:`came` for each."""
        raise NotImplementedError

    def stepped(self, now: int) -> None:
        """The world has just stepped (at ``now``): nothing by default (board-sim's
        wire pushes its streams here)."""

    # -- state -------------------------------------------------------------------------------

    @property
    def alive(self) -> bool:
        """Whether the thread :meth:`start` made still serves."""
        return self._thread is not None and self._thread.is_alive()

    @property
    def owner(self) -> str | None:
        """The address of the connection that owns the outputs, or None."""
        return self._owner.addr if self._owner is not None else None

    @property
    def clients(self) -> int:
        """How many connections are held."""
        return len(self._conns)

    def _say(self, line: str) -> None:
        if self.report is not None:
            try:
                self.report(line)
            except (OSError, ValueError):  # a closed log must not stop the boards
                self.report = None

    # -- the owner and the watchdog ------------------------------------------------------------

    def came(self, conn: Connection) -> None:
        """A complete request came on ``conn``: its idle time starts again."""
        conn.last_ns = self.clock()

    def claim(self, conn: Connection) -> str | None:
        """Make ``conn`` the owner of the outputs: None if it is (or now is), else
        why not (another owner is alive: it fed the watchdog within its time)."""
        owner = self._owner
        if owner is conn:
            return None
        now = self.clock()
        if owner is not None:
            silent = now - self._last_access
            if silent <= self.watchdog_ns:
                self.refused += 1
                if not conn.told:
                    conn.told = True
                    self._say(f"refused {conn.addr}: {owner.addr} owns the outputs")
                return (f"{owner.addr} owns the outputs (one controller at a time; "
                        "reading is open to all)")
            self._drop(owner, f"displaced by {conn.addr} (silent for {silent / 1e9:.3f} s)")
        self._owner = conn
        self._last_access = now
        self._say(f"controller {conn.addr} owns the outputs")
        return None

    def feed(self, conn: Connection) -> None:
        """A register access on ``conn``: the watchdog starts again if it is the owner's."""
        if conn is self._owner:
            self._last_access = self.clock()
            self._fed = True

    def _watchdog(self, now: int) -> None:
        self._fed = False
        self.watchdog_trips += 1
        self.world.trips += 1
        was_on = not self.world.outputs_are_off()
        self.world.outputs_off()
        if was_on:
            self._say(f"watchdog: no register access for "
                      f"{(now - self._last_access) / 1e9:.3f} s: outputs off")

    # -- running ---------------------------------------------------------------------------

    def start(self) -> threading.Thread:
        """Serve in a daemon thread; returns it."""
        t = threading.Thread(target=self.serve_forever, name="board-sim", daemon=True)
        self._thread = t
        t.start()
        return t

    def stop(self) -> None:
        """Ask :meth:`serve_forever` to return (thread-safe)."""
        self._stop.set()
        with contextlib.suppress(OSError):
            self._wake_w.send(b"x")

    def close(self) -> None:
        """Stop, join the thread if :meth:`start` made one, turn the outputs off
        and close every socket."""
        self.stop()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(5.0)
        for conn in list(self._conns):
            self._drop(conn, "closed: server closing")
        self.world.outputs_off()
        for s in (self._listener, self._wake_r, self._wake_w):
            with contextlib.suppress(OSError):
                s.close()

    def serve_forever(self) -> None:
        """Step the world, serve requests and keep the watchdog until :meth:`stop`."""
        # select() waits to the µs, so the world steps on time (epoll and poll wait
        # whole milliseconds: a step every 1 ms would come up to 1 ms late); it
        # watches descriptors below FD_SETSIZE only, so epoll serves beyond that
        fine = max(self._listener.fileno(), self._wake_r.fileno()) < _SELECT_FDS
        sel = selectors.SelectSelector() if fine else selectors.DefaultSelector()
        self._sel = sel
        sel.register(self._listener, selectors.EVENT_READ, "listen")
        sel.register(self._wake_r, selectors.EVENT_READ, "wake")
        clock = self.clock
        step = self.step_ns
        world = self.world
        next_step = next_sweep = clock()
        try:
            while not self._stop.is_set():
                now = clock()
                timeout = (next_step - now) / 1e9
                sel = self._sel
                for key, mask in sel.select(timeout if timeout > 0 else 0):
                    what = key.data
                    if what == "listen":
                        self._accept()
                    elif what == "wake":
                        with contextlib.suppress(OSError):
                            self._wake_r.recv(4096)
                    elif isinstance(what, Connection) and not what.gone:
                        if mask & selectors.EVENT_WRITE:
                            self._flush(what)
                        if mask & selectors.EVENT_READ and not what.gone:
                            self._read(what)
                now = clock()
                if now >= next_step:
                    world.step(now - self.t0)
                    self.steps += 1
                    self.stepped(now)
                    next_step += step
                    if next_step <= now:  # late: skip the missed steps, never burst
                        next_step = now + step
                if self._fed and now - self._last_access > self.watchdog_ns:
                    self._watchdog(now)
                if now >= next_sweep:
                    next_sweep = now + _SWEEP_NS
                    self._sweep(now)
        finally:
            for conn in list(self._conns):
                self._drop(conn, "closed: server stopping")
            world.outputs_off()
            self._sel.close()
            self._sel = None

    # -- connections -------------------------------------------------------------------

    def _sweep(self, now: int) -> None:
        for conn in list(self._conns):
            idle = now - conn.last_ns
            if idle > self.idle_ns:
                self.timed_out += 1
                self._drop(conn, f"closed: no complete request for {idle / 1e9:.1f} s")

    def _accept(self) -> None:
        for _ in range(64):  # what the backlog holds, and no more per pass: the world steps on
            try:
                sock, peer = self._listener.accept()
            except OSError:
                return
            self._admit(sock, peer)

    def _admit(self, sock: socket.socket, peer: tuple) -> None:
        addr = f"{peer[0]}:{peer[1]}"
        if len(self._conns) >= self.max_clients:
            readers = [c for c in self._conns if c is not self._owner]
            victim = min(readers, key=lambda c: c.last_ns)
            self.evicted += 1
            self._drop(victim, f"closed to make room for {addr} "
                               f"(at most {self.max_clients} connections)")
        sock.setblocking(False)
        with contextlib.suppress(OSError):
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        conn = Connection(sock, addr, self.clock())
        self._conns.append(conn)
        assert self._sel is not None
        if sock.fileno() >= _SELECT_FDS and isinstance(self._sel, selectors.SelectSelector):
            self._sel = _moved(self._sel, selectors.DefaultSelector())
        self._sel.register(sock, selectors.EVENT_READ, conn)
        self._say(f"client {addr} connected")
        conn.out += self.greeting()
        self._flush(conn)

    def _drop(self, conn: Connection, why: str) -> None:
        if conn.gone:
            return
        conn.gone = True
        with contextlib.suppress(ValueError):
            self._conns.remove(conn)
        if self._sel is not None:
            with contextlib.suppress(KeyError, ValueError):
                self._sel.unregister(conn.sock)
        with contextlib.suppress(OSError):
            conn.sock.close()
        if conn is not self._owner:
            self._say(f"client {conn.addr} {why}")
            return
        self._owner = None
        self._fed = False
        was_on = not self.world.outputs_are_off()
        self.world.outputs_off()
        self._say(f"controller {conn.addr} {why}" + (": outputs off" if was_on else ""))

    def _read(self, conn: Connection) -> None:
        try:
            data = conn.sock.recv(65536)
        except (BlockingIOError, InterruptedError):
            return
        except OSError as exc:
            self._drop(conn, f"lost ({exc.strerror or exc})")
            return
        if not data:
            self._drop(conn, "disconnected")
            return
        conn.inbuf += data
        self.consume(conn)
        if not conn.gone:
            self._flush(conn)

    def _flush(self, conn: Connection) -> None:
        if conn.gone:
            return
        out = conn.out
        try:
            while out:
                n = conn.sock.send(out)
                del out[:n]
        except (BlockingIOError, InterruptedError):
            pass
        except OSError as exc:
            self._drop(conn, f"lost ({exc.strerror or exc})")
            return
        if conn.quitting and not out:
            self._drop(conn, "said QUIT")
            return
        if len(out) > MAX_PENDING_OUTPUT:
            self._drop(conn, "does not read its replies")
            return
        writing = bool(out)
        if writing != conn.writing:  # wait for room to write only while output waits
            conn.writing = writing
            assert self._sel is not None
            events = selectors.EVENT_READ | (selectors.EVENT_WRITE if writing else 0)
            with contextlib.suppress(KeyError, ValueError):
                self._sel.modify(conn.sock, events, conn)


class BoardServer(LinkServer):
    """Serve ``world`` on ``host:port`` with the wire protocol (port 0: any free
    port; see :attr:`url`).

    ``say(line)`` is told one line per event (connections, the owner, refusals,
    watchdog trips); ``clock`` is the monotonic clock in ns; ``idle_s`` and
    ``max_clients`` bound the connections (see the module text).  Call
    :meth:`serve_forever` (blocks until :meth:`stop`), or :meth:`start` to
    run it in a thread of its own.
    """

    def __init__(self, world: World, host: str = "127.0.0.1", port: int = 0,
                 **options: Any):
        super().__init__(world, host, port, **options)
        #: The packed form's layout of each set of boards asked for (wire ``SNAPX``).
        self._layouts: dict[tuple[str, ...], struct.Struct] = {}

    @property
    def url(self) -> str:
        """The back-end URL a controller opens: ``tcp://HOST:PORT``."""
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"tcp://{host}:{self.port}"

    def greeting(self) -> bytes:
        return greeting_line(self.world.name, self.watchdog_ns // 1_000_000, self.kinds)

    def _layout(self, boards: tuple[str, ...]) -> struct.Struct:
        layout = self._layouts.get(boards)
        if layout is None:
            layout = self._layouts[boards] = snapshot_struct(self.kinds, boards)
        return layout

    def _packed(self, boards: tuple[str, ...], head: bytes) -> bytes:
        views = self.views
        values: list[int] = []
        for name in boards or views:
            values += views[name].snapshot()
        return snapshot_line(self._layout(boards), self.world.trips, values, head)

    def stepped(self, now: int) -> None:
        pushed: dict[tuple[str, ...], bytes] = {}
        for conn in self._conns:
            until = conn.stream_until
            if not until or conn.quitting:
                continue
            if now >= until:
                conn.stream_until = 0
                continue
            if conn.out:  # it has not taken what went before: skip, never queue
                continue
            line = pushed.get(conn.stream)
            if line is None:
                try:
                    line = pushed[conn.stream] = self._packed(conn.stream, PUSH)
                except Exception as exc:  # a bug in the world: say it, stop the stream
                    conn.stream_until = 0
                    self._say(f"internal error pushing to {conn.addr}: "
                              f"{type(exc).__name__}: {exc}")
                    continue
            conn.out += line
            self._flush(conn)

    def consume(self, conn: Connection) -> None:
        buf = conn.inbuf
        while not conn.quitting:
            i = buf.find(b"\n")
            if i < 0:
                if len(buf) >= MAX_LINE:
                    if not conn.discarding:
                        self._reply(conn, error_line(
                            "too-long", f"a request is at most {MAX_LINE} bytes"))
                        conn.discarding = True
                    buf.clear()
                break
            line = bytes(buf[:i])
            del buf[: i + 1]
            self.came(conn)
            if conn.discarding:  # the end of an over-long line
                conn.discarding = False
                continue
            if i + 1 > MAX_LINE:
                self._reply(conn, error_line("too-long",
                                             f"a request is at most {MAX_LINE} bytes"))
                continue
            self._reply(conn, self._answer(conn, line.rstrip(b"\r")))
            if conn.gone:
                return

    def _answer(self, conn: Connection, line: bytes) -> bytes:
        world = self.world
        try:
            req = parse_request(line, self.kinds)
            verb = req.verb
            if verb in ("W", "OWN"):
                busy = self.claim(conn)
                if busy is not None:
                    return error_line("busy", busy)
            if verb not in NOT_ACCESSES:
                self.feed(conn)
                if verb == "OWN":
                    return b"OK\n"
                if verb == "STREAM":
                    conn.stream = req.boards
                    conn.stream_until = self.clock() + req.ms * 1_000_000 if req.ms else 0
                    return ok_line(self.step_ns // 1000)
                return self._access(req.verb, req.accesses, req.boards)
            if verb == "INFO":
                return ok_line(*(f"{k}={v}" for k, v in world.info().items()))
            conn.quitting = True
            return ok_line("bye")
        except WireError as exc:
            return error_line(exc.code, exc.text)
        except ValueError as exc:
            return error_line("range", str(exc))
        except Exception as exc:  # a bug in the world: answer it, keep serving
            self._say(f"internal error on {line[:60]!r}: {type(exc).__name__}: {exc}")
            return error_line("internal", f"{type(exc).__name__}: {exc}")

    def _access(self, verb: str, accesses: tuple[Access, ...], boards: tuple[str, ...]) -> bytes:
        views = self.views
        if verb == "SNAPX":
            return self._packed(boards, b"OK ")
        if verb == "SNAP":
            values: list[int] = [self.world.trips]
            for name in boards or views:
                values += views[name].snapshot()
            return ok_line(*values)
        if verb == "R":
            a = accesses[0]
            return ok_line(views[a.board].read(a.register, a.index))
        n = len(accesses)
        for k, a in enumerate(accesses, 1):
            assert a.value is not None
            try:
                views[a.board].write(a.register, a.value, a.index)
            except ValueError as exc:
                if n == 1:
                    raise
                raise ValueError(f"write {k} of {n}: {exc}") from None
        return b"OK\n"

    def _reply(self, conn: Connection, line: bytes) -> None:
        self.requests += 1
        if line.startswith(b"ERR"):
            self.errors += 1
        conn.out += line
