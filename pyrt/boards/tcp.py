"""The ``tcp://HOST:PORT`` back end: the boards of ``pyrt board-sim`` in another process.

Every register access is one request line and one reply line on a TCP
connection (:mod:`pyrt.boards.wire`).  :class:`TcpGripperBoard` implements
:class:`~pyrt.boards.gripper.GripperBoard` and maps itself into the 8031's
external data space exactly as the simulated board does, so the controller
program is the same; :class:`TcpTIO10` and :class:`TcpDataConcentrator`
implement the manipulator's :class:`~pyrt.boards.tio10.TIO10` and
:class:`~pyrt.boards.dataconcentrator.DataConcentrator`.

One round trip per tick.  ``poll(now_ns)`` (attach it to the loop before
the ready queue) reads every input register with one ``SNAP``; the reads
of that tick are answered from it, and a write goes to the board at once
and updates the copy, so a read after a write sees the value written.  A
copy older than ``max_age`` seconds (default 0.05) is not used: a read
outside the ticks goes to the board.  For the gripper the same ``SNAP``
carries the encoder's pulse counters, and ``poll`` raises the 8031's
external interrupts 0 and 1 once per pulse that arrived since the last
poll (the in-process board raises them as the encoder turns; the count per
tick is the same).

Failures.  A connection refused, reset or closed, or no reply within
``timeout`` seconds (default 0.25), raises :class:`~pyrt.errors.BoardError`
naming the URL, and the link stays down: every later access raises it too,
at once (board-sim turns its outputs off when the connection drops; a link
never resumes a half-known state).  Only what the drop itself did is still
answered on a down link, without a round trip, so that a reflex action can
finish: writing the DAC's null (80), disarming a TIO10 channel and setting
its all-windings-off bit succeed, and a channel reads as disarmed.

When board-sim's watchdog has turned the outputs off while the link was
up (the controller's loop stalled longer than the watchdog time), the next
``poll`` raises BoardError once, saying so; the link stays up.  A value
the board refuses raises ``ValueError``, as the in-process boards do.
"""

from __future__ import annotations

import contextlib
import socket
import struct
import threading
import time
from typing import Any

from pyrt.boards.dataconcentrator import (
    COUNTER_BITS,
    DataConcentrator,
    check_adc_channel,
    check_counter_address,
)
from pyrt.boards.gripper import (
    DAC,
    DAC_NULL,
    PULSE_MODULUS,
    REGISTERS,
    GripperBoard,
    check_byte,
    check_register,
)
from pyrt.boards.i8031 import I8031
from pyrt.boards.registry import Boards, BoardURL
from pyrt.boards.tio10 import (
    AWO_BITS,
    MAX_PERIOD,
    MIN_PERIOD,
    TIO10,
    check_channel,
    check_port,
    source_hz,
)
from pyrt.boards.wire import GREETING, MANIPULATOR_SNAP, MAX_LINE, VERSION
from pyrt.errors import BoardError, ConfigError

__all__ = [
    "DEFAULT_CONNECT_TIMEOUT_S",
    "DEFAULT_MAX_AGE_S",
    "DEFAULT_TIMEOUT_S",
    "TcpDataConcentrator",
    "TcpGripperBoard",
    "TcpLink",
    "TcpManipulatorBoards",
    "TcpTIO10",
    "open_tcp",
]

DEFAULT_TIMEOUT_S = 0.25
DEFAULT_CONNECT_TIMEOUT_S = 2.0
DEFAULT_MAX_AGE_S = 0.05

_COUNTER_MASK = (1 << COUNTER_BITS) - 1
#: The registers of a gripper SNAP reply, after the two pulse counts.
_SNAP_REGISTERS = tuple(REGISTERS)


class TcpLink:
    """One connection to board-sim: a request line out, a reply line back.

    Thread-safe (one request at a time).  Reads the greeting on connect:
    ``kind`` (gripper/manipulator), ``world`` (its name) and
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
        if len(greeting) < 6 or greeting[:2] != ["OK", GREETING] or greeting[2] != str(VERSION):
            self._fail(f"not a pyrt board-sim (protocol {VERSION}): greeting "
                       f"{' '.join(greeting)[:80]!r}", "connect")
        self.kind = greeting[3]
        self.world = greeting[4]
        try:
            self.watchdog_s = int(greeting[5]) / 1000.0
        except ValueError:
            self._fail(f"bad greeting {' '.join(greeting)[:80]!r}", "connect")

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


# -- the gripper -----------------------------------------------------------------------


class TcpGripperBoard(GripperBoard):
    """The gripper cage of a board-sim, mapped into ``cpu`` (see the module text)."""

    def __init__(self, link: TcpLink, cpu: I8031, *, max_age: float = DEFAULT_MAX_AGE_S):
        self.link = link
        self.url = link.url
        self.cpu = cpu
        self.max_age_ns = int(max_age * 1e9)
        self._values: dict[int, int] = {}
        self._fresh_until = 0
        self._up, self._down = self._snap()  # pulses before we came are not ours
        self._fresh_until = 0
        self.map_xdata(cpu)

    def _snap(self) -> tuple[int, int]:
        nums = self.link.request_ints("SNAP")
        if len(nums) != 3 + len(_SNAP_REGISTERS):
            self.link._fail(f"SNAP answered {len(nums)} values", "SNAP")
        self._values = dict(zip(_SNAP_REGISTERS, nums[3:], strict=True))
        self._fresh_until = time.monotonic_ns() + self.max_age_ns
        self.link.check_trips(nums[0])
        return nums[1], nums[2]

    def read(self, addr: int) -> int:
        check_register(addr)
        if time.monotonic_ns() < self._fresh_until:
            return self._values[addr]
        return self.link.request_ints(f"R {addr}")[0]

    def write(self, addr: int, value: int) -> None:
        check_register(addr, write=True)
        check_byte(value)
        if addr == DAC and value == DAC_NULL and self.link.down is not None:
            self._values[addr] = value  # board-sim nulled it when the link dropped
            return
        self.link.request(f"W {addr} {value}")
        self._values[addr] = value

    def pulse_counts(self) -> tuple[int, int]:
        return self._up, self._down

    def poll(self, now_ns: int) -> None:
        up, down = self._snap()
        n_up = (up - self._up) % PULSE_MODULUS
        n_down = (down - self._down) % PULSE_MODULUS
        self._up, self._down = up, down
        if n_up or n_down:
            self.deliver(self.cpu, n_up, n_down)

    def close(self) -> None:
        self.link.close()


# -- the manipulator --------------------------------------------------------------------

_RTC = MANIPULATOR_SNAP["rtc"][0]
_PORT = MANIPULATOR_SNAP["port"][0]
_SRC = MANIPULATOR_SNAP["src"][0]
_PER = MANIPULATOR_SNAP["per"][0]
_ARMED = MANIPULATOR_SNAP["armed"][0]
_PULSES = MANIPULATOR_SNAP["pulses"][0]
_ADC = MANIPULATOR_SNAP["adc"][0]
_CNT = MANIPULATOR_SNAP["cnt"][0]
_AWO = frozenset(AWO_BITS.values())


class TcpManipulatorBoards:
    """The TIO10 and dataConcentrator of a board-sim on one link, with the
    per-tick copy of their inputs that :meth:`poll` takes."""

    def __init__(self, link: TcpLink, *, max_age: float = DEFAULT_MAX_AGE_S):
        self.link = link
        self.url = link.url
        self.max_age_ns = int(max_age * 1e9)
        self._snap: list[int] = []
        self._counters: dict[int, int] = {}
        #: Counter addresses read so far: the next SNAP brings them along.
        self._addresses: tuple[int, ...] = ()
        self._fresh_until = 0
        self.tio10 = TcpTIO10(self)
        self.dc = TcpDataConcentrator(self)

    def poll(self, now_ns: int = 0) -> None:
        """Read every input register in one round trip (the tick's copy)."""
        addrs = self._addresses
        req = "SNAP " + " ".join(map(str, addrs)) if addrs else "SNAP"
        snap = self.link.request_ints(req)
        if len(snap) != _CNT + len(addrs):
            self.link._fail(f"SNAP answered {len(snap)} values", "SNAP")
        self._counters = dict(zip(addrs, snap[_CNT:], strict=True))
        self._snap = snap
        self._fresh_until = time.monotonic_ns() + self.max_age_ns
        self.link.check_trips(snap[0])

    def fresh(self) -> bool:
        """Whether reads are answered from the tick's copy now."""
        return time.monotonic_ns() < self._fresh_until

    def _get(self, index: int, request: str) -> int:
        if time.monotonic_ns() < self._fresh_until:
            return self._snap[index]
        return self.link.request_ints(request)[0]

    def _put(self, index: int, value: int) -> None:
        if self._snap:
            self._snap[index] = value

    def _counter(self, address: int) -> int:
        if time.monotonic_ns() < self._fresh_until:
            raw = self._counters.get(address)
            if raw is not None:
                return raw
        if address not in self._addresses:
            self._addresses = (*self._addresses, address)
        return self.link.request_ints(f"CNT {address}")[0]

    def _clear(self, address: int) -> None:
        self.link.request(f"CLR {address}")
        if address in self._counters:
            self._counters[address] = 0
        elif address not in self._addresses:
            self._addresses = (*self._addresses, address)

    def close(self) -> None:
        """Close the link."""
        self.link.close()


class TcpTIO10(TIO10):
    """A board-sim's TIO10 (see the module text)."""

    def __init__(self, boards: TcpManipulatorBoards):
        self._b = boards
        self.url = boards.url

    def select_source(self, channel: int, source: int) -> None:
        check_channel(channel)
        source_hz(source)
        self._b.link.request(f"SRC {channel} {source}")
        self._b._put(_SRC + channel, source)

    def source(self, channel: int) -> int:
        check_channel(channel, allow_rtc=True)
        return self._b._get(_SRC + channel, f"SRC {channel}")

    def load_period(self, channel: int, ticks: int) -> None:
        check_channel(channel)
        if isinstance(ticks, bool) or not isinstance(ticks, int):
            raise ValueError(f"period must be an integer tick count, got {ticks!r}")
        if not MIN_PERIOD <= ticks <= MAX_PERIOD:
            raise ValueError(
                f"period {ticks} out of the 16-bit load register's range "
                f"{MIN_PERIOD}..{MAX_PERIOD} ticks"
            )
        self._b.link.request(f"PER {channel} {ticks}")
        self._b._put(_PER + channel, ticks)

    def period(self, channel: int) -> int:
        check_channel(channel, allow_rtc=True)
        return self._b._get(_PER + channel, f"PER {channel}")

    def arm(self, channel: int) -> None:
        check_channel(channel)
        self._b.link.request(f"ARM {channel}")
        self._b._put(_ARMED + channel, 1)

    def disarm(self, channel: int) -> None:
        check_channel(channel)
        if self._b.link.down is None:  # else board-sim disarmed it when the link dropped
            self._b.link.request(f"DISARM {channel}")
        self._b._put(_ARMED + channel, 0)

    def armed(self, channel: int) -> bool:
        check_channel(channel, allow_rtc=True)
        if self._b.link.down is not None:
            return False
        return bool(self._b._get(_ARMED + channel, f"ARMED {channel}"))

    def set_bit(self, port: int, bit: int, value: bool) -> None:
        if value and (port, bit) in _AWO and self._b.link.down is not None:
            return  # board-sim set every all-windings-off bit when the link dropped
        super().set_bit(port, bit, value)

    def pulses(self, channel: int) -> int:
        check_channel(channel, allow_rtc=True)
        return self._b._get(_PULSES + channel, f"PULSES {channel}")

    def write_port(self, port: int, value: int) -> None:
        check_port(port)
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 0xFF:
            raise ValueError(f"PIA port value must be 0..255, got {value!r}")
        self._b.link.request(f"PORT {port} {value}")
        self._b._put(_PORT + port, value)

    def read_port(self, port: int) -> int:
        check_port(port)
        return self._b._get(_PORT + port, f"PORT {port}")

    def rtc_ticks(self) -> int:
        return self._b._get(_RTC, "RTC")


class TcpDataConcentrator(DataConcentrator):
    """A board-sim's dataConcentrator (see the module text)."""

    def __init__(self, boards: TcpManipulatorBoards):
        self._b = boards
        self.url = boards.url

    def read_counter(self, address: int) -> int:
        return self._b._counter(check_counter_address(address)) & _COUNTER_MASK

    def clear_counter(self, address: int) -> None:
        self._b._clear(check_counter_address(address))

    def read_adc(self, channel: int) -> int:
        check_adc_channel(channel)
        return self._b._get(_ADC + channel, f"ADC {channel}")


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
    robot: str,
    *,
    cpu: I8031 | None = None,
    timeout: Any = DEFAULT_TIMEOUT_S,
    connect_timeout: Any = DEFAULT_CONNECT_TIMEOUT_S,
    max_age: Any = DEFAULT_MAX_AGE_S,
    **options: Any,
) -> Boards:
    """The ``tcp://HOST:PORT`` back end: connect to board-sim and open ``robot``'s boards.

    Options (seconds): ``timeout`` per access, ``connect_timeout``,
    ``max_age`` of the per-tick copy (0: every read goes to the board).
    """
    if options:
        raise url.error(f"tcp: takes no option {', '.join(sorted(options))} "
                        "(it takes timeout, connect_timeout, max_age)")
    if not url.host or url.port is None or url.port == 0:
        raise url.error("tcp: needs a host and a port 1..65535: tcp://HOST:PORT")
    if url.path not in ("", "/"):
        raise url.error("tcp: takes no path")
    t = _seconds(url, "timeout", timeout)
    ct = _seconds(url, "connect_timeout", connect_timeout)
    age = _seconds(url, "max_age", max_age)
    link = TcpLink(url.text, url.host, url.port, timeout=t, connect_timeout=ct)
    if link.kind != robot:
        link.close()
        raise ConfigError(f"board URL {url.text!r}: board-sim there serves a {link.kind} "
                          f"({link.world}), not a {robot}")
    common: dict[str, Any] = dict(in_process=False, world=link.world, close=link.close,
                                  down=lambda: link.down, info=link.info,
                                  resync=link.forget_trips)
    if robot == "gripper":
        cpu = cpu if cpu is not None else I8031()
        try:
            board = TcpGripperBoard(link, cpu, max_age=age)
        except BaseException:
            link.close()
            raise
        return Boards(url.text, robot, gripper=board, cpu=cpu, poll=board.poll, **common)
    boards = TcpManipulatorBoards(link, max_age=age)
    return Boards(url.text, robot, tio10=boards.tio10, dc=boards.dc, poll=boards.poll, **common)
