"""EPICS Channel Access for the DAQ (``--epics PREFIX``, extra ``pyrt[epics]``).

A caproto server (its asyncio loop in a thread of its own, outside the
control loop) serves the robot as an IOC would, every PV made from a
component's signal record or the station's state, named ``PREFIX`` + field:

* ``T``: loop time of the latest status sample, seconds;
* one PV per STATUS field, upper case (the gripper's ``POSITION``,
  ``TARGET``, ``MOVING``, ``BUSY``, ``SENSORS``, ``FAULT``; the
  manipulator's ``X Y Z DISTERR NETFORCE MOVING FAULT TENSION0`` ...),
  updated every ``period_s`` from the server's status snapshot;
* one PV per signal of every component, ``COMPONENT:SIGNAL`` upper case
  (``AXIS0:LENGTH``, ``AXIS0:TENSION``, ``AXIS0ENCODER:LENGTH``,
  ``AXIS0MOTOR:RUNNING``, ``AXIS0MOTOR:SPEED`` ... ``GRIPPER:ENCODER``),
  read in the loop every 0.1 s while the IOC runs; in a station of several
  robots each robot has a prefix of its own: its components' signals are
  ``ROBOT:COMPONENT:SIGNAL`` (its root's ``ROBOT:SIGNAL``), beside
  ``ROBOT:STATE`` and ``ROBOT:FAULT_MSG``; a text signal (each robot's
  ``WHERE``, ``LAST_STOP`` and ``STATUSLINE`` on its root component:
  ``GRIPPER:WHERE``) is a string PV when it is bounded to 39 characters,
  else a char waveform of 1024 bytes (a long string, as an IOC serves one);
* ``STATE`` (enum ``idle``/``moving``/``fault``), ``STOP_REASON`` (how the
  last move ended), and for the manipulator ``TARGET_X/Y/Z``: the running
  move's endpoint, NaN between moves.  Target PVs are read-backs: a move is
  started only by a privileged command (``CMD`` with the token), never by
  writing a PV any Channel Access client can reach;
* ``FAULT_MSG``: the last fault, whole (a char waveform of 1024 bytes);
* ``TICKS``, ``OVERRUNS``, ``LATE_P99_US``, ``LATE_MAX_US``: tick statistics
  (through the runner's mailbox, once a second).

**Made from the records.**  A signal's units are its PV's EGU and its format
the precision (PREC; an integer format makes an integer PV); a boolean
signal (units ``bool``: ``MOVING``, ``FAULT``, ``AXIS0MOTOR:RUNNING``) is an
enum PV with the states ``no`` and ``yes``, as a ``bo``/``bi`` record.  The
display range (HOPR/LOPR) and the alarm limits (HIHI/HIGH/LOW/LOLO) come
from the station's database (:meth:`~pyrt.server.station.ServedStation.limits`:
tension stops LOW_TENSION and MAX_TENSION, NET_FORCELIMIT, END_ERROR, the
vessel's size, each rope's reach, CRUISE_SPEED), so alarm status and
severity are computed by the IOC on every update: a rope at 0.7 N, below its
2 N low-tension stop, is ``LOLO``/``MAJOR``.  Every value PV is read-only to
Channel Access clients.

**Writes.**  ``STOP`` (enum ``idle``/``stop``): writing ``stop`` (or 1)
stops every motor, like ``stop`` on the line protocol; no token, a stop is
for everyone.  Only when a token is configured: ``CMD`` (a char waveform,
256 bytes) takes ``TOKEN COMMAND``, runs ``COMMAND`` as the console would
and puts the reply (the line protocol's framed lines) in ``REPLY`` and its
last line in ``RESULT``; ``ACK`` takes ``TOKEN`` and acknowledges a fault.
Channel Access has no authentication of its own (host and user names are
the client's say-so), so privilege is decided per write, by the token in the
written value, compared in constant time; a write without the right token is
refused (``RESULT`` says ``ERR auth``) and runs nothing.  ``CMD`` and ``ACK``
read back without the token.  Commands written over Channel Access run one
at a time, in a console session of their own.

**Closed by default.**  The IOC listens on loopback (127.0.0.1) unless
interfaces are named (``interfaces``, ``--epics-interface``, or
``EPICS_CAS_INTF_ADDR_LIST``); caproto's own default would be every
interface.  Listening beyond loopback without a token is refused, and the
token crosses the network in clear inside the written value (see
``docs/daq.md``: a gateway or an SSH tunnel).

**One master.**  A ``CMD``, ``ACK`` or setpoint write takes the one
privilege the DAQ link also grants (:meth:`~pyrt.server.Server.claim_privilege`):
refused (``ERR busy``) while a DAQ client is privileged, and while EPICS
commands come (until ``lease_s`` after the last) a DAQ ``AUTH`` is refused.

**An audit trail that holds.**  A write with a wrong token, and a write to
a read-only PV, is a failure of the writer's real address (never the host
name it claims) in the server's :class:`~pyrt.server.guard.FailureGuard`:
audit lines within a budget, then summaries, and a back-off during which
that address's token writes are refused unread.  Host and user names
(whatever the client claims) are escaped before they reach a log line or
the console, in pyrt's lines and in caproto's.

caproto logs every client's connection at INFO; its logger is set to
WARNING unless ``verbose``.
"""

from __future__ import annotations

import asyncio
import contextlib
import contextvars
import hmac
import io
import logging
import math
import os
import re
import threading
from typing import Any, NamedTuple

from pyrt.component import STRING_LENGTH, Limits
from pyrt.errors import ConfigError, PyrtError
from pyrt.server.guard import check_token, escape_text
from pyrt.server.limits import is_loopback
from pyrt.server.protocol import format_error, format_reply
from pyrt.server.robot import ObserverRunner
from pyrt.server.session import run_shell

__all__ = ["FIXED_PVS", "EpicsService", "caproto_available", "epics_interfaces", "pv_name"]

log = logging.getLogger("pyrt.server.epics")

CMD_LENGTH = 256
REPLY_LENGTH = 4096
#: Long strings (FAULT_MSG, RESULT, STOP_REASON) are char waveforms this long.
TEXT_LENGTH = 1024

#: The PVs beside the status and signal fields (names after the prefix);
#: with a token also ``CMD``, ``REPLY``, ``ACK``.
FIXED_PVS = ("T", "FAULT_MSG", "RESULT", "STOP", "TICKS", "OVERRUNS", "LATE_P99_US",
             "LATE_MAX_US")
#: A boolean status field (units ``bool``) is an enum PV with these states.
BOOL_STATES = ("no", "yes")
#: The states of ``STOP``.
STOP_STATES = ("idle", "stop")
#: How long a master over EPICS keeps the privilege after its last command.
LEASE_S = 10.0
#: The name of that master where the privilege is claimed.
MASTER = "EPICS CMD"
#: caproto's loggers whose lines may carry what a client claims (host, user, PV names).
_CAPROTO_LOGGERS = ("caproto", "caproto.ctx", "caproto.circ", "caproto.ch", "caproto.bcast",
                    "caproto.bcast.search", "caproto.bcast.beacon", "caproto.server.common",
                    "caproto.asyncio.server", "caproto.server.server")


class _Writer(NamedTuple):
    """Who writes a PV: the real address, and the names it claims."""

    addr: str
    port: int
    host: str
    user: str

    def __str__(self) -> str:
        return (f"{self.addr}:{self.port} (claims host '{escape_text(self.host, 60)}', "
                f"user '{escape_text(self.user, 60)}')")


#: The writer of the PV write being handled (set by the channels' ``auth_write``).
_WRITER: contextvars.ContextVar[_Writer | None] = contextvars.ContextVar(
    "pyrt_epics_writer", default=None)


def _writer(hostname: Any, username: Any, user_address: Any) -> _Writer:
    if isinstance(user_address, (tuple, list)) and len(user_address) >= 2:
        addr, port = str(user_address[0]), int(user_address[1])
    else:
        addr, port = "?", 0
    return _Writer(addr, port, str(hostname), str(username))


def epics_interfaces(interfaces: list[str] | None) -> list[str]:
    """The addresses the IOC listens on: ``interfaces`` when named, else
    ``EPICS_CAS_INTF_ADDR_LIST`` when set, else loopback only."""
    if interfaces:
        return list(interfaces)
    env = os.environ.get("EPICS_CAS_INTF_ADDR_LIST", "").split()
    return [a.partition(":")[0] for a in env] if env else ["127.0.0.1"]


class _EscapeClientText(logging.Filter):
    """caproto's log lines made harmless: what a client claims (host and user
    names, PV names) may hold line ends or terminal escapes."""

    def filter(self, record: logging.LogRecord) -> bool:
        if record.name.startswith("caproto"):
            try:
                msg = record.getMessage()
            except Exception:  # a record that cannot format: leave it to logging
                return True
            clean = escape_text(msg, 2000)
            if clean != msg:
                record.msg, record.args = clean, ()
        return True


def _precision(fmt: str) -> int:
    """Decimals of a format spec (``.2f`` -> 2, ``.4g`` -> 4); 3 when it says none."""
    spec = fmt.rsplit(".", 1)
    if len(spec) == 2:
        digits = "".join(c for c in spec[1] if c.isdigit())
        if digits:
            return int(digits)
    return 3


def pv_name(name: str) -> str:
    """``axis0Motor:running`` -> ``AXIS0MOTOR:RUNNING``; ``stopReason`` -> ``STOP_REASON``."""
    if ":" in name:
        return name.upper()
    out = []
    for i, c in enumerate(name):
        if c.isupper() and i and name[i - 1].islower():
            out.append("_")
        out.append(c.upper())
    return "".join(out)


class _RefusedWrites(logging.Filter):
    """A Channel Access client's write to a read-only PV, refused by caproto: one
    line (``refused EPICS write: ...``, its text escaped when the PV refused it)
    instead of caproto's traceback (the audit line is the PV's own, through the
    guard); the follow-up error caproto's write handler leaves in asyncio (a
    KeyError in ``handle_write``) is dropped."""

    def filter(self, record: logging.LogRecord) -> bool:
        # Another IOC's filter may have seen the record first: it keeps the refusal.
        exc = record.exc_info[1] if record.exc_info else getattr(record, "pyrt_refused", None)
        if record.name.startswith("caproto") and type(exc).__name__ == "Forbidden":
            line = f"refused EPICS write: {escape_text(exc, 400)}"
            record.pyrt_refused = exc
            record.msg, record.args = line, ()
            record.exc_info = record.exc_text = None
            return True
        leftover = (record.name == "asyncio" and isinstance(exc, KeyError)
                    and "handle_write" in record.getMessage())
        return not leftover


_PV_WORD = re.compile(r"^[A-Za-z0-9_]+$")


def _read_only(ca: Any, base: type) -> type:
    """``base`` whose value Channel Access clients may read but not write; a
    write is refused through ``pyrt_refuse`` (set by the service: audited,
    counted by the writer's real address), escaped, before caproto logs it."""
    from caproto import AccessRights, Forbidden

    class ReadOnly(base):
        pyrt_name = "?"
        pyrt_refuse: Any = None

        def check_access(self, hostname: str, username: str) -> Any:
            return AccessRights.READ

        async def auth_write(self, hostname: Any, username: Any, data: Any, data_type: Any,
                             metadata: Any, *, flags: int = 0,
                             user_address: Any = None) -> Any:
            who = _writer(hostname, username, user_address)
            refuse = self.pyrt_refuse
            if refuse is not None:
                refuse(self.pyrt_name, who)
            raise Forbidden(f"{self.pyrt_name} is read-only; write from {who}")

    ReadOnly.__name__ = f"ReadOnly{base.__name__}"
    return ReadOnly


def _value_pv(ca: Any, units: str, fmt: str, limits: Any = None, kind: str = "",
              states: tuple[str, ...] = (), length: int = 0) -> tuple[str, Any]:
    """The PV of one value from its record: ``text`` a string PV when it is
    bounded to :data:`~pyrt.component.STRING_LENGTH` characters (``length``),
    else a char waveform of :data:`TEXT_LENGTH`, as an IOC serves a long
    string; ``enum`` (or units ``bool``) an enum, an integer format an
    integer, anything else a double with the units as EGU, the format's
    precision, and ``limits`` (display range and alarm limits) when given."""
    if kind == "text" and 0 < length <= STRING_LENGTH:
        return "string", _read_only(ca, ca.ChannelString)(value="", string_encoding="utf-8")
    if kind == "text":
        return "text", _read_only(ca, ca.ChannelChar)(
            value="", max_length=TEXT_LENGTH, string_encoding="utf-8")
    if kind == "enum" or units == "bool":
        names = states or BOOL_STATES
        return "enum:" + "\t".join(names), _read_only(ca, ca.ChannelEnum)(
            value=names[0], enum_strings=names)
    if fmt.endswith(("d", "X", "x")):
        return "int", _read_only(ca, ca.ChannelInteger)(value=0, units=units)
    kw: dict[str, Any] = {}
    if limits is not None:
        kw = {"lower_disp_limit": limits.lopr, "upper_disp_limit": limits.hopr,
              "lower_alarm_limit": limits.lolo, "upper_alarm_limit": limits.hihi,
              "lower_warning_limit": limits.low, "upper_warning_limit": limits.high}
    return "float", _read_only(ca, ca.ChannelDouble)(
        value=0.0, precision=_precision(fmt), units=units, **kw)


def _pv_value(kind: str, value: Any) -> Any:
    """A value as its PV takes it."""
    if kind == "text":
        return str(value)[:TEXT_LENGTH - 1]
    if kind == "string":  # DBR_STRING: 40 bytes with its end
        return str(value).encode("utf-8")[:STRING_LENGTH].decode("utf-8", "ignore")
    if kind.startswith("enum:"):
        states = kind[5:].split("\t")
        if isinstance(value, bool) or len(states) == 2:
            return states[1] if value else states[0]
        return states[int(value)]
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
    """Serve ``server``'s robot as Channel Access PVs (see the module text).

    ``interfaces``: the addresses to serve on (default: those of
    ``EPICS_CAS_INTF_ADDR_LIST`` when set, else 127.0.0.1 only; beyond
    loopback a token is required); ports follow ``EPICS_CA_SERVER_PORT``.
    ``verbose``: keep caproto's INFO lines (one per client connect ...).
    ``lease_s``: how long a CMD keeps the privilege after it has run.
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
        verbose: bool = False,
        lease_s: float = LEASE_S,
    ):
        ca = _require_caproto()
        if not prefix or any(c.isspace() for c in prefix) or len(prefix) > 40:
            raise ConfigError(f"EPICS prefix must be 1..40 characters, no spaces: {prefix!r}")
        self.interfaces = epics_interfaces(interfaces)
        beyond = [a for a in self.interfaces if not is_loopback(a)]
        if beyond and not token:
            raise ConfigError(
                f"refusing to serve EPICS on {', '.join(beyond)} without a token: anybody who "
                "can reach it could write STOP and read every PV, and nobody could command; "
                "give --token-file or PYRT_TOKEN, or serve on 127.0.0.1")
        if beyond and token:
            check_token(token)
        logging.getLogger("caproto").setLevel(logging.INFO if verbose else logging.WARNING)
        refused = _RefusedWrites()
        escape = _EscapeClientText()
        logging.getLogger("caproto.circ").addFilter(refused)
        logging.getLogger("asyncio").addFilter(refused)
        for name in _CAPROTO_LOGGERS:
            logging.getLogger(name).addFilter(escape)
        self._refused = refused
        self._escape = escape
        self._ca = ca
        self.runner = runner
        self.robot = robot
        self.server = server
        self.prefix = prefix
        self._token = token.encode("utf-8") if token else None
        self.lease_s = float(lease_s)
        self.period_s = period_s
        self.stats_period_s = stats_period_s
        self._shell: Any = None
        self._stop_shell: Any = None
        self._shell_lock = threading.Lock()  # one command at a time, in order
        #: The stop has its own session and lock: a CMD that waits (``wait``)
        #: never holds up a stop.
        self._stop_lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._task: asyncio.Task | None = None
        self._started = threading.Event()
        self._closing = False
        self.error: BaseException | None = None
        self.pvdb = self._build()

    @property
    def summary(self) -> str:
        return f"{len(self.pvdb)} PVs, STOP for everyone, " + (
            "CMD and ACK with the token in the written value" if self._token
            else "no token: no CMD or ACK") + f"; on {', '.join(self.interfaces)}"

    def _build(self) -> dict[str, Any]:
        ca = self._ca
        p = self.prefix
        ro = lambda base: _read_only(ca, base)  # noqa: E731
        db: dict[str, Any] = {p + "T": ro(ca.ChannelDouble)(value=0.0, precision=6, units="s")}
        self._fields: list[tuple[str, Any]] = []
        for name, units, fmt, limits in self._status_fields():
            kind, pv = _value_pv(ca, units, fmt, limits)
            db[p + name.upper()] = pv
            self._fields.append((kind, pv))
        self._extras: list[tuple[str, Any]] = []
        for f in self.robot.extra_fields:
            key = p + pv_name(f.name)
            if key in db:
                continue
            kind, pv = _value_pv(ca, f.units, f.fmt, f.limits, f.kind, f.states, f.length)
            db[key] = pv
            if f.name == "stopReason":  # written once per move-ended event, not sampled
                kind = "event"
            self._extras.append((kind, pv))
        db[p + "FAULT_MSG"] = ro(ca.ChannelChar)(value="none", max_length=TEXT_LENGTH,
                                                 string_encoding="utf-8")
        db[p + "RESULT"] = ro(ca.ChannelChar)(value="", max_length=TEXT_LENGTH,
                                              string_encoding="utf-8")
        db[p + "TICKS"] = ro(ca.ChannelInteger)(value=0)
        db[p + "OVERRUNS"] = ro(ca.ChannelInteger)(value=0)
        db[p + "LATE_P99_US"] = ro(ca.ChannelDouble)(value=0.0, precision=1, units="us")
        db[p + "LATE_MAX_US"] = ro(ca.ChannelDouble)(value=0.0, precision=1, units="us")
        service = self
        # caproto's channel classes (no type information: Any to the checker)
        enum_channel: Any = ca.ChannelEnum
        char_channel: Any = ca.ChannelChar

        from caproto import Forbidden

        def writer_known(base: Any) -> Any:
            """``base`` whose write handlers know who writes (:data:`_WRITER`)."""

            class Known(base):
                pyrt_name = "?"

                async def auth_write(self, hostname: Any, username: Any, data: Any,
                                     data_type: Any, metadata: Any, *, flags: int = 0,
                                     user_address: Any = None) -> Any:
                    who = _writer(hostname, username, user_address)
                    mark = _WRITER.set(who)
                    try:
                        return await super().auth_write(hostname, username, data, data_type,
                                                        metadata, flags=flags,
                                                        user_address=user_address)
                    except (UnicodeDecodeError, ValueError, IndexError) as exc:
                        # a value caproto cannot convert (invalid UTF-8, empty text, a NUL
                        # first, an enum index out of range): refused as a failure of its
                        # writer, one log line, no traceback
                        raise Forbidden(service._undecodable(self.pyrt_name, who, exc)) from None
                    finally:
                        _WRITER.reset(mark)

            return Known

        enum_channel = writer_known(enum_channel)
        char_channel = writer_known(char_channel)

        class StopChannel(enum_channel):
            async def verify_value(self, data: Any) -> Any:
                return await service._stop(data)

        db[p + "STOP"] = StopChannel(value=STOP_STATES[0], enum_strings=STOP_STATES)
        if self._token is not None:

            class CommandChannel(char_channel):
                async def verify_value(self, data: Any) -> Any:
                    return await service._command(data)

            class AckChannel(char_channel):
                async def verify_value(self, data: Any) -> Any:
                    return await service._ack(data)

            db[p + "CMD"] = CommandChannel(value="", max_length=CMD_LENGTH,
                                           string_encoding="utf-8")
            db[p + "ACK"] = AckChannel(value="", max_length=CMD_LENGTH, string_encoding="utf-8")
            db[p + "REPLY"] = ro(ca.ChannelChar)(value="", max_length=REPLY_LENGTH,
                                                 string_encoding="utf-8")
            for comp_name, param_name in self._setpoints():
                key = p + pv_name(f"{comp_name}:{param_name}_SP")
                if key in db:
                    continue

                class SetpointChannel(char_channel):
                    async def verify_value(self, data: Any, _target: str =
                                           f"{comp_name}.{param_name}") -> Any:
                        return await service._setpoint(_target, data)

                db[key] = SetpointChannel(value="", max_length=CMD_LENGTH,
                                          string_encoding="utf-8")
        for key, pv in db.items():
            pv.pyrt_name = key
            if hasattr(pv, "pyrt_refuse"):
                pv.pyrt_refuse = self._refused_write
        return db

    def _undecodable(self, pv: str, who: _Writer, exc: Exception) -> str:
        """A write whose value the PV cannot take (not UTF-8 text, an enum index out
        of range ...): a failure of the writer's address; what is said of it."""
        text = (f"{escape_text(pv)} cannot take the written value ({type(exc).__name__}); "
                f"write from {who} refused, nothing was run")
        self.server.guard.failed(who.addr, "EPICS", f"refused EPICS write: {text}",
                                 "refused EPICS write")
        return text

    def _refused_write(self, pv: str, who: _Writer) -> None:
        """A write to a read-only PV: a failure of the writer's address (audited
        within the guard's budget, then summarised)."""
        self.server.guard.failed(who.addr, "EPICS", f"refused EPICS write to {escape_text(pv)} "
                                 f"from {who}: read-only", "refused EPICS write")

    def _setpoints(self) -> list[tuple[str, str]]:
        """``(object, parameter)`` of every writable run-time parameter (``set``)."""
        st = self.robot.station
        return [(c.name, prm.name) for c in st.components() for prm in st.params_of(c)
                if prm.write is not None and _PV_WORD.match(c.name) and _PV_WORD.match(prm.name)]

    async def _setpoint(self, target: str, data: Any) -> str:
        """A write to ``OBJECT:PARAM_SP``: ``TOKEN VALUE`` runs ``set OBJECT.PARAM VALUE``
        (the CMD token rule; its reply goes to RESULT and REPLY, as CMD's)."""
        token, _, value = self._text(data).partition(" ")
        value = value.strip()
        refusal = self._gate(token, "nothing was set")
        if refusal is None and not value:
            refusal = format_error("syntax", "write 'TOKEN VALUE'")
        if refusal is None:
            refusal = _unprintable(value, "nothing was set")
        if refusal is not None:
            await self._result(refusal)
            return ""
        loop = asyncio.get_running_loop()
        await self._result(await loop.run_in_executor(None, self._run, f"set {target} {value}"))
        return value

    def _status_fields(self) -> list[tuple[str, str, str, Limits | None]]:
        """``(name, units, format, limits)`` of each status field, from the
        station's signal records (a :class:`~pyrt.server.station.ServedStation`'s
        ``fields``)."""
        return [(name, sig.units, fmt, sig.limits) for name, sig, fmt in self.robot.fields]

    # -- life cycle ----------------------------------------------------------------

    def start(self, timeout_s: float = 5.0) -> None:
        """Start the Channel Access server thread; wait until it serves."""
        if self._thread is not None:
            return
        self.server.hub.extras_wanted = bool(self._extras)
        self._thread = threading.Thread(target=self._main, name="pyrt-epics", daemon=True)
        self._thread.start()
        if not self._started.wait(timeout_s) or self.error is not None:
            raise ConfigError(f"the EPICS server did not start: {self.error!r}")

    def close(self, timeout_s: float = 3.0) -> None:
        """Stop the Channel Access server."""
        logging.getLogger("caproto.circ").removeFilter(self._refused)
        logging.getLogger("asyncio").removeFilter(self._refused)
        for name in _CAPROTO_LOGGERS:
            logging.getLogger(name).removeFilter(self._escape)
        self._closing = True
        self.server.hub.extras_wanted = False
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
            if self._started.is_set() and not self._closing:
                self._died(exc)
        finally:
            self._started.set()

    def _died(self, exc: BaseException) -> None:
        """The IOC's thread has failed while serving: a fault the operator sees
        (the station is tripped, naming EPICS)."""
        cause = (f"the EPICS server has stopped ({type(exc).__name__}: {exc}; a bug in pyrt): "
                 "no Channel Access client can reach the station")
        with contextlib.suppress(Exception):
            self.runner.call(self.robot.station.trip, cause[:300], "epics", take_fault=False,
                             name="EPICS stopped")

    async def _serve(self) -> None:
        from caproto.asyncio.server import Context

        self._loop = asyncio.get_running_loop()
        self._task = asyncio.current_task()
        await self._first_values()
        ctx = Context(self.pvdb, self.interfaces)

        async def startup(async_lib: Any) -> None:
            self._started.set()
            await self._update()

        await ctx.run(startup_hook=startup)

    # -- the values ----------------------------------------------------------------

    #: At most this long (s) the server waits for the loop's first status
    #: snapshot before it serves (a loop that has not ticked by then: the PVs
    #: are served and their values follow).
    FIRST_VALUES_S = 2.0

    async def _first_values(self) -> None:
        """The status PVs hold the loop's first snapshot before any client can
        find them, never the placeholders they were built with.  On a virtual
        clock the loop ticks only when its caller asks: nothing to wait for."""
        hub = self.server.hub
        if not self.runner.virtual:
            loop = asyncio.get_running_loop()
            deadline = loop.time() + self.FIRST_VALUES_S
            while hub.snapshot[2] is None and loop.time() < deadline:
                await asyncio.sleep(0.005)
        t_ns, _tick, values = hub.snapshot
        if values is not None:
            await self.pvdb[self.prefix + "T"].write(t_ns / 1e9)
            await self._write_all(self._fields, values)

    async def _update(self) -> None:
        loop = asyncio.get_running_loop()
        hub = self.server.hub
        p = self.prefix
        db = self.pvdb
        last_t = last_extra = None
        shown = moved = None
        next_stats = 0.0
        while True:
            t_ns, _tick, values = hub.snapshot
            if values is not None and t_ns != last_t:
                last_t = t_ns
                await db[p + "T"].write(t_ns / 1e9)
                await self._write_all(self._fields, values)
            te_ns, extra = hub.extra_snapshot
            if extra is not None and te_ns != last_extra:
                last_extra = te_ns
                await self._write_all(self._extras, extra)
            fault = hub.last_fault
            if fault is not None and fault is not shown:
                shown = fault
                await db[p + "FAULT_MSG"].write(str(fault.cause)[:TEXT_LENGTH - 1])
            move = hub.last_move
            if move is not None and move is not moved and p + "STOP_REASON" in db:
                moved = move  # each end of a move once, even when it ends as the last did
                await db[p + "STOP_REASON"].write(str(move.reason)[:TEXT_LENGTH - 1])
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

    @staticmethod
    async def _write_all(pvs: list[tuple[str, Any]], values: tuple) -> None:
        """Write the values that changed; a write computes the PV's alarm."""
        for (kind, pv), value in zip(pvs, values, strict=True):
            if kind == "event":  # written by its event, not by the sample
                continue
            with contextlib.suppress(TypeError, ValueError, OverflowError, IndexError):
                v = _pv_value(kind, value)
                old = pv.value
                if v != old and not (isinstance(v, float) and math.isnan(v)
                                     and isinstance(old, float) and math.isnan(old)):
                    await pv.write(v)

    def _statistics(self) -> Any:
        try:
            return self.runner.statistics(take_fault=False)
        except Exception as exc:
            log.debug("statistics: %s", exc)
            return None

    # -- writes --------------------------------------------------------------------

    async def _result(self, reply: str) -> None:
        p = self.prefix
        if p + "REPLY" in self.pvdb:
            await self.pvdb[p + "REPLY"].write(reply[-REPLY_LENGTH + 1:])
        await self.pvdb[p + "RESULT"].write(
            reply.rstrip("\n").rsplit("\n", 1)[-1][:TEXT_LENGTH - 1])

    async def _stop(self, data: Any) -> str:
        """A write to STOP: ``stop`` (1) stops every motor, for any client."""
        value = data[0] if isinstance(data, (list, tuple)) and data else data
        if isinstance(value, bytes):
            value = value.decode("utf-8", "replace")
        if value in (1, "1", STOP_STATES[1]):
            loop = asyncio.get_running_loop()
            await self._result(await loop.run_in_executor(None, self._run_stop))
        return STOP_STATES[0]

    def _run_stop(self) -> str:
        with self._stop_lock:
            if self._stop_shell is None:
                self._stop_shell = self.robot.make_shell(ObserverRunner(self.runner),
                                                         io.StringIO(), source="EPICS STOP")
            try:
                return run_shell(self._stop_shell, "stop")[0]
            except Exception as exc:
                log.exception("EPICS stop failed")
                return format_error("internal", f"{type(exc).__name__}: {exc}")

    def _token_ok(self, token: str) -> bool:
        assert self._token is not None
        return bool(token) and hmac.compare_digest(token.encode("utf-8"), self._token)

    def _gate(self, token: str, nothing: str) -> str | None:
        """The token rule of a write that acts (CMD, ACK, a setpoint): an ``ERR``
        reply when it may not (its address backs off, or the token is wrong:
        a failure of that address), None when it may.  ``nothing``: what the
        refusal says did not happen."""
        who = _WRITER.get() or _Writer("?", 0, "", "")
        guard = self.server.guard
        wait = guard.blocked(who.addr, "EPICS write")
        if wait > 0:
            return format_error("auth", f"too many refused writes from {who.addr}: try again "
                                f"in {math.ceil(wait):.0f} s; {nothing}")
        if not self._token_ok(token):
            wait = guard.failed(who.addr, "EPICS", f"refused EPICS write from {who}: wrong token",
                                "refused EPICS write")
            more = (f" ({who.addr} may write again in {math.ceil(wait):.0f} s)"
                    if wait > 0 else "")
            return format_error("auth", f"wrong token in the written value; {nothing}{more}")
        return None

    @staticmethod
    def _text(data: Any) -> str:
        text = data if isinstance(data, str) else bytes(data).decode("utf-8", "replace")
        return text.strip().strip("\0")

    async def _command(self, data: Any) -> str:
        token, _, line = self._text(data).partition(" ")
        line = line.strip()
        refusal = self._gate(token, "nothing was run")
        if refusal is None and not line:
            refusal = format_error("syntax", "write 'TOKEN COMMAND'")
        if refusal is None:
            refusal = _unprintable(line, "nothing was run")
        if refusal is not None:
            await self._result(refusal)
            return ""
        loop = asyncio.get_running_loop()
        await self._result(await loop.run_in_executor(None, self._run, line))
        return line

    async def _ack(self, data: Any) -> str:
        """A write to ACK: ``TOKEN`` acknowledges the fault (the operator's act)."""
        token = self._text(data).split(" ", 1)[0]
        reply = self._gate(token, "nothing was acknowledged")
        if reply is None:
            loop = asyncio.get_running_loop()
            reply = await loop.run_in_executor(None, self._run_ack)
        await self._result(reply)
        return ""

    def _run_ack(self) -> str:
        """Acknowledge the fault through the mailbox; the fault's report, which
        the call meets first, is what is being acknowledged."""
        station = self.robot.station
        with self._shell_lock:
            busy = self.server.claim_privilege(MASTER)
            if busy is not None:
                return format_error("busy", busy)
            try:
                self.runner.take_faults()  # FAULT_MSG has shown them; this acknowledges them
                try:
                    said = self.runner.call(station.acknowledge, name="ack", take_fault=False)
                except PyrtError as exc:
                    return format_error("command", str(exc))
                return format_reply([said])
            finally:
                self.server.renew_privilege(MASTER, self.lease_s)

    def _run(self, line: str) -> str:
        """Run ``line`` in the EPICS session, holding the one privilege (one master)."""
        with self._shell_lock:
            busy = self.server.claim_privilege(MASTER)
            if busy is not None:
                return format_error("busy", busy)
            try:
                if self._shell is None:
                    self._shell = self.robot.make_shell(self.runner, io.StringIO(),
                                                        source="EPICS CMD")
                reply, _end = run_shell(self._shell, line)
            except Exception as exc:
                log.exception("EPICS command %r failed", line[:60])
                reply = format_error("internal", f"{type(exc).__name__}: {exc}")
            finally:
                self.server.renew_privilege(MASTER, self.lease_s)
            return reply


def _unprintable(text: str, nothing: str) -> str | None:
    """``ERR text`` when ``text`` holds a character that is not printable (a line
    end, a terminal escape ...), as the DAQ link refuses it; else None."""
    for i, c in enumerate(text):
        if not c.isprintable() and c != "\t":
            return format_error("text", f"control character {ord(c):#04x} at character {i}; "
                                f"{nothing}")
    return None

