"""The National Instruments TIO10 timing card, at register level (000, section 11.3).

Two AM9513 timer/counter chips of five channels each give ten clock channels,
numbered 0 to 9 as MOTOR.dat numbers them (chip A: 0-4, chip B: 5-9).  A
stepper motor takes one half-step per output pulse of its channel, so the
channel's count-down *period* register sets the step rate.  Each channel
counts one of the AM9513 frequency-scaler sources F1..F5, the card's 5 MHz
clock divided by 1, 10, 100, 1000 or 10000 (:meth:`TIO10.select_source`);
the period is a 16-bit count of that source.  Channels 4 and 5 are cascaded
into the real-time clock counting the 5 MHz clock (000, section 14) and
cannot drive a motor.

Two MC6821 PIAs give four 8-bit output ports; their bits carry each motor's
direction and all-windings-off (AWO) lines.  Which bit belongs to which
channel is wiring, and lives with the Motor (000, section 8: ``dirBit[]`` and
``awoBit[]``), not here.

:data:`TIO10_KIND` declares the registers; :class:`TIO10` is the card as a
driver sees it, a view over any register access of that kind (the
in-process register file, a process image, a link): its arguments are
checked against the declarations.  Values are raw integers, as the hardware
has them; nothing here knows about centimetres.
"""

from __future__ import annotations

from collections.abc import Callable

from pyrt.boards.registers import (
    OUTPUT,
    BoardKind,
    Register,
    RegisterBoard,
    Registers,
    bound_reader,
    bound_writer,
)

__all__ = [
    "AWO_BITS",
    "CHANNELS",
    "CLOCK_HZ",
    "DIR_BITS",
    "MAX_PERIOD",
    "MIN_PERIOD",
    "PIA_PORTS",
    "PULSE_COUNTER_MODULUS",
    "RTC_CHANNELS",
    "RTC_MODULUS",
    "SOURCES",
    "TIO10",
    "TIO10_KIND",
    "source_hz",
]

#: The card's time base (000, section 4: "the tio10's 5 MHz clock").
CLOCK_HZ = 5_000_000
#: Clock channels on the card: two AM9513s of five channels each.
CHANNELS = tuple(range(10))
#: Frequency-scaler sources F1..F5: 5 MHz / 10**(source - 1).
SOURCES = (1, 2, 3, 4, 5)
#: Cascaded into the 32-bit real-time clock; refused for anything else.
RTC_CHANNELS = (4, 5)
#: The AM9513 load register is 16 bits; a period of 1 is not a square wave.
MIN_PERIOD = 2
MAX_PERIOD = 0xFFFF
#: The output-pulse counter of each channel wraps at 16 bits.
PULSE_COUNTER_MODULUS = 1 << 16
#: Two cascaded 16-bit counters.
RTC_MODULUS = 1 << 32
#: Four 8-bit PIA output ports: PIA 0 A/B and PIA 1 A/B.
PIA_PORTS = (0, 1, 2, 3)

#: Motor wiring of the PIA bits (000, section 8: ``dirBit[]`` and ``awoBit[]``):
#: clock channel -> (port, bit).  Direction on PIA 0 port A (1 = pay rope
#: out), all-windings-off on PIA 0 port B (1 = windings off).  Rewiring the
#: outputs means changing these tables, as in the document.
_MOTOR = tuple(c for c in CHANNELS if c not in RTC_CHANNELS)
DIR_BITS = {c: (0, b) for b, c in enumerate(_MOTOR)}
AWO_BITS = {c: (1, b) for b, c in enumerate(_MOTOR)}
_AWO_PORTS = {port for port, _ in AWO_BITS.values()}



def source_hz(source: int) -> int:
    """The frequency of AM9513 source F``source`` (1..5) in Hz."""
    if type(source) is not int or source not in SOURCES:
        raise ValueError(f"AM9513 source must be F1..F5 (1..5), got {source!r}")
    return CLOCK_HZ // 10 ** (source - 1)


class TIO10:
    """One TIO10 card over ``registers`` (any register access of
    :data:`TIO10_KIND`; None: a register file of its own, in this process).

    Clock channels: :meth:`select_source` picks the source the channel
    counts (F1..F5, power-up F1), :meth:`load_period` writes its load
    (period) register and :meth:`arm` starts it counting; :meth:`disarm`
    stops its output.  :meth:`pulses` reads the channel's 16-bit
    output-pulse counter (wraps modulo 2**16).  PIA: :meth:`write_port` /
    :meth:`read_port`.  Real-time clock: :meth:`rtc_ticks` (5 MHz ticks,
    modulo 2**32).  A channel, port or value the declarations refuse is a
    ValueError and writes nothing; ``writes`` counts the writes made.
    """

    clock_hz: int = CLOCK_HZ

    def __init__(self, registers: Registers | None = None):
        self.registers: Registers = registers if registers is not None \
            else RegisterBoard(TIO10_KIND)
        self.url = getattr(self.registers, "url", "")
        r = self.registers
        # every register bound once, by channel (port): a read is one call into the image
        self._src, self._per, self._armed, self._pulses = (
            [bound_reader(r, name, c) for c in CHANNELS]
            for name in ("src", "per", "armed", "pulses"))
        self._port = [bound_reader(r, "port", p) for p in PIA_PORTS]
        self.rtc_ticks = bound_reader(r, "rtc")
        self._set_src, self._set_per, self._set_armed = (
            [bound_writer(r, name, c) for c in CHANNELS] for name in ("src", "per", "armed"))
        self._set_port = [bound_writer(r, "port", p) for p in PIA_PORTS]
        self.writes = 0

    @staticmethod
    def check_channel(channel: int, rtc: bool = False) -> int:
        """``channel`` if the period register has it (and, unless ``rtc``, it
        is no real-time-clock channel); ValueError otherwise."""
        _PER.check_index(channel)
        if not rtc and channel in RTC_CHANNELS:
            raise ValueError(f"TIO10 channel {channel} is reserved for the real-time clock "
                             f"(channels {RTC_CHANNELS[0]} and {RTC_CHANNELS[1]})")
        return channel

    # -- readers bound once (a device's tick path) ---------------------------------
    #
    # Each is checked here, when it is bound, exactly as the read it stands for
    # (a ValueError naming the channel or port); the reader it returns is a call
    # of no argument that reads the register with no further check.

    def armed_reader(self, channel: int) -> Callable[[], int]:
        """The channel's ``armed`` register (1 counting, 0 not), bound once."""
        return self._armed[self.check_channel(channel, True)]

    def pulses_reader(self, channel: int) -> Callable[[], int]:
        """The channel's output-pulse counter (as :meth:`pulses`), bound once."""
        return self._pulses[self.check_channel(channel, True)]

    def period_reader(self, channel: int) -> Callable[[], int]:
        """The channel's load register (as :meth:`period`), bound once."""
        return self._per[self.check_channel(channel, True)]

    def source_reader(self, channel: int) -> Callable[[], int]:
        """The source the channel counts (as :meth:`source`), bound once."""
        return self._src[self.check_channel(channel, True)]

    def port_reader(self, port: int) -> Callable[[], int]:
        """PIA output port ``port`` read back (as :meth:`read_port`), bound once."""
        return self._port[_PORT.check_index(port)]

    def select_source(self, channel: int, source: int) -> None:
        """Make the channel count source F``source`` (1..5)."""
        self.check_channel(channel)
        source_hz(_SRC.check_value(source))
        self._set_src[channel](source)
        self.writes += 1

    def source(self, channel: int) -> int:
        """The source (1..5) the channel counts."""
        return self._src[self.check_channel(channel, True)]()

    def load_period(self, channel: int, ticks: int) -> None:
        """Write ``ticks`` (MIN_PERIOD..MAX_PERIOD source counts) to the load register."""
        self.check_channel(channel)
        if not (_PER.fits(ticks) and ticks >= MIN_PERIOD):
            raise ValueError(f"period {ticks!r} out of the {_PER.width}-bit load register's "
                             f"range {MIN_PERIOD}..{_PER.high} ticks")
        self._set_per[channel](ticks)
        self.writes += 1

    def period(self, channel: int) -> int:
        """The channel's load register as last written (0 before any write)."""
        return self._per[self.check_channel(channel, True)]()

    def arm(self, channel: int) -> None:
        """Start the channel counting down from its load register."""
        if self._per[self.check_channel(channel)]() < MIN_PERIOD:
            raise ValueError(f"channel {channel} has no period loaded; load it before arming")
        self._set_armed[channel](1)
        self.writes += 1

    def disarm(self, channel: int) -> None:
        """Stop the channel; its output issues no more pulses."""
        self._set_armed[self.check_channel(channel)](0)
        self.writes += 1

    def armed(self, channel: int) -> bool:
        """Whether the channel is counting."""
        return bool(self._armed[self.check_channel(channel, True)]())

    def pulses(self, channel: int) -> int:
        """The channel's output-pulse counter (0..2**16-1, wrapping)."""
        return self._pulses[self.check_channel(channel, True)]()

    def write_port(self, port: int, value: int) -> None:
        """Write an 8-bit value to PIA output port ``port``."""
        _PORT.check_index(port)
        self._set_port[port](_PORT.check_value(value))
        self.writes += 1

    def read_port(self, port: int) -> int:
        """Read back PIA output port ``port``."""
        return self._port[_PORT.check_index(port)]()

    # -- bit helpers (read-modify-write of a PIA port) -----------------------

    def set_bit(self, port: int, bit: int, value: bool) -> None:
        """Set or clear one bit of a PIA port, leaving the others alone."""
        old = self.read_port(port)
        mask = 1 << _bit(bit)
        new = (old | mask) if value else (old & ~mask & _PORT.high)
        if new != old:
            self.write_port(port, new)

    def bit(self, port: int, bit: int) -> bool:
        """One bit of a PIA port."""
        return bool(self.read_port(port) >> _bit(bit) & 1)

    def __repr__(self) -> str:
        return f"<TIO10 over {self.registers!r}>"



TIO10_KIND = BoardKind("tio10", (
    Register("src", count=len(CHANNELS), width=3, direction=OUTPUT, power_up=1,
             doc="the AM9513 source each channel counts, F1..F5 (power-up F1)"),
    Register("per", count=len(CHANNELS), width=16, direction=OUTPUT, units="source counts",
             doc=f"period (load) register, {MIN_PERIOD}..{MAX_PERIOD}"),
    Register("armed", count=len(CHANNELS), width=1, direction=OUTPUT,
             off=tuple(0 if c in _MOTOR else None for c in CHANNELS),
             doc="1: the channel counts (arm; a period must be loaded), 0: disarmed"),
    Register("port", count=len(PIA_PORTS), width=8, direction=OUTPUT,
             off=tuple(0xFF if p in _AWO_PORTS else None for p in PIA_PORTS), power_up=0,
             doc="PIA output ports: 0 direction bits, 1 all-windings-off bits"),
    Register("pulses", count=len(CHANNELS), width=16, units="pulses",
             doc="output-pulse counter, modulo 2**16"),
    Register("rtc", width=32, units="5 MHz ticks", doc="real-time clock, modulo 2**32"),
), doc="the National Instruments TIO10 timing card (000, 11.3)", board=TIO10)

_SRC, _PER, _PORT = (TIO10_KIND.register(n) for n in ("src", "per", "port"))


def _bit(bit: int) -> int:
    if type(bit) is not int or not 0 <= bit < _PORT.width:
        raise ValueError(f"PIA bit must be 0..{_PORT.width - 1}, got {bit!r}")
    return bit
