"""The dataConcentrator card: encoder counters and loadcell ADCs (000, sections 9-11).

Level 1 is :class:`DataConcentrator`, the card's register interface: up/down
counter channels addressed by the encoder board address on the chain (0..255;
Table 7's ``ADDRESS: 168``) and 12-bit ADC channels (0..15; Table 9's
``CHANNEL: 3``).  Level 2 are :class:`DigitalChannel` (a counter read as a
signed count) and :class:`AnalogChannel` (an ADC read as a code): they know
what the bits are, not what is connected to them.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

__all__ = [
    "ADC_BITS",
    "ADC_CHANNELS",
    "ADC_MAX",
    "COUNTER_ADDRESSES",
    "COUNTER_BITS",
    "AnalogChannel",
    "DataConcentrator",
    "DigitalChannel",
    "check_adc_channel",
    "check_counter_address",
]

#: Up/down counters are 24 bits, two's complement when read as signed.
COUNTER_BITS = 24
COUNTER_ADDRESSES = range(256)
ADC_BITS = 12
ADC_MAX = (1 << ADC_BITS) - 1
ADC_CHANNELS = range(16)


def check_counter_address(address: int) -> int:
    """Return ``address`` if it is a counter address on the chain (0..255)."""
    if type(address) is int and 0 <= address <= 255:
        return address
    if (
        isinstance(address, bool)
        or not isinstance(address, int)
        or address not in COUNTER_ADDRESSES
    ):
        raise ValueError(f"dataConcentrator counter address must be 0..255, got {address!r}")
    return address


def check_adc_channel(channel: int) -> int:
    """Return ``channel`` if it is an ADC channel (0..15)."""
    if type(channel) is int and 0 <= channel <= 15:
        return channel
    if isinstance(channel, bool) or not isinstance(channel, int) or channel not in ADC_CHANNELS:
        raise ValueError(f"dataConcentrator ADC channel must be 0..15, got {channel!r}")
    return channel


class DataConcentrator(ABC):
    """Register interface of one dataConcentrator card."""

    @abstractmethod
    def read_counter(self, address: int) -> int:
        """The raw 24-bit counter at ``address`` (0..2**24-1)."""

    @abstractmethod
    def clear_counter(self, address: int) -> None:
        """Clear the counter at ``address`` to zero."""

    @abstractmethod
    def read_adc(self, channel: int) -> int:
        """The latest 12-bit conversion of ADC ``channel`` (0..4095)."""


class DigitalChannel:
    """Level 2: one counter channel, read as a signed count."""

    def __init__(self, board: DataConcentrator, address: int):
        self.board = board
        self.address = check_counter_address(address)

    def count(self) -> int:
        """The counter as a signed 24-bit two's-complement number."""
        raw = self.board.read_counter(self.address) & ((1 << COUNTER_BITS) - 1)
        if raw >= 1 << (COUNTER_BITS - 1):
            raw -= 1 << COUNTER_BITS
        return raw

    def reset(self) -> None:
        """Clear the counter."""
        self.board.clear_counter(self.address)


class AnalogChannel:
    """Level 2: one ADC channel, read as a code 0..4095."""

    def __init__(self, board: DataConcentrator, channel: int):
        self.board = board
        self.channel = check_adc_channel(channel)

    def code(self) -> int:
        """The latest conversion."""
        return self.board.read_adc(self.channel)
