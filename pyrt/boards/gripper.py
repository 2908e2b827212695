"""The gripper controller cage's I/O, register by register: its interface and simulated back end.

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

:class:`GripperBoard` is the interface every back end implements: the
registers by address (:meth:`~GripperBoard.read`, :meth:`~GripperBoard.write`),
the number of pulses raised on each interrupt line so far
(:meth:`~GripperBoard.pulse_counts`), and :meth:`~GripperBoard.poll`, which
delivers the pulses that arrived since the last tick to the 8031's vectors
(an in-process board raises them as they happen; a remote one, such as
:class:`pyrt.boards.tcp.TcpGripperBoard`, counts them on the far side).  A
back end maps itself into the 8031's external data space, so the
controller program reaches it only through ``movx_read``/``movx_write`` and
its interrupt handlers, whichever back end it is.

Bit meanings follow Appendix A (2D.0 left jaw +Ya ... 2D.7 right jaw -X;
2E.0 crossfire, 2E.1 overload, 2E.2 limit).  002's LED test table swaps
the jaws of the 2D bits (it calls 2D.7 "-X, left jaw") and gives FDFE for
overload where FDFF is meant; the memory map is taken as the reference.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from functools import partial

from pyrt.boards.i8031 import I8031, VECTOR_EXT0, VECTOR_EXT1

__all__ = [
    "DAC",
    "DAC_NULL",
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
    "SimGripperBoard",
    "check_byte",
    "check_register",
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

#: Every register of the cage: address -> name, in address order.
REGISTERS: dict[int, str] = {
    P8155_CMD: "8155 CMD",
    P8155_PA: "8155 PA",
    P8155_PB: "8155 PB",
    P8155_PC: "8155 PC",
    LED_LO: "LED LO",
    LED_HI: "LED HI",
    DAC: "DAC",
}
#: The input ports: read only (a write to them is ignored by the 8155).
INPUTS = frozenset((P8155_PA, P8155_PB, P8155_PC))
#: The pulse counts of :meth:`GripperBoard.pulse_counts` wrap at 32 bits.
PULSE_MODULUS = 1 << 32


def check_register(addr: int, *, write: bool = False) -> int:
    """Return ``addr`` if it is a cage register (and writable, with ``write``)."""
    if isinstance(addr, bool) or not isinstance(addr, int) or addr not in REGISTERS:
        known = " ".join(f"{a:04X}" for a in REGISTERS)
        raise ValueError(f"no gripper cage register at {addr!r}; the registers are {known}")
    if write and addr in INPUTS:
        raise ValueError(f"{REGISTERS[addr]} ({addr:04X}) is an input port: it cannot be written")
    return addr


def check_byte(value: int) -> int:
    """Return ``value`` if it is a register byte (00..FF)."""
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 0xFF:
        raise ValueError(f"register value must be 00..FF, got {value!r}")
    return value


class GripperBoard(ABC):
    """Register interface of the gripper cage (see the module text).

    ``url`` names the back end (``sim:`` in process).  Register values are
    bytes; reading an input port gives its pin levels (1 = high).
    """

    url: str = "sim:"

    @abstractmethod
    def read(self, addr: int) -> int:
        """The register at ``addr`` (one of :data:`REGISTERS`), 00..FF."""

    @abstractmethod
    def write(self, addr: int, value: int) -> None:
        """Write ``value`` (00..FF) to the register at ``addr`` (not an input port)."""

    @abstractmethod
    def pulse_counts(self) -> tuple[int, int]:
        """Encoder pulses raised so far on external interrupt 0 (up) and 1
        (down), each modulo :data:`PULSE_MODULUS`."""

    def poll(self, now_ns: int) -> None:  # noqa: B027 - a default that does nothing
        """Deliver the encoder pulses that arrived since the last poll to the
        8031's interrupt vectors.  Attach it to the loop before the ready queue.

        An in-process board raises each interrupt as the encoder turns, so
        there is nothing to do here; a remote board overrides this.
        """

    def close(self) -> None:  # noqa: B027 - a default that does nothing
        """Release the back end (a link, a device); the registers are no longer reachable."""

    def map_xdata(self, cpu: I8031) -> None:
        """Map every register into ``cpu``'s external data space (the
        input ports read only), so MOVX reaches this board."""
        for addr in REGISTERS:
            cpu.map_xdata(addr, partial(self.read, addr),
                          None if addr in INPUTS else partial(self.write, addr))

    @staticmethod
    def deliver(cpu: I8031, up: int, down: int) -> None:
        """Raise external interrupt 0 ``up`` times and 1 ``down`` times
        (a vector with no handler ignores its pulses, as the chip does)."""
        for vector, n in ((VECTOR_EXT0, up), (VECTOR_EXT1, down)):
            h = cpu.vectors.get(vector)
            if h is not None:
                for _ in range(n):
                    h()


class SimGripperBoard(GripperBoard):
    """The cage's registers with a simulated world on the wire side.

    The program reaches the registers through ``cpu.movx_read`` /
    ``cpu.movx_write``; the physics (:mod:`pyrt.sim.gripper`) reads the
    latched :attr:`dac`, sets the input levels (:attr:`pa`, :attr:`pb`,
    :attr:`pc`) and turns the encoder with :meth:`encoder`, which raises
    the interrupts at once.
    """

    url = "sim:"

    def __init__(self, cpu: I8031):
        self.cpu = cpu
        self._vectors = cpu.vectors
        #: Latched DAC byte: the motor is driven with it until it is overwritten.
        self.dac = DAC_NULL
        # the inputs as the kind declares them (PA, PB, PC, up, down), kept as
        # they change: a process image's read phase copies the list at once
        self._in = [0xFF, 0xFF, 0xFF, 0, 0]
        self._pa = self._pb = self._pc = 0xFF
        #: 8155 command register (port modes) as last written.
        self.cmd = 0x00
        #: Front-panel LED latches (LED on iff its bit is 0); all off at power-up.
        self.led_lo = 0xFF
        self.led_hi = 0xFF
        #: Number of DAC writes (the physics may use it to see a fresh command).
        self.dac_writes = 0
        self._up = 0
        self._down = 0
        self._readers = {
            P8155_CMD: self._read_cmd, P8155_PA: lambda: self.pa,
            P8155_PB: lambda: self.pb | 0xF8, P8155_PC: lambda: self.pc,
            LED_LO: lambda: self.led_lo, LED_HI: lambda: self.led_hi, DAC: lambda: self.dac,
        }
        self._writers = {
            P8155_CMD: self._write_cmd, LED_LO: self._write_led_lo,
            LED_HI: self._write_led_hi, DAC: self._write_dac,
        }
        # the same registers as :meth:`GripperBoard.map_xdata`, each with its
        # own reader (no address dispatch on the controller's MOVX path)
        for addr, reader in self._readers.items():
            cpu.map_xdata(addr, reader, self._writers.get(addr))

    # -- program side (through MOVX) ---------------------------------------------

    def read(self, addr: int) -> int:
        return self._readers[check_register(addr)]() & 0xFF

    def write(self, addr: int, value: int) -> None:
        self._writers[check_register(addr, write=True)](check_byte(value))

    def pulse_counts(self) -> tuple[int, int]:
        return self._up, self._down

    def input_values(self) -> list[int]:
        """Every input at once, as the cage kind declares them: PA, PB, PC and
        the pulses raised on each interrupt line (a process image's read phase)."""
        return self._in[:]

    # Input levels of the 8155 ports (1 = high = sensor off / switch open).
    @property
    def pa(self) -> int:
        """8155 PA's pin levels (the proximity sensors)."""
        return self._pa

    @pa.setter
    def pa(self, value: int) -> None:
        self._pa = value
        self._in[0] = value & 0xFF

    @property
    def pb(self) -> int:
        """8155 PB's pin levels as the world drives them (bits 3-7 read high)."""
        return self._pb

    @pb.setter
    def pb(self, value: int) -> None:
        self._pb = value
        self._in[1] = (value | 0xF8) & 0xFF

    @property
    def pc(self) -> int:
        """8155 PC's pin levels (the jog switch)."""
        return self._pc

    @pc.setter
    def pc(self, value: int) -> None:
        self._pc = value
        self._in[2] = value & 0xFF

    def register_file(self) -> list[int]:
        """Every register at once, in :data:`REGISTERS` order (for a board server)."""
        readers = self._readers
        return [readers[a]() & 0xFF for a in REGISTERS]

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
            self._up = self._in[3] = (self._up + counts) & 0xFFFFFFFF
        elif counts < 0:
            h = self._vectors.get(VECTOR_EXT1)
            counts = -counts
            self._down = self._in[4] = (self._down + counts) & 0xFFFFFFFF
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
