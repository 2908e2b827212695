"""The gripper controller cage's I/O, register by register: its declaration and its view.

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

:data:`GRIPPER_CAGE` declares the registers (the encoder's as two pulse
counters, ``up`` and ``down``, counted by the world).  :class:`GripperBoard`
is the cage over any register access of that kind (the in-process
register file, a process image, a link), mapped into an 8031's external
data space, so the controller program reaches it only through
``movx_read``/``movx_write`` and its interrupt handlers: the registers by
address (:meth:`~GripperBoard.read`, :meth:`~GripperBoard.write`), and
:meth:`~GripperBoard.poll`, which raises the interrupts of the pulses
counted since the last poll.

Bit meanings follow Appendix A (2D.0 left jaw +Ya ... 2D.7 right jaw -X;
2E.0 crossfire, 2E.1 overload, 2E.2 limit).  002's LED test table swaps
the jaws of the 2D bits (it calls 2D.7 "-X, left jaw") and gives FDFE for
overload where FDFF is meant; the memory map is taken as the reference.
"""

from __future__ import annotations

from typing import Any

from pyrt.boards.i8031 import I8031, VECTOR_EXT0, VECTOR_EXT1
from pyrt.boards.registers import (
    INPUT,
    OUTPUT,
    BoardKind,
    Register,
    RegisterBoard,
    Registers,
    bound_reader,
    bound_writer,
)

__all__ = [
    "DAC",
    "DAC_NULL",
    "GRIPPER_CAGE",
    "INPUTS",
    "JOG_CLOSE",
    "JOG_OPEN",
    "LED_HI",
    "LED_LO",
    "P8155_CMD",
    "P8155_PA",
    "P8155_PB",
    "P8155_PC",
    "PULSE_MODULUS",
    "REGISTERS",
    "GripperBoard",
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
#: The pulse counts of :meth:`GripperBoard.pulse_counts` wrap at 32 bits.
PULSE_MODULUS = 1 << 32


class GripperBoard:
    """The cage over ``registers`` (any register access of :data:`GRIPPER_CAGE`;
    None: a register file of its own), mapped into ``cpu`` (a new 8031 if
    None).  ``url`` names the back end.  Register values are bytes; reading
    an input port gives its pin levels (1 = high).  A register or value the
    declarations refuse is a ValueError and writes nothing.
    """

    def __init__(self, registers: Registers | None = None, cpu: I8031 | None = None):
        self.registers: Registers = registers if registers is not None \
            else RegisterBoard(GRIPPER_CAGE)
        self.url = getattr(self.registers, "url", "")
        self.cpu = cpu if cpu is not None else I8031()
        r = self.registers
        # every register bound once: a MOVX is one call into the image
        self._readers = {a: bound_reader(r, reg.name) for a, reg in _BY_ADDRESS.items()}
        self._writers = {a: bound_writer(r, reg.name) for a, reg in _BY_ADDRESS.items()
                         if not reg.is_input}
        # the encoder's pulse counters: two bound reads where the view binds its
        # own readers (a process image: a read is one index into it), else one
        # snapshot of the board's inputs a poll (a read that goes to the board
        # each time costs more than the snapshot)
        self._read_up, self._read_down = bound_reader(r, "up"), bound_reader(r, "down")
        binds = callable(getattr(r, "reader", None))  # as bound_reader decides
        self._inputs = None if binds else r.snapshot
        # pulses counted before this controller came are not its own
        self._up, self._down = self._read_up(), self._read_down()
        self.map_xdata(self.cpu)

    def map_xdata(self, cpu: I8031) -> None:
        """Map every register into ``cpu``'s external data space (the input
        ports read only), so MOVX reaches this board."""
        for addr, read in self._readers.items():
            cpu.map_xdata(addr, read, self._writers.get(addr))

    @staticmethod
    def _register(addr: int) -> Register:
        reg = _BY_ADDRESS.get(addr) if type(addr) is int else None
        if reg is None:
            known = " ".join(f"{a:04X}" for a in REGISTERS)
            raise ValueError(f"no gripper cage register at {addr!r}; the registers are {known}")
        return reg

    def read(self, addr: int) -> int:
        """The register at ``addr`` (one of :data:`REGISTERS`), 00..FF."""
        self._register(addr)
        return self._readers[addr]()

    def write(self, addr: int, value: int) -> None:
        """Write ``value`` (00..FF) to the register at ``addr`` (not an input port)."""
        reg = self._register(addr)
        if reg.is_input:
            raise ValueError(f"{REGISTERS[addr]} ({addr:04X}) is an input port: "
                             "it cannot be written")
        self._writers[addr](reg.check_value(value))

    def pulse_counts(self) -> tuple[int, int]:
        """Encoder pulses raised so far on external interrupt 0 (up) and 1
        (down), each modulo :data:`PULSE_MODULUS`."""
        return self._up, self._down

    @property
    def dac(self) -> int:
        """The drive current byte as the controller last wrote it (excess-128)."""
        return self._readers[DAC]()

    @property
    def leds(self) -> int:
        """The LED latches as one word, 2E bits high, 2D bits low (0 = LED on)."""
        return self._readers[LED_HI]() << 8 | self._readers[LED_LO]()

    def poll(self, now_ns: int = 0) -> None:
        """Raise the 8031's external interrupts for the encoder pulses counted
        since the last poll (attach it after the read phase, before the ready
        queue); a vector with no handler ignores its pulses, as the chip does."""
        if self._inputs is None:
            up, down = self._read_up(), self._read_down()
        else:
            inputs = self._inputs()
            up, down = inputs[_UP], inputs[_DOWN]
        if up != self._up:
            n = (up - self._up) % PULSE_MODULUS
            self._up = up
            h = self.cpu.vectors.get(VECTOR_EXT0)
            if h is not None:
                h()
                while n > 1:
                    h()
                    n -= 1
        if down != self._down:
            n = (down - self._down) % PULSE_MODULUS
            self._down = down
            h = self.cpu.vectors.get(VECTOR_EXT1)
            if h is not None:
                h()
                while n > 1:
                    h()
                    n -= 1

    def close(self) -> None:
        """Nothing to release here (the back end releases the link)."""

    def __repr__(self) -> str:
        return f"<GripperBoard over {self.registers!r}>"


def _byte(name: str, direction: str, addr: int, doc: str, **kw: Any) -> Register:
    return Register(name, width=8, direction=direction, doc=doc, address=addr, **kw)


GRIPPER_CAGE = BoardKind("gripper-cage", (
    _byte("cmd", OUTPUT, P8155_CMD, "8155 command/status register (port modes)"),
    _byte("pa", INPUT, P8155_PA, "8155 PA: proximity sensors, active low", power_up=0xFF),
    _byte("pb", INPUT, P8155_PB,
          "8155 PB: bit 0 crossfire, 1 overload, 2 limit, active low; 3-7 high", power_up=0xFF),
    _byte("pc", INPUT, P8155_PC, "8155 PC: bit 0 jog OPEN, bit 1 jog CLOSE, active low",
          power_up=0xFF),
    _byte("led_lo", OUTPUT, LED_LO, "front-panel LEDs of the 2D bits (on iff bit 0)",
          power_up=0xFF),
    _byte("led_hi", OUTPUT, LED_HI, "front-panel LEDs of the 2E bits (on iff bit 0)",
          power_up=0xFF),
    _byte("dac", OUTPUT, DAC, "drive current, excess-128, latched", off=DAC_NULL,
          units="excess-128"),
    Register("up", width=32, doc="encoder pulses raised on external interrupt 0 (opening)",
             units="counts"),
    Register("down", width=32, doc="encoder pulses raised on external interrupt 1 (closing)",
             units="counts"),
), doc="the 002 gripper controller cage: 8155 ports, LEDs, DAC, encoder interrupts",
    options=frozenset({"cpu"}), board=GripperBoard)

_BY_ADDRESS = {r.address: r for r in GRIPPER_CAGE.registers if r.address is not None}
#: Every register of the cage: address -> name, in address order.
REGISTERS: dict[int, str] = {
    P8155_CMD: "8155 CMD", P8155_PA: "8155 PA", P8155_PB: "8155 PB", P8155_PC: "8155 PC",
    LED_LO: "LED LO", LED_HI: "LED HI", DAC: "DAC"}
#: The input ports: read only (a write to them is ignored by the 8155).
INPUTS = frozenset(r.address for r in GRIPPER_CAGE.inputs() if r.address is not None)
_NAMES = [r.name for r in GRIPPER_CAGE.inputs()]
_UP, _DOWN = _NAMES.index("up"), _NAMES.index("down")
