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
fingerprint, else ConfigError names those missing or different.

One round trip per tick.  ``poll(now_ns)`` (attach it to the loop before
the ready queue) reads every input register of the declared boards with
one ``SNAP``; the input reads of that tick are answered from it (and a
board with a ``poll(now_ns)`` of its own, the gripper cage, then raises
the encoder interrupts that arrived).  Every readable output is read once
on opening (pipelined: one exchange), and again when the watchdog has
turned the outputs off; a write goes to the board at once and is
remembered, so a read of an output is answered without a round trip.  A
copy older than ``max_age`` seconds (default 0.05) is not used: a read
outside the ticks goes to the board; ``max_age=0`` sends every read to the
board, outputs too.

Failures.  A connection refused, reset or closed, or no reply within
``timeout`` seconds (default 0.25), raises :class:`~pyrt.errors.BoardError`
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
from collections.abc import Iterable, Mapping
from typing import Any

from pyrt.boards.kinds import RemoteDataConcentrator, RemoteGripperBoard, RemoteTIO10
from pyrt.boards.registers import BoardKind, options_for, split_options
from pyrt.boards.registry import Boards, BoardURL
from pyrt.boards.wire import MAX_LINE, WireError, parse_greeting
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
        self._buf = b""
        self._down: str | None = None
        self._trips: int | None = None
        #: Round trips made (requests answered).
        self.requests = 0
        try:
            sock = socket.create_connection((host, port), timeout=connect_timeout)
        except OSError as exc:
            raise BoardError(url, f"cannot connect: {_why(exc)}") from None
        self._sock = sock
        try:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            greeting = self._readline().decode("ascii", "replace").split()
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

    def _exchange(self, line: str) -> bytes:
        """One round trip; the payload of the ``OK`` reply."""
        data = line.encode("ascii") + b"\n"
        with self._lock:
            if self._down is not None:
                raise BoardError(self.url, f"{line}: the link is down ({self._down})")
            try:
                self._sock.sendall(data)
                reply = self._readline()
            except (TimeoutError, BlockingIOError):
                self._fail(f"no reply within {self.timeout:g} s", line)
            except (OSError, EOFError) as exc:
                self._fail(_why(exc), line)
            self.requests += 1
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

    def _readline(self) -> bytes:
        buf = self._buf
        while True:
            i = buf.find(b"\n")
            if i >= 0:
                self._buf = buf[i + 1:]
                return buf[:i]
            if len(buf) > MAX_LINE * 64:
                raise EOFError("reply line too long")
            chunk = self._sock.recv(65536)
            if not chunk:
                raise EOFError("board-sim closed the connection")
            buf += chunk

    def _fail(self, reason: str, what: str) -> None:
        self._down = reason
        with contextlib.suppress(OSError):
            self._sock.close()
        raise BoardError(self.url, f"{what}: {reason}") from None

    def close(self) -> None:
        """Say goodbye (best effort) and close; later accesses raise BoardError."""
        with self._lock:
            if self._down is not None:
                return
            self._down = "closed"
            try:
                self._sock.settimeout(0.05)
                self._sock.sendall(b"QUIT\n")
            except OSError:
                pass
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


class TcpRegisters:
    """The declared boards of one board-sim connection, by register (see the module text).

    ``kinds``: the station's boards (name -> kind), each checked against the
    greeting.  :meth:`poll` takes the tick's copy of every input;
    :meth:`read`, :meth:`write` and :meth:`write_many` reach one register.
    """

    def __init__(self, link: TcpLink, kinds: Mapping[str, BoardKind], *,
                 max_age: float = DEFAULT_MAX_AGE_S):
        self.link = link
        self.url = link.url
        self.kinds = dict(kinds)
        self.max_age_ns = int(max_age * 1e9)
        self._check_greeting()
        # every board served, in its order: a plain SNAP; else name the boards declared
        self._snap_request = ("SNAP" if list(link.boards) == list(self.kinds)
                              else "SNAP " + " ".join(self.kinds))
        self._layout = [(board, reg.name, reg.count) for board, kind in self.kinds.items()
                        for reg in kind.inputs()]
        self._values = 1 + sum(count for _, _, count in self._layout)
        #: The tick's copy of the inputs: board -> register -> values.
        self._image: dict[str, dict[str, list[int]]] = {b: {} for b in self.kinds}
        #: Outputs as last written or read: (board, register, index) -> value.
        self._outputs: dict[tuple[str, str, int], int] = {}
        self._fresh_until = 0

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

    # -- per tick ------------------------------------------------------------------------

    def poll(self, now_ns: int = 0) -> None:
        """Read every declared input in one round trip (the tick's copy)."""
        nums = self.link.request_ints(self._snap_request)
        if len(nums) != self._values:
            self.link._fail(f"SNAP answered {len(nums)} values, not {self._values}", "SNAP")
        pos = 1
        image = self._image
        for board, reg, count in self._layout:
            image[board][reg] = nums[pos:pos + count]
            pos += count
        self._fresh_until = time.monotonic_ns() + self.max_age_ns
        try:
            self.link.check_trips(nums[0])
        except BoardError:
            self.load_outputs()  # the watchdog turned them off: read them again
            raise

    def load_outputs(self) -> None:
        """Read every readable output in one pipelined exchange (on opening,
        and after the watchdog turned them off)."""
        self._outputs.clear()
        keys = [(board, reg.name, i) for board, kind in self.kinds.items()
                for reg in kind.outputs() if reg.readback for i in range(reg.count)]
        replies = self.link.pipeline([f"R {b} {n} {i}" for b, n, i in keys])
        for key, values in zip(keys, replies, strict=True):
            if len(values) != 1:
                self.link._fail(f"R answered {len(values)} values", "R")
            self._outputs[key] = values[0]

    def forget(self) -> None:
        """Forget the watchdog count and read the outputs again (the loop starts)."""
        self.link.forget_trips()
        self.load_outputs()

    # -- one register ------------------------------------------------------------------------

    def read(self, board: str, name: str, index: int = 0) -> int:
        """``board``'s register ``name[index]`` (see the module text)."""
        reg = self.kinds[board].check_read(name, index)
        if reg.is_input:
            if time.monotonic_ns() < self._fresh_until:
                return self._image[board][name][index]
        else:
            if self.link.down is not None:
                off = reg.off_value(index)
                if off is not None:
                    return off  # board-sim turned it off when the link dropped
            elif self.max_age_ns:
                value = self._outputs.get((board, name, index))
                if value is not None:
                    return value
        value = self.link.request_ints(f"R {board} {name} {index}")[0]
        if not reg.is_input:
            self._outputs[(board, name, index)] = value
        return value

    def write(self, board: str, name: str, value: int, index: int = 0) -> None:
        """Write ``board``'s output ``name[index]`` (one round trip)."""
        self.write_many([(board, name, index, value)])

    def write_many(self, writes: Iterable[tuple[str, str, int, int]]) -> None:
        """Write several outputs, each ``(board, register, index, value)``, in one
        round trip (checked here first: none is sent if one is refused)."""
        todo = list(writes)
        if not todo:
            return
        regs = [self.kinds[b].check_write(n, i, v) for b, n, i, v in todo]
        if self.link.down is not None and all(
                r.off_value(i) == v for r, (_, _, i, v) in zip(regs, todo, strict=True)):
            for r, (b, n, i, v) in zip(regs, todo, strict=True):
                if r.readback:
                    self._outputs[(b, n, i)] = v
            return  # board-sim turned them off when the link dropped
        line = "; ".join(f"W {b} {n} {i} {v}" for b, n, i, v in todo)
        try:
            self.link.request(line)
        except ValueError:
            for board, name, index, _ in todo:  # those before the refused one stand
                self._outputs.pop((board, name, index), None)
            raise
        for r, (b, n, i, v) in zip(regs, todo, strict=True):
            if r.readback:
                self._outputs[(b, n, i)] = v

    def set_cached(self, board: str, name: str, value: int, index: int = 0) -> None:
        """Set the tick's copy of an input (what a write made of it: a cleared counter)."""
        values = self._image[board].get(name)
        if values is not None and 0 <= index < len(values):
            values[index] = value

    def close(self) -> None:
        """Close the link."""
        self.link.close()


class TcpBoardRegisters:
    """One board of a :class:`TcpRegisters`: ``read(name, index=0)`` and
    ``write(name, value, index=0)`` as a :class:`~pyrt.boards.registers.RegisterBoard`
    has them."""

    def __init__(self, client: TcpRegisters, board: str):
        self.client = client
        self.board = board
        self.kind = client.kinds[board]
        self.url = client.url
        self.link = client.link

    def read(self, name: str, index: int = 0) -> int:
        return self.client.read(self.board, name, index)

    def write(self, name: str, value: int, index: int = 0) -> None:
        self.client.write(self.board, name, value, index)

    def snapshot(self) -> list[int]:
        """Every input of this board, in declared order."""
        return [self.read(reg.name, i) for reg in self.kind.inputs() for i in range(reg.count)]

    def set_cached(self, name: str, value: int, index: int = 0) -> None:
        self.client.set_cached(self.board, name, value, index)

    def __repr__(self) -> str:
        return f"<{self.kind.name} board {self.board!r} at {self.url}>"


# -- the factory -------------------------------------------------------------------------


def _seconds(url: BoardURL, name: str, value: Any) -> float:
    try:
        s = float(value)
    except (TypeError, ValueError):
        raise url.error(f"option {name} must be seconds, got {value!r}") from None
    if not 0 <= s <= 3600 or (s == 0 and name != "max_age"):
        raise url.error(f"option {name} must be more than 0 and at most 3600 s, got {value!r}")
    return s


def open_tcp(
    url: BoardURL,
    station: str,
    kinds: dict[str, BoardKind],
    *,
    timeout: Any = DEFAULT_TIMEOUT_S,
    connect_timeout: Any = DEFAULT_CONNECT_TIMEOUT_S,
    max_age: Any = DEFAULT_MAX_AGE_S,
    **options: Any,
) -> Boards:
    """The ``tcp://HOST:PORT`` back end: connect to board-sim and open the declared boards.

    Options (seconds): ``timeout`` per access, ``connect_timeout``,
    ``max_age`` of the per-tick copy (0: every read goes to the board);
    and those of the declared kinds (the gripper cage's ``cpu``).
    """
    mine, rest = split_options(kinds, options)
    if rest:
        raise url.error(f"tcp: takes no option {', '.join(sorted(rest))} "
                        "(it takes timeout, connect_timeout, max_age)")
    if not url.host or url.port is None or url.port == 0:
        raise url.error("tcp: needs a host and a port 1..65535: tcp://HOST:PORT")
    if url.path not in ("", "/"):
        raise url.error("tcp: takes no path")
    t = _seconds(url, "timeout", timeout)
    ct = _seconds(url, "connect_timeout", connect_timeout)
    age = _seconds(url, "max_age", max_age)
    link = TcpLink(url.text, url.host, url.port, timeout=t, connect_timeout=ct)
    client = TcpRegisters(link, kinds, max_age=age)
    try:
        client.poll(0)  # the first copy: what the boards hold as this controller comes
        client.load_outputs()
        views = {name: TcpBoardRegisters(client, name) for name in kinds}
        boards = {name: kind.remote(views[name], **options_for(kind, mine))
                  for name, kind in kinds.items()}
    except BaseException:
        link.close()
        raise
    pollers = [b.poll for b in boards.values()
               if not isinstance(b, TcpBoardRegisters) and callable(getattr(b, "poll", None))]

    def poll(now_ns: int) -> None:
        client.poll(now_ns)
        for p in pollers:
            p(now_ns)

    return Boards(url.text, station, boards, kinds, in_process=False, world=link.station,
                  views=views, poll=poll, close=link.close, down=lambda: link.down,
                  info=link.info, resync=client.forget)
