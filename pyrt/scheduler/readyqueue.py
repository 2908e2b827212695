"""The 8031-style ready queue of self-scheduling routines (002, "The Ready Queue").

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

Snapshot rule: routines found ready during one check run after the walk, so a
routine scheduled while they run (a self-scheduling routine rescheduling
itself) is first decremented at the *next* check and never runs twice in one.
"""

from __future__ import annotations

import sys
import traceback as _tb
from collections.abc import Callable, Generator
from dataclasses import dataclass
from time import perf_counter_ns

from pyrt.errors import Fault, QueueFullError
from pyrt.scheduler.stats import NBINS, Accumulator

__all__ = ["ByteImage", "ReadyQueue", "Routine"]

#: Address of the built-in routine that ends a :meth:`ReadyQueue.wait`.
WAIT_ADDRESS = 0x0001


@dataclass
class ByteImage:
    """Where a ready queue keeps its state inside a byte image.

    ``mem`` is any mutable byte buffer (the gripper passes its 128-byte RAM);
    the other fields are offsets into it.  ``sema`` is the ``(address, bit)``
    of the flag the wait routine sets.
    """

    mem: bytearray
    t_addr: int
    q_addr: int
    cnt_addr: int
    pd_addr: int
    sema: tuple[int, int]

    @classmethod
    def private(cls, capacity: int) -> ByteImage:
        """A private image: T, Q, SYSCLKCNT, SYSCLKPD and a flag byte, in that order."""
        t = 0
        q = capacity
        cnt = 3 * capacity
        return cls(bytearray(3 * capacity + 3), t, q, cnt, cnt + 1, (cnt + 2, 0))


@dataclass
class Routine:
    """A routine the queue can run: its EPROM-style address, name and body."""

    address: int
    name: str
    fn: Callable[[], None]
    #: For self-scheduling routines: where the period is read from.
    period: Callable[[], int] | None = None


class ReadyQueue:
    """A fixed-capacity ready queue driven by a periodic clock interrupt.

    ``capacity`` slots (the gripper's is 6); ``divisor`` is the initial
    SYSCLKPD (the queue is checked every ``divisor``-th tick).  ``image``
    places the state in an external byte image; by default the queue keeps a
    private one.  ``name`` names the robot the queue belongs to in faults.
    """

    def __init__(
        self,
        capacity: int = 6,
        divisor: int = 1,
        image: ByteImage | None = None,
        name: str = "robot",
    ):
        if not 1 <= capacity <= 255:
            raise ValueError(f"ready queue capacity must be 1..255, got {capacity}")
        if not 0 <= divisor <= 255:
            raise ValueError(f"clock divisor (SYSCLKPD) must be 0..255, got {divisor}")
        self.name = name
        self.capacity = capacity
        self.image = image if image is not None else ByteImage.private(capacity)
        im = self.image
        for label, addr, size in (
            ("T", im.t_addr, capacity),
            ("Q", im.q_addr, 2 * capacity),
            ("SYSCLKCNT", im.cnt_addr, 1),
            ("SYSCLKPD", im.pd_addr, 1),
        ):
            if addr < 0 or addr + size > len(im.mem):
                raise ValueError(f"{label} at {addr:#x} (+{size}) lies outside the byte image")
        self._mem = im.mem
        self._t = im.t_addr
        self._q = im.q_addr
        self._cnt = im.cnt_addr
        self._pd = im.pd_addr
        self._sema_addr, sema_bit = im.sema
        self._sema_mask = 1 << sema_bit
        if sys.byteorder == "little":
            self._q16 = memoryview(self._mem)[self._q : self._q + 2 * capacity].cast("H")
        else:  # pragma: no cover - no big-endian machine to test on
            self._q16 = _LittleEndianWords(self._mem, self._q, capacity)
        self._routines: dict[int, Routine] = {}
        self._by_name: dict[str, Routine] = {}
        self._stats: dict[int, Accumulator] | None = None
        #: (name, duration_ns) of the routines run in the current tick, when timing.
        self.ran: list[tuple[str, int]] | None = None
        #: False while the clock interrupt is disabled (monitor ``I``): queue frozen.
        self.interrupts_enabled = True
        #: The fault that stopped this queue, or None while it runs.
        self.fault: Fault | None = None
        #: Called with the fault, in the same tick, before it is reported.
        self.reflex: Callable[[Fault], None] | None = None
        #: Where faults are reported (the loop sets this when the queue is attached).
        self.fault_sink: Callable[[Fault], None] | None = None
        #: Loop time of the current tick, for routines that need the time.
        self.now_ns = 0
        #: Measures routine execution times (the loop sets its clock's timer).
        self.timer: Callable[[], int] = perf_counter_ns
        #: Gives the loop's tick index for fault records (the loop sets it).
        self.tick_source: Callable[[], int] = lambda: -1
        self.clear()
        self._mem[self._pd] = divisor
        self._mem[self._cnt] = divisor
        self.register(WAIT_ADDRESS, "WAIT", self._wait_done)

    # -- configuration -----------------------------------------------------

    def register(self, address: int, name: str, fn: Callable[[], None]) -> Routine:
        """Make ``fn`` runnable from the queue at ``address`` (1..FFFF)."""
        if not 1 <= address <= 0xFFFF:
            raise ValueError(f"routine address must be 0001..FFFF, got {address:#x}")
        if address in self._routines:
            raise ValueError(f"address {address:04X} already holds {self._routines[address].name}")
        key = name.upper()
        if key in self._by_name:
            raise ValueError(f"a routine named {name!r} is already registered")
        routine = Routine(address, name, fn)
        self._routines[address] = routine
        self._by_name[key] = routine
        if self._stats is not None:
            self._stats[address] = Accumulator(name)
        return routine

    def add_periodic(
        self,
        address: int,
        name: str,
        fn: Callable[[], None],
        period: int | Callable[[], int],
    ) -> Routine:
        """Register a self-scheduling routine: it runs ``fn`` and then reschedules
        itself with the value ``period`` gives at that moment (read it from a
        RAM byte to make the period changeable at run time)."""
        period_fn = period if callable(period) else (lambda p=int(period): p)

        def self_scheduling() -> None:
            fn()
            self.schedule(address, period_fn())

        routine = self.register(address, name, self_scheduling)
        routine.period = period_fn
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
            self._mem[self._t + i] = 0
            self._q16[i] = 0
        self._mem[self._cnt] = self._mem[self._pd]

    def schedule(self, task: int | str, n: int) -> int:
        """Put ``task`` on the queue to run after ``n`` queue checks (1..255; 0 = 256).

        Returns the slot used (the lowest free one).  A full queue raises
        :class:`QueueFullError`; inside the loop that is a fault of the robot.
        """
        routine = self.routine(task)
        if not 0 <= n <= 255:
            raise ValueError(f"schedule value for {routine.name} must be 00..FF, got {n}")
        q16 = self._q16
        for i in range(self.capacity):
            if q16[i] == 0:
                self._mem[self._t + i] = n
                q16[i] = routine.address
                return i
        raise QueueFullError(
            f"ready queue of {self.name} full ({self.capacity} slots): "
            f"cannot schedule {routine.name}"
        )

    def slots(self) -> list[tuple[int, int] | None]:
        """``(schedule value, address)`` per slot, None for a free slot."""
        out: list[tuple[int, int] | None] = []
        for i in range(self.capacity):
            a = self._q16[i]
            out.append((self._mem[self._t + i], a) if a else None)
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

    def enable_timing(self, on: bool = True) -> None:
        """Measure each routine's execution time (off: no cost at all)."""
        if on:
            self._stats = {a: Accumulator(r.name) for a, r in self._routines.items()}
            self.ran = []
        else:
            self._stats = None
            self.ran = None

    def accumulators(self) -> list[Accumulator]:
        """The live timing accumulators (empty when timing is off)."""
        return list(self._stats.values()) if self._stats is not None else []

    # -- faults ------------------------------------------------------------

    def trip(self, cause: str, source: str = "", tb: str = "") -> Fault:
        """Stop this robot: record a fault, run the reflex action, report it.

        Safety checks call this directly; an exception escaping a routine
        ends here too.  The queue dispatches nothing until :meth:`acknowledge`.
        """
        fault = Fault(
            robot=self.name,
            cause=cause,
            source=source,
            tick=self.tick_source(),
            time_ns=self.now_ns,
            traceback=tb,
        )
        if self.fault is None:
            self.fault = fault
        reflex_error = ""
        if self.reflex is not None:
            try:
                self.reflex(fault)
            except Exception as exc:  # the reflex must not hide the fault
                reflex_error = f"; reflex action failed: {exc!r}"
        if reflex_error:
            fault = Fault(
                robot=fault.robot,
                cause=fault.cause + reflex_error,
                source=fault.source,
                tick=fault.tick,
                time_ns=fault.time_ns,
                traceback=fault.traceback,
            )
            self.fault = fault
        if self.fault_sink is not None:
            self.fault_sink(fault)
        return fault

    def acknowledge(self, restart: bool = True) -> None:
        """Clear the fault and resume dispatching.  With ``restart``, every
        self-scheduling routine that is not on the queue is scheduled again
        with its current period (the failed one dropped out when it raised)."""
        self.fault = None
        if restart:
            on_queue = {slot[1] for slot in self.slots() if slot is not None}
            for r in self._routines.values():
                if r.period is not None and r.address not in on_queue:
                    self.schedule(r.address, r.period())

    # -- the clock interrupt handler ---------------------------------------

    def tick(self, now_ns: int) -> None:
        """The clock interrupt: every SYSCLKPD-th call, check the queue."""
        if not self.interrupts_enabled or self.fault is not None:
            return
        mem = self._mem
        c = (mem[self._cnt] - 1) & 0xFF
        if c:
            mem[self._cnt] = c
            return
        mem[self._cnt] = mem[self._pd]
        self.now_ns = now_ns
        self._check()

    def _check(self) -> None:
        mem = self._mem
        q16 = self._q16
        t = self._t
        ready = []
        for i in range(self.capacity):
            a = q16[i]
            if a:
                v = (mem[t + i] - 1) & 0xFF
                if v:
                    mem[t + i] = v
                else:
                    q16[i] = 0
                    ready.append(a)
        if not ready:
            return
        routines = self._routines
        stats = self._stats
        name = "?"
        try:
            if stats is None:
                for a in ready:
                    r = routines.get(a)
                    if r is None:
                        name = f"{a:04X}"
                        raise LookupError(f"no routine at address {a:04X} (corrupted Q?)")
                    name = r.name
                    r.fn()
            else:
                ran = self.ran
                timer = self.timer
                for a in ready:
                    r = routines.get(a)
                    if r is None:
                        name = f"{a:04X}"
                        raise LookupError(f"no routine at address {a:04X} (corrupted Q?)")
                    name = r.name
                    t0 = timer()
                    r.fn()
                    d = timer() - t0
                    acc = stats[a]
                    acc.calls += 1
                    acc.total += d
                    if d > acc.max:
                        acc.max = d
                    if d < 8:
                        acc.hist[d if d > 0 else 0] += 1
                    else:
                        bl = d.bit_length()
                        i = (bl << 2) - 8 + ((d >> (bl - 3)) & 3)
                        acc.hist[i if i < NBINS else NBINS - 1] += 1
                    ran.append((r.name, d))
        except Exception as exc:
            self.trip(f"{type(exc).__name__}: {exc}", source=name, tb=_tb.format_exc())


class _LittleEndianWords:  # pragma: no cover - big-endian hosts only
    """Q as little-endian 16-bit words on a big-endian host."""

    def __init__(self, mem: bytearray, base: int, n: int):
        self._mem, self._base, self._n = mem, base, n

    def __getitem__(self, i: int) -> int:
        b = self._base + 2 * i
        return self._mem[b] | (self._mem[b + 1] << 8)

    def __setitem__(self, i: int, v: int) -> None:
        b = self._base + 2 * i
        self._mem[b] = v & 0xFF
        self._mem[b + 1] = (v >> 8) & 0xFF
