"""The built-in boards as declared kinds: the gripper cage, the TIO10, the dataConcentrator.

Each declares its registers (:mod:`pyrt.boards.registers`), so ``sim:``,
``pyrt board-sim``, ``tcp://`` and ``modbus://`` move them as they move any
kind's, and each gives the control code a typed view over any register
access of its kind (:class:`~pyrt.boards.gripper.GripperBoard`,
:class:`~pyrt.boards.tio10.TIO10`,
:class:`~pyrt.boards.dataconcentrator.DataConcentrator`), the same in
process, over a process image or over a link; the simulation behind the
registers is :mod:`pyrt.sim`'s.  The typed actions are register writes:
``arm(ch)`` writes ``armed[ch] = 1``, ``disarm(ch)`` ``armed[ch] = 0``,
``clear_counter(a)`` the write-only strobe ``clr[a] = 1`` (which clears
``cnt[a]``).

=================  ==================================================================
kind               registers (inputs, then outputs; ``off``: what the watchdog leaves)
=================  ==================================================================
``gripper-cage``   in: ``pa pb pc`` (8155 ports, 8 bits, power-up FF), ``up down``
                   (encoder pulses raised on external interrupt 0/1, 32 bits); out:
                   ``cmd``, ``led_lo``, ``led_hi`` (power-up FF), ``dac`` (off 80,
                   the null current)
``tio10``          in: ``pulses[10]`` (16 bits), ``rtc`` (32 bits); out: ``src[10]``
                   (F1..F5, power-up F1), ``per[10]`` (16 bits), ``armed[10]`` (off 0 on the motor
                   channels), ``port[4]`` (8 bits; port 1, the all-windings-off bits,
                   off FF)
``dataconcentrator``  in: ``cnt[256]`` (24 bits), ``adc[16]`` (12 bits); out: ``clr[256]``
                   (write-only strobe: 1 clears the counter)
=================  ==================================================================
"""

from __future__ import annotations

from pyrt.boards.dataconcentrator import DATACONCENTRATOR
from pyrt.boards.gripper import GRIPPER_CAGE
from pyrt.boards.tio10 import TIO10_KIND

__all__ = ["DATACONCENTRATOR", "GRIPPER_CAGE", "TIO10_KIND"]
