"""The gripper controller's view of the 8031's on-chip RAM (002, Appendix A).

The RAM image *is* the controller's state; this is how the controller reads
and writes it: little-endian words (signed where 002 treats them so), the
FLAGS and sensor bits, the speed bytes, the monitor's byte access with its
range checks, and the schedule variables (SYSCLKPD, MVJAWSPD, SENSORPD,
WTCHJWSPD) as the periods they make at the loop's tick (:class:`Schedule`).
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from pyrt.boards.i8031 import (
    COMMAND_CNT,
    DOJOG,
    DRVON,
    ENCODER_CNT,
    ERROR_CNT,
    FLAGS,
    JSPEED,
    LIMIT,
    MVJAWSPD,
    MXNJSPD,
    MXPJSPD,
    OLD_ENC,
    OTHER,
    RAM_SIZE,
    RATE,
    SENSORPD,
    STOPPED,
    SYSCLKPD,
    WTCHJWSPD,
    RamWords,
)
from pyrt.errors import CommandError
from pyrt.tasks.jawmove import JOGSTALL

__all__ = [
    "CHECK_NS",
    "DEFAULT_SCHEDULE",
    "SCHEDULE_NAMES",
    "SCHEDULE_NS",
    "GripperRam",
    "Schedule",
]

# Appendix B schedule values, loaded into RAM at power-up.
DEFAULT_SYSCLKPD = 0x04
DEFAULT_MVJAWSPD = 0x0C
DEFAULT_SENSORPD = 0x0A
DEFAULT_WTCHJWSPD = 0x01
DEFAULT_SCHEDULE = {SYSCLKPD: DEFAULT_SYSCLKPD, MVJAWSPD: DEFAULT_MVJAWSPD,
                    SENSORPD: DEFAULT_SENSORPD, WTCHJWSPD: DEFAULT_WTCHJWSPD}

#: 002's routine periods at pyrt's 1 ms base tick (Appendix B: 04 checks x
#: 0C, 0A, 01), kept at power-up whatever ``--tick-us`` is (see
#: :meth:`GripperRam.power_up_schedule`).
CHECK_NS = 4_000_000
SCHEDULE_NS = {MVJAWSPD: 48_000_000, SENSORPD: 40_000_000, WTCHJWSPD: 4_000_000}
#: The schedule variables by RAM address, as the monitor names them.
SCHEDULE_NAMES = {SYSCLKPD: "SYSCLKPD", MVJAWSPD: "MVJAWSPD", SENSORPD: "SENSORPD",
                  WTCHJWSPD: "WTCHJWSPD"}

ENC16 = ENCODER_CNT // 2
MASK_STOPPED = 1 << STOPPED
MASK_DRVON = 1 << DRVON
MASK_DOJOG = 1 << DOJOG
MASK_JOGSTALL = 1 << JOGSTALL
MASK_LIMIT = 1 << LIMIT


@dataclass(frozen=True)
class Schedule:
    """The routines' periods as the RAM and the tick make them, in ns."""

    tick_ns: int
    sysclkpd: int
    mvjawspd: int
    sensorpd: int
    wtchjwspd: int

    @property
    def check_ns(self) -> int:
        """Between two checks of the ready queue."""
        return self.tick_ns * (self.sysclkpd or 256)

    @property
    def move_ns(self) -> int:
        """MVJAWS's period."""
        return self.check_ns * (self.mvjawspd or 256)

    @property
    def watch_ns(self) -> int:
        """WATCHJAW's period."""
        return self.check_ns * (self.wtchjwspd or 256)

    @property
    def sensor_ns(self) -> int:
        """SENSORS's period."""
        return self.check_ns * (self.sensorpd or 256)

    def with_value(self, addr: int, value: int) -> Schedule:
        """The schedule with ``value`` stored at schedule variable ``addr``."""
        v = {SYSCLKPD: self.sysclkpd, MVJAWSPD: self.mvjawspd, SENSORPD: self.sensorpd,
             WTCHJWSPD: self.wtchjwspd}
        if addr in v:
            v[addr] = value
        return Schedule(self.tick_ns, v[SYSCLKPD], v[MVJAWSPD], v[SENSORPD], v[WTCHJWSPD])

    def text(self) -> str:
        """The four variables as the monitor shows them."""
        return (f"SYSCLKPD {self.sysclkpd:02X} MVJAWSPD {self.mvjawspd:02X} "
                f"SENSORPD {self.sensorpd:02X} WTCHJWSPD {self.wtchjwspd:02X}, "
                f"tick {self.tick_ns / 1e3:g} µs")


class GripperRam(RamWords):
    """The controller's access to the 8031's on-chip RAM ``ram`` (see the
    module text).  ``tick_ns`` gives the loop's tick (1 ms before the
    controller is attached to one)."""

    def __init__(self, ram: bytearray, tick_ns: Callable[[], int]):
        self.ram = ram
        self._tick_ns = tick_ns
        #: The RAM's even-addressed words, for the encoder interrupt handlers.
        self.w16: Any = memoryview(ram).cast("H") if sys.byteorder == "little" else _Words(ram)

    def zero_counts(self) -> None:
        """The encoder variables at zero: ENCODER_CNT, COMMAND_CNT, OLD_ENC,
        RATE 0000 and ERROR_CNT 0080 (no error, excess-128)."""
        for addr in (ENCODER_CNT, COMMAND_CNT, OLD_ENC, RATE):
            self.set_word(addr, 0)
        self.set_word(ERROR_CNT, 0x0080)

    def set_speed(self, speed: int) -> None:
        """JSPEED and the drive bytes it makes (MXPJSPD, MXNJSPD)."""
        ram = self.ram
        ram[JSPEED] = speed
        ram[MXPJSPD] = 0x80 + speed
        ram[MXNJSPD] = 0x80 - speed

    # -- bits ----------------------------------------------------------------------

    @property
    def moving(self) -> bool:
        """The drive or the jog bit is set."""
        return bool(self.ram[FLAGS] & (MASK_DRVON | MASK_DOJOG))

    @property
    def stopped(self) -> bool:
        """WATCHJAW's stopped bit."""
        return bool(self.ram[FLAGS] & MASK_STOPPED)

    @property
    def at_limit(self) -> bool:
        """The limit sensor is on (its bit is 0)."""
        return not self.ram[OTHER] & MASK_LIMIT

    def clear_drive(self) -> bool:
        """Clear the drive and jog bits; return whether either was set."""
        ram = self.ram
        was = bool(ram[FLAGS] & (MASK_DRVON | MASK_DOJOG))
        ram[FLAGS] &= ~(MASK_DRVON | MASK_DOJOG) & 0xFF
        return was

    # -- the monitor's bytes -------------------------------------------------------

    def peek(self, addr: int) -> int:
        """The RAM byte at ``addr`` (00-7F); CommandError outside the RAM."""
        if not 0 <= addr < RAM_SIZE:
            raise CommandError(f"address {addr:X} is outside the on-chip RAM (00-7F)")
        return self.ram[addr]

    def poke(self, addr: int, value: int) -> int:
        """Store ``value`` at ``addr``; return what is stored there."""
        if not 0 <= addr < RAM_SIZE:
            raise CommandError(f"address {addr:X} is outside the on-chip RAM (00-7F)")
        if not 0 <= value <= 0xFF:
            raise CommandError(f"value {value:X} is not a byte (00-FF)")
        self.ram[addr] = value
        return self.ram[addr]

    # -- the schedule --------------------------------------------------------------

    def schedule(self) -> Schedule:
        """The routines' periods as the RAM and the loop's tick make them now."""
        ram = self.ram
        return Schedule(self._tick_ns(), ram[SYSCLKPD], ram[MVJAWSPD], ram[SENSORPD],
                        ram[WTCHJWSPD])

    def power_up_schedule(self) -> dict[int, int]:
        """The schedule values power-up loads: Appendix B's (04, 0C, 0A, 01) at
        a 1 ms tick.  At another ``--tick-us`` the 8031's timer would be
        reprogrammed in EPROM; pyrt instead scales the values so that every
        routine keeps 002's period as nearly as a byte allows (a 50 µs tick
        with SYSCLKPD 04 would run WATCHJAW every 200 µs, less than one
        encoder count at full speed: the stopped bit would be on while the
        jaws move, and I would fail as 002 describes)."""
        tick = self._tick_ns()
        if tick == 1_000_000:
            return dict(DEFAULT_SCHEDULE)
        div = min(0xFF, max(1, round(CHECK_NS / tick)))
        check = tick * div
        out = {SYSCLKPD: div}
        for addr, period in SCHEDULE_NS.items():
            out[addr] = min(0xFF, max(1, round(period / check)))
        return out


class _Words:  # pragma: no cover - big-endian hosts only
    """The RAM as little-endian words (index = address / 2) on a big-endian host."""

    def __init__(self, ram: bytearray):
        self._ram = ram

    def __getitem__(self, i: int) -> int:
        return self._ram[2 * i] | (self._ram[2 * i + 1] << 8)

    def __setitem__(self, i: int, v: int) -> None:
        self._ram[2 * i] = v & 0xFF
        self._ram[2 * i + 1] = (v >> 8) & 0xFF
