"""board-sim over Modbus TCP: a station's simulated boards served as a Modbus device.

:class:`ModbusBoardServer` serves one :class:`~pyrt.sim.world.World` (any
station's) on a Modbus TCP address, its declared registers placed by a
register map (:mod:`pyrt.boards.modbusmap`; the map shipped for each
built-in station is ``pyrt/boards/maps/NAME.toml``), so that any Modbus
tool -- and pyrt's ``modbus://`` back end -- reads and drives a simulated
robot.  It is a :class:`~pyrt.sim.boardsim.LinkServer`: the same loop,
world stepping, owner, watchdog and connection bounds as ``tcp://``
(read the module text of :mod:`pyrt.sim.boardsim`), speaking the Modbus
application protocol as a device does:

* function 1, 2, 3, 4 (read coils, discrete inputs, holding registers,
  input registers): the places the map gives, each register encoded as
  the map says (a write-only strobe reads 0);
* function 5, 6, 15, 16 (write single / multiple coils and registers) and
  23 (read/write multiple registers): the outputs placed there (a 32-bit
  place written by halves keeps the other half);
* every request of a Modbus TCP frame (MBAP header: transaction, protocol
  0, length, unit) is answered, in order, pipelined requests included.

Exceptions, and what they change: nothing.  01 illegal function (a
function not above); 02 illegal data address (an address the map does not
place on that unit and table, or a write to an input); 03 illegal data
value (a count beyond the protocol's limits, a byte count that disagrees
with it, a coil value other than 0000/FF00, or a value the register cannot
hold: 0x0100 to the 8-bit DAC is refused, never wrapped; a value the board
refuses); 06 server device busy (a write while another connection owns the
outputs); 0B gateway target failed to respond (a unit the map does not
use).  Every value of a write is checked before any is made.  A frame
whose header is not Modbus TCP (protocol id not 0, a length beyond 254)
closes the connection: the stream cannot be followed past it.

Owner and watchdog.  The connection that writes first owns the outputs
(Modbus has no session: a connection is one); a map that names the owner
(``owner = "ADDRESS"``, :mod:`pyrt.boards.modbusmap`) lets only a
connection from there own them, and any other connection's write gets
exception 06 and changes nothing even while nobody owns them; every request of the
owner's connection -- its writes, and its reads, the keep-alive of its
session -- feeds the watchdog, a reader's never does.  When the owner has
made none for ``watchdog_s``, or its connection closes, every output
register that declares an ``off`` value is written with it (the gripper's
DAC to null 80), whoever else is connected and polling.
"""

from __future__ import annotations

import struct
import time
from collections.abc import Callable

from pyrt.boards.modbusmap import COIL, DISCRETE, HOLDING, INPUT_REG, Place, RegisterMap
from pyrt.sim.boardsim import (
    DEFAULT_IDLE_S,
    DEFAULT_MAX_CLIENTS,
    DEFAULT_STEP_NS,
    DEFAULT_WATCHDOG_S,
    Connection,
    LinkServer,
)
from pyrt.sim.world import World

__all__ = ["ILLEGAL_ADDRESS", "ILLEGAL_FUNCTION", "ILLEGAL_VALUE", "SERVER_BUSY",
           "ModbusBoardServer"]

#: The exception codes it answers.
ILLEGAL_FUNCTION = 0x01
ILLEGAL_ADDRESS = 0x02
ILLEGAL_VALUE = 0x03
SERVER_FAILURE = 0x04
SERVER_BUSY = 0x06
NO_SUCH_UNIT = 0x0B

_READ = {1: COIL, 2: DISCRETE, 3: HOLDING, 4: INPUT_REG}
_MAX_LENGTH = 254  # MBAP length: the unit and a PDU of at most 253 bytes
_HEADER = struct.Struct(">HHHB")


class _Exception(Exception):
    """A Modbus exception reply (its code)."""

    def __init__(self, code: int):
        super().__init__(code)
        self.code = code


def _bits(data: bytes, count: int) -> list[int]:
    return [(data[i // 8] >> (i % 8)) & 1 for i in range(count)]


def _pack_bits(values: list[int]) -> bytes:
    out = bytearray((len(values) + 7) // 8)
    for i, v in enumerate(values):
        if v:
            out[i // 8] |= 1 << (i % 8)
    return bytes(out)


class ModbusBoardServer(LinkServer):
    """Serve ``world`` over Modbus TCP on ``host:port`` with ``regmap`` (see the module text).

    Port 0 picks a free port (:attr:`url`).  ``say(line)`` is told one line per
    event (connections, the owner, watchdog trips).  :meth:`serve_forever`
    blocks until :meth:`stop`; :meth:`start` runs it in a thread of its own.
    ConfigError if it cannot listen.
    """

    def __init__(self, world: World, regmap: RegisterMap, host: str = "127.0.0.1",
                 port: int = 0, *, watchdog_s: float = DEFAULT_WATCHDOG_S,
                 step_ns: int = DEFAULT_STEP_NS, idle_s: float = DEFAULT_IDLE_S,
                 max_clients: int = DEFAULT_MAX_CLIENTS,
                 say: Callable[[str], None] | None = None,
                 clock: Callable[[], int] = time.monotonic_ns):
        super().__init__(world, host, port, watchdog_s=watchdog_s, step_ns=step_ns,
                         idle_s=idle_s, max_clients=max_clients, say=say, clock=clock)
        self.map = regmap
        self.at: dict[tuple[int, str, int], tuple[Place, int]] = {}
        for p in regmap.places:
            for k in range(p.size):
                self.at[(p.unit, p.table, p.address + k)] = (p, k)
        self.units = frozenset(p.unit for p in regmap.places)
        self._handlers: dict[int, Callable[[Connection, int, int, bytes], bytes]] = {
            1: self._fc_read, 2: self._fc_read, 3: self._fc_read, 4: self._fc_read,
            5: self._write_coil, 6: self._write_register, 15: self._write_coils,
            16: self._write_registers, 23: self._read_write}

    @property
    def url(self) -> str:
        """The back-end URL of these boards (add ``?map=...``)."""
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"modbus://{host}:{self.port}"

    # -- frames ------------------------------------------------------------------------------

    def consume(self, conn: Connection) -> None:
        buf = conn.inbuf
        while len(buf) >= _HEADER.size:
            tid, protocol, length, unit = _HEADER.unpack_from(buf)
            if protocol != 0 or not 2 <= length <= _MAX_LENGTH:
                self.errors += 1
                self._drop(conn, f"closed: not a Modbus TCP frame (protocol {protocol}, "
                                 f"length {length})")
                return
            end = 6 + length
            if len(buf) < end:
                break
            pdu = bytes(buf[_HEADER.size:end])
            del buf[:end]
            self.came(conn)
            reply = self.answer(conn, unit, pdu)
            self.requests += 1
            if reply[0] & 0x80:
                self.errors += 1
            conn.out += _HEADER.pack(tid, 0, len(reply) + 1, unit) + reply

    def answer(self, conn: Connection, unit: int, pdu: bytes) -> bytes:
        """The reply PDU to the request PDU ``pdu`` for ``unit`` from ``conn``."""
        fc = pdu[0]
        handler = self._handlers.get(fc)
        try:
            if handler is None:
                raise _Exception(ILLEGAL_FUNCTION)
            if unit not in self.units:
                raise _Exception(NO_SUCH_UNIT)
            return handler(conn, unit, fc, pdu)
        except _Exception as exc:
            return bytes([fc | 0x80, exc.code])
        except Exception as exc:  # a bug in the world: answer it, keep serving
            self._say(f"internal error on function {fc} from {conn.addr}: "
                      f"{type(exc).__name__}: {exc}")
            return bytes([fc | 0x80, SERVER_FAILURE])

    # -- the places ----------------------------------------------------------------------------

    def _words(self, p: Place) -> list[int]:
        reg = p.register
        if not reg.readback:
            return [0] * p.size
        return p.encode(self.views[p.board].read(reg.name, p.index))

    def _get(self, unit: int, table: str, address: int, count: int) -> list[int]:
        if address + count > 0x10000:
            raise _Exception(ILLEGAL_ADDRESS)
        out: list[int] = []
        cache: dict[tuple[str, str, int], list[int]] = {}
        for a in range(address, address + count):
            hit = self.at.get((unit, table, a))
            if hit is None:
                raise _Exception(ILLEGAL_ADDRESS)
            p, k = hit
            words = cache.get(p.key)
            if words is None:
                words = cache[p.key] = self._words(p)
            out.append(words[k])
        return out

    def _set(self, conn: Connection, unit: int, table: str, address: int,
             values: list[int]) -> None:
        """Write ``values`` from ``address`` on: every one checked first (02, 03),
        then the claim (06), then the writes."""
        if address + len(values) > 0x10000:
            raise _Exception(ILLEGAL_ADDRESS)
        touched: dict[tuple[str, str, int], tuple[Place, list[int]]] = {}
        for a, v in zip(range(address, address + len(values)), values, strict=True):
            hit = self.at.get((unit, table, a))
            if hit is None or hit[0].register.is_input:
                raise _Exception(ILLEGAL_ADDRESS)
            p, k = hit
            if p.key not in touched:
                touched[p.key] = (p, self._words(p))
            touched[p.key][1][k] = v
        writes = []
        for p, words in touched.values():
            try:
                value = p.decode_write(words)
                self.kinds[p.board].check_write(p.register.name, p.index, value)
            except ValueError:
                raise _Exception(ILLEGAL_VALUE) from None
            writes.append((p, value))
        if not self.map.may_own(conn.addr.rsplit(":", 1)[0]):
            if not conn.told:
                conn.told = True
                self._say(f"refused {conn.addr}: the map names "
                          f"{' or '.join(self.map.owner)} as the outputs' owner")
            self.refused += 1
            raise _Exception(SERVER_BUSY)
        if self.claim(conn) is not None:
            raise _Exception(SERVER_BUSY)
        self.feed(conn)
        for p, value in writes:
            try:
                self.views[p.board].write(p.register.name, value, p.index)
            except ValueError:  # the board refused it (those before it stand)
                raise _Exception(ILLEGAL_VALUE) from None

    # -- the functions -------------------------------------------------------------------------

    def _fc_read(self, conn: Connection, unit: int, fc: int, pdu: bytes) -> bytes:
        if len(pdu) != 5:
            raise _Exception(ILLEGAL_VALUE)
        address, count = struct.unpack_from(">HH", pdu, 1)
        table = _READ[fc]
        bits = table in (COIL, DISCRETE)
        if not 1 <= count <= (2000 if bits else 125):
            raise _Exception(ILLEGAL_VALUE)
        values = self._get(unit, table, address, count)
        self.feed(conn)
        if bits:
            data = _pack_bits(values)
            return bytes([fc, len(data)]) + data
        return bytes([fc, 2 * count]) + struct.pack(f">{count}H", *values)

    def _write_coil(self, conn: Connection, unit: int, fc: int, pdu: bytes) -> bytes:
        if len(pdu) != 5:
            raise _Exception(ILLEGAL_VALUE)
        address, value = struct.unpack_from(">HH", pdu, 1)
        if value not in (0x0000, 0xFF00):
            raise _Exception(ILLEGAL_VALUE)
        self._set(conn, unit, COIL, address, [1 if value else 0])
        return pdu

    def _write_register(self, conn: Connection, unit: int, fc: int, pdu: bytes) -> bytes:
        if len(pdu) != 5:
            raise _Exception(ILLEGAL_VALUE)
        address, value = struct.unpack_from(">HH", pdu, 1)
        self._set(conn, unit, HOLDING, address, [value])
        return pdu

    def _write_coils(self, conn: Connection, unit: int, fc: int, pdu: bytes) -> bytes:
        if len(pdu) < 6:
            raise _Exception(ILLEGAL_VALUE)
        address, count, size = struct.unpack_from(">HHB", pdu, 1)
        if not 1 <= count <= 1968 or size != (count + 7) // 8 or len(pdu) != 6 + size:
            raise _Exception(ILLEGAL_VALUE)
        self._set(conn, unit, COIL, address, _bits(pdu[6:], count))
        return pdu[:5]

    def _write_registers(self, conn: Connection, unit: int, fc: int, pdu: bytes) -> bytes:
        if len(pdu) < 6:
            raise _Exception(ILLEGAL_VALUE)
        address, count, size = struct.unpack_from(">HHB", pdu, 1)
        if not 1 <= count <= 123 or size != 2 * count or len(pdu) != 6 + size:
            raise _Exception(ILLEGAL_VALUE)
        self._set(conn, unit, HOLDING, address, list(struct.unpack_from(f">{count}H", pdu, 6)))
        return pdu[:5]

    def _read_write(self, conn: Connection, unit: int, fc: int, pdu: bytes) -> bytes:
        if len(pdu) < 10:
            raise _Exception(ILLEGAL_VALUE)
        raddr, rcount, waddr, wcount, size = struct.unpack_from(">HHHHB", pdu, 1)
        if not 1 <= rcount <= 125 or not 1 <= wcount <= 121 or size != 2 * wcount \
                or len(pdu) != 10 + size:
            raise _Exception(ILLEGAL_VALUE)
        if raddr + rcount > 0x10000 \
                or any((unit, HOLDING, a) not in self.at for a in range(raddr, raddr + rcount)):
            raise _Exception(ILLEGAL_ADDRESS)
        self._set(conn, unit, HOLDING, waddr, list(struct.unpack_from(f">{wcount}H", pdu, 10)))
        values = self._get(unit, HOLDING, raddr, rcount)
        return bytes([fc, 2 * rcount]) + struct.pack(f">{rcount}H", *values)
