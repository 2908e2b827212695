"""The rope-length shaft encoder (000, section 9, Tables 7 and 8).

``length = ZEROLENGTH + SLOPE * count``: the total unstretched rope length,
dead length included.  The counter is reset when the Encoder is built (the
document's constructor does so), which is why the database keeps the
*current* length as the next ZEROLENGTH: :meth:`Encoder.poll` offers it to
a write-back callback once a second while the length changes.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING

from pyrt.boards.dataconcentrator import COUNTER_BITS, DataConcentrator, DigitalChannel
from pyrt.component import Arg, Component, Limits, Signal, command
from pyrt.devices._args import parse_number
from pyrt.errors import CommandError, ConfigError

if TYPE_CHECKING:
    from pyrt.db import EncoderRecord

__all__ = ["ZEROLENGTH_WRITE_PERIOD", "Encoder"]

_COUNTER_MASK = (1 << COUNTER_BITS) - 1
_COUNTER_HALF = 1 << (COUNTER_BITS - 1)
_COUNTER_WRAP = 1 << COUNTER_BITS

#: 000, section 9: ZEROLENGTH is updated once per second while changing.
ZEROLENGTH_WRITE_PERIOD = 1.0


class Encoder(Component):
    """One encoder (see the module text).  ``slope``: cm per count."""

    def __init__(
        self,
        name: str,
        channel: DigitalChannel,
        slope: float,
        zero_length: float,
        *,
        write_back: Callable[[float], None] | None = None,
    ):
        if not (isinstance(slope, (int, float)) and math.isfinite(slope) and slope != 0):
            raise ConfigError(f"encoder {name}: SLOPE must be a non-zero number, got {slope!r}")
        if not (isinstance(zero_length, (int, float)) and math.isfinite(zero_length)):
            raise ConfigError(f"encoder {name}: ZEROLENGTH must be a number, got {zero_length!r}")
        self.name = name
        self.channel = channel
        self._raw = channel.raw  # the counter's register, bound once
        self.slope = float(slope)
        self.zero_length = float(zero_length)
        self.write_back = write_back
        self.looping = False
        #: The range of the total rope length (cm) ``setZeroLength`` may give
        #: (set from the rope's physical range by its Axis); None: >= 0 only.
        self.length_range: tuple[float, float] | None = None
        self._written = self.zero_length
        self._last_write: float | None = None
        channel.reset()

    @classmethod
    def from_record(cls, record: EncoderRecord, board: DataConcentrator, name: str | None = None,
                    **kw) -> Encoder:
        """An Encoder from a :class:`pyrt.db.EncoderRecord`."""
        return cls(name or record.name, DigitalChannel(board, record.address), record.slope,
                   record.zerolength, **kw)

    def count(self) -> int:
        return self.channel.count()

    def length(self) -> float:
        """Total unstretched rope length (cm), dead length included."""
        raw = self._raw() & _COUNTER_MASK  # (the channel's count(), in line: the tick's path)
        if raw >= _COUNTER_HALF:
            raw -= _COUNTER_WRAP
        return self.zero_length + self.slope * raw

    # -- commands (Table 8) ------------------------------------------------------

    def signals(self) -> list[Signal]:
        r = self.length_range
        return [Signal("length", "cm", self.length, "total unstretched rope length",
                       limits=None if r is None else Limits(r[0], r[1]))]

    @command(name="reset", reply=lambda _r: "reset")
    def reset(self) -> None:
        """reset: clear the counter; the length then reads ZEROLENGTH."""
        self.check_free("reset")
        self.channel.reset()

    @command(name="read", reads_only=True, reply=lambda v: f"{v:.3f} cm")
    def read(self) -> float:
        """read: read and display the length (cm)."""
        return self.length()

    # Not read-only: it turns on a line at every poll on the operator's console
    # (the asker never sees them), a flood that only the operator may start.
    @command(name="readloop", reply=lambda _r: "readloop")
    def readloop(self) -> None:
        """readloop: enter the read/display loop (the length at every poll)."""
        self.looping = True

    @command(name="stoploop", reads_only=True, reply=lambda _r: "stoploop")
    def stoploop(self) -> None:
        """stoploop: quit the read/display loop."""
        self.looping = False

    @property
    def zero_length_range(self) -> tuple[float, float | None]:
        """The ZEROLENGTH values that put the present length inside the rope's range."""
        r = self.length_range
        if r is None:
            return (0.0, None)
        here = self.slope * self.channel.count()
        return (round(max(0.0, r[0] - here), 3), round(r[1] - here, 3))

    @command(Arg("LEN", str, lo=0.0, units="cm", bounds="zero_length_range",
                 what="the rope's length range, dead length included"),
             name="setZeroLength", reply=lambda v: f"zero length {v:.3f} cm")
    def setZeroLength(self, length: float | str) -> float:
        """setZeroLength LEN: set the length (cm) the counter reads at zero."""
        self.check_free("setZeroLength")
        v = parse_number(length, f"{self.name} setZeroLength", "length in cm")
        lo, hi = self.zero_length_range
        if v < lo or (hi is not None and v > hi):
            span = f"{lo:g}..{hi:g}" if hi is not None else f">= {lo:g}"
            raise CommandError(f"{self.name} setZeroLength: LEN {v:g} cm is out of range: "
                               f"{span} cm (the rope's length range, dead length included); "
                               "nothing changed")
        self.zero_length = v
        return v

    set_zero_length = setZeroLength

    # -- polling -----------------------------------------------------------------

    def poll(self, now_s: float, length: float | None = None) -> None:
        """Read loop output; ZEROLENGTH write-back once a second while changing.
        ``length``: :meth:`length` as read in this tick already (its axis's poll),
        or None: read here."""
        if self.looping:  # the read/display loop: asynchronous output
            self.say(f"{self.name}: {self.read():.3f} cm")
        if self.write_back is None:
            return
        if self._last_write is not None and now_s - self._last_write < ZEROLENGTH_WRITE_PERIOD:
            return
        v = self.length() if length is None else length
        if v != self._written:
            self.write_back(v)
            self._written = v
            self._last_write = now_s

