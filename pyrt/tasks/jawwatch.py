"""WATCHJAW (002, routine at 0541): the jaw watcher.

Each run: RATE := ENCODER_CNT - OLD_ENC (counts per check); the stopped bit
(2C.STOPPED) set when RATE is zero, cleared otherwise; ERROR_CNT :=
ENCODER_CNT - COMMAND_CNT in excess-128; OLD_ENC := ENCODER_CNT.  Words are
little-endian RAM words, arithmetic modulo 10000 hex.
"""

from __future__ import annotations

from pyrt.boards.i8031 import COMMAND_CNT, ENCODER_CNT, ERROR_CNT, FLAGS, OLD_ENC, RATE, STOPPED
from pyrt.tasks._i8031 import Controller8031

__all__ = ["ADDRESS", "NAME", "watchjaw"]

#: Appendix B: the routine's EPROM address, and its name on the ready queue.
ADDRESS = 0x0541
NAME = "WATCHJAW"

_MASK_STOPPED = 1 << STOPPED


def watchjaw(ctl: Controller8031) -> None:
    """WATCHJAW (0541): stopped bit, RATE, ERROR_CNT (excess-128), OLD_ENC."""
    ram = ctl.ram
    enc = ram[ENCODER_CNT] | (ram[ENCODER_CNT + 1] << 8)
    rate = (enc - (ram[OLD_ENC] | (ram[OLD_ENC + 1] << 8))) & 0xFFFF
    ram[RATE] = rate & 0xFF
    ram[RATE + 1] = rate >> 8
    if rate:
        ram[FLAGS] &= ~_MASK_STOPPED & 0xFF
    else:
        ram[FLAGS] |= _MASK_STOPPED
    err = (enc - (ram[COMMAND_CNT] | (ram[COMMAND_CNT + 1] << 8)) + 0x80) & 0xFFFF
    ram[ERROR_CNT] = err & 0xFF
    ram[ERROR_CNT + 1] = err >> 8
    ram[OLD_ENC] = enc & 0xFF
    ram[OLD_ENC + 1] = enc >> 8
