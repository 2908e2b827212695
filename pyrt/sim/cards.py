"""The world's side of the manipulator's cards: what the physics does to their registers.

The TIO10 and the dataConcentrator are register files in this process
(:class:`~pyrt.boards.registers.RegisterBoard` of
:data:`~pyrt.boards.tio10.TIO10_KIND` and
:data:`~pyrt.boards.dataconcentrator.DATACONCENTRATOR`); the control code
reaches them through its views, the physics through these functions (or the
register cells themselves, :meth:`RegisterBoard.cells
<pyrt.boards.registers.RegisterBoard.cells>`, where a step is hot).
"""

from __future__ import annotations

from pyrt.boards.dataconcentrator import ADC_MAX, COUNTER_BITS
from pyrt.boards.registers import RegisterBoard
from pyrt.boards.tio10 import CLOCK_HZ, PULSE_COUNTER_MODULUS, RTC_MODULUS

__all__ = ["add_counts", "add_pulses", "channel_period", "set_adc", "set_rtc"]

_COUNTER_MASK = (1 << COUNTER_BITS) - 1


def channel_period(tio10: RegisterBoard, channel: int) -> tuple[int, bool]:
    """(period in 5 MHz ticks, armed) of a TIO10 channel."""
    return (tio10.output("per", channel) * 10 ** (tio10.output("src", channel) - 1),
            bool(tio10.output("armed", channel)))


def add_pulses(tio10: RegisterBoard, channel: int, n: int) -> None:
    """Count ``n`` output pulses on a TIO10 channel (the counter wraps at 16 bits)."""
    pulses = tio10.cells("pulses")
    pulses[channel] = (pulses[channel] + n) % PULSE_COUNTER_MODULUS


def set_rtc(tio10: RegisterBoard, now_ns: int) -> None:
    """Set a TIO10's real-time clock from the loop time."""
    tio10.cells("rtc")[0] = (now_ns * CLOCK_HZ // 1_000_000_000) % RTC_MODULUS


def add_counts(dc: RegisterBoard, address: int, n: int) -> None:
    """Count ``n`` encoder counts (signed) at ``address`` of a dataConcentrator; 24-bit wrap."""
    cnt = dc.cells("cnt")
    cnt[address] = (cnt[address] + n) & _COUNTER_MASK


def set_adc(dc: RegisterBoard, channel: int, code: float) -> None:
    """Latch a conversion, clamped to the converter's 0..4095."""
    dc.cells("adc")[channel] = 0 if code < 0 else (ADC_MAX if code > ADC_MAX else int(code))
