"""The ``tcp://HOST:PORT`` back end: the boards of ``pyrt board-sim`` in another process.

Every register access is a read or write of a declared register, one
request line and one reply line on a TCP connection (:mod:`pyrt.boards.wire`).
:class:`TcpRegisters` is the client of one connection;
:class:`TcpBoardRegisters` the register view of one of its boards (``read``,
``write`` by register name, as :class:`~pyrt.boards.registers.RegisterBoard`
has them).  A station gets, for each board it declares, what the board's
kind makes of that view (:meth:`BoardKind.remote
<pyrt.boards.registers.BoardKind.remote>`): the view itself for a plain
kind, the typed view for a built-in one (the gripper cage mapped into the
8031 as it is over ``sim:``, so the controller program is the same; the
TIO10; the dataConcentrator; :mod:`pyrt.boards.kinds`).

On connect the greeting names the station and its boards with their kinds:
every board the station declares must be there with the same kind and
fingerprint, else ConfigError names those missing or different.  The
controller then claims the outputs (``OWN``): while another controller
owns them, opening fails with BoardError ``busy`` naming it.  Other
connections may read the same boards (an HMI); only the owner's accesses
feed board-sim's watchdog.

The process image (:mod:`pyrt.boards.image`, the back-end contract).  On
connecting the client asks ``STREAM 0``: a board-sim that knows it
answers with its world's step, and its inputs then stream (``prefetch``,
the default).  From the first tick's write phase board-sim pushes every
declared input after each step of its world, in the packed form (one
``unpack`` of the hexadecimal, no conversion per value); a thread of the
link's own (:meth:`TcpLink.start_receiving`) takes them off the socket as
they come, while the loop sleeps, so the read phase makes no system call:
it takes the newest push (before the stream, as on opening, a read asks
with ``SNAPX``: one round trip).  The write phase sends one ``W ...; W ...``
line of the outputs the tick changed with a ``SNAPX`` behind it, in one
system call and without waiting; the next read phase takes the inputs no
older than those writes (the ``SNAPX``'s reply, or a later push).  A tick
that changes nothing sends nothing, except every 50 ms (or a quarter of
the watchdog time, if shorter) the ``STREAM`` asked again, board-sim's
keep-alive.  A read phase that finds no push newer than 1.5 ticks (or 1.5
steps, if longer) waits for the next (board-sim is late: the controller
does not run ahead of a world that has not stepped); one that finds the
stream lapsed (the loop had stopped) asks with ``SNAPX`` and waits.

From a board-sim that does not know the packed form, the read phase is
one ``SNAP`` (every declared input), sent at the end of the tick before
behind its write line (one system call) and read while the loop slept; a
``SNAP`` sent more than 1.5 ticks before its read phase (the loop
stalled) is not used: that read phase asks again.  ``prefetch=0`` asks
in the read phase (a round trip in the tick).  The reflex's writes wait
for their reply.  Every readable output is read once on opening
(pipelined: one exchange), and again when the watchdog has turned the
outputs off.

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

import struct
import time
from binascii import a2b_hex
from collections.abc import Mapping, Sequence
from typing import Any

from pyrt.boards._tcplink import DEFAULT_CONNECT_TIMEOUT_S, DEFAULT_TIMEOUT_S, TcpLink
from pyrt.boards.image import (
    DEFAULT_OVERRUN_LIMIT,
    DEFAULT_OVERRUN_TICKS,
    ImageBackend,
    ImageRegisters,
    Write,
)
from pyrt.boards.registers import BoardKind, options_for, split_options
from pyrt.boards.registry import Boards, BoardURL
from pyrt.boards.wire import snapshot_struct
from pyrt.errors import BoardError, ConfigError

__all__ = [
    "DEFAULT_CONNECT_TIMEOUT_S",
    "DEFAULT_MAX_AGE_S",
    "DEFAULT_TIMEOUT_S",
    "TcpBoardRegisters",
    "TcpLink",
    "TcpRegisters",
    "open_tcp",
]

DEFAULT_MAX_AGE_S = 0.05
#: How long one ``STREAM`` request streams for (ms); the client asks again at half of it
#: (or at a quarter of the watchdog time, if that is sooner).
STREAM_MS = 100


# -- the registers of one connection ---------------------------------------------------------


class TcpRegisters(ImageBackend):
    """The declared boards of one board-sim connection: the process image
    (:class:`~pyrt.boards.image.ImageBackend`) over the wire protocol.

    ``kinds``: the station's boards (name -> kind), each checked against the
    greeting.  The read phase takes the newest of board-sim's pushes (or,
    from an older board-sim, one ``SNAP``); the write phase sends one ``W
    ...; W ...`` line without waiting, with the request for the inputs it
    leaves behind it (see the module text); the reflex's writes wait for
    their reply.
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
        if self.streaming and self.phased and self._rearm_ns:  # the loop runs: it streams
            # what came while the loop slept, no older than the last writes (a SNAPX
            # went with them) nor 1.5 ticks; else, if the stream has lapsed, ask;
            # if not, board-sim is late: its next push
            now = time.monotonic_ns()
            ask = self._snapx_request if now >= self._stream_live_ns else None
            return self._unpack(link.newest(now, self._stale_ns, ask))
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
            # those before the refused one stand, the rest do not: the image takes
            # what board-sim holds (a write-only strobe holds nothing to read)
            keys = [(b, n, i) for b, n, i, _ in writes if self.kinds[b].register(n).readback]
            held = self.link.pipeline([f"R {b} {n} {i}" for b, n, i in keys])
            for key, values in zip(keys, held, strict=True):
                self._outputs[key] = self._output_list[self.output_index[key]] = values[0]
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

    def info(self) -> dict[str, str]:
        """board-sim's ``INFO``: the world's state (not a register access)."""
        return self.link.info()

    def resync(self) -> None:
        """The loop starts: the writes made while the station was built go out,
        the watchdog count is forgotten and the outputs read again."""
        super().resync()
        self.link.forget_trips()
        self.forget_outputs(self.read_outputs())


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
    (:mod:`pyrt.boards.image`), ``prefetch`` (1, the default: the inputs come
    while the loop sleeps, streamed by board-sim, or from an older one the
    next tick's ``SNAP`` sent at the end of the tick; 0: asked for at the
    start of the read phase, a whole round trip in the tick); and those of
    the declared kinds (the gripper cage's ``cpu``).
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
    return Boards(url.text, station, boards, kinds, world=link.station, views=views,
                  **client.boards_hooks(pollers))
