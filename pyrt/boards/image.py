"""The process image: a back end's copy of its boards' registers, one exchange per phase.

:class:`ImageBackend` implements the back-end protocol
(:class:`pyrt.boards.backend.Backend`) with a process image: it is the
base class of every back end that reaches its boards over a link
(``tcp://`` in :mod:`pyrt.boards.tcp`, ``modbus://`` in
:mod:`pyrt.boards.modbus`), and :class:`LocalImage` is the one of
``sim:`` (the simulated boards in this process) and ``replay:`` (the
inputs from a journal).  :class:`ImageRegisters` is the register view of
one of its boards (``read``/``write`` by register name, as
:class:`~pyrt.boards.registers.RegisterBoard` has them), which a built-in
kind wraps in its typed interface; a typed board binds each register it
uses once (:meth:`ImageBackend.reader`, :meth:`ImageBackend.writer`), so
that a read in the tick is one index into the image and a write checks
its value against the declared width and sign, nothing more.

The back-end contract
=====================

This is the one place it is written; ``tests/test_backend_contract.py`` is
the suite every back end passes (``sim:``, ``tcp://``, ``modbus://``, and
one of one's own: add it to the suite's parameters).  There is one tick
shape for every back end: ``sim:`` runs the same phases as a link.

Phases of a tick (the station attaches them to its loop, :class:`pyrt.station.base.Station`):

1. **read** (loop handler ``io:read``, first in the tick): :meth:`read_phase`
   reads every input register of every declared board into the image, in
   **one exchange** (:meth:`exchange_inputs`: one request and its reply, or
   a batch of requests sent together and their replies read together).
2. **tasks** (the ready queues, the motion executors, the mailbox): a
   register read is answered from the image and never blocks on I/O; a
   write of an output is remembered in the image (a later read in the tick
   sees it) and marked changed.  A write of the value the output already
   holds is not a change (a write-only strobe always is).
3. **write** (loop handler ``io:write``, last in the tick, after the
   mailbox): :meth:`write_phase` writes the changed outputs in **one
   exchange** (:meth:`exchange_outputs`), which a back end may send
   without waiting for its reply (it is read with the next exchange: the
   batches are pipelined).

Outside the ticks (opening, a tool, a test), and until :meth:`set_tick`
says that a station runs the phases, a write goes out at once; a read of
an input outside a tick older than ``max_age`` reads the inputs again.
Once the phases run, a read between ticks answers from the image of the
last read phase (the loop keeps it fresh) and makes no I/O.
On a link that is down every read and write raises BoardError naming the
URL (but see the reflex).

Reflex.  :meth:`write_now` (the station calls it after every reflex, in the
tick that tripped) writes the changed outputs **at once**, waiting for the
reply, not at the end of the tick.  On a link that is down it is recorded
as failed: it raises :class:`~pyrt.errors.BoardError` naming the URL, which
the station keeps and names in the fault -- unless the far side is known
to turn its outputs off when the link drops (:attr:`off_on_loss`, board-sim
does) and every write is of an output's declared ``off`` value: then it
succeeds, since the drop did it.  The caller clears its own state whatever
the write does (``finally``).

Timeout.  It is derived from the tick (:meth:`set_tick`, called by the
station with the loop's period): a reply later than ``overrun_ticks``
ticks (N, default :data:`DEFAULT_OVERRUN_TICKS`) is an **overrun**
(counted in :attr:`overruns`); ``overrun_limit`` (M, default
:data:`DEFAULT_OVERRUN_LIMIT`) overruns in a row raise BoardError, and no
reply at all within N x M ticks (at least :data:`MIN_TIMEOUT_S`: a loaded
host can stall a process that long) is a lost link.  A lost link (refused,
reset, closed, timed out) raises BoardError naming the URL and stays down:
every later exchange raises it at once; the station trips on the first.
A ``timeout=S`` option fixes the hard timeout instead.

Open and close.  A back end's factory connects, checks that the far side
holds the declared boards, reads the inputs and the readable outputs once
(:meth:`open`), and returns a :class:`~pyrt.boards.registry.Boards` built
with :meth:`boards_hooks`.  :meth:`close` releases the link (idempotent);
what the far side does with the outputs then is its own (board-sim and a
device with a watchdog turn them off).

Native inputs.  A :class:`LocalImage` whose every board with inputs keeps
them in 64-bit integers, in declared order, and offers them as
``input_buffer()`` (on its register view, or on the board behind it,
``view.board``: an ``array('q')``, a numpy ``int64`` array; see
:func:`input_buffer`) holds its inputs in one flat ``array('q')``
(:attr:`LocalImage.native`) that the read phase fills in one C call, a
``memcpy`` a board (``csrc/image.c``); a journal's recorder then hands a
plain tick over in one C call too (its clock and a copy of that array into
the journal's ring).  Any other board keeps the image on lists (a copy of
each board's list of inputs a read phase).  Either way a tick sees the
inputs as the read phase found them: a value a task sets in the image
(:meth:`set_cached`) is set in a copy, never in what the read phase read.

A subclass implements :meth:`exchange_inputs`, :meth:`exchange_outputs`,
:meth:`exchange_outputs_now`, :meth:`read_outputs`, :meth:`apply_timeout`,
:meth:`close_link` and :attr:`down`.
"""

from __future__ import annotations

import time
from array import array
from collections.abc import Callable, Iterable, Mapping, Sequence
from functools import partial
from typing import Any

from pyrt.boards.backend import Backend
from pyrt.boards.registers import BoardKind, Register
from pyrt.errors import BoardError
from pyrt.native import InputGather, int64_buffer

__all__ = [
    "DEFAULT_OVERRUN_LIMIT",
    "DEFAULT_OVERRUN_TICKS",
    "MIN_TIMEOUT_S",
    "ImageBackend",
    "ImageRegisters",
    "LocalImage",
    "Write",
    "input_buffer",
]

#: A reply later than this many ticks is an overrun.
DEFAULT_OVERRUN_TICKS = 5
#: This many overruns in a row trip the station.
DEFAULT_OVERRUN_LIMIT = 10
#: The hard timeout is never shorter than this.
MIN_TIMEOUT_S = 0.1

#: One output write: (board, register, index, value).
Write = tuple[str, str, int, int]


class ImageBackend(Backend):
    """The process image of one link's boards (see the module text for the contract).

    ``kinds``: the declared boards (name -> kind).  ``max_age``: seconds an
    input copy is good for outside the ticks (0: every read outside a tick
    reads the inputs again).
    """

    #: Whether the far side turns its outputs off when the link drops.
    off_on_loss: bool = False
    #: Whether there is a link that can go down (:attr:`down`); False for boards in
    #: this process, whose reads then skip asking.
    has_link: bool = True
    #: A link's boards and world run in another process at real time.
    realtime: bool = True

    def __init__(self, url: str, kinds: Mapping[str, BoardKind], *,
                 max_age: float = 0.05,
                 overrun_ticks: int = DEFAULT_OVERRUN_TICKS,
                 overrun_limit: int = DEFAULT_OVERRUN_LIMIT,
                 timeout: float | None = None):
        super().__init__(url, kinds)
        self.image = self
        self.max_age_ns = int(max_age * 1e9)
        self.overrun_ticks = int(overrun_ticks)
        self.overrun_limit = int(overrun_limit)
        self.fixed_timeout = timeout
        #: The hard per-exchange timeout in seconds (until :meth:`set_tick`: the fixed one
        #: or 0.25 s).
        self.timeout_s = timeout if timeout is not None else 0.25
        self.overrun_ns = 0
        #: Every input in declared order: (board, register, count).
        self.layout: list[tuple[str, str, int]] = [
            (board, reg.name, reg.count) for board, kind in self.kinds.items()
            for reg in kind.inputs()]
        self.input_count = sum(c for _, _, c in self.layout)
        #: Every output slot in declared order: (board, register, index).
        self.output_layout: list[tuple[str, str, int]] = [
            (board, reg.name, i) for board, kind in self.kinds.items()
            for reg in kind.outputs() for i in range(reg.count)]
        self.output_index = {key: n for n, key in enumerate(self.output_layout)}
        #: What sees the outputs move (a journal's recorder): ``wrote(slot, value)``
        #: for every changed output, or None.
        self.tap: Any = None
        #: The inputs as the last exchange brought them, flat in :attr:`layout`
        #: order: a new list every exchange, which the image never changes, or the
        #: image's array of 64-bit integers (:attr:`LocalImage.native`), which the
        #: next read phase refills (None before the first).
        self.last_inputs: list[int] | None = None
        #: The inputs, flat in :attr:`layout` order; where each register begins and its count.
        self._values: list[int] = [0] * self.input_count
        self._span: dict[tuple[str, str], tuple[int, int]] = {}
        pos = 0
        for board, name, count in self.layout:
            self._span[(board, name)] = (pos, count)
            pos += count
        #: Registers a read has been checked for (board, name) -> (Register, where its
        #: first value is in the inputs, or -1 for an output): a read of one of them
        #: with an index in range skips the check.
        self._readable: dict[tuple[str, str], tuple[Register, int]] = {}
        self._outputs: dict[tuple[str, str, int], int] = {}
        #: The readable outputs as :attr:`_outputs` holds them, by slot (a bound
        #: reader's index; kept with it).
        self._output_list: list[int] = [0] * len(self.output_layout)
        #: The outputs written since the last exchange: slot -> value.
        self._changed: dict[int, int] = {}
        self._fresh_until = 0
        self.in_tick = False
        #: Whether a station runs the phases (:meth:`set_tick` was called): only
        #: then are the writes of a tick kept for the write phase.
        self.phased = False
        #: Exchanges made; replies later than N ticks; of them in a row now.
        self.exchanges = 0
        self.overruns = 0
        self.late_in_row = 0
        #: Run with the loop's time at the start of every read phase (the world's
        #: step, when the world is in this process and not replayed).
        self.before_read: list[Callable[[int], None]] = []
        #: Run with the loop's time at the end of every read phase (a typed board's
        #: own ``poll``: the gripper cage raises the encoder interrupts that came).
        self.after_read: list[Callable[[int], None]] = []
        #: Run at the end of every write phase of an image in this process
        #: (:class:`LocalImage`), or None: a journal's recorder hands the tick over
        #: here when this write phase is the tick's last work.  First
        #: :attr:`hand_over` (if set) is called with the loop's time: one C call
        #: that hands a plain tick over; ``after_write(now_ns, status)`` runs when
        #: its answer (``status``; -1 without one) is not 0.
        self.after_write: Callable[[int, int], None] | None = None
        self.hand_over: Callable[[int], int] | None = None

    # -- what a subclass implements ------------------------------------------------------

    def exchange_inputs(self) -> list[int]:
        """One exchange: every input, in :attr:`layout` order (BoardError on a lost link)."""
        raise NotImplementedError

    def exchange_outputs(self, writes: list[Write]) -> None:
        """One exchange writing ``writes``; it may return before the reply (pipelined)."""
        raise NotImplementedError

    def exchange_outputs_now(self, writes: list[Write]) -> None:
        """Write ``writes`` and wait for the reply (the reflex, writes outside a tick)."""
        raise NotImplementedError

    def read_outputs(self) -> dict[tuple[str, str, int], int]:
        """Every readable output's value (on opening)."""
        raise NotImplementedError

    def apply_timeout(self, seconds: float) -> None:
        """Use ``seconds`` as the hard timeout of an exchange."""

    def close_link(self) -> None:
        """Release the link."""

    @property
    def down(self) -> str | None:
        """Why the link is down, or None while it is up."""
        return None

    # -- the contract ------------------------------------------------------------------------

    def open(self) -> None:
        """Read the inputs and the readable outputs once."""
        self._take_inputs(self.exchange_inputs())
        self._outputs.clear()  # in place: a bound writer holds this dict
        self._outputs.update(self.read_outputs())
        self._list_outputs()

    def set_tick(self, period_s: float) -> None:
        """Derive the timeouts from the loop's tick period (see the module text)
        and run the phases: from now on the writes between :meth:`read_phase`
        and :meth:`write_phase` wait for the write phase (before, and without a
        station, every write goes out at once)."""
        if period_s <= 0:
            raise ValueError(f"tick period must be positive, got {period_s!r}")
        self.phased = True
        self.overrun_ns = int(self.overrun_ticks * period_s * 1e9)
        if self.fixed_timeout is None:
            self.timeout_s = max(MIN_TIMEOUT_S,
                                 self.overrun_ticks * self.overrun_limit * period_s)
        self.apply_timeout(self.timeout_s)

    def _timed(self, start_ns: int, what: str) -> None:
        self.exchanges += 1
        if not self.overrun_ns:
            return
        if time.monotonic_ns() - start_ns > self.overrun_ns:
            self.overruns += 1
            self.late_in_row += 1
            if self.late_in_row >= self.overrun_limit:
                self.late_in_row = 0
                raise BoardError(self.url, f"{what}: {self.overrun_limit} replies in a row "
                                           f"later than {self.overrun_ticks} ticks "
                                           f"({self.overrun_ns / 1e6:g} ms)")
        else:
            self.late_in_row = 0

    def _take_inputs(self, values: list[int]) -> None:
        if len(values) != self.input_count:
            raise BoardError(self.url, f"read {len(values)} input values, "
                                       f"not {self.input_count}")
        # the list the exchange made (last_inputs, never changed): set_cached
        # copies it before changing a value
        self._values = self.last_inputs = values
        if not self.phased:
            self._fresh_until = time.monotonic_ns() + self.max_age_ns

    def read_phase(self, now_ns: int = 0) -> None:
        """The tick's read phase: :attr:`before_read`, every input into the
        image in one exchange, :attr:`after_read`."""
        for step in self.before_read:
            step(now_ns)
        self.in_tick = True
        t0 = time.monotonic_ns()
        values = self.exchange_inputs()
        self._take_inputs(values)
        self._timed(t0, "read")
        for after in self.after_read:
            after(now_ns)

    def read_inputs(self, now_ns: int = 0) -> None:
        """The read phase without :attr:`before_read` (outside the ticks: the
        world steps in the loop's ticks alone)."""
        steps, self.before_read = self.before_read, []
        try:
            self.read_phase(now_ns)
        finally:
            self.before_read = steps

    def write_phase(self, now_ns: int = 0) -> None:
        """The tick's write phase: the changed outputs, one exchange; then
        :meth:`end_of_tick`."""
        self.in_tick = False
        if self._changed:
            writes = self._take_changed()
            t0 = time.monotonic_ns()
            self.exchange_outputs(writes)
            self._timed(t0, "write")
        self.end_of_tick()

    def end_of_tick(self) -> None:
        """After the write phase (nothing by default; ``tcp://`` sends the next
        tick's input request here)."""

    def resync(self) -> None:
        """The station's loop starts: the writes made while it was being built go
        out now (outside a tick from here on until the first read phase)."""
        self.in_tick = False
        self.write_now()

    def write_now(self) -> None:
        """Write the changed outputs at once (the reflex; see the module text)."""
        if not self._changed:
            return
        writes = self._take_changed()
        self._send_now(writes)

    def _take_changed(self) -> list[Write]:
        """The outputs written since the last exchange, as writes; none from now."""
        layout = self.output_layout
        writes = [(*layout[slot], v) for slot, v in self._changed.items()]
        self._changed.clear()
        return writes  # type: ignore[return-value]

    def _send_now(self, writes: list[Write]) -> None:
        if self.down is not None:
            if self.off_on_loss and all(
                    self.kinds[b].register(n).off_value(i) == v for b, n, i, v in writes):
                return  # the far side turned them off when the link dropped
            shown = ", ".join(f"{b}.{n}[{i}]={v}" for b, n, i, v in writes[:4])
            raise BoardError(self.url, f"write {shown}: the link is down ({self.down})")
        self.exchange_outputs_now(writes)

    # -- register access (the tasks' side) --------------------------------------------------

    def read(self, board: str, name: str, index: int = 0) -> int:
        """``board``'s register ``name[index]`` from the image."""
        known = self._readable.get((board, name))
        if known is None or type(index) is not int or not 0 <= index < known[0].count:
            reg = self.kinds[board].check_read(name, index)
            known = (reg, self._span[(board, name)][0] if reg.is_input else -1)
            self._readable[(board, name)] = known
        reg, base = known
        if self.has_link and self.down is not None:
            off = reg.off_value(index) if self.off_on_loss and base < 0 else None
            if off is not None:
                return off  # the far side turned it off when the link dropped
            raise BoardError(self.url, f"read {board}.{name}[{index}]: the link is down "
                                       f"({self.down})")
        if base >= 0:
            if not self.phased and not self.in_tick \
                    and time.monotonic_ns() >= self._fresh_until:
                self._take_inputs(self.exchange_inputs())
            return self._values[base + index]
        return self._outputs.get((board, name, index), 0)  # a write keeps it there

    def write(self, board: str, name: str, value: int, index: int = 0) -> None:
        """Write ``board``'s output ``name[index]``: into the image in a tick (the
        write phase sends it), at once outside one.  ValueError if refused."""
        reg = self.kinds[board].check_write(name, index, value)
        if self.has_link and self.down is not None:
            self._send_now([(board, name, index, value)])  # raises unless the drop did it
            return
        # write_many for one write, without its lists (a task's write, the hot path)
        key = (board, name, index)
        slot = self.output_index[key]
        if reg.readback:
            if self._outputs.get(key) == value and slot not in self._changed:
                return
            self._outputs[key] = value
            self._output_list[slot] = value
        self._changed[slot] = value
        tap = self.tap
        if tap is not None:
            tap.wrote(slot, value)
        if not (self.in_tick and self.phased):
            self.write_now()

    def write_many(self, writes: Iterable[Write], _regs: list[Register] | None = None) -> None:
        """Write several outputs, each ``(board, register, index, value)``
        (checked first: none is made if one is refused)."""
        todo = list(writes)
        regs = _regs or [self.kinds[b].check_write(n, i, v) for b, n, i, v in todo]
        if self.has_link and self.down is not None:
            self._send_now(todo)  # raises unless the drop did it
            return
        tap = self.tap
        for reg, (b, n, i, v) in zip(regs, todo, strict=True):
            key = (b, n, i)
            slot = self.output_index[key]
            if reg.readback:
                if self._outputs.get(key) == v and slot not in self._changed:
                    continue
                self._outputs[key] = v
                self._output_list[slot] = v
            self._changed[slot] = v
            if tap is not None:
                tap.wrote(slot, v)
        if not (self.in_tick and self.phased):
            self.write_now()

    def output_values(self) -> list[int]:
        """Every output slot's value as the image holds it (0 where unknown: a
        write-only strobe), in :attr:`output_layout` order."""
        return list(self._output_list)  # kept with _outputs, slot by slot

    def set_cached(self, board: str, name: str, value: int, index: int = 0) -> None:
        """Set the image's copy of an input (what a write made of it: a cleared counter)."""
        span = self._span.get((board, name))
        if span is not None and 0 <= index < span[1]:
            if self._values is self.last_inputs:  # the exchange's list stays as it was read
                self._values = list(self._values)
            self._values[span[0] + index] = value

    def forget_outputs(self, values: Mapping[tuple[str, str, int], int]) -> None:
        """Take ``values`` as the outputs (the far side changed them: a watchdog)."""
        new = dict(values)
        self._outputs.clear()  # in place: a bound writer holds this dict
        self._outputs.update(new)
        self._changed.clear()
        self._list_outputs()

    def _list_outputs(self) -> None:
        """:attr:`_output_list` from :attr:`_outputs` (after they were replaced)."""
        outs, slots = self._outputs, self._output_list
        for n, key in enumerate(self.output_layout):
            slots[n] = outs.get(key, 0)

    # -- bound accessors (a typed board's hot path) ------------------------------------------

    def reader(self, board: str, name: str, index: int = 0) -> Callable[[], int]:
        """A read of ``board``'s register ``name[index]`` bound once: checked
        here (ValueError as :meth:`read` gives it), then every call answers
        as :meth:`read` does, without looking the register up again.  Once
        the phases run (:meth:`set_tick`) an input is one index into the
        image; a link's reads keep :meth:`read`'s check of the link."""
        reg = self.kinds[board].check_read(name, index)
        slow = partial(self.read, board, name, index)
        if self.has_link:
            return slow
        if reg.is_input:
            slot = self._span[(board, name)][0] + index

            def read_input() -> int:
                if self.phased:
                    return self._values[slot]
                return slow()  # outside a station's ticks: fresh inputs

            return read_input
        # a readable output: the image holds its latest value (a write keeps it there,
        # in this list, which is never replaced): one C call, no Python frame
        return partial(self._output_list.__getitem__, self.output_index[(board, name, index)])

    def writer(self, board: str, name: str, index: int = 0) -> Callable[[int], None]:
        """A write of ``board``'s output ``name[index]`` bound once: the register
        and index checked here, the value at every call against the declared
        width and sign (ValueError as :meth:`write` gives it); otherwise
        exactly :meth:`write`."""
        reg = self.kinds[board].check_write(name, index, self.kinds[board].register(name).low)
        if self.has_link:
            return partial(self._write_one, board, name, index)
        key = (board, name, index)
        slot = self.output_index[key]
        low, high, readback = reg.low, reg.high, reg.readback
        changed, outputs, slots = self._changed, self._outputs, self._output_list

        def write(value: int) -> None:
            if type(value) is not int or not low <= value <= high:
                reg.check_value(value)  # raises (a bool, a float, out of range)
            if readback:  # every readable output is known from open() on
                if slots[slot] == value and slot not in changed:
                    return
                outputs[key] = value
                slots[slot] = value
            changed[slot] = value
            tap = self.tap
            if tap is not None:
                tap.wrote(slot, value)
            if not (self.in_tick and self.phased):
                self.write_now()

        return write

    def _write_one(self, board: str, name: str, index: int, value: int) -> None:
        self.write(board, name, value, index)

    def close(self) -> None:
        """Release the link (idempotent)."""
        self.close_link()

    def boards_hooks(self, pollers: Iterable[Callable[[int], None]] = ()) -> dict[str, Any]:
        """The :class:`~pyrt.boards.registry.Boards` keyword arguments of this back
        end (``backend``: itself).  ``pollers``: a board's own ``poll(now_ns)``,
        run at the end of every read phase (:attr:`after_read`: the gripper cage
        raises its encoder interrupts)."""
        self.after_read.extend(pollers)
        return {"backend": self}


class LocalImage(ImageBackend):
    """A process image over boards in this process (``sim:``, ``replay:``): the
    controller meets its simulated boards exactly as it meets a link's (one
    read phase, one write phase), and a journal can record the image.

    ``views``: the register view of every declared board (the world's side,
    ``simulated``).  The world behind them steps at the start of the read
    phase (:attr:`before_read`, filled by :meth:`attach_world`), so the
    inputs a tick reads are those of the world as it stands at the tick.
    ``feed`` (a replay): an object whose ``current`` is every input, in
    declared order, as the tick being replayed read them (the replay moves it
    on in :attr:`before_read`); the views are then not touched (neither read
    nor written) and the world stands still.  ``info``: what :meth:`info`
    tells (a replay says what it knows of a world it does not replay).
    """

    has_link = False
    realtime = False

    def __init__(self, url: str, kinds: Mapping[str, BoardKind],
                 views: Mapping[str, Any] | None, *,
                 feed: Any = None, outputs: Mapping[tuple[str, str, int], int] | None = None,
                 simulated: Any = None, info: Callable[[], dict[str, str]] | None = None):
        super().__init__(url, kinds, max_age=0.0)
        self.simulated = simulated
        self.replay = feed is not None
        self._tell = info
        self.views = dict(views) if views is not None else {}
        # every board with inputs: its view's snapshot (a new list each call; a
        # simulated board's own register file where the view names it)
        self._snaps = [getattr(self.views[name], "read_inputs", self.views[name].snapshot)
                       for name, kind in self.kinds.items()
                       if kind.inputs() and name in self.views]
        # the boards after the first: each appends its inputs (one copy where it can)
        self._extends = [_extender(snap) for snap in self._snaps[1:]]
        # every output slot's write into its board (checked by the image already)
        self._setters = [_setter(self.views[b], n, i) for b, n, i in self.output_layout] \
            if views is not None else []
        self.feed = feed
        self._initial = dict(outputs) if outputs is not None else None
        #: The inputs in native 64-bit integers, filled by one C call a read phase,
        #: when every board with inputs keeps them so (:func:`input_buffer`); else None.
        self.native: array[int] | None = None
        self._gather: Callable[[], None] | None = None
        if feed is None and views is not None:
            self._go_native()

    def _go_native(self) -> None:
        """Read the inputs by one C copy of each board's register file into a flat
        array of 64-bit integers, if every board with inputs keeps them so."""
        sources = []
        for board, kind in self.kinds.items():
            regs = kind.inputs()
            if not regs:
                continue
            buf = input_buffer(self.views.get(board))
            count = sum(r.count for r in regs)
            if buf is None or len(buf) != count:
                return
            sources.append((buf, self._span[(board, regs[0].name)][0], count))
        if not sources:
            return
        self.native = array("q", bytes(8 * self.input_count))
        self._gather = InputGather(self.native, sources)

    def exchange_inputs(self) -> list[int]:
        if self.feed is not None:
            return list(self.feed.current)
        if self._gather is not None:
            self._gather()
            return self.native.tolist()  # type: ignore[union-attr]
        snaps = self._snaps
        if not snaps:
            return []
        out = snaps[0]()  # a new list: the first board's register file at once
        for extend in self._extends:
            extend(out)
        return out

    def exchange_outputs(self, writes: list[Write]) -> None:
        if self.feed is not None:
            return
        views = self.views
        for b, n, i, v in writes:
            views[b].write(n, v, i)

    exchange_outputs_now = exchange_outputs

    def read_outputs(self) -> dict[tuple[str, str, int], int]:
        if self._initial is not None:
            return dict(self._initial)
        out: dict[tuple[str, str, int], int] = {}
        for b, kind in self.kinds.items():
            view = self.views[b]
            for reg in kind.outputs():
                if reg.readback:
                    for i in range(reg.count):
                        out[(b, reg.name, i)] = view.read(reg.name, i)
        return out

    def _timed(self, start_ns: int, what: str) -> None:
        self.exchanges += 1  # no link: nothing is ever late

    def info(self) -> dict[str, str]:
        if self._tell is None:
            return super().info()
        return self._tell()

    @property
    def tells_world(self) -> bool:
        return self._tell is not None

    def attach_world(self, step: Callable[[int], None]) -> bool:
        """The world steps at the start of every read phase; in a replay it
        stands still (the recorded inputs stand in for it): nothing is attached."""
        if self.feed is None:
            self.before_read.append(step)
        return True

    def read_phase(self, now_ns: int = 0) -> None:
        for step in self.before_read:
            step(now_ns)
        self.in_tick = True
        gather = self._gather
        if gather is not None:
            gather()  # every board's register file into the image: one C call
            self._values = self.last_inputs = self.native  # type: ignore[assignment]
            for after in self.after_read:
                after(now_ns)
            return
        snaps = self._snaps  # none when fed (a replay)
        if len(snaps) == 1:
            # a simulated board's register file, in declared order by construction
            self._values = self.last_inputs = snaps[0]()
        else:
            values = self.exchange_inputs()
            if len(values) != self.input_count:
                raise BoardError(self.url, f"read {len(values)} input values, "
                                           f"not {self.input_count}")
            self._values = self.last_inputs = values  # a new list: never changed after
        for after in self.after_read:
            after(now_ns)

    def write_phase(self, now_ns: int = 0) -> None:
        self.in_tick = False
        changed = self._changed
        if changed:
            if self.feed is None:  # each output straight into its board's register
                setters = self._setters
                for slot, value in changed.items():
                    setters[slot](value)
            changed.clear()
        after = self.after_write
        if after is not None:
            hand = self.hand_over
            status = hand(now_ns) if hand is not None else -1
            if status:
                after(now_ns, status)


def input_buffer(view: Any) -> memoryview | None:
    """The inputs of a board's register view as a buffer of native 64-bit integers,
    in declared order, that the board keeps current in place: the view's (or the
    board's behind it, ``view.board``) ``input_buffer()``, if it has one and it is
    such a buffer; else None (the inputs are read as the view's list of them)."""
    for owner in (view, getattr(view, "board", None)):
        get = getattr(owner, "input_buffer", None)
        if get is not None:
            return int64_buffer(get())
    return None


def _setter(view: Any, name: str, index: int) -> Callable[[int], None]:
    """The write of ``name[index]`` into ``view``: the view's own unchecked
    ``setter`` where it has one (a RegisterBoard's), else its ``write``."""
    make = getattr(view, "setter", None)
    if make is not None:
        return make(name, index)  # type: ignore[no-any-return]

    def write(value: int) -> None:
        view.write(name, value, index)

    return write


def _extender(snap: Callable[[], list[int]]) -> Callable[[list[int]], None]:
    """``out += snap()`` as one call; a simulated board's own ``extend_inputs``
    (one copy, not two) where it has one."""
    extend = getattr(getattr(snap, "__self__", None), "extend_inputs", None)
    if extend is not None and getattr(snap, "__name__", "") == "input_values":
        return extend  # type: ignore[no-any-return]

    def extend_with(out: list[int]) -> None:
        out += snap()

    return extend_with


#: A register of at most this many slots is written by a block writer slot by slot.
_FEW_SLOTS = 4


class ImageRegisters:
    """One board of an :class:`ImageBackend`: ``read(name, index=0)`` and
    ``write(name, value, index=0)`` as a :class:`~pyrt.boards.registers.RegisterBoard`
    has them, each register bound once on its first use (:meth:`ImageBackend.reader`,
    :meth:`ImageBackend.writer`): a servo's every-tick access is one call into the image."""

    def __init__(self, client: ImageBackend, board: str):
        self.client = client
        self.board = board
        self.kind = client.kinds[board]
        self.url = client.url
        self.link = getattr(client, "link", None)
        # where this board's inputs are in the image's (contiguous, declared order)
        spans = [client._span[(board, r.name)] for r in self.kind.inputs()]
        self._first = spans[0][0] if spans else 0
        self._end = spans[-1][0] + spans[-1][1] if spans else 0
        self._readers: dict[str, list[Callable[[], int]]] = {}
        self._writers: dict[str, list[Callable[[int], None]]] = {}

    def read(self, name: str, index: int = 0) -> int:
        bound = self._readers.get(name)
        if bound is None:
            self.client.kinds[self.board].check_read(name, index)  # ValueError if refused
            reg = self.kind.register(name)
            bound = self._readers[name] = [self.client.reader(self.board, name, i)
                                           for i in range(reg.count)]
        if type(index) is int and 0 <= index < len(bound):
            return bound[index]()
        return self.client.read(self.board, name, index)  # the refusal, named

    def write(self, name: str, value: int, index: int = 0) -> None:
        bound = self._writers.get(name)
        if bound is None:
            reg = self.kind.check_write(name, index, value)  # ValueError if refused
            bound = self._writers[name] = [self.client.writer(self.board, name, i)
                                           for i in range(reg.count)]
        if type(index) is int and 0 <= index < len(bound):
            bound[index](value)
            return
        self.client.write(self.board, name, value, index)  # the refusal, named

    def reader(self, name: str, index: int = 0) -> Callable[[], int]:
        """``read(name, index)`` bound once (:meth:`ImageBackend.reader`)."""
        return self.client.reader(self.board, name, index)

    def writer(self, name: str, index: int = 0) -> Callable[[int], None]:
        """``write(name, value, index)`` bound once (:meth:`ImageBackend.writer`)."""
        return self.client.writer(self.board, name, index)

    def block_reader(self, name: str) -> Callable[[], list[int]]:
        """A read of every value of input register ``name`` at once, bound here
        (ValueError for a register that is not an input of this board): once the
        phases run, a slice of the image (a new list); otherwise, and over a link,
        each value as :meth:`read` gives it."""
        reg = self.kind.register(name)
        if not reg.is_input:
            raise ValueError(f"{self.kind.name} register {name!r} is not an input")
        client = self.client
        each = [self.reader(name, i) for i in range(reg.count)]
        start = client._span[(self.board, name)][0]
        end = start + reg.count

        def read_all() -> list[int]:
            return [r() for r in each]

        if client.has_link:
            return read_all

        def read_block() -> list[int]:
            if client.phased:
                values: Any = client._values  # a list, or the native array('q')
                if type(values) is list:
                    return values[start:end]
                return values[start:end].tolist()  # type: ignore[no-any-return]
            return read_all()

        return read_block

    def block_writer(self, name: str) -> Callable[[Sequence[int], int], None]:
        """``write(values, mask)``: the values of output register ``name`` at
        every index whose bit is set in ``mask``, bound here (ValueError for a
        register that is not an output).  The caller vouches that each value
        written is an ``int`` the register's declaration holds (it checked them:
        nothing here looks again); otherwise exactly :meth:`write` of each."""
        reg = self.kind.register(name)
        if reg.is_input:
            raise ValueError(f"{self.kind.name} register {name!r} is not an output")
        client = self.client
        count = reg.count
        if client.has_link or count <= _FEW_SLOTS:
            # over a link, and for a register of a few slots (each slot's bound write
            # is quicker than the block's bookkeeping): slot by slot
            each = [self.writer(name, i) for i in range(count)]

            def write_each(values: Sequence[int], mask: int) -> None:
                for j in range(count):
                    if mask >> j & 1:
                        each[j](values[j])

            return write_each
        board, readback = self.board, reg.readback
        keys = [(board, name, j) for j in range(count)]
        slots = [client.output_index[k] for k in keys]
        changed, outputs, current = client._changed, client._outputs, client._output_list

        first = slots[0]
        end = first + count
        full = (1 << count) - 1
        contiguous = slots == list(range(first, end))

        def write_block(values: Sequence[int], mask: int) -> None:
            tap = client.tap
            if mask == full and tap is None and readback and contiguous:
                # the whole register, nothing watching the writes one by one: an
                # unchanged block is no change, any other is the block's values
                vals = list(values)
                if len(vals) != count:
                    raise ValueError(f"{name}: expected {count} values, got {len(vals)}")
                if current[first:end] != vals:
                    current[first:end] = vals
                    # the lengths are checked above (a strict zip's end costs more than
                    # the two stores of a small register)
                    changed.update(zip(slots, vals, strict=False))
                    outputs.update(zip(keys, vals, strict=False))
                if not (client.in_tick and client.phased):
                    client.write_now()
                return
            for j in range(count):
                if not mask >> j & 1:
                    continue
                value, slot = values[j], slots[j]
                if readback:
                    if current[slot] == value and slot not in changed:
                        continue
                    outputs[keys[j]] = value
                    current[slot] = value
                changed[slot] = value
                if tap is not None:
                    tap.wrote(slot, value)
            if not (client.in_tick and client.phased):
                client.write_now()

        return write_block

    def snapshot(self) -> list[int]:
        """Every input of this board, in declared order (once the phases run: a
        slice of the image, which the read phase brought in)."""
        client = self.client
        if client.phased and not (client.has_link and client.down is not None):
            values: Any = client._values  # a list, or the native array('q')
            if type(values) is list:
                return values[self._first:self._end]
            return values[self._first:self._end].tolist()  # type: ignore[no-any-return]
        return [self.read(reg.name, i) for reg in self.kind.inputs() for i in range(reg.count)]

    def set_cached(self, name: str, value: int, index: int = 0) -> None:
        self.client.set_cached(self.board, name, value, index)

    def __repr__(self) -> str:
        return f"<{self.kind.name} board {self.board!r} at {self.url}>"
