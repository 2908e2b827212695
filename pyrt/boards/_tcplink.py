"""The connection of the ``tcp://`` back end (:mod:`pyrt.boards.tcp`) to one board-sim.

:class:`TcpLink` speaks :mod:`pyrt.boards.wire`: request lines out, reply
lines back in order, requests pipelined (sent without waiting, their
replies taken with the next exchange), and, while a stream runs, the
pushes between the replies.  Any failure (refused, reset, closed, no
reply within the timeout) raises :class:`~pyrt.errors.BoardError` naming
the URL and leaves the link down for good.
"""

from __future__ import annotations

import contextlib
import socket
import struct
import threading
import time
from typing import NoReturn

from pyrt.boards.wire import MAX_LINE, PUSH, WireError, parse_greeting
from pyrt.errors import BoardError

__all__ = ["DEFAULT_CONNECT_TIMEOUT_S", "DEFAULT_TIMEOUT_S", "TcpLink"]

DEFAULT_TIMEOUT_S = 0.25
DEFAULT_CONNECT_TIMEOUT_S = 2.0
_DONTWAIT = getattr(socket, "MSG_DONTWAIT", 0)
_PEEK = socket.MSG_PEEK | _DONTWAIT


class TcpLink:
    """One connection to board-sim: a request line out, a reply line back
    (and, while a stream runs, its pushes, :attr:`latest`).

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
        self._taken = 0  # snapshots at the last newest()
        #: The thread taking the lines that come (:meth:`_take_turn`), and those waiting.
        self._turn: int | None = None
        self._turn_waiters = 0
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
            _kernel_timeouts(sock, timeout)
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
            _take_turn(self, lines[0])
            try:
                self._sock.sendall(data)
                self.sends += 1
                self._read_outstanding()
                replies = [self._readline() for _ in lines]
            except (TimeoutError, BlockingIOError):
                self._fail(f"no reply within {self.timeout:g} s", lines[0])
            except (OSError, EOFError) as exc:
                self._fail(_why(exc), lines[0])
            finally:
                _give_turn(self)
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
        with self._lock:
            if self._down is not None:
                raise BoardError(self.url, f"{lines[0]}: the link is down ({self._down})")
            self._send(lines)

    def _send(self, lines: tuple[str, ...]) -> None:
        """(Lock held, link up.) :meth:`send`."""
        try:
            self._sock.sendall(("\n".join(lines) + "\n").encode("ascii"))
        except (TimeoutError, BlockingIOError):
            self._fail(f"cannot send within {self.timeout:g} s", lines[0])
        except OSError as exc:
            self._fail(_why(exc), lines[0])
        self.sends += 1
        self._outstanding += lines
        for one in lines:
            if one[:5] == "SNAPX":
                self.snapshots_owed += 1

    def start_receiving(self) -> None:
        """Receive in a thread of this link's own from now on: what board-sim
        sends (a stream's pushes, the replies) is taken off the socket as it
        comes, while the controller's loop sleeps, and :meth:`newest` makes no
        system call.  It ends when the link does."""
        with self._lock:
            if self._receiver is not None or self._down is not None:
                return
            self._receiver = threading.Thread(target=_receive, args=(self,), daemon=True,
                                              name=f"pyrt-tcp-receive {self.url}")
            self._receiver.start()

    def newest(self, now_ns: int, stale_ns: int, ask: str | None) -> bytes:
        """The newest packed snapshot, no older than the last write nor than
        ``stale_ns`` at ``now_ns`` (the monotonic clock): first what has come
        (the replies owed, the stream's pushes: with the receiving thread
        without a system call), then, if that is not enough, the next one
        waited for: after sending ``ask`` (a ``SNAPX``) if given and none is
        owed, else a stream's next push.  BoardError if none comes within the
        timeout, the link fails, or a request owed was refused."""
        with self._lock:
            _take_turn(self, "SNAP")
            try:
                refused = self._drain(now_ns)
                if refused is None and self.snapshots == self._taken:
                    refused = self._unread(now_ns)  # nothing new: is the link still there?
                self._taken = self.snapshots
                latest = self.latest
                if refused is None and (self.snapshots_owed or latest is None
                                        or now_ns - self.latest_ns > stale_ns):
                    if ask is not None and not self.snapshots_owed:
                        self._send((ask,))
                    refused = self._wait()
                    latest = self.latest
            finally:
                _give_turn(self)
        if refused is not None:
            raise BoardError(self.url, refused)
        assert latest is not None
        return latest

    def _unread(self, now_ns: int) -> str | None:
        """(Lock held, link up.)  With the receiving thread, whether the socket
        holds what that thread has not taken yet (one system call, which also
        gives that thread its turn; nothing taken): the end of the connection
        fails the link; what the thread has taken meanwhile is taken here.  As
        :meth:`_drain`."""
        if self._receiver is None:
            return None
        try:
            if self._sock.recv(1, _PEEK):
                return self._drain(now_ns)
        except BlockingIOError:
            return self._drain(now_ns)
        except OSError as exc:
            self._fail(_why(exc), "SNAP")
        self._fail("board-sim closed the connection", "SNAP")

    def _drain(self, now_ns: int) -> str | None:
        """(Lock held, link up.) Take what has come without waiting for more:
        the replies owed and the stream's newest push (come at ``now_ns``).
        With the receiving thread, no system call; else one.  The first
        refusal among the replies, or None."""
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
        end = len(buf) - 1
        # one push and nothing else (the usual): no walk through the buffer
        if end > 2 and buf[:2] == PUSH and buf.find(b"\n") == end and self._lost is None:
            self._snapshot(buf[2:end], now_ns)
            self._buf = b""
            return None
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
        return refused

    def _wait(self) -> str | None:
        """(Lock held, link up.) Wait for a snapshot newer than :attr:`latest`
        and for the replies of the ``SNAPX`` requests owed, taking what comes
        before them (:attr:`latest` is then newer than every write); the first
        refusal among them, or None.  The link fails if none comes within the
        timeout."""
        refused = None
        seen = self.snapshots
        try:
            while refused is None and (self.snapshots_owed or self.latest is None
                                       or self.snapshots == seen):
                refused = self._take(self._rawline())
        except (TimeoutError, BlockingIOError):
            self._fail(f"no reply within {self.timeout:g} s", "SNAP")
        except (OSError, EOFError) as exc:
            self._fail(_why(exc), "SNAP")
        return refused

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
        if self._down is None:
            with contextlib.suppress(OSError):
                _kernel_timeouts(self._sock, seconds)

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
        _take_turn(self, what or line)
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
        finally:
            _give_turn(self)
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
            _quit(self._sock, receiver is None)
        if receiver is not None and receiver is not threading.current_thread():
            receiver.join(0.2)
            with contextlib.suppress(OSError):
                self._sock.shutdown(socket.SHUT_RDWR)
            receiver.join(1.0)
        self._sock.close()


def _take_turn(link: TcpLink, what: str) -> None:
    """(``link``'s lock held.) Be the one thread that takes the lines that come, waiting
    while another is (one that waits for the receiving thread lets go of the
    lock: its replies must stay its own); BoardError if the link is down."""
    me = threading.get_ident()
    while link._turn is not None and link._turn != me:
        link._turn_waiters += 1
        try:
            link._came.wait(link.timeout)
        finally:
            link._turn_waiters -= 1
    if link._down is not None:
        raise BoardError(link.url, f"{what}: the link is down ({link._down})")
    link._turn = me


def _give_turn(link: TcpLink) -> None:
    """(``link``'s lock held.) The turn of :func:`_take_turn` ends."""
    link._turn = None
    if link._turn_waiters:
        link._came.notify_all()


def _quit(sock: socket.socket, read: bool) -> None:
    """Say ``QUIT`` on ``sock`` and end the sending side (best effort); if ``read``
    (no receiving thread does), read what is still owed up to board-sim's close."""
    # A socket closed with unread data (a prefetched SNAP's reply, a stream's pushes)
    # resets the link instead of ending it, and board-sim would see a lost controller,
    # not a QUIT.  (The receiving thread reads it, and ends there.)
    with contextlib.suppress(OSError):
        if read:
            sock.settimeout(0.05)
        sock.sendall(b"QUIT\n")
        sock.shutdown(socket.SHUT_WR)
        deadline = time.monotonic() + 0.2
        while read and time.monotonic() < deadline and sock.recv(65536):
            pass


def _receive(link: TcpLink) -> None:
    """``link``'s receiving thread: each chunk onto its buffer, any waiter told."""
    sock = link._sock
    while True:
        lost: BaseException | None = None
        try:
            chunk = sock.recv(65536)
        except (BlockingIOError, TimeoutError, InterruptedError):
            if link._down is not None:
                return
            continue  # the receive timeout: waiters judge their own
        except OSError as exc:
            chunk, lost = b"", exc
        with link._came:
            if chunk:
                buf = link._buf = link._buf + chunk
                # only the line not yet ended counts (a stalled loop finds many pushes)
                if len(buf) - buf.rfind(b"\n") > MAX_LINE * 64:
                    lost = EOFError("reply line too long")
            elif lost is None:
                lost = EOFError("board-sim closed the connection")
            if lost is not None:
                link._lost = lost
            link._came.notify_all()
        if lost is not None:
            return


def _kernel_timeouts(sock: socket.socket, seconds: float) -> None:
    """``seconds`` as ``sock``'s receive and send timeouts (SO_RCVTIMEO, SO_SNDTIMEO)."""
    sec, usec = divmod(max(1, round(seconds * 1e6)), 1_000_000)
    tv = struct.pack("ll", sec, usec)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVTIMEO, tv)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDTIMEO, tv)


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
