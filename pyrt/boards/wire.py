"""The board-sim wire protocol: declared register reads and writes as text lines (version 2).

``pyrt board-sim`` serves a station's simulated boards with the world
behind them; :mod:`pyrt.boards.tcp` is the controller's side.  The protocol
knows no robot: a station declares its boards, a name and a kind each, and
a kind declares its registers (:mod:`pyrt.boards.registers`; the built-in
kinds in :mod:`pyrt.boards.kinds`).  Every request is a read or a write of
a declared register, plus one ``SNAP`` that reads every input of a tick in
one round trip.

Transport.  One TCP connection per client.  ASCII lines ending in LF
(CR LF accepted), at most :data:`MAX_LINE` bytes with the line end.  Every
request line gets exactly one reply line, in order (a client may pipeline
requests without waiting for the replies).  Tokens are separated by
spaces; verbs are case-insensitive, board and register names are lower
case (upper case is taken as lower).  Numbers are integers, decimal or
``0x`` hexadecimal, with a ``-`` for a negative value of a signed
register; replies are always decimal.

Greeting.  The server speaks first::

    OK pyrt-board-sim 2 STATION WATCHDOG_MS BOARD=KIND@FINGERPRINT ...

``STATION`` names the station whose world is served (``gripper``,
``prototype``, ``arm`` ...), ``WATCHDOG_MS`` the watchdog time, then one
token per board in declared order: its name, its kind's name and the
kind's fingerprint (eight hex digits over its register declarations,
:attr:`~pyrt.boards.registers.BoardKind.fingerprint`).  The controller
checks that every board it declares is there with the same kind and
fingerprint, and refuses the boards naming those that are missing or
different.

One owner, any readers.  The controller then claims the outputs with
``OWN``; a connection's first write claims them too.  One connection owns
them at a time: while another owns them (it made a register access within
the watchdog time), ``OWN`` and every write are answered ``ERR busy ...``
and change nothing.  Any connection may read (``R``, ``SNAP``, ``INFO``):
an HMI or a logger next to the controller.  An owner silent for longer
than the watchdog time (its outputs are off already) is displaced by the
next claim.  board-sim holds a bounded number of connections and closes
one that completes no request for its idle time (``pyrt board-sim
--max-clients``, ``--idle``).

Replies.  ``OK [VALUE ...]`` or ``ERR CODE TEXT``, codes:

* ``syntax``: not a request (unknown verb, wrong number of arguments, not a
  number, an empty line);
* ``range``: the access is not one the boards have or take: no such board
  or register, an index or value out of the register's declared range, a
  write to an input, a read of a write-only register, or a value the board
  refuses (a period too short, arming a channel with no period): what an
  in-process board raises as ``ValueError``;
* ``too-long``: the line exceeds :data:`MAX_LINE` (the rest up to the next
  line end is discarded); ``ascii``: the line is not ASCII;
* ``busy``: another connection owns the outputs (``OWN``, ``W``);
* ``internal``: the server failed (a bug; it keeps serving).

An error reply to a single access changes nothing and leaves the connection
usable.

Requests::

    R BOARD REG [INDEX]            OK VALUE        read a register (INDEX 0 if not given)
    W BOARD REG [INDEX] VALUE      OK              write an output
    W ...; W ...; ...              OK              several writes, one reply
    SNAP [BOARD ...]               OK TRIPS V ...  every input, in one round trip
    SNAPX [BOARD ...]              OK HEX          the same, in the packed form
    STREAM MS [BOARD ...]          OK STEP_US      push SNAPX's inputs after every world step
    OWN                            OK              claim the outputs (or ERR busy); a keep-alive
    INFO                           OK KEY=VALUE ...  the world's state (not a register access)
    QUIT                           OK bye          then the server closes the connection

Several writes on one line (separated by ``;``) are checked against the
declarations first (none is made if one is malformed or out of range), then
made in order; if the board refuses one, those before it stand, the rest
are not made, and the reply is ``ERR range write K of N: TEXT``.

``SNAP`` answers the inputs of the boards named (every board, in declared
order, if none is named), each board's input registers in its kind's
declared order and an array index by index, after ``TRIPS``: the count of
the watchdog's trips since board-sim started (a controller that sees it
grow learns that its outputs were turned off).

The packed form (``SNAPX``, ``STREAM``: a controller's tick reads every
input in one step, without a conversion per value).  ``HEX`` is the
hexadecimal text of the values packed little-endian, four bytes each:
``TRIPS`` unsigned (modulo 2**32), then every input as ``SNAP`` orders
them, as a signed 32-bit number if its register is signed, else unsigned
(:func:`snapshot_struct`; both sides derive the layout from the kinds,
whose fingerprints the greeting has matched).  ``STREAM MS`` asks for the
inputs after every step of the world (every ``STEP_US`` µs) for the next
``MS`` milliseconds (1..:data:`MAX_STREAM_MS`; 0 stops it): each comes
as a line of its own, ``S HEX``, which is not a reply (a client that
streams takes every line that begins ``S `` as one; a push is never put
between a reply's bytes).  Asking again before the time is up extends
it; the last request's boards are the ones pushed.  A push waits while
the client leaves earlier output unread (it is skipped, not queued), and
the stream ends with the time asked for, so a stalled client finds at
most ``MS`` of them waiting.  A controller re-asks well within the
watchdog time: that request is its keep-alive.  These two requests came
after the greeting's version 2 was fixed: a board-sim that does not know
them answers ``ERR syntax unknown request``, and a controller then uses
``SNAP`` (the client asks ``STREAM 0`` on connecting to find out).

Watchdog, fed only by the owner.  Every request except ``INFO`` and
``QUIT`` is a register access; the owner's feed the watchdog (its ``SNAP``
every tick, or its ``STREAM`` asked again, is its keep-alive; a push is
not a request and feeds nothing), a reader's never do.  When the owner has
made none for the watchdog time, the boards turn their outputs off, as a
real motion board does: every output register that declares an ``off``
value is written with it (the gripper's DAC to null 80; every TIO10 motor
channel disarmed and every all-windings-off bit set).  The same happens at
once when the owner's connection closes, whoever else is connected.  A
later write of the owner drives the outputs again.
"""

from __future__ import annotations

import re
import struct
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from pyrt.boards.registers import BoardKind
from pyrt.errors import PyrtError

__all__ = [
    "GREETING",
    "MAX_LINE",
    "MAX_STREAM_MS",
    "NOT_ACCESSES",
    "PUSH",
    "VERBS",
    "VERSION",
    "Access",
    "Greeting",
    "Request",
    "WireError",
    "error_line",
    "greeting_line",
    "ok_line",
    "parse_greeting",
    "parse_request",
    "snapshot_line",
    "snapshot_struct",
]

#: The first token after ``OK`` in the greeting, and the protocol version.
GREETING = "pyrt-board-sim"
VERSION = 2
#: Longest line, line end included.
MAX_LINE = 4096
#: The request verbs.
VERBS = ("R", "W", "SNAP", "SNAPX", "STREAM", "OWN", "INFO", "QUIT")
#: The longest stream one ``STREAM`` asks for, milliseconds.
MAX_STREAM_MS = 10_000
#: How a pushed line (not a reply) begins: ``S HEX``.
PUSH = b"S "
#: Requests that are not register accesses (they do not feed the watchdog).
NOT_ACCESSES = frozenset(("INFO", "QUIT"))


class WireError(PyrtError):
    """A request the server answers with ``ERR CODE TEXT``."""

    def __init__(self, code: str, text: str):
        self.code = code
        self.text = text
        super().__init__(f"{code} {text}")


@dataclass(frozen=True)
class Access:
    """One register access of a request: ``value`` is None for a read."""

    board: str
    register: str
    index: int
    value: int | None = None

    def line(self) -> str:
        """The access as a request (``R ...`` or ``W ...``)."""
        if self.value is None:
            return f"R {self.board} {self.register} {self.index}"
        return f"W {self.board} {self.register} {self.index} {self.value}"


@dataclass(frozen=True)
class Request:
    """A parsed request line: the verb, its accesses (``R``: one, ``W``:
    one or more), or the boards a ``SNAP``, ``SNAPX`` or ``STREAM`` names
    (and a ``STREAM``'s milliseconds, ``ms``)."""

    verb: str
    accesses: tuple[Access, ...] = ()
    boards: tuple[str, ...] = ()
    ms: int = 0


@dataclass(frozen=True)
class Greeting:
    """A parsed greeting: the station, the watchdog time, board name -> kind tag."""

    station: str
    watchdog_ms: int
    boards: dict[str, str]


_NUMBER = re.compile(r"-?(?:0[xX][0-9a-fA-F]{1,16}|[0-9]{1,20})")
_WORD = re.compile(r"[a-z][a-z0-9_]{0,31}")


def _number(token: str) -> int:
    if not _NUMBER.fullmatch(token):
        raise WireError("syntax", f"{token[:24]!r} is not a number (decimal or 0x hex)")
    neg = token.startswith("-")
    digits = token[1:] if neg else token
    value = int(digits[2:], 16) if digits[:2].lower() == "0x" else int(digits)
    return -value if neg else value


def _kind(kinds: Mapping[str, BoardKind], token: str) -> tuple[str, BoardKind]:
    name = token.lower()
    kind = kinds.get(name) if _WORD.fullmatch(name) else None
    if kind is None:
        raise WireError("range", f"no board {token[:24]!r}; boards: {' '.join(kinds)}")
    return name, kind


def _access(kinds: Mapping[str, BoardKind], verb: str, args: list[str]) -> Access:
    write = verb == "W"
    lo = 3 if write else 2
    if not lo <= len(args) <= lo + 1:
        form = "W BOARD REG [INDEX] VALUE" if write else "R BOARD REG [INDEX]"
        raise WireError("syntax", f"{verb} takes {lo} or {lo + 1} arguments ({form}), "
                                  f"got {len(args)}")
    board, kind = _kind(kinds, args[0])
    numbers = [_number(a) for a in args[2:]]
    reg_name = args[1].lower()
    index = numbers[0] if len(numbers) == (2 if write else 1) else 0
    try:
        if write:
            reg = kind.check_write(reg_name, index, numbers[-1])
        else:
            reg = kind.check_read(reg_name, index)
    except ValueError as exc:
        raise WireError("range", f"{board}: {exc}") from None
    return Access(board, reg.name, index, numbers[-1] if write else None)


def parse_request(line: bytes, kinds: Mapping[str, BoardKind]) -> Request:
    """The :class:`Request` of one line (line end removed or not), checked
    against the served boards' ``kinds`` (board name -> kind).

    Raises :class:`WireError` (``ascii``, ``syntax``, ``range``) for
    anything else, and nothing else.
    """
    try:
        text = line.decode("ascii")
    except UnicodeDecodeError:
        raise WireError("ascii", "requests are ASCII text") from None
    parts = text.split(";")
    if len(parts) > 1:
        accesses = []
        for part in parts:
            tokens = part.split()
            if not tokens or tokens[0].upper() != "W":
                raise WireError("syntax", "only writes (W ...) may share a line, "
                                          "separated by ;")
            accesses.append(_access(kinds, "W", tokens[1:]))
        return Request("W", tuple(accesses))
    tokens = text.split()
    if not tokens:
        raise WireError("syntax", "empty request")
    verb = tokens[0].upper()
    args = tokens[1:]
    if verb in ("R", "W"):
        return Request(verb, (_access(kinds, verb, args),))
    if verb in ("SNAP", "SNAPX"):
        return Request(verb, boards=_boards(kinds, verb, args))
    if verb == "STREAM":
        if not args:
            raise WireError("syntax", "STREAM takes the milliseconds to stream for "
                                      "(STREAM MS [BOARD ...])")
        ms = _number(args[0])
        if not 0 <= ms <= MAX_STREAM_MS:
            raise WireError("range", f"STREAM for 0..{MAX_STREAM_MS} ms, got {ms}")
        return Request(verb, boards=_boards(kinds, verb, args[1:]), ms=ms)
    if verb in NOT_ACCESSES or verb == "OWN":
        if args:
            raise WireError("syntax", f"{verb} takes no arguments, got {len(args)}")
        return Request(verb)
    raise WireError("syntax", f"unknown request {tokens[0][:20]!r}; known: {' '.join(VERBS)}")


def _boards(kinds: Mapping[str, BoardKind], verb: str, args: list[str]) -> tuple[str, ...]:
    names = tuple(_kind(kinds, a)[0] for a in args)
    if len(set(names)) != len(names):
        raise WireError("syntax", f"{verb} names a board twice")
    return names


def snapshot_struct(kinds: Mapping[str, BoardKind], boards: Sequence[str] = ()) -> struct.Struct:
    """The packed form's layout (``SNAPX``, ``STREAM``) for ``boards`` of
    ``kinds`` (every one, in order, if none is named): ``TRIPS`` then
    every input, four bytes each, little-endian."""
    codes = ["<I"]
    for name in boards or kinds:
        for reg in kinds[name].inputs():
            codes.append(("i" if reg.signed else "I") * reg.count)
    return struct.Struct("".join(codes))


def snapshot_line(layout: struct.Struct, trips: int, values: Sequence[int],
                  head: bytes = b"OK ") -> bytes:
    """A packed snapshot line: ``head`` (``OK `` for a reply, :data:`PUSH`
    for a stream's), then the hexadecimal of ``layout`` packing ``trips``
    (modulo 2**32) and ``values``."""
    return head + layout.pack(trips & 0xFFFFFFFF, *values).hex().encode("ascii") + b"\n"


def greeting_line(station: str, watchdog_ms: int, kinds: Mapping[str, BoardKind]) -> bytes:
    """The server's greeting for ``station``'s boards (board name -> kind)."""
    return ok_line(GREETING, VERSION, station, watchdog_ms,
                   *(f"{name}={kind.tag}" for name, kind in kinds.items()))


def parse_greeting(line: str) -> Greeting:
    """The :class:`Greeting` of a greeting line; WireError ``syntax`` naming
    what is wrong (not a board-sim, another version, malformed)."""
    tokens = line.split()
    shown = " ".join(tokens)[:80]
    if tokens[:2] != ["OK", GREETING]:
        raise WireError("syntax", f"not a pyrt board-sim: greeting {shown!r}")
    if len(tokens) < 3 or tokens[2] != str(VERSION):
        raise WireError("syntax", f"a pyrt board-sim of another protocol version (this "
                                  f"controller speaks {VERSION}): greeting {shown!r}")
    if len(tokens) < 5 or not (tokens[4].isascii() and tokens[4].isdigit()):
        raise WireError("syntax", f"malformed greeting {shown!r}")
    boards: dict[str, str] = {}
    for token in tokens[5:]:
        name, eq, tag = token.partition("=")
        if not eq or not _WORD.fullmatch(name) or "@" not in tag or name in boards:
            raise WireError("syntax", f"malformed board {token[:40]!r} in greeting {shown!r}")
        boards[name] = tag
    return Greeting(tokens[3], int(tokens[4]), boards)


def ok_line(*values: object) -> bytes:
    """An ``OK`` reply line carrying ``values``."""
    if not values:
        return b"OK\n"
    return ("OK " + " ".join(map(str, values)) + "\n").encode("ascii")


def error_line(code: str, text: str) -> bytes:
    """An ``ERR`` reply line (the text on one line, ASCII)."""
    clean = " ".join(text.split()).encode("ascii", "replace").decode("ascii")
    return f"ERR {code} {clean}\n".encode("ascii")
