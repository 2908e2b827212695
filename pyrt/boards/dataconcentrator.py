"""The dataConcentrator card: encoder counters and loadcell ADCs (000, sections 9-11).

:data:`DATACONCENTRATOR` declares its registers: up/down counter channels
addressed by the encoder board address on the chain (0..255; Table 7's
``ADDRESS: 168``), 12-bit ADC channels (0..15; Table 9's ``CHANNEL: 3``)
and a clear strobe per counter.  :class:`DataConcentrator` is the card
over any register access of that kind; :class:`DigitalChannel` (a counter
read as a signed count) and :class:`AnalogChannel` (an ADC read as a code)
know what the bits are, not what is connected to them.
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
    "ADC_BITS",
    "ADC_CHANNELS",
    "ADC_MAX",
    "COUNTER_ADDRESSES",
    "COUNTER_BITS",
    "DATACONCENTRATOR",
    "AnalogChannel",
    "DataConcentrator",
    "DigitalChannel",
]

#: Up/down counters are 24 bits, two's complement when read as signed.
COUNTER_BITS = 24
COUNTER_ADDRESSES = range(256)
ADC_BITS = 12
ADC_MAX = (1 << ADC_BITS) - 1
ADC_CHANNELS = range(16)



class DataConcentrator:
    """One dataConcentrator card over ``registers`` (any register access of
    :data:`DATACONCENTRATOR`; None: a register file of its own, in this
    process).  An address or channel the declarations refuse is a ValueError."""

    def __init__(self, registers: Registers | None = None):
        self.registers: Registers = registers if registers is not None \
            else RegisterBoard(DATACONCENTRATOR)
        self.url = getattr(self.registers, "url", "")
        r = self.registers
        # every register bound once, by address (channel)
        self._cnt = [bound_reader(r, "cnt", a) for a in COUNTER_ADDRESSES]
        self._adc = [bound_reader(r, "adc", c) for c in ADC_CHANNELS]
        self._clr = [bound_writer(r, "clr", a) for a in COUNTER_ADDRESSES]
        # a read later in the tick sees the counter cleared (a process image's copy)
        self._cached = getattr(r, "set_cached", None)

    # -- readers bound once (a device's tick path): checked here, when bound, as
    # the read they stand for; each call then reads the register with no check

    def counter_reader(self, address: int) -> Callable[[], int]:
        """The raw counter at ``address`` (as :meth:`read_counter`), bound once."""
        return self._cnt[_CNT.check_index(address)]

    def adc_reader(self, channel: int) -> Callable[[], int]:
        """ADC ``channel``'s latest conversion (as :meth:`read_adc`), bound once."""
        return self._adc[_ADC.check_index(channel)]

    def read_counter(self, address: int) -> int:
        """The raw 24-bit counter at ``address`` (0..2**24-1)."""
        return self._cnt[_CNT.check_index(address)]()

    def clear_counter(self, address: int) -> None:
        """Clear the counter at ``address`` to zero."""
        self._clr[_CNT.check_index(address)](1)
        if self._cached is not None:
            self._cached("cnt", 0, address)

    def read_adc(self, channel: int) -> int:
        """The latest 12-bit conversion of ADC ``channel`` (0..4095)."""
        return self._adc[_ADC.check_index(channel)]()

    def __repr__(self) -> str:
        return f"<DataConcentrator over {self.registers!r}>"



DATACONCENTRATOR = BoardKind("dataconcentrator", (
    Register("cnt", count=len(COUNTER_ADDRESSES), width=COUNTER_BITS, units="counts",
             doc="up/down counter at each address on the chain (24-bit, wraps)"),
    Register("adc", count=len(ADC_CHANNELS), width=ADC_BITS, units="ADC codes",
             doc="latest 12-bit conversion of each ADC channel"),
    Register("clr", count=len(COUNTER_ADDRESSES), width=1, direction=OUTPUT, readback=False,
             clears="cnt", doc="write 1 to clear the counter at that address (a strobe)"),
), doc="the dataConcentrator card: encoder counters and loadcell ADCs (000, 9-11)",
    board=DataConcentrator)

_CNT, _ADC = DATACONCENTRATOR.register("cnt"), DATACONCENTRATOR.register("adc")


_COUNTER_MASK = (1 << COUNTER_BITS) - 1
_COUNTER_HALF = 1 << (COUNTER_BITS - 1)
_COUNTER_WRAP = 1 << COUNTER_BITS


class DigitalChannel:
    """One counter channel, read as a signed count.  ``raw``: the counter's
    register read, bound once (the address checked when the channel is made)."""

    def __init__(self, board: DataConcentrator, address: int):
        self.board = board
        self.address = _CNT.check_index(address)
        self.raw: Callable[[], int] = board.counter_reader(self.address)

    def count(self) -> int:
        """The counter as a signed 24-bit two's-complement number."""
        raw = self.raw() & _COUNTER_MASK
        if raw >= _COUNTER_HALF:
            raw -= _COUNTER_WRAP
        return raw

    def reset(self) -> None:
        """Clear the counter."""
        self.board.clear_counter(self.address)


class AnalogChannel:
    """One ADC channel, read as a code 0..4095.  ``raw``: the ADC's register
    read, bound once (the channel checked when the channel is made), the same
    value as :meth:`code`."""

    def __init__(self, board: DataConcentrator, channel: int):
        self.board = board
        self.channel = _ADC.check_index(channel)
        self.raw: Callable[[], int] = board.adc_reader(self.channel)

    def code(self) -> int:
        """The latest conversion."""
        return self.raw()
