"""MVJAWS (002, routine at 04C2): the jaw movement routine.

Each run, in this order:

* a jog switch held (port C bit 0 open, bit 1 close; one, not both) and no
  foreground job (init, calibration) driving the motor: jog.  The target
  follows the jaws, the current is the speed limit in the jog's sense, and a
  jog held against a stop is cut off STOPCNT bumps after the stopped bit
  (2C.JOGSTALL: ignored until the switch is released);
* else, with the drive bit (2C.DRVON): current = minus the error WATCHJAW
  left in ERROR_CNT (46, excess-128: actual - target), clipped to
  MXNJSPD..MXPJSPD; STOPCNT bumps after the stopped bit the move ends
  (current nulled, drive bit cleared).  The routines share state only
  through RAM, as 002's do: when WATCHJAW runs much less often than MVJAWS
  the error is stale and the jaws oscillate about the target (002, "the
  value of the error ... is not accurate, which leads to oscillation");
* else, after a jog (2C.DOJOG): the current is nulled and the target is
  where the jaws are.
"""

from __future__ import annotations

from typing import Any

from pyrt.boards.gripper import DAC_NULL, P8155_PC
from pyrt.boards.i8031 import (
    COMMAND_CNT,
    DOJOG,
    DRVON,
    ENCODER_CNT,
    ERROR_CNT,
    FLAGS,
    MXNJSPD,
    MXPJSPD,
    STOPCNT,
    STOPPED,
)
from pyrt.native import excess128
from pyrt.tasks._i8031 import Controller8031

__all__ = ["ADDRESS", "BAND", "JOGSTALL", "NAME", "STOPBUMPS", "MoveSupervisor", "mvjaws"]

#: Appendix B: the routine's EPROM address, and its name on the ready queue.
ADDRESS = 0x04C2
NAME = "MVJAWS"

#: Bumps after the stopped bit before a commanded move ends.  002 gives no
#: number ("a positive value"); 4 MVJAWS periods are about 0.2 s at the
#: defaults: long enough to finish a move that stopped just short.
STOPBUMPS = 0x04
#: 2C.5 (unused in 002): a jog held against a stop was cut off; the jog
#: switch is ignored until it is released.  pyrt's addition, so that a held
#: switch cannot keep current on a stalled motor.
JOGSTALL = 5

#: Errors within this many counts of the target are "at the target" for the
#: supervision: no half-cycle of an oscillation (the deadband and STOPCNT's
#: last bumps leave up to about 16).
BAND = 24

_MASK_STOPPED = 1 << STOPPED
_MASK_DRVON = 1 << DRVON
_MASK_DOJOG = 1 << DOJOG
_MASK_JOGSTALL = 1 << JOGSTALL


def _word(ram: bytearray, addr: int) -> int:
    return ram[addr] | (ram[addr + 1] << 8)


def _set_word(ram: bytearray, addr: int, value: int) -> None:
    ram[addr] = value & 0xFF
    ram[addr + 1] = (value >> 8) & 0xFF


class MoveSupervisor:
    """pyrt's supervision of a commanded move, kept outside the RAM (which
    the monitor can change).  The controller arms it when a move starts
    (:meth:`arm`); MVJAWS feeds it the error it drives with, at the cost of
    a few comparisons per run: the half-cycle peak of the error on each
    side of the target band (:data:`BAND`).  A sign change of the error
    calls :meth:`flip` (rare); the controller's watchdog calls
    :meth:`expired` when the settle deadline passes (every tick, whatever
    the schedule); both go back to the controller (``on_oscillation``,
    ``on_timeout``), which trips the robot.
    """

    __slots__ = ("active", "clock", "deadline_ns", "flips", "on_oscillation", "on_timeout",
                 "peak", "peaks", "side")

    def __init__(self, clock: Any, on_oscillation: Any, on_timeout: Any):
        #: Anything with ``now_ns`` (the loop).
        self.clock = clock
        self.on_oscillation = on_oscillation
        self.on_timeout = on_timeout
        self.active = False
        self.deadline_ns = 0
        self.side = 0
        self.peak = 0
        self.flips = 0
        self.peaks: list[int] = []

    def arm(self, deadline_ns: int) -> None:
        """A move starts (or its target changes): the settle deadline, no history."""
        self.active = True
        self.deadline_ns = deadline_ns
        self.side = 0
        self.peak = 0
        self.flips = 0
        self.peaks = []

    def disarm(self) -> None:
        """The move ended (settled, stopped, abandoned)."""
        self.active = False

    def flip(self, side: int, magnitude: int) -> None:
        """The error crossed the target band to ``side`` (+1 past it, -1 short
        of it); ``magnitude`` is its size there, the new half-cycle's first peak."""
        if self.side:
            self.flips += 1
            self.peaks.append(self.peak)
            peaks = self.peaks
            # three half-cycles, none smaller than 3/4 of the one before: no decay
            if len(peaks) >= 3 and all(
                    b * 4 >= a * 3 for a, b in zip(peaks[-3:], peaks[-2:], strict=False)):
                self.active = False
                self.on_oscillation(max(peaks[-3:]), self.flips)
                return
        self.side = side
        self.peak = magnitude

    def expired(self, error: int) -> None:
        """The settle deadline passed with the drive bit still on."""
        self.active = False
        self.on_timeout(error, max([self.peak, *self.peaks[-3:]]), self.flips)


def mvjaws(ctl: Controller8031) -> None:
    """MVJAWS (04C2): a jog first; else, with the drive bit, current =
    -ERROR_CNT (what WATCHJAW left) within the speed limits, ending STOPCNT
    bumps after the stopped bit; else null the current of a finished jog."""
    ram = ctl.ram
    flags = ram[FLAGS]
    pc = ctl.cpu.movx_read(P8155_PC)
    jog_open = not pc & 0x01
    jog_close = not pc & 0x02
    # A jog is ignored while init or the calibration drives the motor:
    # 002 keeps MVJAWS out of their way (drive bit clear); a jog would fight them.
    if jog_open != jog_close and ctl.job is None:
        _jog(ctl, flags, jog_open)
        return
    if flags & _MASK_JOGSTALL:
        flags &= ~_MASK_JOGSTALL & 0xFF  # switch released: jogging allowed again
        ram[FLAGS] = flags
    if flags & _MASK_DRVON:
        # the error as WATCHJAW left it (excess-128 word: actual - target)
        err = ((ram[ERROR_CNT] | (ram[ERROR_CNT + 1] << 8)) - 0x80) & 0xFFFF
        if err & 0x8000:
            err -= 0x10000
        byte = excess128(-err)
        if byte > ram[MXPJSPD]:
            byte = ram[MXPJSPD]
        elif byte < ram[MXNJSPD]:
            byte = ram[MXNJSPD]
        ctl.drive(byte)
        if flags & _MASK_STOPPED and _last_bump(ram):
            ctl.drive(DAC_NULL)
            ram[FLAGS] = flags & ~_MASK_DRVON & 0xFF
            ctl.move_ended("stopped")
            return
        sup = ctl.supervisor
        if sup.active:
            # pyrt's supervision: the half-cycle peaks of the error (its
            # settle deadline is the controller's watchdog's, every tick)
            if err > BAND:
                if sup.side != 1:
                    sup.flip(1, err)
                elif err > sup.peak:
                    sup.peak = err
            elif err < -BAND:
                if sup.side != -1:
                    sup.flip(-1, -err)
                elif -err > sup.peak:
                    sup.peak = -err
        return
    if flags & _MASK_DOJOG:
        ctl.drive(DAC_NULL)
        ram[FLAGS] = flags & ~_MASK_DOJOG & 0xFF
        _set_word(ram, COMMAND_CNT, _word(ram, ENCODER_CNT))
        ctl.last_stop = "jog ended"


def _jog(ctl: Controller8031, flags: int, open_: bool) -> None:
    ram = ctl.ram
    if flags & _MASK_JOGSTALL:
        return
    if not flags & _MASK_DOJOG:
        ram[STOPCNT] = STOPBUMPS
    if flags & _MASK_DRVON:
        ctl.move_ended("jog took over")
    flags = (flags | _MASK_DOJOG) & ~_MASK_DRVON & 0xFF
    # 002: during a jog the target follows the jaws, so that the jaw
    # movement routine does not drive them back to the old target.
    _set_word(ram, COMMAND_CNT, _word(ram, ENCODER_CNT))
    ctl.drive(ram[MXPJSPD] if open_ else ram[MXNJSPD])
    if flags & _MASK_STOPPED and _last_bump(ram):
        ctl.drive(DAC_NULL)
        flags = (flags | _MASK_JOGSTALL) & ~_MASK_DOJOG & 0xFF
        ctl.last_stop = "jog stalled (against a stop?): release the switch"
    ram[FLAGS] = flags


def _last_bump(ram: bytearray) -> bool:
    """WATCHJAW saw the jaws stopped: count STOPCNT down; True when it has run
    out (the drive then gives up), as both of 002's stop checks do."""
    n = ram[STOPCNT]
    if n > 1:
        ram[STOPCNT] = n - 1
        return False
    ram[STOPCNT] = 0
    return True
