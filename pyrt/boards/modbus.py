"""The ``modbus://HOST:PORT?map=FILE`` back end: board registers on Modbus TCP devices.

A station's declared board registers are placed on a Modbus TCP server (an
I/O module, a drive, a PLC, or ``pyrt board-sim NAME --modbus``) by a
register map the user writes (:mod:`pyrt.boards.modbusmap`).  The back end
is an :class:`~pyrt.boards.image.ImageBackend` (the back-end contract):

* read phase: the inputs in the fewest contiguous requests the map allows
  (one for the shipped gripper map: read input registers 0..6);
* write phase: the outputs the tick changed, grouped the same way (write
  multiple registers / coils), each request waiting for its reply; then,
  when the inputs are one request, the next tick's read is sent without
  waiting (``prefetch=1``, the default) and the next read phase only reads
  its reply, which came while the loop slept: no round trip is left inside
  a tick that changes no output.  One transaction is in flight at a time
  (many devices answer one at a time; board-sim answers pipelined ones too);
* the reflex's writes go out at once; a device is not assumed to turn its
  outputs off when the link drops, so on a dead link they are recorded as
  failed (BoardError naming the URL) -- ``off_on_loss=1`` says the device
  does (board-sim does: its watchdog, fed only by the controller that owns
  the outputs -- the connection that wrote first -- turns them off when that
  connection drops or falls silent, whoever else is reading);
* a reply later than N ticks is an overrun, M in a row or none within the
  timeout (N x M ticks, at least 0.1 s) trips the station naming the URL.

URL: ``modbus://HOST:PORT?map=FILE[&timeout=S&connect_timeout=S&max_age=S&
overrun_ticks=N&overrun_limit=M&off_on_loss=0|1&prefetch=0|1]``; ``map`` is a path, or
``builtin:NAME`` for a map shipped with pyrt (``builtin:gripper``,
``builtin:manipulator``: those ``pyrt board-sim NAME --modbus`` serves).

The client.  pymodbus's synchronous client (:class:`pymodbus.client.ModbusTcpClient`),
chosen by measurement (``bench/bench_image.py``, ``test_modbus_exchange_cost``:
one grouped read of the gripper's inputs, input registers 0..6 of unit 1,
from ``pyrt board-sim gripper --modbus`` in another process on loopback,
2000 reads each, two runs on this shared two-core machine, when board-sim
served Modbus through pymodbus's server):

==========================================  ===============  ===============
client                                      p50              p99
==========================================  ===============  ===============
sync (``ModbusTcpClient``)                  80 / 146 µs      167 / 201 µs
async, called from a synchronous caller     161 / 200 µs     296 / 610 µs
async, awaited inside its own event loop    110 / 152 µs     211 / 209 µs
==========================================  ===============  ===============

The loop thread is a synchronous caller: with the async client it hands
the coroutine to the client's event-loop thread and waits for the result,
two thread hand-offs per request, which is what makes it slower and its
tail wider.  The sync client is lower and steadier.  What remains is
pymodbus's own cost per request (building and parsing the frame in
Python, some 40-60 µs of the figures) and the server's (board-sim's one
thread shares the machine with its world), more than the loopback
(a bare TCP round trip is some 20-30 µs here).  Pipelining (above) takes
the read's wait out of the tick: what is left in ``io:read`` is parsing a
reply that is already there.

pymodbus is an optional extra (``pip install 'pyrt[modbus]'``): it is
imported when a ``modbus://`` URL is opened, and its absence is a
ConfigError saying how to install it.
"""

from __future__ import annotations

import contextlib
import importlib.resources
import logging
import threading
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from pyrt.boards.image import (
    DEFAULT_OVERRUN_LIMIT,
    DEFAULT_OVERRUN_TICKS,
    ImageBackend,
    ImageRegisters,
    Write,
)
from pyrt.boards.modbusmap import COIL, DISCRETE, HOLDING, INPUT_REG, Group, RegisterMap, load_map
from pyrt.boards.registers import BoardKind, options_for, split_options
from pyrt.boards.registry import Boards, BoardURL
from pyrt.errors import BoardError, ConfigError

__all__ = ["ModbusRegisters", "builtin_map", "open_modbus", "pymodbus_client"]

DEFAULT_CONNECT_TIMEOUT_S = 2.0
DEFAULT_MAX_AGE_S = 0.05


def pymodbus_client() -> Any:
    """pymodbus's client module; ConfigError saying how to install it if missing."""
    try:
        import pymodbus.client as client
    except ImportError:
        raise ConfigError("modbus:// needs pymodbus: pip install 'pyrt[modbus]'") from None
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)  # errors are ours to report
    return client


def builtin_map(name: str) -> Path:
    """The path of the map shipped for the built-in station ``name``; ConfigError if none."""
    root = importlib.resources.files("pyrt.boards") / "maps"
    path = Path(str(root / f"{name}.toml"))
    if not path.is_file():
        shipped = sorted(p.stem for p in Path(str(root)).glob("*.toml"))
        raise ConfigError(f"no register map shipped for {name!r}; shipped: "
                          f"{', '.join(shipped)}")
    return path


class ModbusRegisters(ImageBackend):
    """The process image of the declared boards over one Modbus TCP connection."""

    def __init__(self, url: str, host: str, port: int, regmap: RegisterMap,
                 kinds: Mapping[str, BoardKind], *, connect_timeout: float,
                 max_age: float = DEFAULT_MAX_AGE_S, timeout: float | None = None,
                 overrun_ticks: int = DEFAULT_OVERRUN_TICKS,
                 overrun_limit: int = DEFAULT_OVERRUN_LIMIT, off_on_loss: bool = False,
                 prefetch: bool = True):
        super().__init__(url, kinds, max_age=max_age, timeout=timeout,
                         overrun_ticks=overrun_ticks, overrun_limit=overrun_limit)
        self.off_on_loss = off_on_loss
        self.map = regmap
        self._down: str | None = None
        mod = pymodbus_client()
        self._pdu_error = _exception_types()
        self.client = mod.ModbusTcpClient(host, port=port, timeout=connect_timeout, retries=0)
        if not self.client.connect():
            self._down = "cannot connect"
            raise BoardError(url, "cannot connect: connection refused or timed out "
                                  "(is the Modbus server running there?)")
        self.client.comm_params.timeout_connect = self.timeout_s
        self._pdus = _pdu_classes()
        #: Pipelining (see the module text): requests sent without waiting, in order.
        self.prefetch = prefetch
        self._pending: list[tuple[str, str, Any]] = []
        self._rx = b""
        self._prefetch_sent = 0
        self._stale_ns = 0
        #: One exchange at a time (the loop thread's phases, a write from another thread).
        self._lock = threading.RLock()
        order = {p.key: n for n, p in enumerate(
            p for b, k in self.kinds.items() for r in k.inputs() for p in
            (regmap.by_key[(b, r.name, i)] for i in range(r.count)))}
        self._input_groups = regmap.read_groups()
        # where each group's places go in the flat input list
        self._slots = [[(order[p.key], p, p.address - g.address) for p in g.places]
                       for g in self._input_groups]

    # -- the exchanges ------------------------------------------------------------------------

    def _fail(self, what: str, why: str) -> None:
        self._down = why
        with contextlib.suppress(Exception):
            self.client.close()
        raise BoardError(self.url, f"{what}: {why}")

    # -- pipelined requests: pymodbus's framer, our own order --------------------------------

    def _send_nowait(self, kind: str, what: str, pdu: Any) -> None:
        if self._down is not None:
            raise BoardError(self.url, f"{what}: the link is down ({self._down})")
        pdu.transaction_id = self.client.transaction.getNextTID()
        frame = self.client.transaction.framer.buildFrame(pdu)
        try:
            self.client.socket.settimeout(self.timeout_s)
            self.client.socket.sendall(frame)
        except (OSError, AttributeError) as exc:
            self._fail(what, getattr(exc, "strerror", None) or "cannot send")
        self._pending.append((kind, what, pdu))

    def _receive(self, what: str, pdu: Any) -> Any:
        framer = self.client.transaction.framer
        sock = self.client.socket
        while True:
            used, reply = framer.handleFrame(self._rx, 0, 0)
            self._rx = self._rx[used:]
            if reply is not None:
                if reply.transaction_id != pdu.transaction_id:
                    self._fail(what, f"reply to transaction {reply.transaction_id}, "
                                     f"not {pdu.transaction_id}")
                return reply
            try:
                sock.settimeout(self.timeout_s)
                data = sock.recv(4096)
            except TimeoutError:
                self._fail(what, "no reply within the timeout")
            except OSError as exc:
                self._fail(what, exc.strerror or str(exc))
            if not data:
                self._fail(what, "the Modbus server closed the connection")
            self._rx += data

    def _drain(self) -> list[tuple[str, str, Any]]:
        """Read the replies of every request sent without waiting, in order:
        (kind, what, reply); BoardError for an exception reply."""
        out = []
        while self._pending:
            kind, what, pdu = self._pending.pop(0)
            reply = self._receive(what, pdu)
            if reply.isError():
                self._pending.clear()
                raise BoardError(self.url, f"{what}: {_refusal(reply)}")
            out.append((kind, what, reply))
        return out

    def _request(self, what: str, fn: Any, *args: Any, **kw: Any) -> Any:
        if self._down is not None:
            raise BoardError(self.url, f"{what}: the link is down ({self._down})")
        if self._pending:
            self._prefetch_sent = 0
            self._drain()
        try:
            reply = fn(*args, **kw)
        except self._pdu_error as exc:
            self._fail(what, _why(exc))
        except OSError as exc:
            self._fail(what, exc.strerror or str(exc))
        if reply.isError():
            raise BoardError(self.url, f"{what}: {_refusal(reply)}")
        return reply

    def _read_group(self, g: Group) -> list[int]:
        c = self.client
        what = f"read unit {g.unit} {g.table} {g.address}..{g.address + g.count - 1}"
        if g.table == INPUT_REG:
            return self._request(what, c.read_input_registers, g.address, count=g.count,
                                 device_id=g.unit).registers
        if g.table == HOLDING:
            return self._request(what, c.read_holding_registers, g.address, count=g.count,
                                 device_id=g.unit).registers
        fn = c.read_coils if g.table == COIL else c.read_discrete_inputs
        assert g.table in (COIL, DISCRETE)
        return [int(b) for b in self._request(what, fn, g.address, count=g.count,
                                              device_id=g.unit).bits[:g.count]]

    def set_tick(self, period_s: float) -> None:
        super().set_tick(period_s)
        self._stale_ns = int(1.5 * period_s * 1e9)

    def _end_of_tick_unlocked(self) -> None:
        """Pipelining: when the map reads the inputs in one request, send the next
        tick's read now; the next read phase reads the reply that came while the
        loop slept (not used if sent more than 1.5 ticks before: the loop
        stalled).  At most one request is ever in flight: many devices, and
        pymodbus's own server, answer one transaction per connection at a time."""
        if self.prefetch and self.phased and not self._prefetch_sent and self._down is None \
                and len(self._input_groups) == 1:
            for g in self._input_groups:
                self._send_nowait("read", _what("read", g), self._pdus[g.table](
                    dev_id=g.unit, address=g.address, count=g.count))
            self._prefetch_sent = time.monotonic_ns()

    def _exchange_inputs_unlocked(self) -> list[int]:
        sent, self._prefetch_sent = self._prefetch_sent, 0
        replies = [r for kind, _, r in self._drain() if kind == "read"] if self._pending else []
        if sent and len(replies) == len(self._input_groups) \
                and time.monotonic_ns() - sent <= self._stale_ns:
            groups = [_values(g, r) for g, r in zip(self._input_groups, replies, strict=True)]
        else:
            groups = [self._read_group(g) for g in self._input_groups]
        out = [0] * self.input_count
        for g, words, slots in zip(self._input_groups, groups, self._slots, strict=True):
            if len(words) < g.count:
                self._fail("read", f"the device answered {len(words)} values, not {g.count}")
            for n, p, off in slots:
                out[n] = p.decode(words[off:off + p.size])
        return out

    def _write(self, writes: list[Write]) -> None:
        """The writes, one request per contiguous group, each waiting for its reply
        (one transaction in flight at a time)."""
        values = {(b, n, i): v for b, n, i, v in writes}
        for g in self.map.write_groups(values):
            words: list[int] = []
            for p in g.places:
                words += p.encode(values[p.key])
            what = _what("write", g)
            if g.table == HOLDING:
                self._request(what, self.client.write_registers, g.address, words,
                              device_id=g.unit)
            else:
                self._request(what, self.client.write_coils, g.address,
                              [bool(w) for w in words], device_id=g.unit)

    def _exchange_outputs_unlocked(self, writes: list[Write]) -> None:
        self._write(writes)

    def _exchange_outputs_now_unlocked(self, writes: list[Write]) -> None:
        self._write(writes)

    def _read_outputs_unlocked(self) -> dict[tuple[str, str, int], int]:
        out: dict[tuple[str, str, int], int] = {}
        for g in self.map.output_groups():
            words = self._read_group(g)
            for p in g.places:
                off = p.address - g.address
                out[p.key] = p.decode(words[off:off + p.size])
        return out

    # -- the contract's exchanges, one at a time ----------------------------------------------

    def end_of_tick(self) -> None:
        with self._lock:
            self._end_of_tick_unlocked()

    def exchange_inputs(self) -> list[int]:
        with self._lock:
            return self._exchange_inputs_unlocked()

    def exchange_outputs(self, writes: list[Write]) -> None:
        with self._lock:
            self._exchange_outputs_unlocked(writes)

    def exchange_outputs_now(self, writes: list[Write]) -> None:
        with self._lock:
            self._exchange_outputs_now_unlocked(writes)

    def read_outputs(self) -> dict[tuple[str, str, int], int]:
        with self._lock:
            return self._read_outputs_unlocked()

    def apply_timeout(self, seconds: float) -> None:
        self.client.comm_params.timeout_connect = seconds

    def close_link(self) -> None:
        if self._down is None:
            self._down = "closed"
        with contextlib.suppress(Exception):
            self.client.close()

    @property
    def down(self) -> str | None:
        return self._down


def _what(verb: str, g: Group) -> str:
    return f"{verb} unit {g.unit} {g.table} {g.address}..{g.address + g.count - 1}"


def _values(g: Group, reply: Any) -> list[int]:
    if g.table in (COIL, DISCRETE):
        return [int(b) for b in reply.bits[:g.count]]
    return list(reply.registers)


def _pdu_classes() -> dict[str, Any]:
    from pymodbus.pdu.bit_message import (
        ReadCoilsRequest,
        ReadDiscreteInputsRequest,
    )
    from pymodbus.pdu.register_message import (
        ReadHoldingRegistersRequest,
        ReadInputRegistersRequest,
    )
    return {COIL: ReadCoilsRequest, DISCRETE: ReadDiscreteInputsRequest,
            INPUT_REG: ReadInputRegistersRequest, HOLDING: ReadHoldingRegistersRequest}


def _exception_types() -> tuple[type[BaseException], ...]:
    from pymodbus.exceptions import ModbusException
    return (ModbusException,)


#: The exception codes of the Modbus application protocol, in words.
_EXCEPTIONS = {
    1: "illegal function",
    2: "illegal data address; the map places a register where the device has none?",
    3: "illegal data value",
    4: "server device failure",
    5: "acknowledge; the device is still working on it",
    6: "server device busy; board-sim says so while another controller owns the outputs",
    8: "memory parity error",
    10: "gateway path unavailable",
    11: "gateway target device failed to respond; no such unit there?",
}


def _refusal(reply: Any) -> str:
    """An exception reply in words: ``the device answered exception 06 (...)``."""
    code = getattr(reply, "exception_code", None)
    if not isinstance(code, int):
        return f"the device answered {reply}"
    return f"the device answered exception {code:02X} ({_EXCEPTIONS.get(code, 'unknown')})"


def _why(exc: BaseException) -> str:
    text = str(exc)
    if "No response" in text or "timeout" in text.lower():
        return "no reply within the timeout"
    if "Connection" in type(exc).__name__ or "closed" in text.lower():
        return "the Modbus server closed the connection"
    return text[:120] or type(exc).__name__


# -- the factory -------------------------------------------------------------------------


def _number(url: BoardURL, name: str, value: Any, lo: float, hi: float,
            *, whole: bool = False) -> Any:
    try:
        v = int(value) if whole else float(value)
    except (TypeError, ValueError):
        raise url.error(f"option {name} must be a number, got {value!r}") from None
    if not lo <= v <= hi:
        raise url.error(f"option {name} must be {lo:g}..{hi:g}, got {value!r}")
    return v


def open_modbus(url: BoardURL, station: str, kinds: dict[str, BoardKind], *,
                map: Any = None, timeout: Any = None,
                connect_timeout: Any = DEFAULT_CONNECT_TIMEOUT_S,
                max_age: Any = DEFAULT_MAX_AGE_S, overrun_ticks: Any = DEFAULT_OVERRUN_TICKS,
                overrun_limit: Any = DEFAULT_OVERRUN_LIMIT, off_on_loss: Any = "0",
                prefetch: Any = "1", **options: Any) -> Boards:
    """The ``modbus://HOST:PORT?map=FILE`` back end (see the module text)."""
    mine, rest = split_options(kinds, options)
    if rest:
        raise url.error(f"modbus: takes no option {', '.join(sorted(rest))} (it takes map, "
                        "timeout, connect_timeout, max_age, overrun_ticks, overrun_limit, "
                        "off_on_loss, prefetch)")
    if not url.host or url.port is None or url.port == 0:
        raise url.error("modbus: needs a host and a port: modbus://HOST:PORT?map=FILE")
    if url.path not in ("", "/"):
        raise url.error("modbus: takes no path (the map is ?map=FILE)")
    if not map:
        raise url.error("modbus: needs a register map: modbus://HOST:PORT?map=FILE "
                        "(or map=builtin:NAME)")
    text = str(map)
    path = builtin_map(text[len("builtin:"):]) if text.startswith("builtin:") else Path(text)
    regmap = load_map(path, kinds)
    t = _number(url, "timeout", timeout, 0.001, 3600) if timeout is not None else None
    ct = _number(url, "connect_timeout", connect_timeout, 0.001, 3600)
    age = _number(url, "max_age", max_age, 0, 3600)
    n = _number(url, "overrun_ticks", overrun_ticks, 1, 10_000, whole=True)
    m = _number(url, "overrun_limit", overrun_limit, 1, 10_000, whole=True)
    for name, flag in (("off_on_loss", off_on_loss), ("prefetch", prefetch)):
        if str(flag) not in ("0", "1", "True", "False"):
            raise url.error(f"option {name} must be 0 or 1, got {flag!r}")
    client = ModbusRegisters(url.text, url.host, url.port, regmap, kinds, connect_timeout=ct,
                             max_age=age, timeout=t, overrun_ticks=n, overrun_limit=m,
                             off_on_loss=str(off_on_loss) in ("1", "True"),
                             prefetch=str(prefetch) in ("1", "True"))
    try:
        client.open()
        views = {name: ImageRegisters(client, name) for name in kinds}
        boards = {name: kind.remote(views[name], **options_for(kind, mine))
                  for name, kind in kinds.items()}
    except BaseException:
        client.close()
        raise
    pollers = [b.poll for b in boards.values()
               if not isinstance(b, ImageRegisters) and callable(getattr(b, "poll", None))]
    return Boards(url.text, station, boards, kinds, in_process=False, world="",
                  views=views, **client.boards_hooks(pollers))
