"""The 8031-style ready queue of self-scheduling routines (002, "The Ready Queue").

What is 002's and what is general: the queue below is exactly 002's (byte
schedule variables, DJNZ arithmetic, 16-bit routine addresses in a byte
image, a fixed capacity, a full queue is a fault), and the gripper keeps it
in its RAM image as 002 does.  A station that has no 8031 uses
:meth:`ReadyQueue.general`: the same queue with 32-bit schedule variables in
a private image (periods of any length up to 2**32 - 1 checks), sized to
the routines registered on it, and routine addresses it assigns itself
(:meth:`ReadyQueue.register` with ``address=None``).  The rules (snapshot,
self-rescheduling, full queue is a fault, ``wait``) are the same for both.

A periodic clock interrupt calls :meth:`ReadyQueue.tick`.  Every SYSCLKPD-th
call it *checks the queue*: it decrements the schedule variable of each
occupied slot and removes the routines whose variable reaches zero; when the
walk is done those routines run to completion, in slot order.  A routine that
must repeat schedules itself again near its end, with a period read from its
period variable, so the period can be changed while the robot runs.

Storage is an external byte image, exactly as the gripper keeps it in its
on-chip RAM: ``T`` (one schedule byte per slot), ``Q`` (one 16-bit routine
address per slot, little-endian: low byte at the lower address, the byte
order the gripper report uses for its sensor word), ``SYSCLKCNT`` and
``SYSCLKPD``.  A slot whose address is 0000 is free.  Whatever writes the
image (the gripper's monitor ``C`` command, say) changes what the queue does.

Arithmetic is the 8031's: bytes decrement modulo 256 and are tested for zero
after the decrement (DJNZ), so a schedule value or SYSCLKPD of 00 means 256.
On a general queue ``T`` holds 32-bit little-endian words, decremented the
same way modulo 2**32, and 0 is refused rather than read as 2**32;
SYSCLKCNT and SYSCLKPD are bytes on both.

Snapshot rule: routines found ready during one check run after the walk, so a
routine scheduled while they run (a self-scheduling routine rescheduling
itself) is first decremented at the *next* check and never runs twice in one.

The check and the dispatch that follows it run in C by default
(csrc/ext/dispatch.c: the walk, each body called, its rescheduling and one
clock read per dispatch); ``native=False`` runs the same steps in Python
(:func:`_check_py`), the reference the C path is tested against.
"""

from __future__ import annotations

import sys
import traceback as _tb
from collections.abc import Callable, Generator, MutableSequence, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

from pyrt.errors import QueueFullError
from pyrt.native import QueueChecker, native_dispatcher
from pyrt.scheduler._routinetiming import RoutineTiming
from pyrt.scheduler.stats import Accumulator

__all__ = ["ByteImage", "ByteRef", "ReadyQueue", "Routine"]

#: Address of the built-in routine that ends a :meth:`ReadyQueue.wait`.
WAIT_ADDRESS = 0x0001

#: Timing samples kept before they are folded into the accumulators: at
#: least this many, and this many per routine (a fold costs a few µs per
#: routine, so a queue of many routines folds as rarely per routine as a
#: small one and the cost per dispatch stays flat).
_FOLD_AT = 2048
_FOLD_PER_ROUTINE = 256

#: The largest schedule value of a queue with 32-bit schedule variables.
WIDE_MAX = 0xFFFFFFFF

#: Most slots a queue can have (the C check's limit, and 002's byte count).
MAX_CAPACITY = 255


class _Words(Protocol):
    """Indexable schedule variables or routine addresses (a byte image, a word view)."""

    def __getitem__(self, i: int, /) -> int: ...

    def __setitem__(self, i: int, v: int, /) -> None: ...


def _cell_reader(cell: list[int]) -> Callable[[], int]:
    def read() -> int:
        return cell[0]

    return read


@dataclass
class ByteImage:
    """Where a ready queue keeps its state inside a byte image.

    ``mem`` is any mutable byte buffer (the gripper passes its 128-byte RAM);
    the other fields are offsets into it.  ``sema`` is the ``(address, bit)``
    of the flag the wait routine sets.  ``t_width`` is the size of one
    schedule variable in T: 1 byte (002's 8031) or 4 (a 32-bit little-endian
    word, :meth:`ReadyQueue.general`).
    """

    mem: bytearray
    t_addr: int
    q_addr: int
    cnt_addr: int
    pd_addr: int
    sema: tuple[int, int]
    t_width: int = 1

    @classmethod
    def private(cls, capacity: int, wide: bool = False) -> ByteImage:
        """A private image: T, Q, SYSCLKCNT, SYSCLKPD and a flag byte, in that
        order; with ``wide``, T holds 32-bit words."""
        w = 4 if wide else 1
        t = 0
        q = w * capacity
        cnt = q + 2 * capacity
        return cls(bytearray(cnt + 3), t, q, cnt, cnt + 1, (cnt + 2, 0), w)

    def check(self, capacity: int) -> None:
        """Refuse an image that cannot hold a queue of ``capacity`` slots."""
        if not isinstance(self.mem, bytearray):
            raise TypeError(f"the byte image must be a bytearray, got {type(self.mem).__name__}")
        for label, addr, size in (
            ("T", self.t_addr, self.t_width * capacity),
            ("Q", self.q_addr, 2 * capacity),
            ("SYSCLKCNT", self.cnt_addr, 1),
            ("SYSCLKPD", self.pd_addr, 1),
        ):
            if addr < 0 or addr + size > len(self.mem):
                raise ValueError(f"{label} at {addr:#x} (+{size}) lies outside the byte image")

    def words(self, addr: int, n: int, size: int) -> _Words:
        """``n`` little-endian words of ``size`` bytes (2 or 4) from ``addr``."""
        if sys.byteorder == "little":
            return memoryview(self.mem)[addr : addr + size * n].cast("H" if size == 2 else "I")
        return _LittleEndianWords(self.mem, addr, n, size)  # pragma: no cover - big-endian


@dataclass(frozen=True)
class ByteRef:
    """A period variable held in one byte of a byte image (``mem[address]``)."""

    mem: bytearray
    address: int

    def __call__(self) -> int:
        return self.mem[self.address]


@dataclass
class Routine:
    """A routine the queue can run: its EPROM-style address, name and body."""

    address: int
    name: str
    fn: Callable[[], None]
    #: For self-scheduling routines: where the period is read from.
    period: Callable[[], int] | None = None


class ReadyQueue:
    """A ready queue driven by a periodic clock interrupt.

    002's queue: ``capacity`` slots (the gripper's is 6) of byte schedule
    variables; ``divisor`` is the initial SYSCLKPD (the queue is checked every
    ``divisor``-th tick).  ``image`` places the state in an external byte
    image; by default the queue keeps a private one.  ``name`` names the robot
    the queue belongs to in faults.

    General (no 8031): with ``wide`` the schedule variables are 32 bits
    (1..2**32 - 1 checks; 0 is refused), and with ``capacity=None`` the queue
    has one slot per registered routine, growing as routines are registered
    (both need a private image).  :meth:`general` makes such a queue.

    ``native`` (default True): the check and the dispatch run in C
    (csrc/ext/dispatch.c); False runs them in Python (:func:`_check_py`),
    with the same semantics and statistics, slower.
    """

    def __init__(
        self,
        capacity: int | None = 6,
        divisor: int = 1,
        image: ByteImage | None = None,
        name: str = "robot",
        *,
        wide: bool = False,
        native: bool = True,
    ):
        self._auto = capacity is None
        self._native = native
        self._core: Any = None
        if capacity is None:
            if image is not None:
                raise ValueError("a ready queue in an external byte image needs a capacity")
            capacity = 1  # the WAIT routine's slot; grows with every routine registered
        if not 1 <= capacity <= MAX_CAPACITY:
            raise ValueError(f"ready queue capacity must be 1..{MAX_CAPACITY}, got {capacity}")
        if not 0 <= divisor <= 255:
            raise ValueError(f"clock divisor (SYSCLKPD) must be 0..255, got {divisor}")
        if image is not None and wide and image.t_width != 4:
            raise ValueError("a wide ready queue needs an image whose T holds 32-bit words "
                             "(t_width=4)")
        if image is not None and image.t_width not in (1, 4):
            raise ValueError(f"T must hold 1- or 4-byte schedule variables, got {image.t_width}")
        self.name = name
        self._routines: dict[int, Routine] = {}
        # the address whose body the Python dispatch runs now (0: none)
        self._running = 0
        self._by_name: dict[str, Routine] = {}
        # address -> (body, period variable or None, its index)
        self._dispatch: dict[
            int, tuple[Callable[[], None], MutableSequence[int] | None, int]] = {}
        self._timing = RoutineTiming()
        self._fold_at = _FOLD_AT
        self._bind(image if image is not None else ByteImage.private(capacity, wide), capacity)
        self._interrupts = True
        self._halted = False
        # True while the clock handler does anything: interrupts on, not halted.
        self._active = True
        #: Called as ``on_error(cause, source, traceback)`` in the tick a routine
        #: raised (or overfilled the queue); the queue is halted first.  The
        #: station that owns the queue sets it (its fault state and reflex live
        #: there, not here); the loop sets a default for a queue on its own.
        self.on_error: Callable[[str, str, str], None] | None = None
        #: Loop time of the current tick, for routines that need the time.
        self.now_ns = 0
        self.clear()
        self._mem[self._pd] = divisor
        self._mem[self._cnt] = divisor
        self.register(WAIT_ADDRESS, "WAIT", self._wait_done)

    @classmethod
    def general(cls, name: str = "robot", *, divisor: int = 1,
                capacity: int | None = None) -> ReadyQueue:
        """A queue for a station that has no 8031: 32-bit schedule variables
        (a period is any number of checks from 1 to 2**32 - 1), checked every
        tick by default (``divisor`` 1: a check is a tick), and one slot per
        registered routine unless ``capacity`` is given."""
        return cls(capacity, divisor, name=name, wide=True)

    def _bind(self, im: ByteImage, capacity: int) -> None:
        """Take ``im`` as the queue's image, with ``capacity`` slots."""
        im.check(capacity)
        wide = im.t_width == 4
        self.image = im
        self.capacity = capacity
        #: True when the schedule variables are 32-bit words (:meth:`general`).
        self.wide = wide
        #: The schedule values a slot takes: 00..FF (00 = 256) or 1..2**32 - 1.
        self.schedule_range = (1, WIDE_MAX) if wide else (0, 0xFF)
        self._mem = im.mem
        self._t = im.t_addr
        self._q = im.q_addr
        self._cnt = im.cnt_addr
        self._pd = im.pd_addr
        self._sema_addr, sema_bit = im.sema
        self._sema_mask = 1 << sema_bit
        self._q16 = im.words(self._q, capacity, 2)
        # T as indexable schedule variables: _tv[_t0 + slot]
        self._tv: _Words
        if wide:
            self._tv, self._t0 = im.words(self._t, capacity, 4), 0
        else:
            self._tv, self._t0 = self._mem, self._t
        self._slot_range = range(capacity)
        self._walk = QueueChecker(self._mem, self._t, self._q, capacity, wide=wide).check
        if self._native:  # a dispatcher over this image, told every routine and the timing
            self._core = native_dispatcher(self._mem, self._t, self._q, capacity, wide=wide)
            self._core.set_full(self._put)
            for address, (fn, pmem, paddr) in self._dispatch.items():
                self._core.set_routine(address, fn, pmem, paddr)
            self._timing.attach(self._core)

    def _grow(self) -> None:
        """One slot more (a queue sized to its routines), the state kept."""
        if self.capacity >= MAX_CAPACITY:
            raise ValueError(f"ready queue of {self.name} holds at most {MAX_CAPACITY} routines")
        slots = self.slots()
        pending = self._timing.pending
        old = self._mem
        cnt, pd, sema = old[self._cnt], old[self._pd], old[self._sema_addr]
        self._bind(ByteImage.private(self.capacity + 1, self.wide), self.capacity + 1)
        for i, slot in enumerate(slots):
            if slot is not None:
                self._tv[self._t0 + i], self._q16[i] = slot
        self._mem[self._cnt], self._mem[self._pd], self._mem[self._sema_addr] = cnt, pd, sema
        self._timing.pending = pending

    # -- state -------------------------------------------------------------

    @property
    def interrupts_enabled(self) -> bool:
        """False while the clock interrupt is disabled (monitor ``I``): queue frozen."""
        return self._interrupts

    @interrupts_enabled.setter
    def interrupts_enabled(self, on: bool) -> None:
        self._interrupts = bool(on)
        self._active = self._interrupts and not self._halted

    @property
    def halted(self) -> bool:
        """True while the queue is stopped by its owner (a fault): nothing is dispatched."""
        return self._halted

    def halt(self) -> None:
        """Stop dispatching until :meth:`resume` (the owner's fault state says why)."""
        self._halted = True
        self._active = False

    def resume(self, restart: bool = True) -> None:
        """Dispatch again.  With ``restart``, every self-scheduling routine that
        is not on the queue is scheduled again with its current period (a
        routine that raised dropped out of the queue)."""
        self._halted = False
        self._active = self._interrupts
        if restart:
            on_queue = {slot[1] for slot in self.slots() if slot is not None}
            for r in self._routines.values():
                if r.period is not None and r.address not in on_queue:
                    self.schedule(r.address, r.period())

    @property
    def sized_to_routines(self) -> bool:
        """True when the queue has one slot per registered routine (``capacity=None``)."""
        return self._auto

    # -- configuration -----------------------------------------------------

    def register(self, address: int | None, name: str, fn: Callable[[], None]) -> Routine:
        """Make ``fn`` runnable from the queue at ``address`` (1..FFFF); with
        None, at an address the queue assigns (:meth:`free_address`).  A queue
        sized to its routines gets one slot more."""
        if not isinstance(name, str) or not name.strip():
            raise ValueError(f"a routine needs a name, got {name!r}")
        key = name.upper()
        if key in self._by_name:
            raise ValueError(f"a routine named {name!r} is already registered")
        if address is None:
            address = self.free_address()
        elif not 1 <= address <= 0xFFFF:
            raise ValueError(f"routine address of {name} must be 0001..FFFF, got {address:#x}")
        if address in self._routines:
            raise ValueError(f"address {address:04X} already holds {self._routines[address].name}")
        if self._auto and len(self._routines) >= self.capacity:
            self._grow()
        routine = Routine(address, name, fn)
        self._routines[address] = routine
        self._fold_at = max(_FOLD_AT, _FOLD_PER_ROUTINE * len(self._routines))
        self._dispatch[address] = (fn, None, 0)
        self._by_name[key] = routine
        if self._core is not None:
            self._core.set_routine(address, fn, None, 0)
        self._timing.add(address, name)
        return routine

    def free_address(self) -> int:
        """The address the queue assigns to a routine registered without one:
        the highest that no registered routine holds and no slot of Q shows,
        counting down from FFFF (002's routines, low in its EPROM, keep theirs)."""
        used = set(self._routines)
        used.update(self._q16[i] for i in self._slot_range)
        for address in range(0xFFFF, 0, -1):
            if address not in used:
                return address
        raise ValueError(f"ready queue of {self.name}: no routine address is free")

    def _range_text(self) -> str:
        lo, hi = self.schedule_range
        return f"{lo}..{hi} queue checks" if self.wide else "00..FF"

    def add_periodic(
        self,
        address: int | None,
        name: str,
        fn: Callable[[], None],
        period: int | ByteRef | Callable[[], int],
    ) -> Routine:
        """Register a self-scheduling routine: it runs ``fn`` and then reschedules
        itself with the period it reads at that moment.  ``period`` is a
        constant, a :class:`ByteRef` to a RAM byte (the gripper's 43/44/45:
        changeable at run time, and the fastest form), or any zero-argument
        callable returning a schedule value (00..FF; on a :attr:`wide` queue
        1..2**32 - 1).  ``address`` None: the queue assigns one."""
        lo, hi = self.schedule_range
        pmem: MutableSequence[int] | None
        if isinstance(period, ByteRef) and not self.wide:
            pmem, paddr = period.mem, period.address
            period_fn: Callable[[], int] = period
        elif callable(period):
            period_fn = period
            pmem, paddr = None, 0
        else:
            p = int(period)
            if not lo <= p <= hi:
                raise ValueError(f"period of {name} must be {self._range_text()}, got {period!r}")
            if self.wide:
                cell = [p]
                pmem, paddr = cell, 0
                period_fn = _cell_reader(cell)
            else:
                pmem, paddr = bytearray([p]), 0
                period_fn = ByteRef(pmem, 0)

        def self_scheduling() -> None:
            fn()
            n = period_fn()
            if not lo <= n <= hi:
                raise ValueError(f"period of {name} must be {self._range_text()}, got {n!r}")
            self._put(routine.address, n)

        routine = self.register(address, name, self_scheduling)
        routine.period = period_fn
        if pmem is not None:
            # The dispatcher runs the body and reschedules it itself, from the
            # period variable: the same thing, one call less on the hot path.
            self._dispatch[routine.address] = (fn, pmem, paddr)
            if self._core is not None:
                self._core.set_routine(routine.address, fn, pmem, paddr)
        return routine

    def routine(self, task: int | str) -> Routine:
        """The registered routine with address or name ``task``."""
        r = self._by_name.get(task.upper()) if isinstance(task, str) else self._routines.get(task)
        if r is None:
            raise KeyError(f"no routine {task!r} on ready queue {self.name}")
        return r

    @property
    def routines(self) -> list[Routine]:
        """All registered routines, in registration order."""
        return list(self._routines.values())

    @property
    def running(self) -> str | None:
        """The routine whose body runs now (each dispatch stores its address),
        still the one that raised while its fault is handled; None between."""
        a = self._core.running if self._core is not None else self._running
        r = self._routines.get(a) if a else None
        return None if not a else r.name if r is not None else f"{a:04X}"

    # -- snapshots -----------------------------------------------------------

    def snapshot_state(self) -> list[Any]:
        """What :meth:`restore_state` puts back, as plain values: ``[name, the
        byte image in hex, interrupts enabled, halted, now_ns]``."""
        return [self.name, self.image.mem.hex(), self.interrupts_enabled, self.halted,
                self.now_ns]

    def restore_state(self, state: Sequence[Any]) -> None:
        """Put back what :meth:`snapshot_state` gave: an image that is not this
        queue's size is refused (ValueError) and nothing changes; a queue
        halted then is halted now, else it dispatches (no routine restarted)."""
        _name, mem, interrupts, halted, now_ns = state
        data = bytes.fromhex(mem)
        if len(data) != len(self.image.mem):
            raise ValueError(f"the state's image of ready queue {self.name} is "
                             f"{len(data)} bytes, not {len(self.image.mem)}")
        self.image.mem[:] = data
        self.interrupts_enabled = bool(interrupts)
        if halted:
            self.halt()
        else:
            self.resume(restart=False)
        self.now_ns = int(now_ns)

    # -- the queue -----------------------------------------------------------

    @property
    def divisor(self) -> int:
        """SYSCLKPD: the queue is checked every ``divisor``-th tick (0 = 256)."""
        return self._mem[self._pd]

    @divisor.setter
    def divisor(self, value: int) -> None:
        if not 0 <= value <= 255:
            raise ValueError(f"clock divisor (SYSCLKPD) must be 0..255, got {value}")
        self._mem[self._pd] = value

    def clear(self) -> None:
        """Empty every slot and reset SYSCLKCNT to SYSCLKPD."""
        for i in range(self.capacity):
            self._tv[self._t0 + i] = 0
            self._q16[i] = 0
        self._mem[self._cnt] = self._mem[self._pd]

    def schedule(self, task: int | str, n: int) -> int:
        """Put ``task`` on the queue to run after ``n`` queue checks (1..255; 0 = 256;
        on a :attr:`wide` queue 1..2**32 - 1).

        Returns the slot used (the lowest free one).  A full queue raises
        :class:`QueueFullError`; inside the loop that is a fault of the robot.
        """
        routine = self.routine(task)
        lo, hi = self.schedule_range
        if not lo <= n <= hi:
            raise ValueError(f"schedule value for {routine.name} must be {self._range_text()}, "
                             f"got {n}")
        return self._put(routine.address, n)

    def _put(self, address: int, n: int) -> int:
        """Schedule a known routine address with a checked byte ``n`` (the hot path)."""
        q16 = self._q16
        for i in self._slot_range:
            if not q16[i]:
                self._tv[self._t0 + i] = n
                q16[i] = address
                return i
        name = self._routines[address].name if address in self._routines else f"{address:04X}"
        raise QueueFullError(
            f"ready queue of {self.name} full ({self.capacity} slots): cannot schedule {name}"
        )

    def slots(self) -> list[tuple[int, int] | None]:
        """``(schedule value, address)`` per slot, None for a free slot."""
        out: list[tuple[int, int] | None] = []
        for i in range(self.capacity):
            a = self._q16[i]
            out.append((self._tv[self._t0 + i], a) if a else None)
        return out

    def pending(self) -> list[str]:
        """Names of the routines on the queue, in slot order."""
        names = []
        for slot in self.slots():
            if slot is not None:
                r = self._routines.get(slot[1])
                names.append(r.name if r else f"?{slot[1]:04X}")
        return names

    # -- wait (002, HHSYSTEM.51) -------------------------------------------

    def wait(self, n: int) -> Generator[None, None, None]:
        """Pause a foreground job for ``n`` queue checks, as 002's wait routine:
        clear the semaphore, schedule the routine that sets it, and yield (the
        job's busy wait) until it is set.  Use as ``yield from rq.wait(n)``."""
        self._mem[self._sema_addr] &= ~self._sema_mask & 0xFF
        self.schedule(WAIT_ADDRESS, n)
        while not self._mem[self._sema_addr] & self._sema_mask:
            yield

    def _wait_done(self) -> None:
        self._mem[self._sema_addr] |= self._sema_mask

    # -- timing ------------------------------------------------------------

    def enable_timing(self, on: bool = True, track_ticks: bool = True) -> None:
        """Measure each routine's execution time (off: no cost at all).

        Each dispatch appends its duration to its routine's sample list (one
        timer read, one append); every few thousand samples they are folded
        into the accumulators with numpy, in bulk.  With ``track_ticks`` the
        routines run in the current tick are also kept, for overrun records
        (a loop on virtual time cannot overrun and turns it off).
        """
        self._timing.enable(on, track_ticks, {a: r.name for a, r in self._routines.items()})

    @property
    def timer(self) -> Callable[[], int]:
        """Measures routine execution times (the loop sets its clock's timer)."""
        return self._timing.timer

    @timer.setter
    def timer(self, timer: Callable[[], int]) -> None:
        self._timing.timer = timer

    def take_samples(self) -> dict[int, list[int]]:
        """Hand over the samples recorded so far and start new lists (loop
        thread, O(routines)), so that folding them can happen in another
        thread (:meth:`fold_into_accumulators`)."""
        return self._timing.take()

    def fold_into_accumulators(self, samples: dict[int, list[int]]) -> None:
        """Fold samples taken with :meth:`take_samples` (any thread)."""
        self._timing.fold(samples)

    def fold_timing(self) -> None:
        """Fold every recorded sample into the accumulators (the loop thread)."""
        self._timing.fold_all()

    def accumulators(self, fold: bool = True) -> list[Accumulator]:
        """The timing accumulators (empty when timing is off); with ``fold``,
        first fold what was recorded (do that in the loop thread only)."""
        return self._timing.accumulators(fold)

    def count_overrun(self, name: str) -> None:
        """Attribute one overrun to the routine called ``name``."""
        routine = self._by_name.get(name.upper())
        stats = self._timing.stats
        if stats is not None and routine is not None:
            stats[routine.address].overruns += 1

    def tasks_in_tick(self, now_ns: int) -> list[tuple[str, int]]:
        """``(name, duration_ns)`` of the routines run in the tick at ``now_ns``."""
        names = self._routines
        return [(names[a].name if a in names else f"{a:04X}", d)
                for a, d in self._timing.in_tick(now_ns)]

    # -- errors --------------------------------------------------------------

    def _error(self, cause: str, source: str, tb: str = "") -> None:
        """A routine failed: halt, then tell the owner (in this tick)."""
        self.halt()
        if self.on_error is not None:
            self.on_error(cause, source, tb)

    # -- the clock interrupt handler ---------------------------------------

    def tick(self, now_ns: int) -> None:
        """The clock interrupt: every SYSCLKPD-th call, check the queue."""
        if not self._active:
            return
        mem = self._mem
        c = (mem[self._cnt] - 1) & 0xFF
        if c:
            mem[self._cnt] = c
            return
        mem[self._cnt] = mem[self._pd]
        self.now_ns = now_ns
        core = self._core
        if core is None:
            _check_py(self)
            return
        try:
            pending = core.check(now_ns)  # csrc/ext/dispatch.c: _check_py in C
        except Exception as exc:
            self._failed(core.last, exc)
            return
        if pending >= self._fold_at:
            self._timing.fold_all()

    def _failed(self, a: int, exc: Exception) -> None:
        """The routine at ``a`` raised ``exc`` (call it while handling it); it is
        :attr:`running` until its fault is handled."""
        r = self._routines.get(a)
        try:
            if r is None:
                self._error(f"no routine at address {a:04X} (corrupted Q?)", f"{a:04X}")
            else:
                self._error(f"{type(exc).__name__}: {exc}", r.name, _tb.format_exc())
        finally:
            self._running = 0
            if self._core is not None:
                self._core.running = 0


def _check_py(q: ReadyQueue) -> None:
    """One check of ``q`` and its dispatch in Python (the reference of the C path)."""
    ready = q._walk()  # csrc/readyq.c: decrement, free, collect
    if not ready:
        return
    table = q._dispatch
    # T as schedule variables: 002's bytes in the image, or 32-bit words
    tv, q16, t, slots = q._tv, q._q16, q._t0, q._slot_range
    tm = q._timing
    timer = tm.timer if tm.samples is not None else None
    log: list[tuple[int, int]] | None = None
    a = 0
    try:
        if timer is not None:
            if tm.pending >= q._fold_at:
                tm.fold_all()
            samples = tm.samples or {}
            if tm.track:
                log = []
                tm.tick_log = log
                tm.checked_at = q.now_ns
            tm.pending += len(ready)
            t0 = timer()
        for a in ready:
            q._running = a
            fn, pmem, paddr = table[a]
            fn()
            if pmem is not None:  # self-scheduling: again, with its period now
                n = pmem[paddr]
                for i in slots:
                    if not q16[i]:
                        tv[t + i] = n
                        q16[i] = a
                        break
                else:
                    q._put(a, n)  # raises QueueFullError
            if timer is not None:
                t1 = timer()
                samples[a].append(t1 - t0)
                if log is not None:
                    log.append((a, t1 - t0))
                t0 = t1
        q._running = 0
    except Exception as exc:
        q._failed(a, exc)


class _LittleEndianWords:  # pragma: no cover - big-endian hosts only
    """Q (or a wide T) as little-endian words on a big-endian host."""

    def __init__(self, mem: bytearray, base: int, n: int, size: int = 2):
        self._mem, self._base, self._n, self._size = mem, base, n, size

    def __getitem__(self, i: int) -> int:
        b = self._base + self._size * i
        return int.from_bytes(self._mem[b : b + self._size], "little")

    def __setitem__(self, i: int, v: int) -> None:
        b = self._base + self._size * i
        self._mem[b : b + self._size] = v.to_bytes(self._size, "little")
