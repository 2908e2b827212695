"""The scope's samples, live, to PlotJuggler's UDP server (its JSON protocol).

``scope stream udp://HOST:PORT [HZ]`` sends the scope's channels as they are
sampled, at most ``HZ`` objects a second of loop time (default
:data:`DEFAULT_HZ`): every ``1/HZ`` s of loop time the latest sample is one
UDP datagram holding one JSON object, its loop time in seconds as
``timestamp`` (PlotJuggler: *UDP Server*, message protocol *JSON*, "use
field as timestamp", field ``timestamp``), and its channels grouped by object
as the scope names them::

    {"timestamp":12.345,"encoder":-1022,"gripper":{"dac":131},"sim":{"x":21.07}}

The loop never waits for the network.  In the loop thread the scope only
compares the sample's time with the next send time and, when it is due,
appends the sample's packed bytes to a bounded queue; a thread of the
stream turns them into JSON and sends them on a non-blocking socket.  A
receiver that is slow, absent or refusing (``ECONNREFUSED``) costs the loop
nothing: a datagram the socket cannot take is dropped and counted
(:attr:`UdpStream.lost`), and so is a sample the queue has no room for
(:attr:`UdpStream.dropped`; the thread fell behind).  No dependency beyond
the standard library.
"""

from __future__ import annotations

import collections
import json
import math
import socket
import struct
import threading
import weakref
from dataclasses import dataclass
from typing import Protocol
from urllib.parse import urlsplit

from pyrt.errors import CommandError

__all__ = ["DEFAULT_HZ", "MAX_HZ", "MIN_HZ", "Layout", "Sink", "UdpStream", "parse_udp_url"]

#: Objects a second of loop time, unless the command names a rate.
DEFAULT_HZ = 50.0
#: The highest rate (and the lowest: :data:`MIN_HZ`).
MAX_HZ = 1000.0
MIN_HZ = 0.1
#: Samples the queue toward the stream's thread holds.
QUEUE = 4096
#: How often the thread looks at its queue, s (wall time).
POLL_S = 0.01


def parse_udp_url(url: str) -> tuple[str, int]:
    """``udp://HOST:PORT`` as (host, port); CommandError saying what is wrong."""
    try:
        parts = urlsplit(url)
        port = parts.port
    except ValueError as exc:
        raise CommandError(f"scope stream: {url[:60]!r} is not udp://HOST:PORT ({exc})") from None
    if parts.scheme.lower() != "udp" or not parts.hostname or port is None \
            or parts.path not in ("", "/") or parts.query or parts.fragment:
        raise CommandError(f"scope stream: {url[:60]!r} is not udp://HOST:PORT (e.g. "
                           "udp://127.0.0.1:9870, PlotJuggler's UDP server)")
    if not 1 <= port <= 65535:
        raise CommandError(f"scope stream: port {port} outside 1..65535")
    return parts.hostname, port


@dataclass(frozen=True)
class Layout:
    """What the scope's packed samples hold: the struct (``<q`` + a double per
    channel) and the channel names, and how each becomes a JSON key."""

    packer: struct.Struct
    channels: tuple[str, ...]

    def template(self) -> tuple[str, list[int]]:
        """The JSON object's %-template and the channel order it takes."""
        groups: dict[str, list[tuple[int, str]]] = {}
        for k, name in enumerate(self.channels):
            obj, dot, sig = name.partition(".")
            if not dot or not sig:
                obj, sig = "", name
            groups.setdefault(obj, []).append((k, sig))
        parts = ['"timestamp":%s']
        order: list[int] = []
        for obj, fields in groups.items():
            inner = ",".join(_key(sig) + ":%s" for _k, sig in fields)
            order += [k for k, _sig in fields]
            parts.append(inner if not obj else _key(obj) + ":{" + inner + "}")
        return "{" + ",".join(parts) + "}", order


class Sink(Protocol):
    """What the scope hands live samples to (:class:`UdpStream`, the Foxglove
    server): in the loop thread, :meth:`offer` every :attr:`period_ns` of loop
    time; it only queues.  :meth:`close` (application side) ends it."""

    period_ns: int

    def offer(self, layout: Layout, row: bytes) -> None: ...

    def bind(self, owner: object) -> None: ...

    def close(self) -> None: ...


def _key(name: str) -> str:
    return json.dumps(name).replace("%", "%%")


def _num(v: float) -> str:
    if math.isfinite(v):
        return repr(int(v)) if v.is_integer() and abs(v) < 2**53 else repr(v)
    return "null"  # JSON has no NaN or infinity


class UdpStream:
    """A live stream of scope samples to ``host:port`` at ``hz`` objects a second
    of loop time (see the module text).  :meth:`offer` is the loop's side."""

    def __init__(self, host: str, port: int, hz: float = DEFAULT_HZ):
        if not isinstance(hz, int | float) or isinstance(hz, bool) \
                or not MIN_HZ <= hz <= MAX_HZ:
            raise CommandError(f"scope stream: rate must be {MIN_HZ:g}..{MAX_HZ:g} Hz, "
                               f"got {hz!r}")
        try:
            info = socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM)
        except (OSError, UnicodeError) as exc:
            raise CommandError(f"scope stream: cannot resolve {host[:60]!r}: {exc}") from None
        family, _type, proto, _name, address = info[0]
        self.host, self.port, self.hz = host, port, float(hz)
        self.address = address
        #: Loop time between two objects, ns.
        self.period_ns = round(1e9 / hz)
        self._sock = socket.socket(family, socket.SOCK_DGRAM, proto)
        self._sock.setblocking(False)
        self._queue: collections.deque[tuple[Layout, bytes]] = collections.deque()
        #: Objects sent; datagrams the socket would not take (receiver absent,
        #: refusing or slow); samples the queue had no room for.
        self.sent = 0
        self.lost = 0
        self.dropped = 0
        self._stop = threading.Event()
        self._owner: weakref.ref[object] | None = None
        self._templates: dict[Layout, tuple[str, list[int]]] = {}
        self._thread = threading.Thread(target=self._run, name="pyrt scope stream",
                                        daemon=True)
        self._thread.start()

    @property
    def url(self) -> str:
        """Where the stream goes, as the command names it."""
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"udp://{host}:{self.port}"

    # -- the loop's side -----------------------------------------------------------

    def offer(self, layout: Layout, row: bytes) -> None:
        """Hand one packed sample over (loop thread): an append, or a count when
        the queue is full."""
        if len(self._queue) >= QUEUE:
            self.dropped += 1
            return
        self._queue.append((layout, row))

    # -- the stream's thread ---------------------------------------------------------

    def bind(self, owner: object) -> None:
        """Tie the stream's thread to ``owner`` (the scope): once the owner is gone
        (a station closed and dropped without ``scope stream off``), the thread ends."""
        self._owner = weakref.ref(owner)

    def _run(self) -> None:
        while not self._stop.wait(POLL_S):
            self.drain()
            owner = self._owner
            if owner is not None and owner() is None:
                break
        self.drain()

    def drain(self) -> int:
        """Send what is queued (the stream's thread; and once more when it stops);
        the number of objects sent."""
        queue = self._queue
        n = 0
        while queue:
            layout, row = queue.popleft()
            self._send(self.encode(layout, row))
            n += 1
        return n

    def encode(self, layout: Layout, row: bytes) -> bytes:
        """One packed sample as the JSON object sent."""
        cached = self._templates.get(layout)
        if cached is None:
            cached = self._templates[layout] = layout.template()
        template, order = cached
        values = layout.packer.unpack(row)
        t_s = values[0] / 1e9
        return (template % (repr(t_s), *(_num(float(values[1 + k])) for k in order))).encode()

    def _send(self, data: bytes) -> None:
        try:
            self._sock.sendto(data, self.address)
            self.sent += 1
        except OSError:  # would block, refused (no receiver), unreachable, too big
            self.lost += 1

    def close(self) -> None:
        """Send what is queued, stop the thread, close the socket."""
        self._stop.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout=5)
        self._sock.close()

    def describe(self) -> str:
        """One line: where, how often, and what was sent, lost and dropped."""
        line = (f"streaming to {self.url} at {self.hz:g} Hz of loop time: {self.sent} sent")
        if self.lost:
            line += f", {self.lost} not taken by the socket (receiver absent or slow)"
        if self.dropped:
            line += f", {self.dropped} dropped (the stream fell behind the loop)"
        return line
