"""A blocking client of pyrt's DAQ server (the line protocol of ``pyrt.server``).

::

    from pyrt.client import Client

    with Client.connect("127.0.0.1:5050") as c:
        c.auth(token)                   # ServerError("auth"|"busy") when refused
        c.command("P E47A")             # reply lines (text after OK), or ServerError
        print(c.command("W"))           # ['E47A']
        print(c.status().fields)        # {'position': -7046, 'target': -7046, ...}
        for s in c.subscribe(50):       # Status every 20 ms, faults as they happen
            ...

A reply is ``OK-`` continuation lines and a last ``OK`` or ``ERR <code>``
line; ``STATUS`` lines (subscription samples, pushed faults) can come
between replies and are kept for :meth:`Client.statuses`.

The server answers every request once, in the order they came.  A request
whose reply was not read (a Ctrl-C or a timeout while waiting for it) is
still owed: the client reads and sets aside every owed reply before it
sends the next request, so a reply always answers its own request
(:attr:`Client.owed`, :meth:`Client.settle`, :attr:`Client.late`).
"""

from __future__ import annotations

import socket
import time
from collections import deque
from collections.abc import Iterator
from dataclasses import dataclass, field

from pyrt.errors import PyrtError

__all__ = ["Client", "Reply", "ServerError", "Status", "parse_address", "parse_status"]

#: Longest line the client accepts from a server.
MAX_REPLY_LINE = 1 << 20
#: How many replies to abandoned requests :attr:`Client.late` keeps.
LATE_KEPT = 16
#: Longest wait for the connection and the server's greeting, seconds.
CONNECT_TIMEOUT_S = 5.0


class ServerError(PyrtError):
    """The server answered ``ERR <code> <text>`` (``lines``: output before it)."""

    def __init__(self, code: str, text: str = "", lines: list[str] | None = None):
        self.code = code
        self.text = text
        self.lines = list(lines or [])
        super().__init__(f"ERR {code}" + (f" {text}" if text else ""))


@dataclass(frozen=True)
class Reply:
    """One reply: ``ok``; ``lines`` (the text of every line); ``code`` when it failed."""

    ok: bool
    lines: list[str]
    code: str = ""
    text: str = ""


@dataclass(frozen=True)
class Status:
    """A ``STATUS`` line: a sample (``fields``, ``time_s``), or a pushed fault, end
    of a move (``stop``: how it ended) or message of the robot (``message``)."""

    raw: str
    time_s: float | None = None
    fields: dict = field(default_factory=dict)
    fault: str | None = None
    stop: str | None = None
    message: str | None = None


def _value(text: str) -> int | float | str:
    """A field's value: an integer (decimal or 0x hex), a float, or the text."""
    for parse in (int, lambda t: int(t, 0), float):
        try:
            return parse(text)
        except ValueError:
            pass
    return text


def parse_status(line: str) -> Status:
    """Parse ``STATUS t=... key=value ...``, ``STATUS FAULT <text>``, ``STATUS STOP
    <text>`` or ``STATUS MESSAGE <text>``."""
    body = line[len("STATUS"):].strip()
    if body.startswith("FAULT"):
        return Status(raw=line, fault=body[len("FAULT"):].strip())
    if body.startswith("STOP ") or body == "STOP":
        return Status(raw=line, stop=body[len("STOP"):].strip())
    if body.startswith("MESSAGE "):
        return Status(raw=line, message=body[len("MESSAGE"):].strip())
    fields: dict = {}
    for item in body.split():
        key, sep, val = item.partition("=")
        if sep:
            fields[key] = _value(val)
    t = fields.pop("t", None)
    return Status(raw=line, time_s=float(t) if isinstance(t, (int, float)) else None,
                  fields=fields)


def parse_address(
    text: str, default_host: str = "127.0.0.1", allow_zero: bool = False
) -> tuple[str, int]:
    """``[HOST:]PORT`` (``[::1]:PORT`` for IPv6) to ``(host, port)``; ValueError when bad.
    ``allow_zero``: port 0 (a server's "any free port") is accepted."""
    t = text.strip()
    host = default_host
    if t.startswith("["):
        end = t.find("]")
        if end < 0 or t[end + 1 : end + 2] != ":":
            raise ValueError(f"expected [HOST]:PORT, got {text!r}")
        host, t = t[1:end], t[end + 2 :]
    elif ":" in t:
        host, _, t = t.rpartition(":")
        host = host or default_host
    low = 0 if allow_zero else 1
    if not (t.isascii() and t.isdigit()) or not low <= int(t) <= 65535:
        raise ValueError(f"port must be {low}..65535, got {text!r}")
    return host, int(t)


class Client:
    """A connection to a pyrt server; ``timeout_s`` bounds every wait for a reply,
    ``connect_timeout_s`` (default the shorter of ``timeout_s`` and
    :data:`CONNECT_TIMEOUT_S`) the connection and the server's greeting: a
    live server greets at once, so a dead or stuck one is reported in
    seconds even when replies may take minutes (``wait``)."""

    def __init__(self, host: str, port: int, timeout_s: float = 10.0,
                 connect_timeout_s: float | None = None):
        if not timeout_s > 0:
            raise ValueError(f"timeout_s must be > 0, got {timeout_s!r}")
        self.timeout_s = timeout_s
        greet_s = (min(timeout_s, CONNECT_TIMEOUT_S) if connect_timeout_s is None
                   else connect_timeout_s)
        try:
            self._sock = socket.create_connection((host, port), timeout=greet_s)
        except ConnectionRefusedError:
            raise ConnectionRefusedError("cannot connect: connection refused (is a station "
                                         "served there with --serve?)") from None
        except TimeoutError:
            raise TimeoutError(f"cannot connect: no answer within {greet_s:g} s") from None
        except OSError as exc:
            raise OSError(f"cannot connect: {exc.strerror or exc}") from None
        self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        #: The server's ``(host, port)``.
        self.address = (host, port)
        self._buf = bytearray()
        self._statuses: deque[Status] = deque()
        #: Lines of a reply read so far (kept across an interrupted read).
        self._partial: list[str] = []
        #: Requests sent whose replies are not read yet, oldest first.
        self.owed: deque[str] = deque()
        #: Replies read for abandoned requests, ``(request, Reply)``, the latest LATE_KEPT.
        self.late: deque[tuple[str, Reply]] = deque(maxlen=LATE_KEPT)
        self.closed = False
        try:
            greeting = self._read_reply(greet_s)
        except TimeoutError:
            self.close()
            raise TimeoutError(f"no greeting from {host}:{port} within {greet_s:g} s: "
                               "the server is not serving (stopped, stuck or not pyrt)") from None
        except BaseException:
            self.close()
            raise
        if not greeting.ok:
            self.close()
            raise ServerError(greeting.code, greeting.text, greeting.lines)
        #: The server's greeting (robot, version, whether AUTH is possible).
        self.greeting = greeting.lines[-1] if greeting.lines else ""

    @classmethod
    def connect(cls, address: str, timeout_s: float = 10.0) -> Client:
        """Connect to ``[HOST:]PORT``."""
        host, port = parse_address(address)
        return cls(host, port, timeout_s)

    def __enter__(self) -> Client:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Close the connection (the server forgets privilege and subscription)."""
        if not self.closed:
            self.closed = True
            self._sock.close()

    # -- lines ---------------------------------------------------------------------

    def _readline(self, timeout_s: float | None = None) -> str:
        deadline = time.monotonic() + (self.timeout_s if timeout_s is None else timeout_s)
        while True:
            i = self._buf.find(b"\n")
            if i >= 0:
                raw = bytes(self._buf[:i])
                del self._buf[: i + 1]
                return raw.decode("utf-8", errors="replace").rstrip("\r")
            if len(self._buf) > MAX_REPLY_LINE:
                raise ServerError("protocol", "reply line too long")
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise TimeoutError("no reply from the server")
            self._sock.settimeout(remaining)
            try:
                data = self._sock.recv(65536)
            except TimeoutError:
                raise TimeoutError("no reply from the server") from None
            if not data:
                raise ConnectionError("the server closed the connection")
            self._buf += data

    def send_line(self, line: str) -> None:
        """Send one request line (no line end in it)."""
        if "\n" in line or "\r" in line:
            raise ValueError("a request is one line")
        self._sock.sendall(line.encode("utf-8") + b"\n")

    def _read_reply(self, timeout_s: float | None = None) -> Reply:
        """The next reply.  Its lines are kept in ``_partial`` as they come, so
        a read that is interrupted (Ctrl-C, a timeout) resumes where it stopped."""
        lines = self._partial
        while True:
            line = self._readline(timeout_s)
            if line.startswith("STATUS"):
                self._statuses.append(parse_status(line))
                continue
            if line.startswith("OK-"):
                lines.append(line[3:])
                continue
            self._partial = []
            if line == "OK" or line.startswith("OK "):
                if line != "OK":
                    lines.append(line[3:])
                return Reply(True, lines)
            if line.startswith("ERR"):
                _, _, rest = line.partition(" ")
                code, _, text = rest.partition(" ")
                return Reply(False, lines, code, text)
            raise ServerError("protocol", f"unexpected line {line[:80]!r}")

    # -- requests ------------------------------------------------------------------

    def settle(self, timeout_s: float | None = None) -> list[tuple[str, Reply]]:
        """Read the reply of every request still owed (see the module text);
        each is also kept in :attr:`late`.  TimeoutError when one does not come
        within ``timeout_s`` (default: the client's timeout); it stays owed."""
        done: list[tuple[str, Reply]] = []
        while self.owed:
            reply = self._read_reply(timeout_s)
            done.append((self.owed.popleft(), reply))
            self.late.append(done[-1])
        return done

    def request(self, line: str) -> Reply:
        """Send ``line``; its :class:`Reply` whether it succeeded or not.  Replies
        still owed to earlier requests are read first (:meth:`settle`)."""
        self.settle()
        self.send_line(line)
        self.owed.append(line)
        reply = self._read_reply()
        self.owed.popleft()
        return reply

    def command(self, line: str) -> list[str]:
        """Send ``line``; the reply's lines, or :class:`ServerError` for ``ERR``."""
        reply = self.request(line)
        if not reply.ok:
            raise ServerError(reply.code, reply.text, reply.lines)
        return reply.lines

    def auth(self, token: str) -> None:
        """Become the privileged client (ServerError ``auth`` or ``busy`` if refused)."""
        self.command(f"AUTH {token}")

    def status(self) -> Status:
        """The latest status sample (the ``STATUS`` request)."""
        lines = self.command("STATUS")
        return parse_status("STATUS " + (lines[-1] if lines else ""))

    def subscribe(self, hz: float, timeout_s: float | None = None) -> Iterator[Status]:
        """Subscribe at ``hz``; an iterator of :class:`Status` (see :meth:`statuses`)."""
        self.command(f"SUBSCRIBE {hz:g}")
        return self.statuses(timeout_s)

    def unsubscribe(self) -> None:
        """Stop the subscription (samples already sent are still read)."""
        self.command("UNSUBSCRIBE")

    def statuses(self, timeout_s: float | None = None) -> Iterator[Status]:
        """``STATUS`` lines as they come; ends when none comes within ``timeout_s``
        (default: the client's timeout) or the server closes."""
        while True:
            while self._statuses:
                yield self._statuses.popleft()
            try:
                if self.owed:  # a reply owed is read as a reply, not dropped as noise
                    self.settle(timeout_s)
                    continue
                line = self._readline(timeout_s)
            except (TimeoutError, ConnectionError):
                return
            if line.startswith("STATUS"):
                yield parse_status(line)
