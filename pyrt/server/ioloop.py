"""The I/O thread (``selectors``): accept, read, write, flush, hand
subscription samples on, time out idle connections, stand aside for the loop.

One thread owns every socket; a slow or dead peer can only fill its own
bounded output buffer and is dropped when that is full, so nothing it does
can stall another client, the commands or the loop.  On a wall clock the
thread stands aside from just before each tick until the tick has run.
"""

from __future__ import annotations

import contextlib
import logging
import os
import selectors
import socket
import threading
import time
from typing import Any

from pyrt._version import __version__
from pyrt.server.connection import Connection
from pyrt.server.limits import (
    GUARD_NS,
    GUARD_POLL_S,
    LINGER_S,
    PUMP_S,
    RATE_WINDOW_S,
    address_is_loopback,
    lower_priority,
)
from pyrt.server.protocol import format_error, format_reply
from pyrt.server.state import ServerState

__all__ = ["IOLoopMixin"]

log = logging.getLogger("pyrt.server")


class IOLoopMixin(ServerState):
    """The I/O-thread part of :class:`~pyrt.server.Server` (see the module text)."""

    def _wake(self) -> None:
        with contextlib.suppress(OSError):  # a full pipe is already a wake-up
            os.write(self._wake_w, b"\0")


    # -- the I/O thread --------------------------------------------------------------

    def _io_main(self) -> None:
        lower_priority(self.nice)
        try:
            self._io_loop()
        except BaseException as exc:  # a bug outside any one client's handling
            if not self._stopping:
                self._died(exc)
        finally:
            for conn in list(self._conns.values()):
                with contextlib.suppress(Exception):
                    self._finish(conn)

    def _io_loop(self) -> None:
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
                        try:
                            self._parse(conn)
                            self._set_events(conn)
                        except Exception as exc:
                            self._client_failed(conn, exc)
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
                    try:
                        if mask & selectors.EVENT_READ:
                            self._on_readable(data)
                        if mask & selectors.EVENT_WRITE and not data.closed:
                            self._flush(data)
                    except Exception as exc:
                        self._client_failed(data, exc)
            if self.hub.events:
                self._pump()
            self._service_dirty()
            now = time.monotonic()
            if now >= next_check:
                next_check = now + 0.1
                self._check_timeouts(now)
                self.guard.flush()

    def _client_failed(self, conn: Connection, exc: BaseException) -> None:
        """A bug met while handling ``conn`` (any server thread): that client is
        closed with ``ERR internal`` and the traceback goes to the log; the
        server, and every other client, go on."""
        self.counters["internal"] += 1
        log.error("%r: a bug in pyrt handling this client; it is closed, the server goes on",
                  conn, exc_info=exc)
        if conn.failed:  # failing again: close at once, without a reply
            with conn.lock:
                conn.drop = conn.drop or "a bug in pyrt handling it"
            with contextlib.suppress(Exception):
                self._touch(conn)
            return
        conn.failed = True
        try:
            self._output(conn, format_error(
                "internal", f"{type(exc).__name__} (a bug in pyrt; the server log has the "
                "traceback); closing this connection"))
            self._close_after_flush(conn)
        except Exception:
            with conn.lock:
                conn.drop = "a bug in pyrt handling it"
            with contextlib.suppress(Exception):
                self._touch(conn)

    def _died(self, exc: BaseException) -> None:
        """The I/O thread itself has failed: nobody can reach the station over
        the network any more, a fault the operator must see.  The station is
        tripped (every motor stopped), naming the server."""
        self.crashed = exc
        log.critical("the DAQ server has stopped: a bug in pyrt", exc_info=exc)
        listener = self._listener
        if listener is not None:  # refuse newcomers at once rather than leave them unanswered
            with contextlib.suppress(Exception):
                assert self._sel is not None
                self._sel.unregister(listener)
            with contextlib.suppress(OSError):
                listener.close()
        cause = (f"the DAQ server has stopped ({type(exc).__name__}: {exc}; a bug in pyrt): "
                 "no client can reach the station")
        with contextlib.suppress(Exception):
            self.runner.call(self.robot.station.trip, cause[:300], "server", take_fault=False,
                             name="server stopped")

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
            try:
                self._greet(sock, peer)
            except Exception as exc:
                self.counters["internal"] += 1
                log.error("a bug in pyrt accepting %s; that connection is closed", peer,
                          exc_info=exc)
                with contextlib.suppress(OSError):
                    sock.close()

    def _greet(self, sock: socket.socket, peer: Any) -> None:
        """Admit a new connection (or refuse it) and greet it."""
        reserve, refusal = self._admit(peer)
        if reserve is None:
            log.warning("refused %s: %s", peer, refusal)
            with contextlib.suppress(OSError):
                sock.setblocking(False)
                sock.send(format_error("full", refusal).encode())
            sock.close()
            return
        sock.setblocking(False)
        with contextlib.suppress(OSError):
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        conn = Connection(self._next_id, sock, peer)
        conn.reserve = reserve
        self._next_id += 1
        self._conns[conn.id] = conn
        self.counters["accepted"] += 1
        assert self._sel is not None
        self._sel.register(sock, selectors.EVENT_READ, conn)
        conn.events = selectors.EVENT_READ
        who = "AUTH to command" if self._token is not None else "no token: status only"
        if reserve:
            self.counters["reserve"] += 1
            who = f"{self.max_clients} clients already: a reserved slot, AUTH or stop only"
        self._output(conn, format_reply(
            [f"pyrt {__version__} {self.robot.name} server; {who}; HELP lists the commands"]
        ))
        log.info("%r connected%s", conn, " (reserved slot)" if reserve else "")

    def _admit(self, peer: Any) -> tuple[bool | None, str]:
        """Where a new connection from ``peer`` goes: a slot (False), a reserved
        slot (True), or nowhere (None, and why)."""
        addr = str(peer[0]) if isinstance(peer, tuple) and peer else str(peer)
        conns = list(self._conns.values())
        if not (self.exempt_loopback and address_is_loopback(addr)):
            fresh = sum(1 for c in conns if c.fresh and not c.closing and c.addr == addr)
            if fresh >= self.max_fresh_per_address:
                self.counters["refused_address"] += 1
                return None, (f"{fresh} connections from {addr} have sent nothing yet; "
                              "send a request on one of them first")
        regular = sum(1 for c in conns if not c.reserve and not c.closing)
        if regular < self.max_clients:
            return False, ""
        victim = self._evictable(conns, reserve=False)
        if victim is not None:
            self._evict(victim)
            return False, ""
        if sum(1 for c in conns if c.reserve and not c.closing) < self.reserved_slots:
            return True, ""
        victim = self._evictable(conns, reserve=True)
        if victim is not None:
            self._evict(victim)
            return True, ""
        self.counters["refused_full"] += 1
        return None, f"{self.max_clients} clients already and every reserved slot in use"

    def _evictable(self, conns: list[Connection], reserve: bool) -> Connection | None:
        """The connection a newcomer may replace: the oldest that has sent
        nothing, else the unprivileged, unsubscribed one idle longest (at
        least ``evict_idle_s``), else the unprivileged subscriber that has
        had neither a request nor a sample for longest (at least
        ``evict_idle_s``: a subscription too slow to be in use); never the
        privileged one or one with work in hand."""
        mine = [c for c in conns if c.reserve == reserve and not c.closing and not c.closed
                and not c.privileged and c.pending == 0]
        fresh = [c for c in mine if c.fresh and not c.subscribed]
        if fresh:
            return min(fresh, key=lambda c: c.connected_at)
        limit = time.monotonic() - self.evict_idle_s
        idle = [c for c in mine if not c.subscribed and c.last_active <= limit]
        if idle:
            return min(idle, key=lambda c: c.last_active)
        quiet = [c for c in mine if c.subscribed and max(c.last_active, c.last_sample) <= limit]
        return min(quiet, key=lambda c: max(c.last_active, c.last_sample)) if quiet else None

    def _evict(self, conn: Connection) -> None:
        """Close ``conn`` at once for a newcomer: one ``ERR full`` line, sent
        if the socket takes it, no lingering (a flood must not hold descriptors)."""
        self.counters["evicted"] += 1
        quiet = time.monotonic() - max(conn.last_active, conn.last_sample)
        why = ("sent nothing" if conn.fresh
               else f"had no sample and sent no request for {quiet:.0f} s" if conn.subscribed
               else f"no request for {time.monotonic() - conn.last_active:.0f} s")
        log.info("%r evicted: the server is full and it %s", conn, why)
        text = format_error("full", f"{self.max_clients} clients already; this connection "
                            f"{why}: closed for a newcomer")
        with conn.lock:
            data = bytes(conn.out) + text.encode()
        with contextlib.suppress(OSError):
            conn.sock.send(data)
        self._end(conn)
        self._finish(conn)

    def _set_events(self, conn: Connection) -> None:
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

    def _output(self, conn: Connection, text: str) -> None:
        """Queue ``text`` for ``conn`` (any thread); a full buffer drops the client."""
        data = text.encode("utf-8")
        with conn.lock:
            if conn.closed or conn.drop:
                return
            if len(conn.out) + len(data) > self.max_output:
                conn.drop = f"slow reader: more than {self.max_output} bytes unread"
                conn.out.clear()
            else:
                if not conn.out:  # the peer has everything so far: its clock starts now
                    conn.last_sent = time.monotonic()
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
            try:
                self._flush(conn)
                if resume and not conn.closed:
                    self._parse(conn)
                    self._set_events(conn)
            except Exception as exc:
                self._client_failed(conn, exc)

    def _flush(self, conn: Connection) -> None:
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
                    conn.last_sent = time.monotonic()
            else:
                n = 0
        if n < 0:
            self._drop(conn, "connection reset")
            return
        self._set_events(conn)

    def _pump(self) -> None:
        """Hand subscription samples, faults, ends of moves and messages on to the
        subscribers."""
        fmt = self.robot.format_status
        conns = self._conns
        now = time.monotonic()
        for n, (kind, key, t_ns, payload) in enumerate(self.hub.drain()):
            if n & 63 == 63:
                self._stand_aside()
            if kind == "sample":
                conn = conns.get(key)
                if conn is not None and conn.subscribed:
                    try:
                        self._output(conn, f"STATUS t={t_ns / 1e9:.6f} {fmt(payload)}\n")
                        conn.last_sample = now
                    except Exception as exc:
                        self._client_failed(conn, exc)
            else:
                if kind == "stop":  # a move ended: its reason, once
                    text = f"STATUS STOP {payload.reason}"
                elif kind == "message":
                    text = f"STATUS MESSAGE {payload.source} {payload.level}: {payload.text}"
                else:
                    text = f"STATUS FAULT {payload}"
                line = "".join(c if c.isprintable() else " " for c in text) + "\n"
                for conn in list(conns.values()):
                    if conn.subscribed:
                        self._output(conn, line)

    def _check_timeouts(self, now: float) -> None:
        for conn in list(self._conns.values()):
            if conn.closed:
                continue
            try:
                self._check_timeout(conn, now)
            except Exception as exc:
                self._client_failed(conn, exc)

    def _check_timeout(self, conn: Connection, now: float) -> None:
        """Close ``conn`` if it has been idle, or has taken no byte of its
        replies, too long (the I/O thread, every 0.1 s)."""
        if conn.out and now - conn.last_sent > self.write_stall_s:
            self.counters["dropped_slow"] += 1
            self._drop(conn, f"silent reader: no byte taken for {self.write_stall_s:g} s")
            return
        if conn.linger_until:
            if now >= conn.linger_until:
                self._finish(conn)
            return
        if conn.closing or conn.subscribed or conn.pending:
            return
        if conn.privileged:
            bound, what, since = self.idle_timeout_s, "no request", conn.last_active
        elif conn.fresh or conn.reserve:
            bound, what = self.greeting_timeout_s, "no request"
            since = conn.connected_at if conn.fresh else conn.last_active
        else:
            bound, what = self.guest_idle_s, "unprivileged: no request"
            since = conn.last_active
        if now - since > bound:
            self.counters["idle"] += 1
            self._output(conn, format_error("idle", f"{what} for {bound:g} s; closing"))
            self._close_after_flush(conn)

    def _close_after_flush(self, conn: Connection) -> None:
        self._end(conn)
        self._touch(conn)

    def _touch(self, conn: Connection) -> None:
        """Have the I/O thread look at ``conn`` again (after the current request)."""
        with conn.lock:
            if conn.dirty or conn.closed:
                return
            conn.dirty = True
        self._dirty.append(conn)
        if threading.current_thread() is not self._thread:
            self._wake()

    def _end(self, conn: Connection) -> None:
        """Read and run nothing more from ``conn``; close once its replies are out."""
        with conn.lock:
            conn.closing = conn.stop_requests = True
            conn.pending -= len(conn.requests)  # queued, not started: never run
            conn.requests.clear()

    def _drop(self, conn: Connection, why: str) -> None:
        log.info("%r dropped: %s", conn, why)
        self._end(conn)
        self._finish(conn)

    def _finish(self, conn: Connection) -> None:
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
