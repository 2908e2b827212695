"""board-sim: simulated boards served over TCP, their world stepping at real time.

:class:`BoardServer` serves one :class:`~pyrt.sim.world.World` (any
station's: its boards' declared registers) on a TCP address with the wire
protocol of :mod:`pyrt.boards.wire`, so that a
controller in another process reaches the boards through the ``tcp://``
back end (:mod:`pyrt.boards.tcp`) exactly as it reaches the in-process
``sim:`` boards.

One thread does everything, in a selectors loop: it steps the world every
``step_ns`` of the monotonic clock (dt = now - last, so a late step moves
the world by the time that really passed), answers requests as they come,
and keeps the watchdog.  One controller is served at a time: a second
connection is answered ``ERR busy ...`` and closed.

Watchdog: when no register access has come for ``watchdog_s`` the world's
outputs are turned off (:meth:`~pyrt.sim.world.World.outputs_off`);
so they are at once when the controller's connection closes, whether it
said QUIT or its process died.  A bad request gets an error reply; nothing
a client sends stops the server.
"""

from __future__ import annotations

import contextlib
import selectors
import socket
import threading
import time
from collections.abc import Callable

from pyrt.boards.wire import (
    MAX_LINE,
    NOT_ACCESSES,
    Access,
    WireError,
    error_line,
    greeting_line,
    ok_line,
    parse_request,
)
from pyrt.errors import ConfigError
from pyrt.sim.world import World

__all__ = ["DEFAULT_STEP_NS", "DEFAULT_WATCHDOG_S", "BoardServer"]

DEFAULT_WATCHDOG_S = 0.5
DEFAULT_STEP_NS = 1_000_000
#: A client that leaves this much of our output unread is dropped.
MAX_PENDING_OUTPUT = 1 << 20


class _Client:
    __slots__ = ("addr", "discarding", "inbuf", "out", "quitting", "sock", "writing")

    def __init__(self, sock: socket.socket, addr: str):
        self.sock = sock
        self.addr = addr
        self.inbuf = bytearray()
        self.out = bytearray()
        self.discarding = False
        self.quitting = False
        self.writing = False


class BoardServer:
    """Serve ``world`` on ``host:port`` (port 0: any free port; see :attr:`url`).

    ``say(line)`` is told one line per event (connections, refusals, watchdog
    trips); ``clock`` is the monotonic clock in ns.  Call
    :meth:`serve_forever` (blocks until :meth:`stop`), or :meth:`start` to
    run it in a thread of its own.
    """

    def __init__(
        self,
        world: World,
        host: str = "127.0.0.1",
        port: int = 0,
        *,
        watchdog_s: float = DEFAULT_WATCHDOG_S,
        step_ns: int = DEFAULT_STEP_NS,
        say: Callable[[str], None] | None = None,
        clock: Callable[[], int] = time.monotonic_ns,
    ):
        if not 0.001 <= watchdog_s <= 3600:
            raise ConfigError(f"watchdog time must be 0.001..3600 s, got {watchdog_s!r}")
        if not 50_000 <= step_ns <= 100_000_000:
            raise ConfigError(f"world step must be 50 µs..100 ms, got {step_ns} ns")
        self.world = world
        #: The boards served (name -> kind) and their register views.
        self.kinds = dict(world.kinds)
        self._views = {name: world.registers(name) for name in self.kinds}
        self.watchdog_ns = int(watchdog_s * 1e9)
        self.step_ns = int(step_ns)
        self.report = say
        self.clock = clock
        try:
            family = socket.AF_INET6 if ":" in host else socket.AF_INET
            self._listener = socket.create_server((host, port), family=family, backlog=8)
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
        self._client: _Client | None = None
        self._sel: selectors.BaseSelector | None = None
        self._last_access = 0
        self._fed = False
        self.t0 = clock()
        #: Counters: requests answered, error replies, watchdog trips, refused connections.
        self.requests = 0
        self.errors = 0
        self.watchdog_trips = 0
        self.refused = 0
        self.steps = 0

    @property
    def url(self) -> str:
        """The back-end URL a controller opens: ``tcp://HOST:PORT``."""
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"tcp://{host}:{self.port}"

    def _say(self, line: str) -> None:
        if self.report is not None:
            try:
                self.report(line)
            except (OSError, ValueError):  # a closed log must not stop the boards
                self.report = None

    # -- running ------------------------------------------------------------------

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
        if self._client is not None:
            self._drop("server closing")
        for s in (self._listener, self._wake_r, self._wake_w):
            with contextlib.suppress(OSError):
                s.close()

    def serve_forever(self) -> None:
        """Step the world, serve requests and keep the watchdog until :meth:`stop`."""
        sel = selectors.DefaultSelector()
        self._sel = sel
        sel.register(self._listener, selectors.EVENT_READ, "listen")
        sel.register(self._wake_r, selectors.EVENT_READ, "wake")
        clock = self.clock
        step = self.step_ns
        world = self.world
        next_step = clock()
        try:
            while not self._stop.is_set():
                now = clock()
                timeout = (next_step - now) / 1e9
                for key, mask in sel.select(timeout if timeout > 0 else 0):
                    what = key.data
                    if what == "listen":
                        self._accept()
                    elif what == "wake":
                        with contextlib.suppress(OSError):
                            self._wake_r.recv(4096)
                    elif isinstance(what, _Client) and what is self._client:
                        if mask & selectors.EVENT_WRITE:
                            self._flush(what)
                        if mask & selectors.EVENT_READ and what is self._client:
                            self._read(what)
                now = clock()
                if now >= next_step:
                    world.step(now - self.t0)
                    self.steps += 1
                    next_step += step
                    if next_step <= now:  # late: skip the missed steps, never burst
                        next_step = now + step
                if self._fed and now - self._last_access > self.watchdog_ns:
                    self._watchdog(now)
        finally:
            if self._client is not None:
                self._drop("server stopping")
            sel.close()
            self._sel = None

    # -- the watchdog ----------------------------------------------------------------

    def _watchdog(self, now: int) -> None:
        self._fed = False
        self.watchdog_trips += 1
        self.world.trips += 1
        was_on = not self.world.outputs_are_off()
        self.world.outputs_off()
        if was_on:
            self._say(f"watchdog: no register access for "
                      f"{(now - self._last_access) / 1e9:.3f} s: outputs off")

    # -- connections -------------------------------------------------------------------

    def _accept(self) -> None:
        try:
            sock, peer = self._listener.accept()
        except OSError:
            return
        addr = f"{peer[0]}:{peer[1]}"
        if self._client is not None:
            self.refused += 1
            with contextlib.suppress(OSError):
                sock.setblocking(False)
                sock.send(error_line("busy", f"board-sim serves one controller at a time and "
                                             f"{self._client.addr} is connected"))
            sock.close()
            self._say(f"refused {addr}: busy with {self._client.addr}")
            return
        sock.setblocking(False)
        with contextlib.suppress(OSError):
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        client = _Client(sock, addr)
        self._client = client
        assert self._sel is not None
        self._sel.register(sock, selectors.EVENT_READ, client)
        self._say(f"controller {addr} connected")
        client.out += greeting_line(self.world.name, self.watchdog_ns // 1_000_000, self.kinds)
        self._flush(client)

    def _drop(self, why: str) -> None:
        client = self._client
        if client is None:
            return
        self._client = None
        if self._sel is not None:
            with contextlib.suppress(KeyError, ValueError):
                self._sel.unregister(client.sock)
        with contextlib.suppress(OSError):
            client.sock.close()
        self._fed = False
        was_on = not self.world.outputs_are_off()
        self.world.outputs_off()
        self._say(f"controller {client.addr} {why}"
                  + (": outputs off" if was_on else ""))

    def _read(self, client: _Client) -> None:
        try:
            data = client.sock.recv(65536)
        except (BlockingIOError, InterruptedError):
            return
        except OSError as exc:
            self._drop(f"lost ({exc.strerror or exc})")
            return
        if not data:
            self._drop("disconnected")
            return
        buf = client.inbuf
        buf += data
        while True:
            i = buf.find(b"\n")
            if i < 0:
                if len(buf) >= MAX_LINE:
                    if not client.discarding:
                        self._reply(client, error_line(
                            "too-long", f"a request is at most {MAX_LINE} bytes"))
                        client.discarding = True
                    buf.clear()
                break
            line = bytes(buf[:i])
            del buf[: i + 1]
            if client.discarding:  # the end of an over-long line
                client.discarding = False
                continue
            if i + 1 > MAX_LINE:
                self._reply(client, error_line("too-long",
                                               f"a request is at most {MAX_LINE} bytes"))
                continue
            self._reply(client, self._answer(client, line.rstrip(b"\r")))
            if client.quitting:
                break
        self._flush(client)

    def _answer(self, client: _Client, line: bytes) -> bytes:
        world = self.world
        try:
            req = parse_request(line, self.kinds)
            verb = req.verb
            if verb not in NOT_ACCESSES:
                self._last_access = self.clock()
                self._fed = True
                return self._access(req.verb, req.accesses, req.boards)
            if verb == "INFO":
                return ok_line(*(f"{k}={v}" for k, v in world.info().items()))
            client.quitting = True
            return ok_line("bye")
        except WireError as exc:
            return error_line(exc.code, exc.text)
        except ValueError as exc:
            return error_line("range", str(exc))
        except Exception as exc:  # a bug in the world: answer it, keep serving
            self._say(f"internal error on {line[:60]!r}: {type(exc).__name__}: {exc}")
            return error_line("internal", f"{type(exc).__name__}: {exc}")

    def _access(self, verb: str, accesses: tuple[Access, ...], boards: tuple[str, ...]) -> bytes:
        views = self._views
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

    def _reply(self, client: _Client, line: bytes) -> None:
        self.requests += 1
        if line.startswith(b"ERR"):
            self.errors += 1
        client.out += line

    def _flush(self, client: _Client) -> None:
        if client is not self._client:
            return
        out = client.out
        try:
            while out:
                n = client.sock.send(out)
                del out[:n]
        except (BlockingIOError, InterruptedError):
            pass
        except OSError as exc:
            self._drop(f"lost ({exc.strerror or exc})")
            return
        if client.quitting and not out:
            self._drop("said QUIT")
            return
        if len(out) > MAX_PENDING_OUTPUT:
            self._drop("does not read its replies")
            return
        writing = bool(out)
        if writing != client.writing:  # wait for room to write only while output waits
            client.writing = writing
            assert self._sel is not None
            events = selectors.EVENT_READ | (selectors.EVENT_WRITE if writing else 0)
            with contextlib.suppress(KeyError, ValueError):
                self._sel.modify(client.sock, events, client)
