"""The board-sim wire protocol: register accesses as text lines over TCP (version 1).

``pyrt board-sim`` serves a simulated board set (the gripper's cage, or a
manipulator's TIO10 and dataConcentrator with the rope world behind them);
:mod:`pyrt.boards.tcp` is the controller's side.  The protocol is small on
purpose: one request line, one reply line, each register access as the
board interfaces (:class:`~pyrt.boards.gripper.GripperBoard`,
:class:`~pyrt.boards.tio10.TIO10`,
:class:`~pyrt.boards.dataconcentrator.DataConcentrator`) have it, plus one
``SNAP`` that reads every input of a tick in one round trip.

Transport.  One TCP connection per controller.  ASCII lines ending in LF
(CR LF accepted), at most :data:`MAX_LINE` bytes with the line end.  Every
request line gets exactly one reply line, in order (a client may pipeline).
Tokens are separated by spaces; verbs are case-insensitive.  Numbers are
unsigned integers, decimal or ``0x`` hexadecimal in requests, always decimal
in replies.

Greeting.  The server speaks first::

    OK pyrt-board-sim 1 KIND NAME WATCHDOG_MS

``KIND`` is ``gripper`` or ``manipulator``, ``NAME`` the world (``gripper``,
or the station's polyaxis name, e.g. ``prototype``), ``WATCHDOG_MS`` the
watchdog time.  While another controller is connected the server answers
``ERR busy ...`` instead and closes the connection: one controller at a time.

Replies.  ``OK [VALUE ...]`` or ``ERR CODE TEXT``, codes:

* ``syntax``: not a request (unknown verb, wrong number of arguments, not a
  number, an empty line);
* ``range``: the board refused the value (a channel, port or address that is
  not there, a period out of range, arming a channel with no period): the
  refusal an in-process board raises as ``ValueError``;
* ``too-long``: the line exceeds :data:`MAX_LINE` (the rest up to the next
  line end is discarded); ``ascii``: the line is not ASCII;
* ``internal``: the server failed (a bug; it keeps serving).

An error reply changes nothing and leaves the connection usable.

Requests of every board::

    INFO              OK KEY=VALUE ...    the world's state (not a register access)
    QUIT              OK bye              then the server closes the connection

Gripper cage (addresses of :data:`pyrt.boards.gripper.REGISTERS`)::

    R ADDR            OK VALUE            read a register
    W ADDR VALUE      OK                  write one (not the input ports PA/PB/PC)
    SNAP              OK TRIPS UP DOWN CMD PA PB PC LEDLO LEDHI DAC

``TRIPS`` counts the watchdog's trips since board-sim started (both
boards' ``SNAP`` begin with it: a controller that sees it grow learns that
its outputs were turned off).  ``UP``/``DOWN`` count the encoder pulses the board raised on external
interrupt 0 and 1 since it started, modulo 2**32; the controller's side
fires the 8031 vectors for the difference since its last ``SNAP``.

Manipulator: TIO10 clock channels 0..9, PIA ports 0..3, dataConcentrator
counter addresses 0..255 and ADC channels 0..15::

    SRC CH [S]        OK S | OK           the channel's source F1..F5: read, or select
    PER CH [T]        OK T | OK           its period (load) register: read, or load
    ARM CH            OK                  start counting (a period must be loaded)
    DISARM CH         OK
    ARMED CH          OK 0|1
    PULSES CH         OK N                output-pulse counter, modulo 2**16
    PORT P [V]        OK V | OK           a PIA port: read back, or write
    RTC               OK TICKS            5 MHz ticks, modulo 2**32
    CNT A             OK RAW              24-bit up/down counter
    CLR A             OK                  clear it
    ADC C             OK CODE             latest 12-bit conversion
    SNAP [A ...]      OK TRIPS RTC PORT0..3 SRC0..9 PER0..9 ARMED0..9 PULSES0..9 ADC0..15 CNT(A)...

Watchdog.  Every request except ``INFO`` and ``QUIT`` is a register access.
When none has come for the watchdog time, the board turns its outputs off,
as a real motion board does: the gripper's DAC goes to null (80); every
TIO10 motor channel is disarmed and every all-windings-off bit set.  The
same happens at once when the controller's connection closes.  A later
write drives the outputs again.
"""

from __future__ import annotations

from pyrt.errors import PyrtError

__all__ = [
    "GREETING",
    "GRIPPER_SNAP",
    "GRIPPER_VERBS",
    "MANIPULATOR_SNAP",
    "MANIPULATOR_VERBS",
    "MAX_LINE",
    "NOT_ACCESSES",
    "VERSION",
    "WireError",
    "error_line",
    "ok_line",
    "parse_request",
]

#: The first token after ``OK`` in the greeting, and the protocol version.
GREETING = "pyrt-board-sim"
VERSION = 1
#: Longest line, line end included.
MAX_LINE = 4096

#: Verb -> the numbers of arguments it takes.
GRIPPER_VERBS: dict[str, tuple[int, ...]] = {
    "R": (1,), "W": (2,), "SNAP": (0,), "INFO": (0,), "QUIT": (0,),
}
MANIPULATOR_VERBS: dict[str, tuple[int, ...]] = {
    "SRC": (1, 2), "PER": (1, 2), "ARM": (1,), "DISARM": (1,), "ARMED": (1,),
    "PULSES": (1,), "PORT": (1, 2), "RTC": (0,), "CNT": (1,), "CLR": (1,), "ADC": (1,),
    "SNAP": tuple(range(257)), "INFO": (0,), "QUIT": (0,),
}
#: Requests that are not register accesses (they do not feed the watchdog).
NOT_ACCESSES = frozenset(("INFO", "QUIT"))

#: Fields of a gripper ``SNAP`` reply, in order.
GRIPPER_SNAP = ("trips", "up", "down", "cmd", "pa", "pb", "pc", "led_lo", "led_hi", "dac")
#: Fields of a manipulator ``SNAP`` reply before the counters: name -> (first index, count).
MANIPULATOR_SNAP = {
    "trips": (0, 1), "rtc": (1, 1), "port": (2, 4), "src": (6, 10), "per": (16, 10),
    "armed": (26, 10), "pulses": (36, 10), "adc": (46, 16), "cnt": (62, 0),
}


class WireError(PyrtError):
    """A request the server answers with ``ERR CODE TEXT``."""

    def __init__(self, code: str, text: str):
        self.code = code
        self.text = text
        super().__init__(f"{code} {text}")


_HEX = frozenset("0123456789abcdefABCDEF")


def _number(token: str) -> int:
    if token[:2].lower() == "0x":
        digits = token[2:]
        if digits and len(digits) <= 16 and _HEX.issuperset(digits):
            return int(digits, 16)
    elif token.isdigit() and len(token) <= 20:
        return int(token)
    raise WireError("syntax", f"{token!r} is not an unsigned number (decimal or 0x hex)")


def parse_request(line: bytes, verbs: dict[str, tuple[int, ...]]) -> tuple[str, list[int]]:
    """``(VERB, [numbers])`` of one request line (line end removed or not).

    Raises :class:`WireError` (``ascii``, ``syntax``) for anything else.
    """
    try:
        text = line.decode("ascii")
    except UnicodeDecodeError:
        raise WireError("ascii", "requests are ASCII text") from None
    tokens = text.split()
    if not tokens:
        raise WireError("syntax", "empty request")
    verb = tokens[0].upper()
    counts = verbs.get(verb)
    if counts is None:
        raise WireError("syntax", f"unknown request {tokens[0][:20]!r}; known: "
                                  f"{' '.join(verbs)}")
    args = tokens[1:]
    if len(args) not in counts:
        want = " or ".join(str(c) for c in counts) if len(counts) < 4 else "any number of"
        raise WireError("syntax", f"{verb} takes {want} arguments, got {len(args)}")
    return verb, [_number(a) for a in args]


def ok_line(*values: object) -> bytes:
    """An ``OK`` reply line carrying ``values``."""
    if not values:
        return b"OK\n"
    return ("OK " + " ".join(map(str, values)) + "\n").encode("ascii")


def error_line(code: str, text: str) -> bytes:
    """An ``ERR`` reply line (the text on one line, ASCII)."""
    clean = " ".join(text.split()).encode("ascii", "replace").decode("ascii")
    return f"ERR {code} {clean}\n".encode("ascii")
