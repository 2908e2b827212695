"""Line framing (I/O thread): bytes from a socket into request lines, within
the line limit and the server's rate budget; end of input and over-long lines.

A request is a line ended by ``\\n`` (a ``\\r`` before it is dropped); a line
longer than ``max_line`` bytes gets ``ERR too-long`` and closes the
connection; a half line left at end of input is discarded, never run.
"""

from __future__ import annotations

from pyrt.server.connection import Connection
from pyrt.server.protocol import format_error
from pyrt.server.state import ServerState

__all__ = ["FramingMixin"]


class FramingMixin(ServerState):
    """The framing part of :class:`~pyrt.server.Server` (see the module text)."""

    def _on_readable(self, conn: Connection) -> None:
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

    def _parse(self, conn: Connection) -> None:
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

    def _too_long(self, conn: Connection) -> None:
        self.counters["too_long"] += 1
        conn.inbuf.clear()
        self._output(conn, format_error("too-long", f"request lines are at most {self.max_line} "
                                        "bytes; closing"))
        self._close_after_flush(conn)
