"""The gripper controller cage's I/O, register by register, and its simulated back end.

002 places the 8155's ports and the DAC in the 8031's external data space
but gives no addresses; pyrt's map (a real-board back end must match it or
change these constants, nothing above the board reads them as numbers):

========  ==========  =====================================================
address   register    meaning
========  ==========  =====================================================
0100      8155 CMD    command/status register (init writes the port modes)
0101      8155 PA     input: proximity sensors, active low (RAM 2D layout)
0102      8155 PB     input: bit 0 crossfire, 1 overload, 2 limit, active
                      low (RAM 2E layout); bits 3-7 float high
0103      8155 PC     input: bit 0 jog OPEN, bit 1 jog CLOSE, active low
0200      LED LO      front-panel LEDs of the 2D bits (LED on iff bit 0)
0201      LED HI      front-panel LEDs of the 2E bits (LED on iff bit 0)
8000      DAC         drive current, excess-128, latched (80 = null)
========  ==========  =====================================================

The encoder is not a register: each count raises external interrupt 0
(worm turning towards larger counts, jaws opening) or 1 (smaller counts).

Bit meanings follow Appendix A (2D.0 left jaw +Ya ... 2D.7 right jaw -X;
2E.0 crossfire, 2E.1 overload, 2E.2 limit).  002's LED test table swaps
the jaws of the 2D bits (it calls 2D.7 "-X, left jaw") and gives FDFE for
overload where FDFF is meant; the memory map is taken as the reference.
"""

from __future__ import annotations

from pyrt.boards.i8031 import I8031, VECTOR_EXT0, VECTOR_EXT1

__all__ = [
    "DAC",
    "DAC_NULL",
    "JOG_CLOSE",
    "JOG_OPEN",
    "LED_HI",
    "LED_LO",
    "P8155_CMD",
    "P8155_PA",
    "P8155_PB",
    "P8155_PC",
    "SimGripperBoard",
]

P8155_CMD = 0x0100
P8155_PA = 0x0101
P8155_PB = 0x0102
P8155_PC = 0x0103
LED_LO = 0x0200
LED_HI = 0x0201
DAC = 0x8000

#: Excess-128 null (quiescent) current.
DAC_NULL = 0x80
#: 8155 PC bits of the jog switch (active low).
JOG_OPEN = 0
JOG_CLOSE = 1


class SimGripperBoard:
    """The cage's registers with a simulated world on the wire side.

    The program reaches the registers through ``cpu.movx_read`` /
    ``cpu.movx_write``; the physics (:mod:`pyrt.sim.gripper`) reads the
    latched :attr:`dac`, sets the input levels (:attr:`pa`, :attr:`pb`,
    :attr:`pc`) and turns the encoder with :meth:`encoder`.
    """

    def __init__(self, cpu: I8031):
        self.cpu = cpu
        self._vectors = cpu.vectors
        #: Latched DAC byte: the motor is driven with it until it is overwritten.
        self.dac = DAC_NULL
        #: Input levels of the 8155 ports (1 = high = sensor off / switch open).
        self.pa = 0xFF
        self.pb = 0xFF
        self.pc = 0xFF
        #: 8155 command register (port modes) as last written.
        self.cmd = 0x00
        #: Front-panel LED latches (LED on iff its bit is 0); all off at power-up.
        self.led_lo = 0xFF
        self.led_hi = 0xFF
        #: Number of DAC writes (the physics may use it to see a fresh command).
        self.dac_writes = 0
        cpu.map_xdata(P8155_CMD, self._read_cmd, self._write_cmd)
        cpu.map_xdata(P8155_PA, lambda: self.pa)
        cpu.map_xdata(P8155_PB, lambda: self.pb | 0xF8)
        cpu.map_xdata(P8155_PC, lambda: self.pc)
        cpu.map_xdata(LED_LO, lambda: self.led_lo, self._write_led_lo)
        cpu.map_xdata(LED_HI, lambda: self.led_hi, self._write_led_hi)
        cpu.map_xdata(DAC, lambda: self.dac, self._write_dac)

    # -- program side (through MOVX) ---------------------------------------------

    def _read_cmd(self) -> int:
        return self.cmd

    def _write_cmd(self, value: int) -> None:
        self.cmd = value

    def _write_led_lo(self, value: int) -> None:
        self.led_lo = value

    def _write_led_hi(self, value: int) -> None:
        self.led_hi = value

    def _write_dac(self, value: int) -> None:
        self.dac = value
        self.dac_writes += 1

    # -- wire side (the physics) -------------------------------------------------

    def encoder(self, counts: int) -> None:
        """The worm turned ``counts`` encoder steps: one interrupt per step."""
        if counts > 0:
            h = self._vectors.get(VECTOR_EXT0)
        elif counts < 0:
            h = self._vectors.get(VECTOR_EXT1)
            counts = -counts
        else:
            return
        if h is not None:
            h()
            while counts > 1:
                h()
                counts -= 1

    def set_jog(self, open_: bool, close: bool) -> None:
        """Jog switch position (both at once reads as both pins low)."""
        pc = self.pc | (1 << JOG_OPEN) | (1 << JOG_CLOSE)
        if open_:
            pc &= ~(1 << JOG_OPEN)
        if close:
            pc &= ~(1 << JOG_CLOSE)
        self.pc = pc & 0xFF

    @property
    def leds(self) -> int:
        """The LED latches as one word, 2E bits high, 2D bits low (0 = LED on)."""
        return (self.led_hi << 8) | self.led_lo
