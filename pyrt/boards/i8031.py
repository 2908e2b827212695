"""The Intel 8031 of the gripper controller: on-chip RAM, SP, interrupts, MOVX space.

The 128-byte on-chip RAM is laid out exactly as 002 Appendix A; the named
addresses below are the program names of that map.  16-bit words are stored
little-endian (low byte at the lower address), the order the report states
for the monitor's ``L`` command and the order the ready queue's Q uses.

The chip's other resources appear as registers, as the program sees them:
the stack pointer SP (SFR 81, not addressable by the monitor's ``D``), the
interrupt vectors (external request 0/1 carry the encoder counts), and the
external data memory space (MOVX), where the board maps its I/O ports.
"""

from __future__ import annotations

from collections.abc import Callable

__all__ = [
    "COMMAND_CNT",
    "CROSSFIRE",
    "DOJOG",
    "DRVON",
    "ENCODER_CNT",
    "ERROR_CNT",
    "FLAGS",
    "I8031",
    "IBUF",
    "IBYTCNT",
    "IINPTR",
    "IOUTPTR",
    "JSPEED",
    "LIMIT",
    "MVJAWSPD",
    "MXNJSPD",
    "MXPJSPD",
    "OBUF",
    "OBYTCNT",
    "OINPTR",
    "OLD_ENC",
    "OOUTPTR",
    "OTHER",
    "OVERLOAD",
    "PROX",
    "RAM_SIZE",
    "RATE",
    "SEMA",
    "SENSORPD",
    "SP_RESET",
    "STACK_BOTTOM",
    "STACK_TOP",
    "STOPCNT",
    "STOPPED",
    "SYSCLKCNT",
    "SYSCLKPD",
    "TBFULL",
    "VECTOR_EXT0",
    "VECTOR_EXT1",
    "VECTOR_SERIAL",
    "VECTOR_TIMER0",
    "WTCHJWSPD",
    "Q",
    "RamWords",
    "T",
]

RAM_SIZE = 0x80

# -- Appendix A: on-chip RAM memory map ---------------------------------------
# 00-07 REG0..REG7 (register bank 0; the only bank the program uses)
OINPTR = 0x08  #: address of characters entering the output buffer
OOUTPTR = 0x09  #: address of characters leaving the output buffer
OBYTCNT = 0x0A  #: count of bytes in the output buffer
OBUF = 0x0B  #: output buffer (0B-14)
IINPTR = 0x15  #: address of characters entering the input buffer
IOUTPTR = 0x16  #: address of characters leaving the input buffer
IBYTCNT = 0x17  #: count of bytes in the input buffer
IBUF = 0x18  #: input buffer (18-2B)
FLAGS = 0x2C  #: bit flags (bit numbers below)
TBFULL = 0  #: 2C.0: transmit buffer full
SEMA = 1  #: 2C.1: semaphore of the WAIT routine
STOPPED = 2  #: 2C.2: jaws are stopped
DRVON = 3  #: 2C.3: jaws driven in servo mode (the *drive* bit)
DOJOG = 4  #: 2C.4: last jaw movement was a jog
PROX = 0x2D  #: proximity sensor bits (active low)
OTHER = 0x2E  #: crossfire, overload, limit bits (active low)
CROSSFIRE = 0  #: 2E.0
OVERLOAD = 1  #: 2E.1
LIMIT = 2  #: 2E.2
T = 0x2F  #: ready queue: schedule values (6 slots)
Q = 0x35  #: ready queue: routine addresses (6 words)
SYSCLKCNT = 0x41  #: system software clock; the queue is checked when it reaches 0
SYSCLKPD = 0x42  #: reload value of SYSCLKCNT
MVJAWSPD = 0x43  #: MVJAWS schedule value
SENSORPD = 0x44  #: SENSORS schedule value
WTCHJWSPD = 0x45  #: WATCHJAW schedule value
ERROR_CNT = 0x46  #: word: actual - target encoder counts, excess-128
RATE = 0x48  #: word: current - previous encoder count
ENCODER_CNT = 0x4A  #: word: current encoder count
COMMAND_CNT = 0x4C  #: word: target encoder count
OLD_ENC = 0x4E  #: word: previous encoder count
STOPCNT = 0x50  #: times to bump the jaws at the end of a commanded move
JSPEED = 0x51  #: maximum absolute jaw speed
MXPJSPD = 0x52  #: maximum positive jaw speed, excess-128
MXNJSPD = 0x53  #: maximum negative jaw speed, excess-128
STACK_BOTTOM = 0x54  #: system stack 54-7F
STACK_TOP = 0x7F

#: SP after reset: the stack grows upward from 54, SP points at the last byte pushed.
SP_RESET = STACK_BOTTOM - 1

# -- interrupt vectors (code addresses, HHVECTORS.51) --------------------------
VECTOR_EXT0 = 0x0003  #: external request 0: encoder counting up
VECTOR_TIMER0 = 0x000B  #: clock/timer 0: the ready queue
VECTOR_EXT1 = 0x0013  #: external request 1: encoder counting down
VECTOR_SERIAL = 0x0023  #: serial port: terminal I/O

Reader = Callable[[], int]
Writer = Callable[[int], None]


class RamWords:
    """16-bit words over a RAM image ``ram`` (low byte first, as the 8031's
    programs keep them): the processor's view and every controller view of
    the same RAM share these."""

    __slots__ = ()
    ram: bytearray

    def word(self, addr: int) -> int:
        """Unsigned 16-bit word at ``addr``, ``addr+1`` (low byte first)."""
        ram = self.ram
        return ram[addr] | (ram[addr + 1] << 8)

    def sword(self, addr: int) -> int:
        """The word at ``addr`` read as two's complement (-8000..7FFF)."""
        ram = self.ram
        w = ram[addr] | (ram[addr + 1] << 8)
        return w - 0x10000 if w & 0x8000 else w

    def set_word(self, addr: int, value: int) -> None:
        """Store the low 16 bits of ``value`` at ``addr`` (low byte first)."""
        ram = self.ram
        ram[addr] = value & 0xFF
        ram[addr + 1] = (value >> 8) & 0xFF


class I8031(RamWords):
    """The processor as the controller program sees it.

    ``ram`` is the 128-byte on-chip RAM (a ``bytearray`` that never changes
    size); ``sp`` the stack pointer.  Interrupt handlers are installed at
    their vectors and raised by the board (:meth:`interrupt`); I/O ports live
    in the external data space and are reached with :meth:`movx_read` /
    :meth:`movx_write`, as the program's MOVX instructions reach them.
    """

    __slots__ = ("_xread", "_xwrite", "ports", "ram", "sp", "vectors")

    def __init__(self) -> None:
        self.ram = bytearray(RAM_SIZE)
        self.sp = SP_RESET
        #: Port latches P0-P3 (all FF after reset).  On the controller's CPU
        #: board P0/P2 carry the external bus (MOVX), P3.0/P3.1 the serial
        #: port and P3.2/P3.3 the encoder's INT0/INT1; P1 is not used.
        self.ports = bytearray(b"\xff\xff\xff\xff")
        #: The interrupt vector table: vector address -> handler (see :meth:`set_vector`).
        self.vectors: dict[int, Callable[[], None]] = {}
        self._xread: dict[int, Reader] = {}
        self._xwrite: dict[int, Writer] = {}

    # -- on-chip RAM -------------------------------------------------------------

    def read_byte(self, addr: int) -> int:
        """RAM byte at ``addr`` (00-7F; MOV @Ri reaches nothing else)."""
        _check_addr(addr)
        return self.ram[addr]

    def write_byte(self, addr: int, value: int) -> None:
        """Store ``value`` (00-FF) at RAM ``addr`` (00-7F)."""
        _check_addr(addr)
        if not 0 <= value <= 0xFF:
            raise ValueError(f"byte value must be 00..FF, got {value:#x}")
        self.ram[addr] = value

    def bit(self, addr: int, bit: int) -> bool:
        """Bit ``bit`` of RAM byte ``addr``."""
        return bool(self.ram[addr] >> bit & 1)

    def set_bit(self, addr: int, bit: int, on: bool = True) -> None:
        """Set (or clear, with ``on=False``) bit ``bit`` of RAM byte ``addr``."""
        if on:
            self.ram[addr] |= 1 << bit
        else:
            self.ram[addr] &= ~(1 << bit) & 0xFF

    # -- ports -------------------------------------------------------------------

    def port_read(self, n: int) -> int:
        """MOV A,Pn: the latch of port ``n`` (0-3)."""
        if not 0 <= n <= 3:
            raise ValueError(f"the 8031 has ports P0-P3, not P{n}")
        return self.ports[n]

    def port_write(self, n: int, value: int) -> None:
        """MOV Pn,A: set the latch of port ``n`` (0-3) to ``value`` (00-FF)."""
        if not 0 <= n <= 3:
            raise ValueError(f"the 8031 has ports P0-P3, not P{n}")
        if not 0 <= value <= 0xFF:
            raise ValueError(f"port value must be 00..FF, got {value:#x}")
        self.ports[n] = value

    # -- interrupts --------------------------------------------------------------

    def set_vector(self, vector: int, handler: Callable[[], None]) -> None:
        """Install ``handler`` at an interrupt vector (VECTOR_*)."""
        if vector not in (VECTOR_EXT0, VECTOR_TIMER0, VECTOR_EXT1, VECTOR_SERIAL):
            raise ValueError(f"{vector:04X} is not an 8031 interrupt vector")
        self.vectors[vector] = handler

    def handler(self, vector: int) -> Callable[[], None] | None:
        """The handler installed at ``vector``, if any."""
        return self.vectors.get(vector)

    def interrupt(self, vector: int) -> None:
        """Raise an interrupt: run the handler at ``vector`` (none installed: ignored)."""
        h = self.vectors.get(vector)
        if h is not None:
            h()

    # -- external data memory (MOVX) -------------------------------------------

    def map_xdata(self, addr: int, read: Reader | None = None, write: Writer | None = None) -> None:
        """Map an I/O register at external data address ``addr`` (0000-FFFF)."""
        if not 0 <= addr <= 0xFFFF:
            raise ValueError(f"external data address must be 0000..FFFF, got {addr:#x}")
        if read is not None:
            self._xread[addr] = read
        if write is not None:
            self._xwrite[addr] = write

    def movx_read(self, addr: int) -> int:
        """MOVX A,@DPTR: read an external register (unmapped addresses read FF)."""
        r = self._xread.get(addr)
        return r() & 0xFF if r is not None else 0xFF

    def movx_write(self, addr: int, value: int) -> None:
        """MOVX @DPTR,A: write an external register (unmapped addresses ignore it)."""
        w = self._xwrite.get(addr)
        if w is not None:
            w(value & 0xFF)


def _check_addr(addr: int) -> None:
    if not 0 <= addr < RAM_SIZE:
        raise ValueError(f"on-chip RAM address must be 00..7F, got {addr:#x}")
