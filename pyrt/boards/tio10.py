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

:class:`TIO10` is the interface a driver sees (a real card would be a sibling
of :mod:`pyrt.boards.simboards`, exactly as pySerial has one ``Serial``
interface and a back end per platform).  Values are raw integers, as the
hardware has them; nothing here knows about centimetres.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

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
    "check_channel",
    "check_period",
    "check_port",
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
_MOTOR_CHANNELS = tuple(c for c in CHANNELS if c not in RTC_CHANNELS)
_OUTPUT_CHANNELS = frozenset(_MOTOR_CHANNELS)
DIR_BITS = {c: (0, b) for b, c in enumerate(_MOTOR_CHANNELS)}
AWO_BITS = {c: (1, b) for b, c in enumerate(_MOTOR_CHANNELS)}


def check_channel(channel: int, *, allow_rtc: bool = False) -> int:
    """Return ``channel`` if it names a clock channel usable for output.

    Raises :class:`ValueError` for anything that is not 0..9, and for the
    real-time-clock channels 4 and 5 unless ``allow_rtc``.
    """
    if type(channel) is int and (channel in _OUTPUT_CHANNELS
                                 or (allow_rtc and channel in RTC_CHANNELS)):
        return channel  # the fast path of every register access
    if isinstance(channel, bool) or not isinstance(channel, int) or channel not in CHANNELS:
        raise ValueError(f"TIO10 clock channel must be an integer 0..9, got {channel!r}")
    if not allow_rtc and channel in RTC_CHANNELS:
        raise ValueError(
            f"TIO10 channel {channel} is reserved for the real-time clock (channels 4 and 5)"
        )
    return channel


def check_period(channel: int, ticks: int) -> None:
    """A load of ``ticks`` into ``channel``'s period register, checked as the card
    takes it (ValueError naming what is wrong): an output channel, an integer
    MIN_PERIOD..MAX_PERIOD."""
    check_channel(channel)
    if isinstance(ticks, bool) or not isinstance(ticks, int):
        raise ValueError(f"period must be an integer tick count, got {ticks!r}")
    if not MIN_PERIOD <= ticks <= MAX_PERIOD:
        raise ValueError(
            f"period {ticks} out of the 16-bit load register's range "
            f"{MIN_PERIOD}..{MAX_PERIOD} ticks"
        )


def source_hz(source: int) -> int:
    """The frequency of AM9513 source F``source`` (1..5) in Hz."""
    if isinstance(source, bool) or not isinstance(source, int) or source not in SOURCES:
        raise ValueError(f"AM9513 source must be F1..F5 (1..5), got {source!r}")
    return CLOCK_HZ // 10 ** (source - 1)


def check_port(port: int) -> int:
    """Return ``port`` if it is one of the four PIA ports (0..3)."""
    if isinstance(port, bool) or not isinstance(port, int) or port not in PIA_PORTS:
        raise ValueError(f"TIO10 PIA port must be 0..3, got {port!r}")
    return port


class TIO10(ABC):
    """Register interface of one TIO10 card.

    Clock channels: :meth:`select_source` picks the source the channel
    counts (F1..F5, power-up F1), :meth:`load_period` writes its load
    (period) register and :meth:`arm` starts it counting; :meth:`disarm` stops its
    output.  :meth:`pulses` reads the channel's 16-bit output-pulse counter
    (wraps modulo 2**16).  PIA: :meth:`write_port` / :meth:`read_port`.
    Real-time clock: :meth:`rtc_ticks` (5 MHz ticks, modulo 2**32).
    """

    clock_hz: int = CLOCK_HZ

    @abstractmethod
    def select_source(self, channel: int, source: int) -> None:
        """Make the channel count source F``source`` (1..5)."""

    @abstractmethod
    def source(self, channel: int) -> int:
        """The source (1..5) the channel counts."""

    @abstractmethod
    def load_period(self, channel: int, ticks: int) -> None:
        """Write ``ticks`` (MIN_PERIOD..MAX_PERIOD source counts) to the load register."""

    @abstractmethod
    def period(self, channel: int) -> int:
        """The channel's load register as last written (0 before any write)."""

    @abstractmethod
    def arm(self, channel: int) -> None:
        """Start the channel counting down from its load register."""

    @abstractmethod
    def disarm(self, channel: int) -> None:
        """Stop the channel; its output issues no more pulses."""

    @abstractmethod
    def armed(self, channel: int) -> bool:
        """Whether the channel is counting."""

    @abstractmethod
    def pulses(self, channel: int) -> int:
        """The channel's output-pulse counter (0..2**16-1, wrapping)."""

    @abstractmethod
    def write_port(self, port: int, value: int) -> None:
        """Write an 8-bit value to PIA output port ``port``."""

    @abstractmethod
    def read_port(self, port: int) -> int:
        """Read back PIA output port ``port``."""

    @abstractmethod
    def rtc_ticks(self) -> int:
        """The cascaded channels 4 and 5: 5 MHz ticks since power-up, modulo 2**32."""

    # -- bit helpers (read-modify-write of a PIA port) -----------------------

    def set_bit(self, port: int, bit: int, value: bool) -> None:
        """Set or clear one bit of a PIA port, leaving the others alone."""
        if isinstance(bit, bool) or not isinstance(bit, int) or not 0 <= bit <= 7:
            raise ValueError(f"PIA bit must be 0..7, got {bit!r}")
        old = self.read_port(port)
        new = (old | (1 << bit)) if value else (old & ~(1 << bit) & 0xFF)
        if new != old:
            self.write_port(port, new)

    def bit(self, port: int, bit: int) -> bool:
        """One bit of a PIA port."""
        if isinstance(bit, bool) or not isinstance(bit, int) or not 0 <= bit <= 7:
            raise ValueError(f"PIA bit must be 0..7, got {bit!r}")
        return bool(self.read_port(port) >> bit & 1)
