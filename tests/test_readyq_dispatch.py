"""The ready queue's dispatch in C against the Python dispatch it replaces, on random queues."""

from __future__ import annotations

from collections.abc import Callable

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pyrt.errors import QueueFullError
from pyrt.native import native_dispatcher
from pyrt.scheduler.readyqueue import ByteRef, ReadyQueue

# A routine: (kind, period, raises at its n-th run (0: never), routine it schedules or -1)
# kinds: const (constant period), byteref (a RAM byte, changed as it runs),
# callable (a period function), once (registered, scheduled, not periodic)
_routine = st.tuples(
    st.sampled_from(["const", "byteref", "callable", "once"]),
    st.integers(min_value=1, max_value=4),
    st.integers(min_value=0, max_value=12),
    st.integers(min_value=-1, max_value=7),
)


class _Timer:
    """A fake execution timer: each read advances by the next of a fixed cycle of steps."""

    def __init__(self, steps: list[int]):
        self.t = 0
        self.i = 0
        self.steps = steps

    def __call__(self) -> int:
        self.t += self.steps[self.i % len(self.steps)]
        self.i += 1
        return self.t


def _build(native: bool, wide: bool, capacity: int | None, routines, steps, track: bool):
    """A queue of the given routines, its run log and its error log."""
    if wide:  # capacity None: one slot per routine, grown as they are registered
        q = ReadyQueue(capacity, wide=True, name="r", native=native)
    else:
        q = ReadyQueue(capacity or 6, name="r", native=native)
    ran: list[str] = []
    errors: list[tuple[str, str]] = []
    q.on_error = lambda cause, source, tb: errors.append((cause, source))
    ram = bytearray(16)
    names = [f"R{i}" for i in range(len(routines))]
    counts = [0] * len(routines)

    def body(i: int, raises: int, other: int) -> Callable[[], None]:
        def run() -> None:
            counts[i] += 1
            ran.append(names[i])
            ram[i] = 1 + (ram[i] + counts[i]) % 3  # a period that changes as it runs
            if raises and counts[i] == raises:
                raise RuntimeError(f"{names[i]} failed at run {counts[i]}")
            if 0 <= other < len(routines) and other != i and counts[i] % 2:
                try:
                    q.schedule(names[other], 1 + counts[i] % 3)
                except QueueFullError:
                    ran.append("full")
        return run

    for i, (kind, period, raises, other) in enumerate(routines):
        fn = body(i, raises, other)
        if kind == "const":
            q.add_periodic(None if wide else 0x100 + i, names[i], fn, period)
        elif kind == "byteref":
            ram[i] = period
            q.add_periodic(None if wide else 0x100 + i, names[i], fn,
                           ByteRef(ram, i) if not wide else (lambda i=i: ram[i]))
        elif kind == "callable":
            q.add_periodic(None if wide else 0x100 + i, names[i], fn,
                           lambda i=i: 1 + counts[i] % 4)
        else:
            q.register(None if wide else 0x100 + i, names[i], fn)
    q.timer = _Timer(steps)
    q.enable_timing(True, track_ticks=track)
    for i, (_, period, _, _) in enumerate(routines):
        try:
            q.schedule(names[i], period)
        except QueueFullError:
            ran.append("full at start")
    return q, ran, errors


def _state(q: ReadyQueue) -> list:
    return [(a.name, a.calls, a.total, a.max, list(a.hist), a.overruns)
            for a in q.accumulators()]


@settings(max_examples=150, deadline=None)
@given(
    routines=st.lists(_routine, min_size=1, max_size=8),
    wide=st.booleans(),
    capacity=st.one_of(st.none(), st.integers(min_value=1, max_value=9)),
    divisor=st.integers(min_value=1, max_value=3),
    steps=st.lists(st.integers(min_value=0, max_value=5000), min_size=1, max_size=6),
    ticks=st.integers(min_value=1, max_value=40),
    track=st.booleans(),
)
def test_c_dispatch_equals_the_python_dispatch(routines, wide, capacity, divisor, steps, ticks,
                                               track):
    """Random queues: the same routines run in the same order, the same slots, log and statistics."""
    if capacity is None and not wide:
        capacity = 6
    runs = []
    for native in (False, True):
        q, ran, errors = _build(native, wide, capacity, routines, steps, track)
        q.divisor = divisor
        per_tick = []
        for k in range(ticks):
            now = (k + 1) * 1_000_000
            q.tick(now)
            per_tick.append((list(ran), q.slots(), q.tasks_in_tick(now), q.halted))
        q.count_overrun("R0")
        runs.append((per_tick, errors, _state(q), q.pending()))
    assert runs[0] == runs[1]


def _ticks(native: bool, timing: bool) -> tuple[list[str], list, list[int]]:
    q = ReadyQueue(6, native=native)
    ran: list[str] = []
    for i, p in enumerate((1, 2, 3)):
        q.add_periodic(0x200 + i, f"P{i}", lambda i=i: ran.append(f"P{i}"), p)
        q.schedule(0x200 + i, p)
    q.enable_timing(timing)
    for k in range(12):
        q.tick(k)
    assert all(a.total >= 0 for a in q.accumulators())
    return ran, q.slots(), [a.calls for a in q.accumulators()]


@pytest.mark.parametrize("timing", [False, True])
def test_timing_off_and_the_real_timer_run_the_same_routines(timing):
    """Timing off, or on with the real clock: the C dispatch runs and reschedules as Python does."""
    py, c = _ticks(False, timing), _ticks(True, timing)
    assert py == c
    assert c[2] == ([0, 12, 6, 4] if timing else [])  # WAIT, P0, P1, P2


def _faulting_queue(native: bool) -> tuple[ReadyQueue, list[tuple[str, str]]]:
    q = ReadyQueue(1, native=native)
    errors: list[tuple[str, str]] = []
    q.on_error = lambda cause, source, tb: errors.append((cause, source))
    return q, errors


@pytest.mark.parametrize("native", [False, True])
def test_a_full_queue_faults_with_the_same_message_on_both_paths(native):
    """A self-scheduling routine finding no free slot: QueueFullError, named, on either path."""
    q, errors = _faulting_queue(native)
    q.add_periodic(0x300, "A", lambda: q.schedule("B", 5), 1)
    q.register(0x301, "B", lambda: None)
    q.schedule("A", 1)
    q.tick(0)
    assert q.halted
    assert errors == [("QueueFullError: ready queue of robot full (1 slots): cannot "
                       "schedule A", "A")]
    assert q.pending() == ["B"]


@pytest.mark.parametrize("native", [False, True])
def test_a_corrupted_address_is_named_on_both_paths(native):
    """A Q word naming no routine: the fault names the address, on either path."""
    q, errors = _faulting_queue(native)
    q.image.mem[q.image.q_addr:q.image.q_addr + 2] = b"\x34\x12"
    q.image.mem[q.image.t_addr] = 1
    q.tick(0)
    assert q.halted
    assert errors == [("no routine at address 1234 (corrupted Q?)", "1234")]


def test_native_dispatcher_refuses_bad_arguments():
    """A non-bytearray image, a queue outside it, bad routines and timers: clear errors."""
    with pytest.raises(TypeError):
        native_dispatcher(bytes(20), 0, 6, 6)  # type: ignore[arg-type]
    with pytest.raises(ValueError):
        native_dispatcher(bytearray(10), 0, 6, 6)
    with pytest.raises(ValueError):
        native_dispatcher(bytearray(100), 0, 10, 0)
    d = native_dispatcher(bytearray(20), 0, 6, 6)
    with pytest.raises(ValueError):
        d.set_routine(0, lambda: None, None, 0)
    with pytest.raises(TypeError):
        d.set_routine(1, 42, None, 0)
    with pytest.raises(TypeError):
        d.set_routine(1, lambda: None, (1,), 0)
    with pytest.raises(TypeError):
        d.set_timing(42, False, False, None)
    with pytest.raises(TypeError):
        d.set_samples([])


@pytest.mark.parametrize("native", [False, True])
def test_running_names_the_routine_whose_body_runs_and_none_between(native):
    """running is the routine whose body runs now (C and Python dispatch alike), None between checks."""
    q = ReadyQueue(6, name="r", native=native)
    seen: list[str | None] = []
    q.add_periodic(0x10, "FIRST", lambda: seen.append(q.running), 1)
    q.add_periodic(0x20, "SECOND", lambda: seen.append(q.running), 2)
    q.schedule("FIRST", 1)
    q.schedule("SECOND", 1)
    assert q.running is None
    for t in range(4):
        q.tick(t)
        assert q.running is None
    assert seen == ["FIRST", "SECOND", "FIRST", "FIRST", "SECOND", "FIRST"]


@pytest.mark.parametrize("native", [False, True])
def test_running_names_the_routine_that_raised_while_its_fault_is_handled(native):
    """The owner's reflex (on_error, in the same tick) runs with running naming the routine
    that raised; once handled, running is None again."""
    q = ReadyQueue(6, name="r", native=native)
    during: list[str | None] = []
    q.on_error = lambda cause, source, tb: during.append(q.running)

    def fails() -> None:
        raise RuntimeError("jammed")

    q.add_periodic(0x10, "GOOD", lambda: None, 1)
    q.add_periodic(0x20, "BAD", fails, 1)
    q.schedule("GOOD", 1)
    q.schedule("BAD", 1)
    q.tick(0)
    assert during == ["BAD"] and q.halted
    assert q.running is None
