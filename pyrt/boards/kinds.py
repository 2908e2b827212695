"""The built-in boards as declared kinds: the gripper cage, the TIO10, the dataConcentrator.

Each declares its registers (:mod:`pyrt.boards.registers`), so ``sim:``,
``pyrt board-sim`` and the ``tcp://`` back end move them as they move any
kind's.  The control code keeps the typed interfaces
(:class:`~pyrt.boards.gripper.GripperBoard`, :class:`~pyrt.boards.tio10.TIO10`,
:class:`~pyrt.boards.dataconcentrator.DataConcentrator`): each kind builds
its simulated board for ``sim:``, gives a register view of a typed board
(what board-sim serves) and wraps a remote register view in the typed
interface (what ``tcp://`` gives the controller).  The typed actions are
register writes: ``arm(ch)`` writes ``armed[ch] = 1``, ``disarm(ch)``
``armed[ch] = 0``, ``clear_counter(a)`` the write-only strobe ``clr[a] = 1``.

=================  ==================================================================
kind               registers (inputs, then outputs; ``off``: what the watchdog leaves)
=================  ==================================================================
``gripper-cage``   in: ``pa pb pc`` (8155 ports, 8 bits), ``up down`` (encoder pulses
                   raised on external interrupt 0/1, 32 bits); out: ``cmd``,
                   ``led_lo``, ``led_hi``, ``dac`` (off 80, the null current)
``tio10``          in: ``pulses[10]`` (16 bits), ``rtc`` (32 bits); out: ``src[10]``
                   (F1..F5), ``per[10]`` (16 bits), ``armed[10]`` (off 0 on the motor
                   channels), ``port[4]`` (8 bits; port 1, the all-windings-off bits,
                   off FF)
``dataconcentrator``  in: ``cnt[256]`` (24 bits), ``adc[16]`` (12 bits); out: ``clr[256]``
                   (write-only strobe: 1 clears the counter)
=================  ==================================================================
"""

from __future__ import annotations

from typing import Any

from pyrt.boards.dataconcentrator import (
    ADC_BITS,
    ADC_CHANNELS,
    COUNTER_ADDRESSES,
    COUNTER_BITS,
    DataConcentrator,
    check_adc_channel,
    check_counter_address,
)
from pyrt.boards.gripper import (
    DAC,
    DAC_NULL,
    INPUTS,
    LED_HI,
    LED_LO,
    P8155_CMD,
    P8155_PA,
    P8155_PB,
    P8155_PC,
    PULSE_MODULUS,
    GripperBoard,
    SimGripperBoard,
    check_byte,
    check_register,
)
from pyrt.boards.i8031 import I8031, VECTOR_EXT0, VECTOR_EXT1
from pyrt.boards.registers import (
    INPUT,
    OUTPUT,
    BoardKind,
    Register,
    Registers,
    bound_reader,
    bound_writer,
)
from pyrt.boards.simboards import SimDataConcentrator, SimTIO10
from pyrt.boards.tio10 import (
    AWO_BITS,
    CHANNELS,
    MAX_PERIOD,
    MIN_PERIOD,
    PIA_PORTS,
    RTC_CHANNELS,
    TIO10,
    check_channel,
    check_period,
    check_port,
    source_hz,
)

__all__ = [
    "DATACONCENTRATOR",
    "GRIPPER_CAGE",
    "TIO10_KIND",
    "DataConcentratorRegisters",
    "GripperCageRegisters",
    "RemoteDataConcentrator",
    "RemoteGripperBoard",
    "RemoteTIO10",
    "TIO10Registers",
]


# -- the gripper cage ---------------------------------------------------------------------

#: Cage address -> register name.
CAGE_NAMES = {P8155_CMD: "cmd", P8155_PA: "pa", P8155_PB: "pb", P8155_PC: "pc",
              LED_LO: "led_lo", LED_HI: "led_hi", DAC: "dac"}
_CAGE_ADDRS = {v: k for k, v in CAGE_NAMES.items()}


def _byte(name: str, direction: str, doc: str, **kw: Any) -> Register:
    return Register(name, width=8, direction=direction, doc=doc, address=_CAGE_ADDRS[name], **kw)


class _GripperCageKind(BoardKind):
    """The cage: builds a SimGripperBoard / RemoteGripperBoard mapped into ``cpu``."""

    def sim(self, *, cpu: I8031 | None = None, **options: Any) -> SimGripperBoard:
        return SimGripperBoard(cpu if cpu is not None else I8031())

    def view(self, board: Any) -> Registers:
        return GripperCageRegisters(board)

    def remote(self, registers: Registers, *, cpu: I8031 | None = None,
               **options: Any) -> RemoteGripperBoard:
        return RemoteGripperBoard(registers, cpu if cpu is not None else I8031())


GRIPPER_CAGE = _GripperCageKind("gripper-cage", (
    _byte("cmd", OUTPUT, "8155 command/status register (port modes)"),
    _byte("pa", INPUT, "8155 PA: proximity sensors, active low"),
    _byte("pb", INPUT, "8155 PB: bit 0 crossfire, 1 overload, 2 limit, active low; 3-7 high"),
    _byte("pc", INPUT, "8155 PC: bit 0 jog OPEN, bit 1 jog CLOSE, active low"),
    _byte("led_lo", OUTPUT, "front-panel LEDs of the 2D bits (on iff bit 0)"),
    _byte("led_hi", OUTPUT, "front-panel LEDs of the 2E bits (on iff bit 0)"),
    _byte("dac", OUTPUT, "drive current, excess-128, latched", off=DAC_NULL, units="excess-128"),
    Register("up", width=32, doc="encoder pulses raised on external interrupt 0 (opening)",
             units="counts"),
    Register("down", width=32, doc="encoder pulses raised on external interrupt 1 (closing)",
             units="counts"),
), doc="the 002 gripper controller cage: 8155 ports, LEDs, DAC, encoder interrupts",
    options=frozenset({"cpu"}))


class GripperCageRegisters:
    """The register view of a :class:`~pyrt.boards.gripper.GripperBoard` (board-sim's side)."""

    kind: BoardKind = GRIPPER_CAGE

    def __init__(self, board: GripperBoard):
        self.board = board
        #: :meth:`snapshot` as fast as the board gives it (a process image's read phase).
        self.read_inputs = board.input_values if isinstance(board, SimGripperBoard) \
            else self.snapshot

    def read(self, name: str, index: int = 0) -> int:
        GRIPPER_CAGE.check_read(name, index)
        if name == "up":
            return self.board.pulse_counts()[0]
        if name == "down":
            return self.board.pulse_counts()[1]
        return self.board.read(_CAGE_ADDRS[name])

    def write(self, name: str, value: int, index: int = 0) -> None:
        GRIPPER_CAGE.check_write(name, index, value)
        self.board.write(_CAGE_ADDRS[name], value)

    def snapshot(self) -> list[int]:
        b = self.board
        if isinstance(b, SimGripperBoard):  # the register file at once
            return b.input_values()
        up, down = b.pulse_counts()
        return [b.read(P8155_PA), b.read(P8155_PB), b.read(P8155_PC), up, down]


class RemoteGripperBoard(GripperBoard):
    """The cage over a register view of a remote board, mapped into ``cpu``:
    ``poll`` raises the 8031's external interrupts for the encoder pulses
    counted on the far side since the last poll."""

    def __init__(self, registers: Registers, cpu: I8031):
        self.registers = registers
        self.url = getattr(registers, "url", "")
        self.cpu = cpu
        # every register bound once: a MOVX is one call into the image
        self._readers = {a: bound_reader(registers, n) for a, n in CAGE_NAMES.items()}
        self._writers = {a: bound_writer(registers, n) for a, n in CAGE_NAMES.items()
                         if a not in INPUTS}
        self._read_up = bound_reader(registers, "up")
        self._read_down = bound_reader(registers, "down")
        # pulses counted before this controller came are not its own
        self._up = self._read_up()
        self._down = self._read_down()
        self.map_xdata(cpu)

    def map_xdata(self, cpu: I8031) -> None:
        for addr, read in self._readers.items():
            cpu.map_xdata(addr, read, self._writers.get(addr))

    def read(self, addr: int) -> int:
        return self._readers[check_register(addr)]()

    def write(self, addr: int, value: int) -> None:
        check_register(addr, write=True)
        self._writers[addr](check_byte(value))

    def pulse_counts(self) -> tuple[int, int]:
        return self._up, self._down

    @property
    def dac(self) -> int:
        """The drive current byte as the controller last wrote it (excess-128)."""
        return self._readers[DAC]()

    def poll(self, now_ns: int) -> None:
        up = self._read_up()
        if up != self._up:
            n = (up - self._up) % PULSE_MODULUS
            self._up = up
            h = self.cpu.vectors.get(VECTOR_EXT0)
            if h is not None:  # a vector with no handler ignores its pulses
                h()
                while n > 1:
                    h()
                    n -= 1
        down = self._read_down()
        if down != self._down:
            n = (down - self._down) % PULSE_MODULUS
            self._down = down
            h = self.cpu.vectors.get(VECTOR_EXT1)
            if h is not None:
                h()
                while n > 1:
                    h()
                    n -= 1


# -- the TIO10 --------------------------------------------------------------------------------

_MOTOR = tuple(c for c in CHANNELS if c not in RTC_CHANNELS)
_AWO_PORTS = {port for port, _ in AWO_BITS.values()}
_AWO_MASK = {p: sum(1 << b for q, b in AWO_BITS.values() if q == p) for p in _AWO_PORTS}
# off is a whole-port value: the all-windings-off ports hold nothing else
assert all(m == 0xFF for m in _AWO_MASK.values()), _AWO_MASK


class _TIO10Kind(BoardKind):
    def sim(self, **options: Any) -> SimTIO10:
        return SimTIO10()

    def view(self, board: Any) -> Registers:
        return TIO10Registers(board)

    def remote(self, registers: Registers, **options: Any) -> RemoteTIO10:
        return RemoteTIO10(registers)


TIO10_KIND = _TIO10Kind("tio10", (
    Register("src", count=len(CHANNELS), width=3, direction=OUTPUT,
             doc="the AM9513 source each channel counts, F1..F5"),
    Register("per", count=len(CHANNELS), width=16, direction=OUTPUT, units="source counts",
             doc=f"period (load) register, {MIN_PERIOD}..{MAX_PERIOD}"),
    Register("armed", count=len(CHANNELS), width=1, direction=OUTPUT,
             off=tuple(0 if c in _MOTOR else None for c in CHANNELS),
             doc="1: the channel counts (arm; a period must be loaded), 0: disarmed"),
    Register("port", count=len(PIA_PORTS), width=8, direction=OUTPUT,
             off=tuple(0xFF if p in _AWO_PORTS else None for p in PIA_PORTS),
             doc="PIA output ports: 0 direction bits, 1 all-windings-off bits"),
    Register("pulses", count=len(CHANNELS), width=16, units="pulses",
             doc="output-pulse counter, modulo 2**16"),
    Register("rtc", width=32, units="5 MHz ticks", doc="real-time clock, modulo 2**32"),
), doc="the National Instruments TIO10 timing card (000, 11.3)")


class TIO10Registers:
    """The register view of a :class:`~pyrt.boards.tio10.TIO10` (board-sim's side)."""

    kind: BoardKind = TIO10_KIND

    def __init__(self, board: TIO10):
        self.board = board
        #: :meth:`snapshot` as fast as the board gives it (a process image's read phase).
        self.read_inputs = board.input_values if isinstance(board, SimTIO10) else self.snapshot

    def read(self, name: str, index: int = 0) -> int:
        TIO10_KIND.check_read(name, index)
        b = self.board
        if name == "src":
            return b.source(index)
        if name == "per":
            return b.period(index)
        if name == "armed":
            return int(b.armed(index))
        if name == "port":
            return b.read_port(index)
        if name == "pulses":
            return b.pulses(index)
        return b.rtc_ticks()

    def write(self, name: str, value: int, index: int = 0) -> None:
        TIO10_KIND.check_write(name, index, value)
        b = self.board
        if name == "src":
            b.select_source(index, value)
        elif name == "per":
            b.load_period(index, value)
        elif name == "armed":
            if value:
                b.arm(index)
            else:
                b.disarm(index)
        else:
            b.write_port(index, value)

    def snapshot(self) -> list[int]:
        b = self.board
        if isinstance(b, SimTIO10):  # the register file at once
            return b.input_values()
        return [*(b.pulses(c) for c in CHANNELS), b.rtc_ticks()]


class RemoteTIO10(TIO10):
    """A TIO10 over a register view of a remote card: the typed checks here,
    the registers there."""

    def __init__(self, registers: Registers):
        self.registers = registers
        self.url = getattr(registers, "url", "")
        # every register bound once, by channel (port): a read is one call into the image
        self._src = [bound_reader(registers, "src", c) for c in CHANNELS]
        self._per = [bound_reader(registers, "per", c) for c in CHANNELS]
        self._armed = [bound_reader(registers, "armed", c) for c in CHANNELS]
        self._pulses = [bound_reader(registers, "pulses", c) for c in CHANNELS]
        self._port = [bound_reader(registers, "port", p) for p in PIA_PORTS]
        self._rtc = bound_reader(registers, "rtc")
        self._set_src = [bound_writer(registers, "src", c) for c in CHANNELS]
        self._set_per = [bound_writer(registers, "per", c) for c in CHANNELS]
        self._set_armed = [bound_writer(registers, "armed", c) for c in CHANNELS]
        self._set_port = [bound_writer(registers, "port", p) for p in PIA_PORTS]
        #: Register writes made (periods, arm/disarm, ports): a test can check
        #: that a refused command touched nothing.
        self.writes = 0

    def select_source(self, channel: int, source: int) -> None:
        check_channel(channel)
        source_hz(source)
        self._set_src[channel](source)
        self.writes += 1

    def source(self, channel: int) -> int:
        return self._src[check_channel(channel, allow_rtc=True)]()

    def load_period(self, channel: int, ticks: int) -> None:
        check_period(channel, ticks)
        self._set_per[channel](ticks)
        self.writes += 1

    def period(self, channel: int) -> int:
        return self._per[check_channel(channel, allow_rtc=True)]()

    def arm(self, channel: int) -> None:
        self._set_armed[check_channel(channel)](1)
        self.writes += 1

    def disarm(self, channel: int) -> None:
        self._set_armed[check_channel(channel)](0)
        self.writes += 1

    def armed(self, channel: int) -> bool:
        return bool(self._armed[check_channel(channel, allow_rtc=True)]())

    def pulses(self, channel: int) -> int:
        return self._pulses[check_channel(channel, allow_rtc=True)]()

    def write_port(self, port: int, value: int) -> None:
        check_port(port)
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 0xFF:
            raise ValueError(f"PIA port value must be 0..255, got {value!r}")
        self._set_port[port](value)
        self.writes += 1

    def read_port(self, port: int) -> int:
        return self._port[check_port(port)]()

    def rtc_ticks(self) -> int:
        return self._rtc()


# -- the dataConcentrator ------------------------------------------------------------------------

_COUNTER_MASK = (1 << COUNTER_BITS) - 1


class _DataConcentratorKind(BoardKind):
    def sim(self, **options: Any) -> SimDataConcentrator:
        return SimDataConcentrator()

    def view(self, board: Any) -> Registers:
        return DataConcentratorRegisters(board)

    def remote(self, registers: Registers, **options: Any) -> RemoteDataConcentrator:
        return RemoteDataConcentrator(registers)


DATACONCENTRATOR = _DataConcentratorKind("dataconcentrator", (
    Register("cnt", count=len(COUNTER_ADDRESSES), width=COUNTER_BITS, units="counts",
             doc="up/down counter at each address on the chain (24-bit, wraps)"),
    Register("adc", count=len(ADC_CHANNELS), width=ADC_BITS, units="ADC codes",
             doc="latest 12-bit conversion of each ADC channel"),
    Register("clr", count=len(COUNTER_ADDRESSES), width=1, direction=OUTPUT, readback=False,
             doc="write 1 to clear the counter at that address (a strobe)"),
), doc="the dataConcentrator card: encoder counters and loadcell ADCs (000, 9-11)")


class DataConcentratorRegisters:
    """The register view of a :class:`~pyrt.boards.dataconcentrator.DataConcentrator`."""

    kind: BoardKind = DATACONCENTRATOR

    def __init__(self, board: DataConcentrator):
        self.board = board
        #: :meth:`snapshot` as fast as the board gives it (a process image's read phase).
        self.read_inputs = board.input_values if isinstance(board, SimDataConcentrator) \
            else self.snapshot

    def read(self, name: str, index: int = 0) -> int:
        DATACONCENTRATOR.check_read(name, index)
        if name == "cnt":
            return self.board.read_counter(index)
        return self.board.read_adc(index)

    def write(self, name: str, value: int, index: int = 0) -> None:
        DATACONCENTRATOR.check_write(name, index, value)
        if value:
            self.board.clear_counter(index)

    def snapshot(self) -> list[int]:
        b = self.board
        if isinstance(b, SimDataConcentrator):  # the register file at once
            return b.input_values()
        return [*(b.read_counter(a) for a in COUNTER_ADDRESSES),
                *(b.read_adc(c) for c in ADC_CHANNELS)]


class RemoteDataConcentrator(DataConcentrator):
    """A dataConcentrator over a register view of a remote card."""

    def __init__(self, registers: Registers):
        self.registers = registers
        self.url = getattr(registers, "url", "")
        # every register bound once, by address (channel)
        self._cnt = [bound_reader(registers, "cnt", a) for a in COUNTER_ADDRESSES]
        self._adc = [bound_reader(registers, "adc", c) for c in ADC_CHANNELS]
        self._clr = [bound_writer(registers, "clr", a) for a in COUNTER_ADDRESSES]

    def read_counter(self, address: int) -> int:
        return self._cnt[check_counter_address(address)]() & _COUNTER_MASK

    def clear_counter(self, address: int) -> None:
        self._clr[check_counter_address(address)](1)
        cached = getattr(self.registers, "set_cached", None)
        if cached is not None:  # a read in this tick sees the counter cleared
            cached("cnt", 0, address)

    def read_adc(self, channel: int) -> int:
        return self._adc[check_adc_channel(channel)]()
