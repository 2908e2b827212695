"""Simulated back ends of the board interfaces: plain register files.

A driver uses them exactly as it would the real cards (through the
:class:`~pyrt.boards.tio10.TIO10` and
:class:`~pyrt.boards.dataconcentrator.DataConcentrator` interfaces).  The
physics in :mod:`pyrt.sim` sits on the other side of the registers: it reads
what the driver wrote (periods, arm state, PIA ports) and writes what the
sensors would (pulse counters, encoder counters, ADC codes, the RTC) through
the ``plant_*`` methods, which no driver calls.
"""

from __future__ import annotations

from pyrt.boards.dataconcentrator import (
    ADC_CHANNELS,
    ADC_MAX,
    COUNTER_ADDRESSES,
    COUNTER_BITS,
    DataConcentrator,
    check_adc_channel,
    check_counter_address,
)
from pyrt.boards.tio10 import (
    CHANNELS,
    CLOCK_HZ,
    MIN_PERIOD,
    PIA_PORTS,
    PULSE_COUNTER_MODULUS,
    RTC_MODULUS,
    TIO10,
    check_channel,
    check_period,
    check_port,
    source_hz,
)

__all__ = ["SimDataConcentrator", "SimTIO10"]

_COUNTER_MASK = (1 << COUNTER_BITS) - 1
#: Where the RTC is in a TIO10's inputs (after the ten pulse counters).
_RTC = len(CHANNELS)
#: Where the ADC codes begin in a dataConcentrator's register file.
_ADC_BASE = len(COUNTER_ADDRESSES)


class SimTIO10(TIO10):
    """A TIO10 whose registers are Python integers.

    ``writes`` counts register writes (periods, arm/disarm, ports): a test can
    check that a refused command touched nothing.
    """

    def __init__(self) -> None:
        self._source = dict.fromkeys(CHANNELS, 1)
        self._period = dict.fromkeys(CHANNELS, 0)
        self._armed = dict.fromkeys(CHANNELS, False)
        self._ports = dict.fromkeys(PIA_PORTS, 0)
        # the inputs as the kind declares them: the pulse counters of channels
        # 0-9, then the RTC (a process image's read phase copies the list)
        self._in = [0] * (len(CHANNELS) + 1)
        self.writes = 0

    # -- driver side ---------------------------------------------------------

    def select_source(self, channel: int, source: int) -> None:
        check_channel(channel)
        source_hz(source)
        self._source[channel] = source
        self.writes += 1

    def source(self, channel: int) -> int:
        return self._source[check_channel(channel, allow_rtc=True)]

    def load_period(self, channel: int, ticks: int) -> None:
        check_period(channel, ticks)
        self._period[channel] = ticks
        self.writes += 1

    def period(self, channel: int) -> int:
        return self._period[check_channel(channel, allow_rtc=True)]

    def arm(self, channel: int) -> None:
        check_channel(channel)
        if self._period[channel] < MIN_PERIOD:
            raise ValueError(f"channel {channel} has no period loaded; load it before arming")
        self._armed[channel] = True
        self.writes += 1

    def disarm(self, channel: int) -> None:
        check_channel(channel)
        self._armed[channel] = False
        self.writes += 1

    def armed(self, channel: int) -> bool:
        return self._armed[check_channel(channel, allow_rtc=True)]

    def pulses(self, channel: int) -> int:
        return self._in[check_channel(channel, allow_rtc=True)]

    def write_port(self, port: int, value: int) -> None:
        check_port(port)
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 0xFF:
            raise ValueError(f"PIA port value must be 0..255, got {value!r}")
        self._ports[port] = value
        self.writes += 1

    def read_port(self, port: int) -> int:
        return self._ports[check_port(port)]

    def rtc_ticks(self) -> int:
        return self._in[_RTC]

    def input_values(self) -> list[int]:
        """Every input at once, as the TIO10 kind declares them: the pulse
        counters of channels 0-9, then the RTC (a process image's read phase)."""
        return self._in[:]

    def register_file(self) -> list[int]:
        """Every register at once, for a board server: the RTC, PIA ports
        0-3, then per channel 0-9 the source, the period, armed (0/1) and
        the pulse counter (the order of the wire protocol's ``SNAP``)."""
        ports, src, per = self._ports, self._source, self._period
        armed, pulses = self._armed, self._in
        return [
            self._in[_RTC], *(ports[p] for p in PIA_PORTS),
            *(src[c] for c in CHANNELS), *(per[c] for c in CHANNELS),
            *(1 if armed[c] else 0 for c in CHANNELS), *(pulses[c] for c in CHANNELS),
        ]

    # -- plant side ----------------------------------------------------------

    def plant_channel(self, channel: int) -> tuple[int, bool]:
        """(period in 5 MHz ticks, armed) of a channel, for the physics."""
        return (
            self._period[channel] * 10 ** (self._source[channel] - 1),
            self._armed[channel],
        )

    def plant_add_pulses(self, channel: int, n: int) -> None:
        """Count ``n`` output pulses on ``channel`` (the counter wraps at 16 bits)."""
        self._in[channel] = (self._in[channel] + n) % PULSE_COUNTER_MODULUS

    def plant_set_time(self, now_ns: int) -> None:
        """Set the real-time clock from the loop time."""
        self._in[_RTC] = (now_ns * CLOCK_HZ // 1_000_000_000) % RTC_MODULUS


class SimDataConcentrator(DataConcentrator):
    """A dataConcentrator whose counters and ADCs are Python integers."""

    def __init__(self) -> None:
        # the register file as one list, in the kind's declared order: the
        # counters at 0..255, the ADCs after them (a process image copies it
        # every tick, in one slice)
        self._inputs: list[int] = [0] * (len(COUNTER_ADDRESSES) + len(ADC_CHANNELS))
        self.writes = 0

    # -- driver side ---------------------------------------------------------

    def read_counter(self, address: int) -> int:
        return self._inputs[check_counter_address(address)]

    def clear_counter(self, address: int) -> None:
        self._inputs[check_counter_address(address)] = 0
        self.writes += 1

    def read_adc(self, channel: int) -> int:
        return self._inputs[_ADC_BASE + check_adc_channel(channel)]

    def counter_values(self) -> list[int]:
        """Every counter, addresses 0..255 (for a board server)."""
        return self._inputs[:_ADC_BASE]

    def adc_codes(self) -> list[int]:
        """The latest conversion of every ADC channel, 0..15 (for a board server)."""
        return self._inputs[_ADC_BASE:]

    def input_values(self) -> list[int]:
        """Every input at once, as the dataConcentrator kind declares them: the
        counters, then the ADCs (a process image's read phase)."""
        return self._inputs[:]

    def extend_inputs(self, out: list[int]) -> None:
        """Append :meth:`input_values` to ``out`` (one copy)."""
        out += self._inputs

    # -- plant side ----------------------------------------------------------

    def plant_add_counts(self, address: int, n: int) -> None:
        """Count ``n`` encoder counts (signed) at ``address``; 24-bit wrap."""
        self._inputs[address] = (self._inputs[address] + n) & _COUNTER_MASK

    def plant_set_adc(self, channel: int, code: int) -> None:
        """Latch a conversion, clamped to the converter's 0..4095."""
        self._inputs[_ADC_BASE + channel] = \
            0 if code < 0 else (ADC_MAX if code > ADC_MAX else int(code))
