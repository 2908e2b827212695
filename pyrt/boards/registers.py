"""Board kinds declare their registers; one generic board holds them.

A board is known to pyrt by its **kind**: a name and the registers it has.
Each :class:`Register` is a named integer (or an array of them,
``name[0..count-1]``) of 1..32 bits, signed or not, that is either an
**input** (the world sets it: an encoder counter, a sensor port; the
controller reads it) or an **output** (the controller writes it: a drive
register, an enable; it may be read back unless it is a write-only
strobe).  An output may say what **off** is (a DAC's null, a disarmed
channel): the value a board's watchdog or a lost link leaves it at.

Everything that moves registers (the ``sim:`` back end, the wire protocol
of ``pyrt board-sim`` and its ``tcp://`` back end, a register map for
another bus) is derived from these declarations, never kept beside them::

    SERVO = BoardKind("arm-servo", (
        Register("drive", count=2, width=16, signed=True, direction=OUTPUT, off=0,
                 units="DAC counts", doc="motor drive, per joint"),
        Register("enable", direction=OUTPUT, off=0, doc="1: drives enabled"),
        Register("count", count=2, width=32, signed=True, doc="encoder counts, per joint"),
    ))

    board = RegisterBoard(SERVO)      # what sim: builds for a plain kind
    board.write("drive", -300, 1)     # the controller's side
    board.set_input("count", 1234, 0) # the world's side
    board.read("count", 0), board.output("drive", 1), board.snapshot()

A station uses :class:`RegisterBoard` directly (in process) or the register
view a back end gives (``tcp://``): both have :meth:`RegisterBoard.read`,
:meth:`RegisterBoard.write` and :attr:`RegisterBoard.kind`.  The built-in
boards (the gripper cage, the TIO10, the dataConcentrator;
:mod:`pyrt.boards.kinds`) declare their registers too and give the control
code a typed view over any register access of their kind
(:attr:`BoardKind.board`, built by :meth:`BoardKind.remote`), whose
argument checks are the declarations'.  In process every kind is a
:class:`RegisterBoard`, the world's side, which the simulation in
:mod:`pyrt.sim` drives.
"""

from __future__ import annotations

import re
import zlib
from array import array
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from functools import partial
from typing import Any, Protocol, runtime_checkable

from pyrt.errors import ConfigError

__all__ = [
    "INPUT",
    "OUTPUT",
    "BoardKind",
    "Register",
    "RegisterBoard",
    "Registers",
    "bound_reader",
    "bound_writer",
    "check_board_name",
]

#: Register directions: the world sets an input; the controller writes an output.
INPUT = "input"
OUTPUT = "output"

_NAME = re.compile(r"[a-z][a-z0-9_]*")
_KIND_NAME = re.compile(r"[a-z][a-z0-9_.-]*")
#: The longest register array a kind may declare.
MAX_COUNT = 4096


def check_board_name(name: object) -> str:
    """Return ``name`` if it can name a board or a register (``[a-z][a-z0-9_]*``,
    at most 32 characters); ConfigError otherwise."""
    if not isinstance(name, str) or len(name) > 32 or not _NAME.fullmatch(name):
        raise ConfigError(f"a board or register name is lower-case letters, digits and _ "
                          f"(a letter first, at most 32), got {name!r}")
    return name


@dataclass(frozen=True)
class Register:
    """One declared register, or an array of ``count`` of them (see the module text).

    ``off`` is the value an output is left at when the board's outputs are
    turned off (one value for every index, or one per index with None for an
    index left alone); None: the watchdog leaves it alone.  ``readback``
    False makes an output write-only (a strobe).  ``address`` is where a
    memory-mapped board has it (documentation for a real-board back end).
    ``clears``: the input (of as many registers) that a write of 1 here
    clears at the same index (a counter's clear strobe).  ``power_up``: the
    value every index holds when the board starts (None: its off value, else 0).
    """

    name: str
    count: int = 1
    width: int = 1
    signed: bool = False
    direction: str = INPUT
    doc: str = ""
    units: str = ""
    off: int | tuple[int | None, ...] | None = None
    readback: bool = True
    address: int | None = None
    clears: str = ""
    power_up: int | None = None

    def __post_init__(self) -> None:
        check_board_name(self.name)
        what = f"register {self.name!r}"
        if isinstance(self.count, bool) or not isinstance(self.count, int) \
                or not 1 <= self.count <= MAX_COUNT:
            raise ConfigError(f"{what}: count must be 1..{MAX_COUNT}, got {self.count!r}")
        if isinstance(self.width, bool) or not isinstance(self.width, int) \
                or not 1 <= self.width <= 32:
            raise ConfigError(f"{what}: width must be 1..32 bits, got {self.width!r}")
        if self.signed and self.width < 2:
            raise ConfigError(f"{what}: a signed register needs at least 2 bits")
        if self.direction not in (INPUT, OUTPUT):
            raise ConfigError(f"{what}: direction must be {INPUT!r} or {OUTPUT!r}, "
                              f"got {self.direction!r}")
        if self.direction == INPUT and (self.off is not None or not self.readback):
            raise ConfigError(f"{what}: an input has no off value and is always readable")
        offs = self.off if isinstance(self.off, tuple) else (self.off,)
        if isinstance(self.off, tuple) and len(self.off) != self.count:
            raise ConfigError(f"{what}: {len(self.off)} off values for {self.count} registers")
        for v in (*offs, self.power_up):
            if v is not None and not self.fits(v):
                raise ConfigError(f"{what}: off value {v!r} does not fit {self.describe()}")

    @property
    def is_input(self) -> bool:
        """Whether the world sets it (the controller only reads it)."""
        return self.direction == INPUT

    @property
    def low(self) -> int:
        """The smallest value."""
        return -(1 << (self.width - 1)) if self.signed else 0

    @property
    def high(self) -> int:
        """The largest value."""
        return (1 << (self.width - 1)) - 1 if self.signed else (1 << self.width) - 1

    def fits(self, value: object) -> bool:
        """Whether ``value`` is an int this register holds."""
        return (isinstance(value, int) and not isinstance(value, bool)
                and self.low <= value <= self.high)

    def describe(self) -> str:
        """``name[count]``, width and signedness in words."""
        arr = f"[{self.count}]" if self.count > 1 else ""
        return (f"{self.name}{arr} ({'signed' if self.signed else 'unsigned'} {self.width}-bit, "
                f"{self.low}..{self.high})")

    def check_index(self, index: object) -> int:
        """Return ``index`` if it is 0..count-1; ValueError otherwise."""
        if type(index) is int and 0 <= index < self.count:
            return index
        raise ValueError(f"{self.name}: index must be 0..{self.count - 1}, got {index!r}")

    def check_value(self, value: object) -> int:
        """Return ``value`` if it fits the register; ValueError otherwise."""
        if self.fits(value):
            return value  # type: ignore[return-value]
        raise ValueError(f"{self.name}: value must be an integer {self.low}..{self.high}, "
                         f"got {value!r}")

    def off_value(self, index: int) -> int | None:
        """The off value of ``name[index]``, or None."""
        return self.off[index] if isinstance(self.off, tuple) else self.off

    def signature(self) -> str:
        """The declaration as one line (for the kind's fingerprint)."""
        return (f"{self.name}:{self.count}:{self.width}:{int(self.signed)}:{self.direction}:"
                f"{self.off!r}:{int(self.readback)}" + (f":{self.clears}" if self.clears else "")
                + (f":{self.power_up}" if self.power_up is not None else ""))


@dataclass(frozen=True)
class BoardKind:
    """A kind of board: its name and its registers (see the module text).

    ``board``: the typed board the control code uses over a register access
    of this kind (called as ``board(registers, **options)``: a built-in
    board's view, such as :class:`~pyrt.boards.tio10.TIO10`), or None: the
    register access itself.  ``options`` are the keyword options it takes
    (the gripper cage: ``cpu``, the 8031 it is mapped into); a back end
    passes them on.  ConfigError for duplicate register names, a bad name or width.
    """

    name: str
    registers: tuple[Register, ...]
    doc: str = ""
    options: frozenset[str] = field(default=frozenset())
    board: Any = field(default=None, compare=False)
    _by_name: dict[str, Register] = field(init=False, repr=False, compare=False, hash=False)

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or len(self.name) > 40 \
                or not _KIND_NAME.fullmatch(self.name):
            raise ConfigError(f"a board kind's name is lower-case letters, digits and _ . - "
                              f"(a letter first, at most 40), got {self.name!r}")
        regs = tuple(self.registers)
        if not regs:
            raise ConfigError(f"board kind {self.name!r} declares no register")
        by_name: dict[str, Register] = {}
        for reg in regs:
            if not isinstance(reg, Register):
                raise ConfigError(f"board kind {self.name!r}: {reg!r} is not a Register")
            if reg.name in by_name:
                raise ConfigError(f"board kind {self.name!r} declares register "
                                  f"{reg.name!r} twice")
            by_name[reg.name] = reg
        for reg in regs:
            cleared = by_name.get(reg.clears) if reg.clears else reg
            if cleared is None or (reg.clears and (reg.is_input or not cleared.is_input
                                                   or cleared.count != reg.count)):
                raise ConfigError(f"board kind {self.name!r}: {reg.name} clears {reg.clears!r}, "
                                  f"which is no input of {reg.count} registers")
        object.__setattr__(self, "registers", regs)
        object.__setattr__(self, "options", frozenset(self.options))
        object.__setattr__(self, "_by_name", by_name)

    # -- the declaration ----------------------------------------------------------------

    def register(self, name: str) -> Register:
        """The register called ``name``; ValueError naming the kind's registers if none."""
        reg = self._by_name.get(name)
        if reg is None:
            raise ValueError(f"a {self.name} board has no register {str(name)[:40]!r}; "
                             f"registers: {' '.join(self._by_name)}")
        return reg

    def __contains__(self, name: object) -> bool:
        return name in self._by_name

    def inputs(self) -> tuple[Register, ...]:
        """The input registers, in declared order (the order of a snapshot)."""
        return tuple(r for r in self.registers if r.is_input)

    def outputs(self) -> tuple[Register, ...]:
        """The output registers, in declared order."""
        return tuple(r for r in self.registers if not r.is_input)

    @property
    def input_count(self) -> int:
        """How many values a snapshot holds."""
        return sum(r.count for r in self.registers if r.is_input)

    @property
    def fingerprint(self) -> str:
        """Eight hex digits over the registers' declarations: two kinds of one
        name that declare different registers differ here."""
        text = "\n".join(r.signature() for r in self.registers)
        return f"{zlib.crc32(text.encode()):08x}"

    @property
    def tag(self) -> str:
        """``NAME@FINGERPRINT``, as the wire protocol's greeting names the kind."""
        return f"{self.name}@{self.fingerprint}"

    def check_write(self, name: str, index: int, value: object) -> Register:
        """The register of a controller's write of ``value`` to ``name[index]``;
        ValueError if there is none, the index or value is out of range, or
        it is an input."""
        reg = self.register(name)
        reg.check_index(index)
        if reg.is_input:
            raise ValueError(f"{reg.name} is an input of a {self.name} board: "
                             "the controller cannot write it")
        reg.check_value(value)
        return reg

    def check_read(self, name: str, index: int) -> Register:
        """The register of a controller's read of ``name[index]``; ValueError
        if there is none, the index is out of range, or it is write-only."""
        reg = self.register(name)
        reg.check_index(index)
        if not reg.readback:
            raise ValueError(f"{reg.name} of a {self.name} board is write-only")
        return reg

    # -- builders -------------------------------------------------------------------------

    def sim(self, **options: Any) -> RegisterBoard:
        """A new in-process register file of this kind (the world's side of ``sim:``)."""
        return RegisterBoard(self)

    def view(self, board: Any) -> Registers:
        """The register view of an in-process board of this kind (the board itself)."""
        return board  # type: ignore[no-any-return]

    def remote(self, registers: Registers, **options: Any) -> Any:
        """The board the control code uses over ``registers`` (any register
        access of this kind: in process, an image, a link): :attr:`board` of
        them, or the access itself."""
        return registers if self.board is None else self.board(registers, **options)


@runtime_checkable
class Registers(Protocol):
    """Register access by name: what the wire protocol and the back ends move."""

    kind: BoardKind

    def read(self, name: str, index: int = 0) -> int:
        """The value of ``name[index]``; ValueError if refused."""

    def write(self, name: str, value: int, index: int = 0) -> None:
        """Write ``name[index]`` (an output); ValueError if refused."""

    def snapshot(self) -> list[int]:
        """Every input, in declared order (arrays index by index)."""


class RegisterBoard:
    """An in-process board of any kind: its outputs held as lists of ints, its
    inputs in one ``array('q')`` in declared order (:meth:`input_buffer`).

    The controller's side: :meth:`read` (any readable register) and
    :meth:`write` (outputs only, checked against width and signedness).
    The world's side: :meth:`set_input`, :meth:`output` and :meth:`cells`.
    Registers start at their power-up value, else their off value, else 0.  ``writes`` counts the
    controller's writes through :meth:`write`.
    """

    url = "sim:"

    def __init__(self, kind: BoardKind):
        self.kind = kind
        # Every input in one buffer of native 64-bit integers, in declared order
        # (what input_buffer() offers a process image); each input register is a
        # memoryview of its slice, each output a list.  Every declared width is
        # at most 32 bits, so the buffer holds every value a register can.
        self._inbuf = array("q", bytes(8 * kind.input_count))
        whole = memoryview(self._inbuf)
        self._values: dict[str, list[int] | memoryview] = {}
        at = 0
        for reg in kind.registers:
            start = [reg.power_up if reg.power_up is not None else (reg.off_value(i) or 0)
                     for i in range(reg.count)]
            if reg.is_input:
                cells = whole[at:at + reg.count]
                cells[:] = array("q", start)
                self._values[reg.name] = cells
                at += reg.count
            else:
                self._values[reg.name] = start
        self._inputs = kind.inputs()
        self.writes = 0
        # The fast path of every access (the servo rate): name -> (values, count,
        # low, high) of the registers a side may write, and of those the
        # controller may read; anything else takes the checked path and its errors.
        self._writable = {r.name: (self._values[r.name], r.count, r.low, r.high)
                          for r in kind.registers if not r.is_input}
        self._settable = {r.name: (self._values[r.name], r.count, r.low, r.high)
                          for r in kind.registers if r.is_input}
        # a clear strobe's input (the list it clears)
        self._clears = {r.name: self._values[r.clears] for r in kind.registers if r.clears}
        self._readable: dict[str, list[int] | memoryview] = {}
        for r in kind.registers:
            try:
                kind.check_read(r.name, 0)
            except ValueError:
                continue
            self._readable[r.name] = self._values[r.name]

    # -- the controller's side ------------------------------------------------------------

    def read(self, name: str, index: int = 0) -> int:
        """The value of ``name[index]``."""
        values = self._readable.get(name)
        if values is not None and type(index) is int and 0 <= index < len(values):
            return values[index]
        self.kind.check_read(name, index)
        return self._values[name][index]

    def write(self, name: str, value: int, index: int = 0) -> None:
        """Write ``value`` to the output ``name[index]``."""
        fast = self._writable.get(name)
        if (fast is None or type(value) is not int or type(index) is not int
                or not (0 <= index < fast[1] and fast[2] <= value <= fast[3])):
            self.kind.check_write(name, index, value)
            fast = self._writable[name]
        fast[0][index] = value
        self.writes += 1
        cleared = self._clears.get(name)
        if cleared is not None and value == 1:
            cleared[index] = 0

    def setter(self, name: str, index: int = 0) -> Callable[[int], None]:
        """The write of the output ``name[index]`` bound once, for a caller that
        checked the value against the declaration already (a process image's
        write phase); ValueError now if ``name[index]`` is no output."""
        values = self._writable.get(name)
        if values is None:
            raise ValueError(f"{name} is no output of a {self.kind.name} board")
        self.kind.register(name).check_index(index)
        cleared = self._clears.get(name)
        if cleared is None:
            return partial(values[0].__setitem__, index)  # not counted in writes
        cells = values[0]

        def strobe(value: int) -> None:
            cells[index] = value
            if value == 1:
                cleared[index] = 0

        return strobe

    def snapshot(self) -> list[int]:
        """Every input in declared order."""
        return self._inbuf.tolist()

    def input_buffer(self) -> memoryview:
        """Every input in declared order as the board keeps them: a buffer of
        native 64-bit integers, current in place (a process image gathers it
        in one call)."""
        return memoryview(self._inbuf)

    # -- the world's side -----------------------------------------------------------------

    def set_input(self, name: str, value: int, index: int = 0) -> None:
        """The world sets the input ``name[index]`` (ValueError if it is not
        an input or the value does not fit)."""
        fast = self._settable.get(name)
        if (fast is not None and type(value) is int and type(index) is int
                and 0 <= index < fast[1] and fast[2] <= value <= fast[3]):
            fast[0][index] = value
            return
        reg = self.kind.register(name)
        reg.check_index(index)
        if not reg.is_input:
            raise ValueError(f"{name} is an output of a {self.kind.name} board: "
                             "the world reads it with output()")
        self._values[name][index] = reg.check_value(value)

    def output(self, name: str, index: int = 0) -> int:
        """What the controller last wrote to ``name[index]`` (an output; a
        strobe included)."""
        reg = self.kind.register(name)
        reg.check_index(index)
        if reg.is_input:
            raise ValueError(f"{name} is an input of a {self.kind.name} board: "
                             "read it with read()")
        return self._values[name][index]

    def values(self, name: str) -> list[int]:
        """Every value of ``name`` (a copy)."""
        self.kind.register(name)
        return list(self._values[name])

    def cells(self, name: str) -> list[int] | memoryview:
        """The register file's own storage of ``name`` (the world's side, bound
        once: a plant reads an output and sets an input as an item of it; what it
        sets must fit the declaration, nothing here looks again): an output's
        list, an input's writable memoryview of its slice of the input buffer."""
        self.kind.register(name)
        return self._values[name]

    def __repr__(self) -> str:
        return f"<RegisterBoard {self.kind.name}>"


# -- helpers for back ends ----------------------------------------------------------------


def bound_reader(registers: Registers, name: str, index: int = 0) -> Callable[[], int]:
    """``registers.read(name, index)`` as a call of no argument, bound once: the
    view's own ``reader`` if it has one (a process image's: one index a read),
    else the read itself."""
    make = getattr(registers, "reader", None)
    if make is not None:
        return make(name, index)  # type: ignore[no-any-return]
    return partial(registers.read, name, index)


def bound_writer(registers: Registers, name: str, index: int = 0) -> Callable[[int], None]:
    """``registers.write(name, value, index)`` as a call of the value, bound once
    (the view's own ``writer`` if it has one)."""
    make = getattr(registers, "writer", None)
    if make is not None:
        return make(name, index)  # type: ignore[no-any-return]

    def write(value: int) -> None:
        registers.write(name, value, index)

    return write


def outputs_off(kind: BoardKind, registers: Registers) -> None:
    """Write every declared off value through ``registers`` (an output
    already off is not written again)."""
    for reg in kind.outputs():
        for i in range(reg.count):
            off = reg.off_value(i)
            if off is None:
                continue
            if reg.readback and registers.read(reg.name, i) == off:
                continue
            registers.write(reg.name, off, i)


def outputs_are_off(kind: BoardKind, registers: Registers) -> bool:
    """Whether every output with an off value reads as off (write-only
    outputs are not looked at)."""
    for reg in kind.outputs():
        if not reg.readback:
            continue
        for i in range(reg.count):
            off = reg.off_value(i)
            if off is not None and registers.read(reg.name, i) != off:
                return False
    return True


def check_kinds(kinds: Mapping[str, BoardKind]) -> dict[str, BoardKind]:
    """``kinds`` (board name -> kind) checked: names usable, values kinds;
    ConfigError otherwise."""
    if not isinstance(kinds, Mapping) or not kinds:
        raise ConfigError(f"a station declares its boards as a mapping of names to board "
                          f"kinds, got {kinds!r}")
    out: dict[str, BoardKind] = {}
    for name, kind in kinds.items():
        check_board_name(name)
        if not isinstance(kind, BoardKind):
            raise ConfigError(f"board {name!r}: {kind!r} is not a BoardKind")
        out[name] = kind
    return out


def split_options(kinds: Mapping[str, BoardKind],
                  options: Mapping[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """``options`` split into (those some kind takes, the rest)."""
    taken: set[str] = set()
    for kind in kinds.values():
        taken |= kind.options
    mine = {k: v for k, v in options.items() if k in taken}
    rest = {k: v for k, v in options.items() if k not in taken}
    return mine, rest


def options_for(kind: BoardKind, options: Mapping[str, Any]) -> dict[str, Any]:
    """The subset of ``options`` that ``kind`` takes."""
    return {k: v for k, v in options.items() if k in kind.options}


def iter_inputs(kind: BoardKind) -> Iterator[tuple[Register, int]]:
    """(register, index) of every input in snapshot order."""
    for reg in kind.inputs():
        for i in range(reg.count):
            yield reg, i
