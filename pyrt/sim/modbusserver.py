"""board-sim over Modbus TCP: a station's simulated boards served by a pymodbus server.

:class:`ModbusBoardServer` serves one :class:`~pyrt.sim.world.World` (any
station's) on a Modbus TCP address, its declared registers placed by a
register map (:mod:`pyrt.boards.modbusmap`; the map shipped for each
built-in station is ``pyrt/boards/maps/NAME.toml``), so that any Modbus
tool -- and pyrt's ``modbus://`` back end -- reads and drives a simulated
robot.  The server is pymodbus's :class:`~pymodbus.server.ModbusTcpServer`
with a data store that answers every request from the world's boards:

* read coils / discrete inputs / input registers / holding registers: the
  places the map gives, each register encoded as the map says (an
  address the map does not place is an ``ILLEGAL_ADDRESS`` exception;
  a write-only strobe reads 0);
* write single / multiple coils and registers: the outputs placed there
  (a 32-bit place written by halves keeps the other half); an input, or a
  value the board refuses, is an exception reply and changes nothing.

One thread runs an asyncio loop: the server, and a task that steps the
world every ``step_ns`` of the monotonic clock (dt = now - last) and keeps
the **watchdog**: when no request has come for ``watchdog_s``, or the
client's connection closes, every output register that declares an
``off`` value is written with it (the gripper's DAC to null 80).  Any
number of clients may connect (Modbus has no greeting); the last one to
close turns the outputs off.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import socket
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

from pyrt.boards.modbusmap import COIL, DISCRETE, HOLDING, INPUT_REG, Place, RegisterMap
from pyrt.errors import ConfigError
from pyrt.sim.world import World

__all__ = ["ModbusBoardServer"]

_READ = {1: COIL, 2: DISCRETE, 3: HOLDING, 4: INPUT_REG}
_WRITE = {5: COIL, 15: COIL, 6: HOLDING, 16: HOLDING, 23: HOLDING}


def _pymodbus() -> tuple[Any, Any, Any]:
    try:
        from pymodbus.constants import ExcCodes
        from pymodbus.datastore import ModbusServerContext
        from pymodbus.server import ModbusTcpServer
    except ImportError:
        raise ConfigError("board-sim --modbus needs pymodbus: pip install 'pyrt[modbus]'") \
            from None
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
    return ModbusTcpServer, ModbusServerContext, ExcCodes


class _WorldStore:
    """The data store: Modbus places -> the world's registers (the server's context)."""

    old_simulator = True  # pymodbus: call async_getValues/async_setValues of this object
    simdevices: list[Any] = []

    def __init__(self, server: ModbusBoardServer, exc_codes: Any):
        self.server = server
        self.exc = exc_codes
        self.at: dict[tuple[int, str, int], tuple[Place, int]] = {}
        for p in server.map.places:
            for k in range(p.size):
                self.at[(p.unit, p.table, p.address + k)] = (p, k)
        self.units = sorted({p.unit for p in server.map.places})

    def device_ids(self) -> list[int]:
        return self.units

    def _words(self, p: Place) -> list[int]:
        reg = p.register
        if not reg.readback:
            return [0] * p.size
        return p.encode(self.server.views[p.board].read(reg.name, p.index))

    async def async_getValues(self, device_id: int, func_code: int, address: int,
                              count: int = 1) -> Any:
        table = _READ.get(func_code, _WRITE.get(func_code))
        if table is None:
            return self.exc.ILLEGAL_FUNCTION
        self.server.feed()
        out: list[int] = []
        cache: dict[tuple[str, str, int], list[int]] = {}
        for a in range(address, address + count):
            hit = self.at.get((device_id, table, a))
            if hit is None:
                return self.exc.ILLEGAL_ADDRESS
            p, k = hit
            words = cache.get(p.key)
            if words is None:
                words = cache[p.key] = self._words(p)
            out.append(words[k])
        if table in (COIL, DISCRETE):
            return [bool(v) for v in out]
        return out

    async def async_setValues(self, device_id: int, func_code: int, address: int,
                              values: Sequence[int] | Sequence[bool]) -> Any:
        table = _WRITE.get(func_code)
        if table is None:
            return self.exc.ILLEGAL_FUNCTION
        self.server.feed()
        touched: dict[tuple[str, str, int], tuple[Place, list[int]]] = {}
        for a, v in zip(range(address, address + len(values)), values, strict=True):
            hit = self.at.get((device_id, table, a))
            if hit is None or hit[0].register.is_input:
                return self.exc.ILLEGAL_ADDRESS
            p, k = hit
            if p.key not in touched:
                touched[p.key] = (p, self._words(p))
            touched[p.key][1][k] = int(v)
        writes = []
        for p, words in touched.values():
            value = p.decode(words)
            try:
                self.server.kinds[p.board].check_write(p.register.name, p.index, value)
            except ValueError:
                return self.exc.ILLEGAL_VALUE
            writes.append((p, value))
        for p, value in writes:
            try:
                self.server.views[p.board].write(p.register.name, value, p.index)
            except ValueError:
                return self.exc.ILLEGAL_VALUE
        return None


class ModbusBoardServer:
    """Serve ``world`` over Modbus TCP on ``host:port`` with ``regmap`` (see the module text).

    Port 0 picks a free port (:attr:`url`).  ``say(line)`` is told one line per
    event (connections, watchdog trips).  :meth:`serve_forever` blocks until
    :meth:`stop`; :meth:`start` runs it in a thread of its own.
    """

    def __init__(self, world: World, regmap: RegisterMap, host: str = "127.0.0.1",
                 port: int = 0, *, watchdog_s: float = 0.5, step_ns: int = 1_000_000,
                 say: Callable[[str], None] | None = None,
                 clock: Callable[[], int] = time.monotonic_ns):
        self._server_cls, ctx, self._exc = _pymodbus()
        # pymodbus serves a ModbusServerContext: ours answers from the world
        self._store_cls = type("WorldStore", (_WorldStore, ctx), {})
        if not 0.001 <= watchdog_s <= 3600:
            raise ConfigError(f"watchdog time must be 0.001..3600 s, got {watchdog_s!r}")
        self.world = world
        self.map = regmap
        self.kinds = dict(world.kinds)
        self.views = {name: world.registers(name) for name in self.kinds}
        self.watchdog_ns = int(watchdog_s * 1e9)
        self.step_ns = int(step_ns)
        self.report = say
        self.clock = clock
        if port == 0:
            try:
                with socket.create_server((host, 0)) as probe:
                    port = probe.getsockname()[1]
            except OSError as exc:
                raise ConfigError(f"board-sim cannot listen on {host}:0: "
                                  f"{exc.strerror or exc}") from None
        self.host, self.port = host, port
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._last_access = 0
        self._fed = False
        self.clients = 0
        #: Counters: requests served, watchdog trips.
        self.requests = 0
        self.watchdog_trips = 0
        self.t0 = clock()

    @property
    def url(self) -> str:
        """The back-end URL of these boards with the shipped map of the world's station."""
        return f"modbus://{self.host}:{self.port}"

    def _say(self, line: str) -> None:
        if self.report is not None:
            try:
                self.report(line)
            except (OSError, ValueError):
                self.report = None

    def feed(self) -> None:
        """A register access came: the watchdog starts again."""
        self.requests += 1
        self._last_access = self.clock()
        self._fed = True

    def _connected(self, up: bool) -> None:
        if up:
            self.clients += 1
            self._say("controller connected")
            return
        self.clients = max(0, self.clients - 1)
        if self.clients == 0:
            self._fed = False
            was_on = not self.world.outputs_are_off()
            self.world.outputs_off()
            self._say("controller disconnected" + (": outputs off" if was_on else ""))

    # -- running ------------------------------------------------------------------------

    def start(self) -> threading.Thread:
        """Serve in a daemon thread (returns once it listens); ConfigError if it cannot."""
        t = threading.Thread(target=self.serve_forever, name="board-sim-modbus", daemon=True)
        self._thread = t
        t.start()
        self._ready.wait(10.0)
        if self._error is not None:
            raise ConfigError(f"board-sim cannot listen on {self.host}:{self.port}: "
                              f"{self._error}")
        return t

    @property
    def alive(self) -> bool:
        """Whether the thread :meth:`start` made still serves."""
        return self._thread is not None and self._thread.is_alive()

    def stop(self) -> None:
        """Ask :meth:`serve_forever` to return (thread-safe)."""
        self._stop.set()

    def close(self) -> None:
        """Stop, join the thread, turn the outputs off."""
        self.stop()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(5.0)
        self.world.outputs_off()

    def serve_forever(self) -> None:
        """Step the world, serve requests and keep the watchdog until :meth:`stop`."""
        try:
            asyncio.run(self._main())
        except BaseException as exc:
            self._error = exc
            self._ready.set()
            if not isinstance(exc, (OSError, RuntimeError)):
                raise
        finally:
            self.world.outputs_off()

    async def _main(self) -> None:
        server = self._server_cls(self._store_cls(self, self._exc), address=(self.host, self.port),
                                  trace_connect=self._connected)
        await server.serve_forever(background=True)
        self._ready.set()
        clock, world, step = self.clock, self.world, self.step_ns
        next_step = clock()
        try:
            while not self._stop.is_set():
                now = clock()
                if now >= next_step:
                    world.step(now - self.t0)
                    next_step += step
                    if next_step <= now:
                        next_step = now + step
                if self._fed and now - self._last_access > self.watchdog_ns:
                    self._fed = False
                    self.watchdog_trips += 1
                    world.trips += 1
                    if not world.outputs_are_off():
                        world.outputs_off()
                        self._say(f"watchdog: no register access for "
                                  f"{(now - self._last_access) / 1e9:.3f} s: outputs off")
                await asyncio.sleep(max(0.0, (next_step - clock()) / 1e9))
        finally:
            with contextlib.suppress(Exception):
                await server.shutdown()
