"""EPICS Channel Access for the DAQ (``--epics PREFIX``, extra ``pyrt[epics]``).

A caproto server (its asyncio loop in a thread of its own, outside the
control loop) publishes, with PV names ``PREFIX`` + field:

* ``T``: loop time of the latest status sample, seconds;
* one PV per status field of the robot, upper case (the gripper's
  ``POSITION``, ``TARGET``, ``MOVING``, ``BUSY``, ``SENSORS``, ``FAULT``;
  the manipulator's position and tensions), updated every ``period_s``,
  made from the field's signal record: its units are the PV's EGU, its
  format the precision (an integer format makes an integer PV), and a
  boolean signal (units ``bool``: ``MOVING``, ``FAULT``) is an enum PV
  whose states are ``no`` and ``yes``;
* ``FAULT_MSG``: the last fault pushed by the loop (40 characters);
* ``TICKS``, ``OVERRUNS``, ``LATE_P99_US``, ``LATE_MAX_US``: tick statistics
  (through the runner's mailbox, once a second).

The values come from the server's status snapshot, exactly what a
``STATUS`` request answers, so Channel Access adds nothing to the tick.

**Commands.** Only when a token is configured there is ``CMD`` (a char
waveform, 256 bytes, read and written as a string): writing
``TOKEN COMMAND`` runs ``COMMAND`` as the console would and puts the reply
(the line protocol's framed lines) in ``REPLY`` and its last line in
``RESULT``.  Channel Access has no authentication of its own (host and user
names are the client's say-so), so privilege is decided per write, by the
token in the written value, compared in constant time; a write without the
right token is refused (``RESULT`` says ``ERR auth``) and runs nothing.
``CMD`` then reads back without the token.  Commands written over Channel
Access run one at a time, in a console session of their own.
"""

from __future__ import annotations

import asyncio
import contextlib
import hmac
import io
import logging
import threading
from typing import Any

from pyrt.errors import ConfigError
from pyrt.server.protocol import format_error
from pyrt.server.session import run_shell

__all__ = ["FIXED_PVS", "EpicsService", "caproto_available"]

log = logging.getLogger("pyrt.server.epics")

CMD_LENGTH = 256
REPLY_LENGTH = 4096

#: The PVs beside the status fields (names after the prefix); with a token
#: also ``CMD``, ``REPLY`` and ``RESULT``.
FIXED_PVS = ("T", "FAULT_MSG", "TICKS", "OVERRUNS", "LATE_P99_US", "LATE_MAX_US")
#: A boolean status field (units ``bool``) is an enum PV with these states.
BOOL_STATES = ("no", "yes")


def _precision(fmt: str) -> int:
    """Decimals of a format spec (``.2f`` -> 2, ``.4g`` -> 4); 3 when it says none."""
    spec = fmt.rsplit(".", 1)
    if len(spec) == 2:
        digits = "".join(c for c in spec[1] if c.isdigit())
        if digits:
            return int(digits)
    return 3


def _status_pv(ca: Any, units: str, fmt: str) -> tuple[str, Any]:
    """The PV of one status field from its signal's units and format:
    ``bool`` an enum (no/yes), an integer format (``d``, ``X``) an integer,
    anything else a double with the units as EGU and the format's precision."""
    if units == "bool":
        return "bool", ca.ChannelEnum(value=BOOL_STATES[0], enum_strings=BOOL_STATES)
    if fmt.endswith(("d", "X", "x")):
        return "int", ca.ChannelInteger(value=0, units=units)
    return "float", ca.ChannelDouble(value=0.0, precision=_precision(fmt), units=units)


def _pv_value(kind: str, value: Any) -> Any:
    """A status value as its PV takes it."""
    if kind == "bool":
        return BOOL_STATES[1] if value else BOOL_STATES[0]
    if kind == "int":
        return int(value)
    return float(value)


def caproto_available() -> bool:
    """True when caproto (the ``epics`` extra) can be imported."""
    try:
        import caproto  # noqa: F401
    except ImportError:
        return False
    return True


def _require_caproto() -> Any:
    try:
        import caproto
        import caproto.asyncio.server
    except ImportError:
        raise ConfigError(
            "--epics needs caproto, which is not installed: pip install 'pyrt[epics]'"
        ) from None
    return caproto


class EpicsService:
    """Serve ``server``'s status (and commands, with a token) as Channel Access PVs.

    ``interfaces``: the addresses to serve on (default: caproto's, from
    ``EPICS_CAS_INTF_ADDR_LIST``); ports follow ``EPICS_CA_SERVER_PORT``.
    """

    def __init__(
        self,
        runner: Any,
        robot: Any,
        server: Any,
        prefix: str,
        *,
        token: str | None = None,
        interfaces: list[str] | None = None,
        period_s: float = 0.1,
        stats_period_s: float = 1.0,
    ):
        ca = _require_caproto()
        if not prefix or any(c.isspace() for c in prefix) or len(prefix) > 40:
            raise ConfigError(f"EPICS prefix must be 1..40 characters, no spaces: {prefix!r}")
        self._ca = ca
        self.runner = runner
        self.robot = robot
        self.server = server
        self.prefix = prefix
        self._token = token.encode("utf-8") if token else None
        self.interfaces = interfaces
        self.period_s = period_s
        self.stats_period_s = stats_period_s
        self._shell: Any = None
        self._shell_lock = threading.Lock()  # one command at a time, in order
        self._thread: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._task: asyncio.Task | None = None
        self._started = threading.Event()
        self.error: BaseException | None = None
        self.pvdb = self._build()

    @property
    def summary(self) -> str:
        return f"{len(self.pvdb)} PVs, " + (
            "command PV CMD (token in the written value)" if self._token else "status only"
        )

    def _build(self) -> dict[str, Any]:
        ca = self._ca
        p = self.prefix
        db: dict[str, Any] = {p + "T": ca.ChannelDouble(value=0.0, precision=6, units="s")}
        self._fields = []
        for name, units, fmt in self._status_fields():
            kind, pv = _status_pv(ca, units, fmt)
            db[p + name.upper()] = pv
            self._fields.append((kind, pv))
        db[p + "FAULT_MSG"] = ca.ChannelString(value="none")
        db[p + "TICKS"] = ca.ChannelInteger(value=0)
        db[p + "OVERRUNS"] = ca.ChannelInteger(value=0)
        db[p + "LATE_P99_US"] = ca.ChannelDouble(value=0.0, precision=1, units="us")
        db[p + "LATE_MAX_US"] = ca.ChannelDouble(value=0.0, precision=1, units="us")
        if self._token is not None:
            service = self

            class CommandChannel(ca.ChannelChar):
                async def verify_value(self, data: Any) -> Any:
                    return await service._command(data)

            db[p + "CMD"] = CommandChannel(value="", max_length=CMD_LENGTH,
                                           string_encoding="utf-8")
            db[p + "REPLY"] = ca.ChannelChar(value="", max_length=REPLY_LENGTH,
                                             string_encoding="utf-8")
            db[p + "RESULT"] = ca.ChannelString(value="")
        return db

    def _status_fields(self) -> list[tuple[str, str, str]]:
        """``(name, units, format)`` of each status field: from the station's
        signal records (a :class:`~pyrt.server.station.ServedStation`'s
        ``fields``), else the names alone (units unknown, 3 decimals)."""
        fields = getattr(self.robot, "fields", None)
        if fields is None:
            return [(name, "", ".3f") for name in self.robot.status_names]
        return [(name, sig.units, fmt) for name, sig, fmt in fields]

    # -- life cycle ----------------------------------------------------------------

    def start(self, timeout_s: float = 5.0) -> None:
        """Start the Channel Access server thread; wait until it serves."""
        if self._thread is not None:
            return
        self._thread = threading.Thread(target=self._main, name="pyrt-epics", daemon=True)
        self._thread.start()
        if not self._started.wait(timeout_s) or self.error is not None:
            raise ConfigError(f"the EPICS server did not start: {self.error!r}")

    def close(self, timeout_s: float = 3.0) -> None:
        """Stop the Channel Access server."""
        loop, task = self._loop, self._task
        if loop is not None and task is not None:
            with contextlib.suppress(RuntimeError):
                loop.call_soon_threadsafe(task.cancel)
        if self._thread is not None:
            self._thread.join(timeout_s)
            self._thread = None

    def _main(self) -> None:
        try:
            asyncio.run(self._serve())
        except asyncio.CancelledError:
            pass
        except BaseException as exc:
            self.error = exc
            log.exception("EPICS server stopped")
        finally:
            self._started.set()

    async def _serve(self) -> None:
        from caproto.asyncio.server import Context

        self._loop = asyncio.get_running_loop()
        self._task = asyncio.current_task()
        ctx = Context(self.pvdb, self.interfaces)

        async def startup(async_lib: Any) -> None:
            self._started.set()
            await self._update()

        await ctx.run(startup_hook=startup)

    # -- the values ----------------------------------------------------------------

    async def _update(self) -> None:
        loop = asyncio.get_running_loop()
        hub = self.server.hub
        p = self.prefix
        db = self.pvdb
        last_t = None
        shown = None
        next_stats = 0.0
        while True:
            t_ns, _tick, values = hub.snapshot
            if values is not None and t_ns != last_t:
                last_t = t_ns
                await db[p + "T"].write(t_ns / 1e9)
                for (kind, pv), value in zip(self._fields, values, strict=True):
                    with contextlib.suppress(TypeError, ValueError, OverflowError):
                        v = _pv_value(kind, value)
                        if v != pv.value:
                            await pv.write(v)
            fault = hub.last_fault
            if fault is not None and fault is not shown:
                shown = fault
                await db[p + "FAULT_MSG"].write(str(fault.cause)[:39])
            now = loop.time()
            if now >= next_stats:
                next_stats = now + self.stats_period_s
                stats = await loop.run_in_executor(None, self._statistics)
                if stats is not None:
                    await db[p + "TICKS"].write(stats.ticks)
                    await db[p + "OVERRUNS"].write(stats.overruns)
                    await db[p + "LATE_P99_US"].write(stats.lateness.p99_ns / 1e3)
                    await db[p + "LATE_MAX_US"].write(stats.lateness.max_ns / 1e3)
            await asyncio.sleep(self.period_s)

    def _statistics(self) -> Any:
        try:
            return self.runner.statistics(take_fault=False)
        except Exception as exc:
            log.debug("statistics: %s", exc)
            return None

    # -- commands ------------------------------------------------------------------

    async def _command(self, data: Any) -> str:
        text = data if isinstance(data, str) else bytes(data).decode("utf-8", "replace")
        text = text.strip().strip("\0")
        token, _, line = text.partition(" ")
        line = line.strip()
        p = self.prefix
        assert self._token is not None
        if not hmac.compare_digest(token.encode("utf-8"), self._token):
            reply = format_error("auth", "wrong token in the written value; nothing was run")
        elif not line:
            reply = format_error("syntax", "write 'TOKEN COMMAND'")
        else:
            loop = asyncio.get_running_loop()
            reply = await loop.run_in_executor(None, self._run, line)
        await self.pvdb[p + "REPLY"].write(reply[-REPLY_LENGTH + 1:])
        await self.pvdb[p + "RESULT"].write(reply.rstrip("\n").rsplit("\n", 1)[-1][:39])
        return line if token and hmac.compare_digest(token.encode("utf-8"), self._token) else ""

    def _run(self, line: str) -> str:
        with self._shell_lock:
            if self._shell is None:
                self._shell = self.robot.make_shell(self.runner, io.StringIO())
            try:
                reply, _end = run_shell(self._shell, line)
            except Exception as exc:
                log.exception("EPICS command %r failed", line[:60])
                reply = format_error("internal", f"{type(exc).__name__}: {exc}")
            return reply
