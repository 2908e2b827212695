"""A serial arm's passive servo board (004's hardware (b)), declared register by register.

One board serves every joint of one arm: the controller writes a motor
current per joint at the servo rate and reads back each joint's incremental
encoder and the wrist force/torque sensor.  The board closes no loop of its
own (a passive board: the servo is the controller's).  Per joint ``j`` of
``n``:

===============  ======  ====================  ==============================================
register         dir     width                 meaning
===============  ======  ====================  ==============================================
``dac[j]``       output  16-bit signed, off 0  the amplifier's current command, DAC counts:
                                               +-:data:`DAC_FULL_SCALE` is full-scale current
``enable[j]``    output  1 bit, off 0          the amplifier's enable (0: no current)
``release[j]``   output  1 bit, off 0          the joint's brake released (0: the brake
                                               holds the joint; fail-safe)
``count[j]``     input   32-bit signed         the encoder's counter; it wraps at 32 bits
``ft[k]``        input   32-bit signed         the wrist sensor, k = fx fy fz tx ty tz
                                               (:data:`FT_CHANNELS`), counts
===============  ======  ====================  ==============================================

``off`` is what the board's watchdog (``pyrt board-sim``) and a lost link
leave an output at: no current, amplifiers disabled, brakes engaged.  The
number of joints is part of the kind: an arm of six joints and one of seven have boards of
different fingerprints, and a controller refuses a board that is not its own.

The servo task moves these registers as blocks, every servo tick
(:class:`ArmServoRegisters`: the encoders in, the DACs whose counts changed
out), through whatever register view it is given: a back end's image
(its ``block_reader``/``block_writer``: a slice of the image in, the changed
slots out; else ``read``/``write``, and ``write_many`` when the view has one)
or the in-process register file itself (:func:`register_cells`), whose
storage it reads and writes in place, with the checks the declarations imply.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from pyrt.boards.registers import OUTPUT, BoardKind, Register, RegisterBoard, Registers

__all__ = ["DAC_FULL_SCALE", "FT_CHANNELS", "KIND_NAME", "MAX_JOINTS", "ArmServoRegisters",
           "arm_servo_kind", "input_cells", "register_cells"]

#: The kind's name (its boards' kind tag starts with it).
KIND_NAME = "arm-servo"
_INT = {int}

#: DAC counts of full-scale current (the 16-bit DAC's largest value).
DAC_FULL_SCALE = 32767
#: The wrist sensor's channels, in register order.
FT_CHANNELS = ("fx", "fy", "fz", "tx", "ty", "tz")
#: The most joints one board serves.
MAX_JOINTS = 32


def arm_servo_kind(n: int) -> BoardKind:
    """The passive servo board of an ``n``-joint arm (see the module text);
    ValueError for a joint count outside 1 .. :data:`MAX_JOINTS`."""
    if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= MAX_JOINTS:
        raise ValueError(f"an arm servo board serves 1 to {MAX_JOINTS} joints, got {n!r}")
    return BoardKind(KIND_NAME, (
        Register("dac", count=n, width=16, signed=True, direction=OUTPUT, off=0,
                 units="DAC counts",
                 doc=f"motor current command, per joint: +-{DAC_FULL_SCALE} is full scale"),
        Register("enable", count=n, width=1, direction=OUTPUT, off=0,
                 doc="amplifier enable, per joint"),
        Register("release", count=n, width=1, direction=OUTPUT, off=0,
                 doc="brake release, per joint (0: the brake holds the joint)"),
        Register("count", count=n, width=32, signed=True, units="counts",
                 doc="incremental encoder counter, per joint (wraps at 32 bits)"),
        Register("ft", count=len(FT_CHANNELS), width=32, signed=True, units="counts",
                 doc="wrist force/torque fx fy fz tx ty tz, sensor frame"),
    ), doc=f"{n}-joint passive servo board: DACs, amplifier enables, brake releases, "
           "encoders, wrist F/T")


def register_cells(board: Any, name: str) -> list[int] | None:
    """The in-process register file's own storage of the output ``name`` (a list
    of its values by index, read and written in place), when ``board`` is a
    :class:`~pyrt.boards.registers.RegisterBoard` that keeps its values so; None
    for an input (:func:`input_cells`) and for any other register view (use its
    ``read``/``write``).  A caller writing the list writes only values the
    register's declaration holds (its width and sign): nothing checks them after it."""
    if type(board) is not RegisterBoard or name not in board.kind:
        return None
    cells = board.cells(name)
    if type(cells) is not list or len(cells) != board.kind.register(name).count:
        return None
    return cells


def input_cells(board: Any, name: str) -> memoryview | None:
    """The in-process register file's own storage of the input ``name``: a
    writable memoryview of its slice of the board's 64-bit input buffer (set an
    item, read an item, ``tolist()``; a slice is assigned from an ``array('q')``),
    when ``board`` is a :class:`~pyrt.boards.registers.RegisterBoard`; None for an
    output and for any other register view.  What a caller sets must fit the
    register's declaration: nothing checks it after."""
    if type(board) is not RegisterBoard or name not in board.kind:
        return None
    cells = board.cells(name)
    if type(cells) is not memoryview or len(cells) != board.kind.register(name).count:
        return None
    return cells


class ArmServoRegisters:
    """The registers of one arm servo board as the servo task moves them: the
    encoders as one block in, the DACs as one block out, every amplifier or
    brake at once (see the module text).

    ``registers`` is any register view of an :func:`arm_servo_kind` board
    (:class:`~pyrt.boards.registers.Registers`); ValueError for a board of
    another kind.  :attr:`direct` says whether the fast path is taken (the view
    is the in-process register file); either path reads and writes the same
    registers with the same values.
    """

    def __init__(self, registers: Registers) -> None:
        kind = registers.kind
        if kind.name != KIND_NAME or "dac" not in kind:
            raise ValueError(f"an arm servo board's registers, got a {kind.name} board")
        self.registers = registers
        #: The joints the board serves.
        self.n = n = kind.register("dac").count
        dac = kind.register("dac")
        self._low, self._high = dac.low, dac.high
        self._all = (1 << n) - 1
        self._read = registers.read
        self._write = registers.write
        self._write_many = getattr(registers, "write_many", None)
        self._count = input_cells(registers, "count")
        self._ft = input_cells(registers, "ft")
        self._dac = register_cells(registers, "dac")
        self._cells = {name: register_cells(registers, name) for name in ("enable", "release")}
        #: True: the in-process register file's storage is read and written in place.
        self.direct = (self._count is not None and self._ft is not None and self._dac is not None
                       and None not in self._cells.values())
        self._joints = range(n)
        # a process image's view moves a register as one block (a slice of the
        # image in, the changed slots out): bound once here
        blocks = not self.direct and callable(getattr(registers, "block_reader", None))
        image: Any = registers
        self._counts_in = image.block_reader("count") if blocks else None
        self._ft_in = image.block_reader("ft") if blocks else None
        self._out = ({name: image.block_writer(name) for name in ("dac", "enable", "release")}
                     if blocks else None)

    def counts(self) -> list[int]:
        """Every joint's encoder counter, as the board has them now (a new list)."""
        if self.direct:
            return self._count.tolist()  # type: ignore[union-attr,no-any-return]
        if self._counts_in is not None:
            return self._counts_in()
        read = self._read
        return [read("count", j) for j in self._joints]

    def counts_reader(self) -> Callable[[], list[int]]:
        """:meth:`counts` bound once (the quickest read the view allows), for a
        servo task's every tick."""
        if self.direct:
            return self._count.tolist  # type: ignore[union-attr]
        if self._counts_in is not None:
            return self._counts_in
        return self.counts

    def dac_writer(self) -> Callable[[Sequence[int], int], None]:
        """``write(dac, changed)``: :meth:`write_dacs` with ``checked`` False
        bound once (the quickest write the view allows), for a servo task's every
        tick; the caller vouches for the values as ``checked`` False says."""
        if self._out is not None and not self.direct:
            return self._out["dac"]
        write = self.write_dacs

        def write_unchecked(dac: Sequence[int], changed: int) -> None:
            write(dac, changed, checked=False)

        return write_unchecked

    def ft(self) -> list[int]:
        """The wrist sensor's counts fx fy fz tx ty tz, as the board has them now."""
        if self.direct:
            return self._ft.tolist()  # type: ignore[union-attr]
        if self._ft_in is not None:
            return self._ft_in()
        read = self._read
        return [read("ft", k) for k in range(len(FT_CHANNELS))]

    def write_dacs(self, dac: Sequence[int], changed: int | None = None, *,
                   checked: bool = True) -> None:
        """Write ``dac[j]`` to the DAC of every joint ``j`` whose bit is set in
        ``changed`` (None: every joint), as one block.  ValueError (nothing
        written) for a value the DAC does not hold or a count of values that is
        not the board's.  ``checked`` False: the caller vouches that every value
        is an ``int`` the DAC holds (a servo's counts, clamped within
        +-:data:`DAC_FULL_SCALE`), and it is not looked at again."""
        n = self.n
        mask = self._all if changed is None else changed & self._all
        if len(dac) != n:
            raise ValueError(f"dac: expected {n} values, got {len(dac)}")
        if not mask:
            return
        if checked and (set(map(type, dac)) != _INT or min(dac) < self._low
                        or max(dac) > self._high):
            raise ValueError(f"dac: values must be integers {self._low}..{self._high}, "
                             f"got {list(dac)!r}")
        cells = self._dac
        if cells is not None and self.direct:
            if mask == self._all:
                cells[:] = dac
                self.registers.writes += n  # type: ignore[attr-defined]
            else:
                for j in self._joints:
                    if mask >> j & 1:
                        cells[j] = dac[j]
                self.registers.writes += mask.bit_count()  # type: ignore[attr-defined]
            return
        if self._out is not None:
            self._out["dac"](dac, mask)
            return
        self._many("dac", [(j, dac[j]) for j in self._joints if mask >> j & 1])

    def write_all(self, name: str, value: int) -> None:
        """Write ``value`` to register ``name`` (``dac``, ``enable`` or ``release``)
        of every joint, as one block."""
        if name not in ("dac", "enable", "release"):
            raise ValueError(f"write_all: dac, enable or release, got {name!r}")
        if name == "dac":
            self.write_dacs([value] * self.n)
            return
        reg = self.registers.kind.register(name)
        reg.check_value(value)
        cells = self._cells[name]
        if cells is not None and self.direct:
            cells[:] = [value] * self.n
            self.registers.writes += self.n  # type: ignore[attr-defined]
            return
        if self._out is not None:
            self._out[name]([value] * self.n, self._all)
            return
        self._many(name, [(j, value) for j in self._joints])

    def _many(self, name: str, writes: list[tuple[int, int]]) -> None:
        """Through the view: ``write_many`` of ``(register, index, value)`` when it
        has one, else one ``write`` each."""
        if self._write_many is not None:
            self._write_many([(name, j, v) for j, v in writes])
            return
        write = self._write
        for j, v in writes:
            write(name, v, j)
