"""The ``tcp://HOST:PORT`` back end: the boards of ``pyrt board-sim`` in another process.

Every register access is a read or write of a declared register, one
request line and one reply line on a TCP connection (:mod:`pyrt.boards.wire`).
:class:`TcpRegisters` is the client of one connection;
:class:`TcpBoardRegisters` the register view of one of its boards (``read``,
``write`` by register name, as :class:`~pyrt.boards.registers.RegisterBoard`
has them).  A station gets, for each board it declares, what the board's
kind makes of that view (:meth:`BoardKind.remote
<pyrt.boards.registers.BoardKind.remote>`): the view itself for a plain
kind, the typed interface for a built-in one (the gripper cage mapped into
the 8031 exactly as the simulated board is, so the controller program is
the same; the TIO10; the dataConcentrator; :mod:`pyrt.boards.kinds`).

On connect the greeting names the station and its boards with their kinds:
every board the station declares must be there with the same kind and
fingerprint, else ConfigError names those missing or different.  The
controller then claims the outputs (``OWN``): while another controller
owns them, opening fails with BoardError ``busy`` naming it.  Other
connections may read the same boards (an HMI); only the owner's accesses
feed board-sim's watchdog.

The process image (:mod:`pyrt.boards.image`, the back-end contract).  The
read phase is one ``SNAP`` (every declared input); the write phase one
``W ...; W ...`` line of the outputs the tick changed, sent without
waiting, followed by the next tick's ``SNAP`` (``prefetch``, the
default): both replies come back while the loop sleeps, and the next read
phase only reads them -- one request and one reply each way per tick, and
no round trip inside the tick.  A ``SNAP`` sent more than 1.5 ticks
before its read phase (the loop stalled) is not used: that read phase
asks again.  The reflex's writes wait for their reply.  Every readable
output is read once on opening (pipelined: one exchange), and again when
the watchdog has turned the outputs off.

Failures.  A connection refused, reset or closed, or no reply within the
timeout (derived from the tick, or ``timeout`` seconds), raises :class:`~pyrt.errors.BoardError`
naming the URL, and the link stays down: every later access raises it too,
at once (board-sim turns its outputs off when the connection drops; a link
never resumes a half-known state).  Only what the drop itself did is still
answered on a down link, without a round trip, so that a reflex action can
finish: writing an output's declared ``off`` value succeeds, and an output
that declares one reads as off.

When board-sim's watchdog has turned the outputs off while the link was
up (the controller's loop stalled longer than the watchdog time), the next
``poll`` raises BoardError once, saying so, and forgets the outputs it
remembered; the link stays up.  A value the board refuses raises
``ValueError``, as the in-process boards do.
"""

from __future__ import annotations

import contextlib
import socket
import struct
import threading
import time
from binascii import a2b_hex
from collections.abc import Mapping, Sequence
from typing import Any, NoReturn

from pyrt.boards.image import (
    DEFAULT_OVERRUN_LIMIT,
    DEFAULT_OVERRUN_TICKS,
    ImageBackend,
    ImageRegisters,
    Write,
)
from pyrt.boards.kinds import RemoteDataConcentrator, RemoteGripperBoard, RemoteTIO10
from pyrt.boards.registers import BoardKind, options_for, split_options
from pyrt.boards.registry import Boards, BoardURL
from pyrt.boards.wire import MAX_LINE, PUSH, WireError, parse_greeting, snapshot_struct
from pyrt.errors import BoardError, ConfigError

__all__ = [
    "DEFAULT_CONNECT_TIMEOUT_S",
    "DEFAULT_MAX_AGE_S",
    "DEFAULT_TIMEOUT_S",
    "TcpBoardRegisters",
    "TcpDataConcentrator",
    "TcpGripperBoard",
    "TcpLink",
    "TcpRegisters",
    "TcpTIO10",
    "open_tcp",
]

DEFAULT_TIMEOUT_S = 0.25
DEFAULT_CONNECT_TIMEOUT_S = 2.0
DEFAULT_MAX_AGE_S = 0.05
#: How long one ``STREAM`` request streams for (ms); the client asks again at half of it
#: (or at a quarter of the watchdog time, if that is sooner).
STREAM_MS = 100
_DONTWAIT = getattr(socket, "MSG_DONTWAIT", 0)

#: The typed boards over tcp:// (the built-in kinds' remote adapters).
TcpGripperBoard = RemoteGripperBoard
TcpTIO10 = RemoteTIO10
TcpDataConcentrator = RemoteDataConcentrator


class TcpLink:
    """One connection to board-sim: a request line out, a reply line back.

    Thread-safe (one request at a time).  Reads the greeting on connect:
    ``station`` (whose world is served), ``boards`` (name -> kind tag) and
    ``watchdog_s``.  Failures raise BoardError naming ``url`` and leave the
    link down.
    """

    def __init__(
        self,
        url: str,
        host: str,
        port: int,
        *,
        timeout: float = DEFAULT_TIMEOUT_S,
        connect_timeout: float = DEFAULT_CONNECT_TIMEOUT_S,
    ):
        self.url = url
        self.timeout = timeout
        self._lock = threading.Lock()
        #: The receiving thread (:meth:`start_receiving`) tells a waiting request here.
        self._came = threading.Condition(self._lock)
        self._receiver: threading.Thread | None = None
        #: Why the receiving thread stopped (the link failed), for the next access to say.
        self._lost: BaseException | None = None
        self._buf = b""
        self._down: str | None = None
        self._trips: int | None = None
        #: Requests sent whose replies are read with the next exchange (pipelined writes).
        self._outstanding: list[str] = []
        #: Round trips made (requests answered); system calls that sent requests.
        self.requests = 0
        self.sends = 0
        #: The newest packed snapshot come (a ``SNAPX`` reply's or a stream's push: its
        #: hexadecimal), None once a write's reply has come after it (it is older than the
        #: write); when it came (the monotonic clock, ns); how many have come; ``SNAPX``
        #: requests sent whose replies have not.
        self.latest: bytes | None = None
        self.latest_ns = 0
        self.snapshots = 0
        self.snapshots_owed = 0
        try:
            sock = socket.create_connection((host, port), timeout=connect_timeout)
        except OSError as exc:
            raise BoardError(url, f"cannot connect: {_why(exc)}") from None
        self._sock = sock
        try:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            greeting = self._rawline().decode("ascii", "replace").split()
            # A blocking socket with kernel time-outs: one system call per
            # send or receive (a Python time-out polls before each); a
            # receive that times out fails with EAGAIN.
            sock.settimeout(None)
            sec, usec = divmod(max(1, round(timeout * 1e6)), 1_000_000)
            tv = struct.pack("ll", sec, usec)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVTIMEO, tv)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDTIMEO, tv)
        except (OSError, EOFError) as exc:
            self._fail(f"no greeting: {_why(exc)}", "connect")
        if greeting[:1] == ["ERR"]:
            self._fail(" ".join(greeting[1:]) or "refused", "connect")
        try:
            hello = parse_greeting(" ".join(greeting))
        except WireError as exc:
            self._fail(exc.text, "connect")
        #: The station whose world board-sim serves, and its boards: name -> kind tag.
        self.station = hello.station
        self.boards = hello.boards
        self.watchdog_s = hello.watchdog_ms / 1000.0

    def check_trips(self, trips: int) -> None:
        """Raise BoardError once when the board's watchdog count has grown
        since the last look (the first look takes it as it is)."""
        last, self._trips = self._trips, trips
        if last is not None and trips > last:
            raise BoardError(self.url, f"the board's watchdog turned the outputs off (no "
                                       f"register access for {self.watchdog_s:g} s)")

    def forget_trips(self) -> None:
        """Take the board's watchdog count as it is at the next look (the
        controller's loop starts: trips while nothing polled are not news)."""
        self._trips = None

    def own(self) -> None:
        """Claim the outputs for this connection (``OWN``): BoardError ``busy``
        naming the owner while another controller owns them.  (A board-sim that
        does not know ``OWN`` has its one controller per connection already.)"""
        try:
            self._exchange("OWN")
        except BoardError as exc:
            if "refused: syntax " not in str(exc):
                raise

    def stream_step_us(self) -> int | None:
        """Whether board-sim streams (``STREAM 0``, which also stops a stream):
        its world's step in µs, or None from a board-sim that does not know the
        packed form (it answers ``ERR syntax``)."""
        try:
            values = self.request("STREAM 0")
        except BoardError as exc:
            if "refused: syntax " in str(exc):
                return None
            raise
        if len(values) != 1 or not values[0].isdigit():
            with self._lock:
                self._fail(f"reply {' '.join(values)[:60]!r} is not a step", "STREAM 0")
        return int(values[0])

    def info(self) -> dict[str, str]:
        """The world's state (``INFO``, not a register access): KEY -> VALUE."""
        return dict(kv.partition("=")[::2] for kv in self.request("INFO"))

    @property
    def down(self) -> str | None:
        """Why the link is down, or None while it is up."""
        return self._down

    def request(self, line: str) -> list[str]:
        """Send one request; the reply's values (strings).  BoardError if the
        link fails or the board answers with an error other than ``range``
        (ValueError: the board refused the value)."""
        return self._exchange(line).decode("ascii").split()

    def request_ints(self, line: str) -> list[int]:
        """:meth:`request` for a reply of numbers: the values as integers."""
        payload = self._exchange(line)
        try:
            return list(map(int, payload.split()))
        except ValueError:
            with self._lock:
                self._fail(f"reply {payload[:60]!r} is not numbers", line)
            raise  # pragma: no cover - _fail raises

    def pipeline(self, lines: list[str]) -> list[list[int]]:
        """Send ``lines`` at once, then read their replies: the numbers of each
        (BoardError if any is an error: used for reads that cannot be refused)."""
        if not lines:
            return []
        data = "".join(f"{line}\n" for line in lines).encode("ascii")
        with self._lock:
            if self._down is not None:
                raise BoardError(self.url, f"{lines[0]}: the link is down ({self._down})")
            try:
                self._sock.sendall(data)
                self.sends += 1
                self._read_outstanding()
                replies = [self._readline() for _ in lines]
            except (TimeoutError, BlockingIOError):
                self._fail(f"no reply within {self.timeout:g} s", lines[0])
            except (OSError, EOFError) as exc:
                self._fail(_why(exc), lines[0])
            self.requests += len(lines)
        out: list[list[int]] = []
        for line, reply in zip(lines, replies, strict=True):
            try:
                if reply[:2] != b"OK":
                    raise ValueError
                out.append(list(map(int, reply[2:].split())))
            except ValueError:
                with self._lock:
                    self._fail(f"unexpected reply {reply[:60]!r}", line)
        return out

    def send(self, *lines: str) -> None:
        """Send requests without waiting for their replies, in one system call:
        the next exchange reads them first (a refusal then raises BoardError there)."""
        line = lines[0]
        data = ("\n".join(lines) + "\n").encode("ascii")
        with self._lock:
            if self._down is not None:
                raise BoardError(self.url, f"{line}: the link is down ({self._down})")
            try:
                self._sock.sendall(data)
            except (TimeoutError, BlockingIOError):
                self._fail(f"cannot send within {self.timeout:g} s", line)
            except OSError as exc:
                self._fail(_why(exc), line)
            self.sends += 1
            self._outstanding += lines
            for one in lines:
                if one[:5] == "SNAPX":
                    self.snapshots_owed += 1

    def start_receiving(self) -> None:
        """Receive in a thread of this link's own from now on: what board-sim
        sends (a stream's pushes, the replies) is taken off the socket as it
        comes, while the controller's loop sleeps, and :meth:`drain` makes no
        system call.  It ends when the link does."""
        with self._lock:
            if self._receiver is not None or self._down is not None:
                return
            self._receiver = threading.Thread(target=self._receive, daemon=True,
                                              name=f"pyrt-tcp-receive {self.url}")
            self._receiver.start()

    def _receive(self) -> None:
        """The receiving thread: each chunk onto the buffer, any waiter told."""
        sock = self._sock
        while True:
            lost: BaseException | None = None
            try:
                chunk = sock.recv(65536)
            except (BlockingIOError, TimeoutError, InterruptedError):
                if self._down is not None:
                    return
                continue  # the receive timeout: waiters judge their own
            except OSError as exc:
                chunk, lost = b"", exc
            with self._came:
                if chunk:
                    self._buf += chunk
                    if len(self._buf) > MAX_LINE * 64:
                        lost = EOFError("reply line too long")
                elif lost is None:
                    lost = EOFError("board-sim closed the connection")
                if lost is not None:
                    self._lost = lost
                self._came.notify_all()
            if lost is not None:
                return

    def drain(self, now_ns: int = 0) -> None:
        """Take what has come without waiting for more: the replies owed
        (BoardError for a refusal, as :meth:`collect`) and the stream's newest
        push (:attr:`latest`, come at ``now_ns``, the monotonic clock's ns).
        With the receiving thread, no system call; else one."""
        with self._lock:
            if self._down is not None:
                raise BoardError(self.url, f"SNAP: the link is down ({self._down})")
            buf = self._buf
            if self._receiver is None:
                try:
                    chunk = self._sock.recv(65536, _DONTWAIT)
                except BlockingIOError:
                    chunk = None
                except OSError as exc:
                    self._fail(_why(exc), "SNAP")
                if chunk is not None:
                    if not chunk:
                        self._fail("board-sim closed the connection", "SNAP")
                    buf += chunk
            refused = None
            push = -1  # where the newest push not yet taken begins
            pos = 0
            while True:
                i = buf.find(b"\n", pos)
                if i < 0:
                    break
                if buf.startswith(PUSH, pos):
                    push = pos
                else:  # a reply: the push before it first (a write's makes it old)
                    if push >= 0:
                        self._snapshot(buf[push + 2:buf.index(b"\n", push)], now_ns)
                        push = -1
                    why = self._take(buf[pos:i])
                    if why is not None and refused is None:
                        refused = why
                pos = i + 1
            if push >= 0:
                self._snapshot(buf[push + 2:buf.index(b"\n", push)], now_ns)
            self._buf = buf[pos:]
            if len(self._buf) > MAX_LINE * 64:
                self._fail("reply line too long", "SNAP")
            if self._lost is not None:
                self._fail(_why(self._lost), "SNAP")
        if refused is not None:
            raise BoardError(self.url, refused)

    def wait_snapshot(self) -> None:
        """Wait for a snapshot newer than :attr:`latest` and for the replies of
        the ``SNAPX`` requests owed (the caller has sent one, or a stream is
        running), taking what comes before them; :attr:`latest` is then newer
        than every write.  BoardError if none comes within the timeout, the
        link fails or a request is refused."""
        refused = None
        with self._lock:
            if self._down is not None:
                raise BoardError(self.url, f"SNAP: the link is down ({self._down})")
            seen = self.snapshots
            try:
                while refused is None and (self.snapshots_owed or self.latest is None
                                           or self.snapshots == seen):
                    refused = self._take(self._rawline())
            except (TimeoutError, BlockingIOError):
                self._fail(f"no reply within {self.timeout:g} s", "SNAP")
            except (OSError, EOFError) as exc:
                self._fail(_why(exc), "SNAP")
        if refused is not None:
            raise BoardError(self.url, refused)

    def _take(self, line: bytes) -> str | None:
        """(Lock held.) One line come: a push, or the reply to the oldest request
        owed; the refusal's text, or None."""
        if line[:2] == PUSH:
            self._snapshot(line[2:])
            return None
        if not self._outstanding:
            self._fail(f"unexpected line {line[:60]!r}", "SNAP")
        request = self._outstanding.pop(0)
        self.requests += 1
        self._note(request, line)
        if line[:2] != b"OK":
            return f"{request[:60]}: refused: {line.decode('ascii', 'replace')[4:]}"
        return None

    def _snapshot(self, payload: bytes, now_ns: int = 0) -> None:
        self.latest = payload
        self.latest_ns = now_ns or time.monotonic_ns()
        self.snapshots += 1

    def _note(self, request: str, reply: bytes) -> None:
        """(Lock held.) What ``request``'s reply tells the snapshots: a write's makes
        the newest one older than it (None); a ``SNAPX``'s is the newest."""
        if request[:1] == "W":
            self.latest = None
        elif request[:5] == "SNAPX":
            self.snapshots_owed -= 1
            if reply[:3] == b"OK ":
                self._snapshot(reply[3:])

    def set_timeout(self, seconds: float) -> None:
        """Use ``seconds`` as the receive and send timeout."""
        self.timeout = seconds
        if self._down is not None:
            return
        sec, usec = divmod(max(1, round(seconds * 1e6)), 1_000_000)
        tv = struct.pack("ll", sec, usec)
        with contextlib.suppress(OSError):
            self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVTIMEO, tv)
            self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDTIMEO, tv)

    def _read_outstanding(self) -> str | None:
        """Read the replies of the requests sent without waiting (lock held);
        the first refusal's text, or None."""
        refused = None
        while self._outstanding:
            line = self._outstanding.pop(0)
            reply = self._readline()
            self.requests += 1
            self._note(line, reply)
            if reply[:2] != b"OK" and refused is None:
                refused = f"{line[:60]}: refused: {reply.decode('ascii', 'replace')[4:]}"
        return refused

    def collect(self) -> bytes | None:
        """The payload of the last request sent without waiting (the replies of
        those before it are read first); None if none is outstanding.
        BoardError as :meth:`request`, also for a refusal of an earlier one."""
        with self._lock:
            if self._down is not None:
                raise BoardError(self.url, f"the link is down ({self._down})")
            if not self._outstanding:
                return None
            line = self._outstanding.pop()
            refused, reply = self._reply(line)
        if refused is not None:
            raise BoardError(self.url, refused)
        if reply[:3] == b"OK " or reply == b"OK":
            return reply[3:]
        with self._lock:
            self._fail(f"unexpected reply {reply[:60]!r}", line)
        raise AssertionError("unreachable")  # pragma: no cover

    def _exchange(self, line: str, what: str | None = None) -> bytes:
        """One round trip; the payload of the ``OK`` reply (failures name ``what``,
        the request if not given)."""
        data = line.encode("ascii") + b"\n"
        with self._lock:
            if self._down is not None:
                raise BoardError(self.url, f"{what or line}: the link is down ({self._down})")
            if line[:5] == "SNAPX":
                self.snapshots_owed += 1
            refused, reply = self._reply(line, data, what)
        if refused is not None:
            raise BoardError(self.url, refused)
        if reply[:3] == b"OK " or reply == b"OK":
            return reply[3:]
        text = reply.decode("ascii", "replace")
        if text.startswith("ERR range "):
            raise ValueError(text[len("ERR range "):])
        if text.startswith("ERR "):
            raise BoardError(self.url, f"{line}: refused: {text[4:]}")
        with self._lock:
            self._fail(f"unexpected reply {text[:60]!r}", line)
        raise AssertionError("unreachable")  # pragma: no cover

    def _reply(self, line: str, data: bytes | None = None,
               what: str | None = None) -> tuple[str | None, bytes]:
        """(Lock held.) Send ``data`` if given, read the replies still owed, then
        ``line``'s: (the first refusal among those owed or None, the reply).  A
        lost link fails it (BoardError naming the URL and ``what``, else ``line``)."""
        refused: str | None = None
        reply = b""
        try:
            if data is not None:
                self._sock.sendall(data)
                self.sends += 1
            refused = self._read_outstanding()
            reply = self._readline()
        except (TimeoutError, BlockingIOError):
            self._fail(f"no reply within {self.timeout:g} s", what or line)
        except (OSError, EOFError) as exc:
            self._fail(_why(exc), what or line)
        self.requests += 1
        self._note(line, reply)
        return refused, reply

    def _readline(self) -> bytes:
        """The next reply line (a stream's pushes before it are taken)."""
        while True:
            line = self._rawline()
            if line[:2] != PUSH:
                return line
            self._snapshot(line[2:])

    def _rawline(self) -> bytes:
        """(Lock held.) The next line come: from the buffer, else received (by
        this thread, or waited for from the receiving thread within the timeout)."""
        buf = self._buf
        deadline = 0.0
        while True:
            i = buf.find(b"\n")
            if i >= 0:
                self._buf = buf[i + 1:]
                return buf[:i]
            if len(buf) > MAX_LINE * 64:
                raise EOFError("reply line too long")
            if self._receiver is None:
                chunk = self._sock.recv(65536)
                if not chunk:
                    raise EOFError("board-sim closed the connection")
                buf += chunk
                continue
            if self._lost is not None:
                raise self._lost
            now = time.monotonic()
            deadline = deadline or now + self.timeout
            if now >= deadline or not self._came.wait(deadline - now):
                raise TimeoutError
            buf = self._buf

    def _fail(self, reason: str, what: str) -> NoReturn:
        self._down = reason
        with contextlib.suppress(OSError):
            self._sock.shutdown(socket.SHUT_RDWR)  # the receiving thread wakes and ends
        with contextlib.suppress(OSError):
            self._sock.close()
        raise BoardError(self.url, f"{what}: {reason}") from None

    def close(self) -> None:
        """Say goodbye (best effort) and close; later accesses raise BoardError."""
        with self._lock:
            if self._down is not None:
                return
            self._down = "closed"
            receiver = self._receiver
            try:
                if receiver is None:
                    self._sock.settimeout(0.05)
                self._sock.sendall(b"QUIT\n")
                # Read what is still owed (a prefetched SNAP's reply, a stream's pushes)
                # up to board-sim's close: a socket closed with unread data resets the
                # link instead of ending it, and board-sim would see a lost controller,
                # not a QUIT.  (The receiving thread reads it, and ends there.)
                self._sock.shutdown(socket.SHUT_WR)
                deadline = time.monotonic() + 0.2
                while receiver is None and time.monotonic() < deadline \
                        and self._sock.recv(65536):
                    pass
            except OSError:
                pass
        if receiver is not None and receiver is not threading.current_thread():
            receiver.join(0.2)
            with contextlib.suppress(OSError):
                self._sock.shutdown(socket.SHUT_RDWR)
            receiver.join(1.0)
        self._sock.close()


def _why(exc: BaseException) -> str:
    if isinstance(exc, EOFError):
        return str(exc) or "board-sim closed the connection"
    if isinstance(exc, ConnectionResetError):
        return "connection reset by board-sim"
    if isinstance(exc, BrokenPipeError):
        return "connection closed by board-sim (broken pipe)"
    if isinstance(exc, ConnectionRefusedError):
        return "connection refused (is board-sim running there?)"
    if isinstance(exc, TimeoutError):
        return "timed out"
    return getattr(exc, "strerror", None) or str(exc) or type(exc).__name__


# -- the registers of one connection ---------------------------------------------------------


class TcpRegisters(ImageBackend):
    """The declared boards of one board-sim connection: the process image
    (:class:`~pyrt.boards.image.ImageBackend`) over the wire protocol.

    ``kinds``: the station's boards (name -> kind), each checked against the
    greeting.  The read phase is one ``SNAP``; the write phase one ``W ...;
    W ...`` line sent without waiting (its reply is read with the next
    ``SNAP``: one request and one reply each way per tick); the reflex's
    writes wait for their reply.
    """

    off_on_loss = True  # board-sim turns the outputs off when the link drops

    def __init__(self, link: TcpLink, kinds: Mapping[str, BoardKind], *,
                 max_age: float = DEFAULT_MAX_AGE_S, timeout: float | None = None,
                 overrun_ticks: int = DEFAULT_OVERRUN_TICKS,
                 overrun_limit: int = DEFAULT_OVERRUN_LIMIT, prefetch: bool = True):
        super().__init__(link.url, kinds, max_age=max_age, timeout=timeout,
                         overrun_ticks=overrun_ticks, overrun_limit=overrun_limit)
        self.link = link
        #: The inputs come before the read phase (see :meth:`end_of_tick`).
        self.prefetch = prefetch
        self._prefetch_sent = 0
        self._stale_ns = 0
        self._check_greeting()
        # every board served, in its order: a plain SNAP; else name the boards declared
        names = "" if list(link.boards) == list(self.kinds) else " " + " ".join(self.kinds)
        self._snap_request = "SNAP" + names
        #: board-sim's world step in µs if it speaks the packed form (``SNAPX``,
        #: ``STREAM``), else None (an older board-sim: text ``SNAP``).
        self.step_us = link.stream_step_us()
        self._snapx_request = "SNAPX" + names
        self._layout = snapshot_struct(self.kinds)
        self._unpacked_from: bytes | None = None
        self._unpacked: tuple[int, ...] = ()
        #: Whether the inputs stream (prefetch, from a board-sim that streams).
        self.streaming = prefetch and self.step_us is not None
        self._stream_request = f"STREAM {STREAM_MS}{names}"
        self._rearm_ns = 0
        self._stream_live_ns = 0
        self._rearm_every_ns = int(min(STREAM_MS / 2e3, link.watchdog_s / 4) * 1e9)

    def _check_greeting(self) -> None:
        served = self.link.boards
        missing = [f"{n} ({k.name})" for n, k in self.kinds.items() if n not in served]
        different = [f"{n} (declared {k.tag}, served {served[n]})"
                     for n, k in self.kinds.items() if n in served and served[n] != k.tag]
        if missing or different:
            self.link.close()
            what = "; ".join(p for p in (
                f"missing: {', '.join(missing)}" if missing else "",
                f"different: {', '.join(different)}" if different else "") if p)
            have = " ".join(f"{n}={t}" for n, t in served.items()) or "none"
            raise ConfigError(f"board URL {self.url!r}: board-sim there serves the "
                              f"{self.link.station} station (boards {have}), not the boards "
                              f"declared here: {what}")

    # -- the exchanges ------------------------------------------------------------------------

    def set_tick(self, period_s: float) -> None:
        super().set_tick(period_s)
        self._stale_ns = int(1.5 * period_s * 1e9)
        if self.streaming:  # a push comes after every step of the world
            assert self.step_us is not None
            self._stale_ns = max(self._stale_ns, int(1.5 * self.step_us * 1e3))

    def end_of_tick(self) -> None:
        """Pipelining: the next tick's inputs come while the loop sleeps.  From a
        board-sim that streams, the pushes after every world step: asked for
        again (``STREAM``) when half of the time asked for has passed (that
        request feeds board-sim's watchdog); from an older board-sim, the next
        tick's ``SNAP`` sent now.  A copy more than 1.5 ticks (or steps) old
        (the loop stalled, or board-sim did) is not used: that read phase asks
        again."""
        if not (self.prefetch and self.phased) or self.link.down is not None:
            return
        if self.streaming:
            if time.monotonic_ns() >= self._rearm_ns:
                self.link.send(*self._rearm())
        elif not self._prefetch_sent:
            self.link.send(self._snap_request)
            self._prefetch_sent = time.monotonic_ns()

    def exchange_inputs(self) -> list[int]:
        link = self.link
        if self.streaming and self.phased:
            now = time.monotonic_ns()
            link.drain(now)  # what came while the loop slept: the pushes, the replies owed
            # the inputs after the last writes (a SNAPX went with them), and not too old
            if link.snapshots_owed or link.latest is None or now - link.latest_ns > self._stale_ns:
                if not link.snapshots_owed and now >= self._stream_live_ns:
                    link.send(self._snapx_request)  # the stream has lapsed: ask
                link.wait_snapshot()  # (else board-sim is late: its next push)
            return self._unpack(link.latest)
        if self.step_us is not None:
            return self._unpack(link._exchange(self._snapx_request, "SNAP"))
        sent, self._prefetch_sent = self._prefetch_sent, 0
        payload = link.collect() if sent else None
        if payload is not None and time.monotonic_ns() - sent <= self._stale_ns:
            try:
                nums = list(map(int, payload.split()))
            except ValueError:
                link._fail(f"reply {payload[:60]!r} is not numbers", "SNAP")
        else:
            nums = link.request_ints(self._snap_request)
        if len(nums) != self.input_count + 1:
            link._fail(f"SNAP answered {len(nums)} values, not {self.input_count + 1}", "SNAP")
        return self._inputs_of(nums)

    def _rearm(self) -> tuple[str]:
        """The stream's request, asked for again from now on (the first time, the
        link starts receiving in its own thread)."""
        if not self._rearm_ns:
            self.link.start_receiving()
        now = time.monotonic_ns()
        self._rearm_ns = now + self._rearm_every_ns
        # board-sim streams for STREAM_MS from when the request comes: surely till then
        self._stream_live_ns = now + STREAM_MS * 800_000
        return (self._stream_request,)

    def _unpack(self, payload: bytes | None) -> list[int]:
        """The inputs of a packed snapshot (its hexadecimal), in one step."""
        if payload is not self._unpacked_from:  # else the same push as the last read phase
            try:
                self._unpacked = self._layout.unpack(a2b_hex(payload))  # type: ignore[arg-type]
            except (ValueError, TypeError, struct.error):
                shown = (payload or b"")[:60]
                self.link._fail(f"snapshot {shown!r} is not {self._layout.size} packed bytes",
                                "SNAP")
            self._unpacked_from = payload
        return self._inputs_of(self._unpacked)

    def _inputs_of(self, nums: Sequence[int]) -> list[int]:
        if nums[0] != self.link._trips:
            try:
                self.link.check_trips(nums[0])
            except BoardError:
                self.forget_outputs(self.read_outputs())  # the watchdog turned them off
                raise
        return list(nums[1:])

    def exchange_outputs(self, writes: list[Write]) -> None:
        link = self.link
        line = _write_line(writes)
        if not (self.prefetch and self.phased) or link.down is not None:
            link.send(line)
        elif self.streaming:  # the inputs as the writes left them, in the same system call
            if time.monotonic_ns() >= self._rearm_ns:
                link.send(line, self._snapx_request, *self._rearm())
            else:
                link.send(line, self._snapx_request)
        else:
            link.send(line, self._snap_request)
            self._prefetch_sent = time.monotonic_ns()

    def exchange_outputs_now(self, writes: list[Write]) -> None:
        try:
            self.link.request(_write_line(writes))
        except ValueError:
            for b, n, i, _ in writes:  # those before the refused one stand: read them again
                self._outputs.pop((b, n, i), None)
            raise

    def read_outputs(self) -> dict[tuple[str, str, int], int]:
        keys = [(board, reg.name, i) for board, kind in self.kinds.items()
                for reg in kind.outputs() if reg.readback for i in range(reg.count)]
        replies = self.link.pipeline([f"R {b} {n} {i}" for b, n, i in keys])
        out: dict[tuple[str, str, int], int] = {}
        for key, values in zip(keys, replies, strict=True):
            if len(values) != 1:
                self.link._fail(f"R answered {len(values)} values", "R")
            out[key] = values[0]
        return out

    def apply_timeout(self, seconds: float) -> None:
        self.link.set_timeout(seconds)

    def close_link(self) -> None:
        self.link.close()

    @property
    def down(self) -> str | None:
        return self.link._down

    # -- compatibility -----------------------------------------------------------------------

    def poll(self, now_ns: int = 0) -> None:
        """The read phase (:meth:`read_phase`)."""
        self.read_phase(now_ns)

    def load_outputs(self) -> None:
        """Read every readable output again (one pipelined exchange)."""
        self.forget_outputs(self.read_outputs())

    def forget(self) -> None:
        """The loop starts: the writes made while the station was built go out,
        the watchdog count is forgotten and the outputs read again."""
        super().resync()
        self.link.forget_trips()
        self.load_outputs()

    def resync(self) -> None:
        self.forget()


def _write_line(writes: list[Write]) -> str:
    return "; ".join(f"W {b} {n} {i} {v}" for b, n, i, v in writes)


#: One board of a :class:`TcpRegisters` (the generic image view).
TcpBoardRegisters = ImageRegisters


# -- the factory -------------------------------------------------------------------------


def _seconds(url: BoardURL, name: str, value: Any) -> float:
    try:
        s = float(value)
    except (TypeError, ValueError):
        raise url.error(f"option {name} must be seconds, got {value!r}") from None
    if not 0 <= s <= 3600 or (s == 0 and name != "max_age"):
        raise url.error(f"option {name} must be more than 0 and at most 3600 s, got {value!r}")
    return s


def _ticks(url: BoardURL, name: str, value: Any) -> int:
    try:
        n = int(value)
    except (TypeError, ValueError):
        raise url.error(f"option {name} must be a whole number, got {value!r}") from None
    if not 1 <= n <= 10_000:
        raise url.error(f"option {name} must be 1..10000, got {value!r}")
    return n


def open_tcp(
    url: BoardURL,
    station: str,
    kinds: dict[str, BoardKind],
    *,
    timeout: Any = None,
    connect_timeout: Any = DEFAULT_CONNECT_TIMEOUT_S,
    max_age: Any = DEFAULT_MAX_AGE_S,
    overrun_ticks: Any = DEFAULT_OVERRUN_TICKS,
    overrun_limit: Any = DEFAULT_OVERRUN_LIMIT,
    prefetch: Any = "1",
    **options: Any,
) -> Boards:
    """The ``tcp://HOST:PORT`` back end: connect to board-sim and open the declared boards.

    Options: ``timeout`` (seconds: a fixed hard timeout per exchange instead of
    the one derived from the tick), ``connect_timeout``, ``max_age`` of the
    input copy outside the ticks (0: every read there reads the inputs),
    ``overrun_ticks`` (N) and ``overrun_limit`` (M) of the back-end contract
    (:mod:`pyrt.boards.image`), ``prefetch`` (1, the default: the next tick's
    ``SNAP`` is sent at the end of the tick; 0: at the start of the read
    phase, a whole round trip in the tick); and those of the declared kinds
    (the gripper cage's ``cpu``).
    """
    mine, rest = split_options(kinds, options)
    if rest:
        raise url.error(f"tcp: takes no option {', '.join(sorted(rest))} "
                        "(it takes timeout, connect_timeout, max_age, overrun_ticks, "
                        "overrun_limit, prefetch)")
    if not url.host or url.port is None or url.port == 0:
        raise url.error("tcp: needs a host and a port 1..65535: tcp://HOST:PORT")
    if url.path not in ("", "/"):
        raise url.error("tcp: takes no path")
    t = _seconds(url, "timeout", timeout) if timeout is not None else None
    ct = _seconds(url, "connect_timeout", connect_timeout)
    age = _seconds(url, "max_age", max_age)
    n = _ticks(url, "overrun_ticks", overrun_ticks)
    m = _ticks(url, "overrun_limit", overrun_limit)
    if str(prefetch) not in ("0", "1", "True", "False"):
        raise url.error(f"option prefetch must be 0 or 1, got {prefetch!r}")
    link = TcpLink(url.text, url.host, url.port, timeout=t or DEFAULT_TIMEOUT_S,
                   connect_timeout=ct)
    client = TcpRegisters(link, kinds, max_age=age, timeout=t, overrun_ticks=n,
                          overrun_limit=m, prefetch=str(prefetch) in ("1", "True"))
    try:
        link.own()  # the outputs are this controller's, or BoardError busy
        client.open()  # the first copy: what the boards hold as this controller comes
        views = {name: ImageRegisters(client, name) for name in kinds}
        boards = {name: kind.remote(views[name], **options_for(kind, mine))
                  for name, kind in kinds.items()}
    except BaseException:
        link.close()
        raise
    pollers = [b.poll for b in boards.values()
               if not isinstance(b, ImageRegisters) and callable(getattr(b, "poll", None))]
    return Boards(url.text, station, boards, kinds, in_process=False, world=link.station,
                  views=views, info=link.info, **client.boards_hooks(pollers))
