"""Tasks without an 8031: periods in ticks of any length, assigned addresses, default names, refusals."""

from __future__ import annotations

from functools import partial

import pytest
from _ref_readyq import check_wide as ref_check_wide
from hypothesis import given, settings
from hypothesis import strategies as st

from pyrt.errors import QueueFullError
from pyrt.native import QueueChecker
from pyrt.scheduler import ByteRef, Loop, ReadyQueue, SimClock, Task, install

MS = 1_000_000


def servo() -> None:
    """A body whose name becomes the task's."""


def arm_loop(*tasks: Task, name: str = "arm") -> tuple[Loop, ReadyQueue]:
    loop = Loop(SimClock(), period_ns=MS)
    queue = ReadyQueue.general(name=name)
    install(queue, tasks)
    loop.attach(queue, name=f"queue:{name}")
    return loop, queue


# -- periods in ticks ----------------------------------------------------------------------


def test_a_period_of_1000_ticks_runs_every_1000_ticks_on_simclock():
    """Task(fn, period=1000) on a general queue runs at ticks 1000, 2000, ... : 10 calls in 10 000 ticks."""
    seen: list[int] = []
    loop, _ = arm_loop(Task(seen.append, period=1000, name="slow", timed=True))
    loop.run(10_000)
    assert seen == [k * 1000 * MS for k in range(1, 11)]
    loop.run(999)
    assert len(seen) == 10
    loop.run(1)
    assert len(seen) == 11


@settings(max_examples=40, deadline=None)
@given(period=st.integers(1, 3000), ticks=st.integers(0, 7000))
def test_any_period_runs_ticks_over_period_times(period, ticks):
    """Over n ticks a task of period p (first run one period in) runs exactly n // p times."""
    calls = [0]

    def body() -> None:
        calls[0] += 1

    loop, _ = arm_loop(Task(body, period=period))
    loop.run(ticks)
    assert calls[0] == ticks // period


def test_a_servo_and_a_trajectory_task_share_one_queue_without_addresses():
    """Two tasks without addresses get two free addresses and their own names; both keep their rates."""
    runs = {"servo": 0, "traj": 0}

    def plan() -> None:
        runs["traj"] += 1

    def servo_body() -> None:
        runs["servo"] += 1

    loop, queue = arm_loop(Task(servo_body, period=1, name="servo"), Task(plan, period=10,
                                                                        name="traj"))
    servo_r, traj_r = queue.routine("servo"), queue.routine("traj")
    assert servo_r.address != traj_r.address
    assert {servo_r.address, traj_r.address}.isdisjoint({0x0001})  # WAIT keeps its own
    assert queue.capacity == 3  # sized to its routines: two tasks and WAIT
    loop.run(1000)
    assert runs == {"servo": 1000, "traj": 100}
    stats = loop.statistics()
    assert stats.tasks["servo"].calls == 1000 and stats.tasks["traj"].calls == 100


def test_a_task_is_named_after_its_function_by_default():
    """Without a name, the task takes its function's name (through a partial too)."""
    assert Task(servo, period=1).name == "servo"
    assert Task(partial(servo), period=5).name == "servo"
    assert Task(servo, period=5, name="fast").name == "fast"


def test_a_changeable_period_may_exceed_a_byte_on_a_general_queue():
    """A callable period is read at every reschedule: changed from 300 to 700 ticks, the next reschedule takes it."""
    period = [300]
    seen: list[int] = []
    loop, _ = arm_loop(Task(seen.append, period=lambda: period[0], name="log", timed=True))
    loop.run(450)
    period[0] = 700
    loop.run(1550)
    assert [t // MS for t in seen] == [300, 600, 1300, 2000]


def test_first_run_can_be_given_or_left_to_the_component():
    """first=1 runs at the first check; first=None leaves the task off the queue until scheduled."""
    a: list[int] = []
    b: list[int] = []
    loop, queue = arm_loop(Task(a.append, period=500, name="a", first=1, timed=True),
                           Task(b.append, period=500, name="b", first=None, timed=True))
    loop.run(1001)
    assert [t // MS for t in a] == [1, 501, 1001] and b == []
    queue.schedule("b", 2)
    loop.run(2)
    assert [t // MS for t in b] == [1003]


# -- 002's form, unchanged -----------------------------------------------------------------


def test_the_002_positional_form_still_declares_an_eprom_routine():
    """Task(name, address, fn, period, first, timed) keeps its meaning (first None by default)."""
    ram = bytearray(0x80)
    ram[0x44] = 0x0A
    t = Task("SENSORS", 0x0473, servo, ByteRef(ram, 0x44))
    assert (t.name, t.address, t.first, t.timed) == ("SENSORS", 0x0473, None, False)
    assert t.period_now() == 0x0A
    q = ReadyQueue(capacity=6, divisor=4)
    (r,) = install(q, [t])
    assert r.address == 0x0473 and not q.wide and q.pending() == []


def test_a_general_task_on_002s_queue_gets_a_free_address_and_runs():
    """A task without an address on a byte queue takes a free one; a period of 1..255 fits."""
    q = ReadyQueue(capacity=4)
    calls = [0]

    def body() -> None:
        calls[0] += 1

    (r,) = install(q, [Task(body, period=3)])
    assert r.address not in (0x0001, 0) and q.routine("body") is r
    for t in range(1, 10):
        q.tick(t)
    assert calls[0] == 3


# -- refusals ------------------------------------------------------------------------------


@pytest.mark.parametrize(("period", "error", "text"), [
    (0, ValueError, "1 or more"),
    (-5, ValueError, "1 or more"),
    (2.5, TypeError, "whole number"),
    (10.0, TypeError, "whole number"),
    ("10", TypeError, "whole number"),
    (True, TypeError, "whole number"),
    (None, TypeError, "whole number"),
])
def test_a_bad_period_is_refused_naming_the_task(period, error, text):
    """A period of 0, negative or not a whole number is refused with the task's name."""
    with pytest.raises(error, match=f"period of task traj .*{text}"):
        Task(servo, period=period, name="traj")
    with pytest.raises(error, match=f"period of task SENSORS .*{text}"):
        Task("SENSORS", 0x0473, servo, period)


def test_other_bad_declarations_are_refused():
    """A body that is not callable, an address out of range, a negative first run, an empty name, a missing period."""
    with pytest.raises(TypeError, match="callable"):
        Task(42, period=1)  # type: ignore[call-overload]
    with pytest.raises(ValueError, match="address of task traj"):
        Task(servo, period=1, name="traj", address=0x10000)
    with pytest.raises(ValueError, match="first run of task traj"):
        Task(servo, period=1, name="traj", first=-1)
    with pytest.raises(ValueError, match="non-empty name"):
        Task(servo, period=1, name=" ")
    with pytest.raises(TypeError, match="period"):
        Task(servo)  # type: ignore[call-overload]


def test_a_period_above_a_byte_on_002s_queue_is_refused_and_nothing_is_installed():
    """A period of 1000 on a byte queue is refused at install, naming the task; no routine is registered."""
    q = ReadyQueue(capacity=6)
    with pytest.raises(ValueError, match=r"period of task slow is 1000 .*ReadyQueue\.general"):
        install(q, [Task(servo, period=10), Task(servo, period=1000, name="slow")])
    assert [r.name for r in q.routines] == ["WAIT"] and q.pending() == []


def test_duplicate_names_and_addresses_are_refused_before_anything_is_installed():
    """Two tasks named alike (any case), or sharing an address, are refused and the queue is left as it was."""
    q = ReadyQueue.general()
    with pytest.raises(ValueError, match="'SERVO' is already"):
        install(q, [Task(servo, period=1), Task(servo, period=2, name="SERVO")])
    with pytest.raises(ValueError, match="address 0100 of task b"):
        install(q, [Task(servo, period=1, name="a", address=0x100),
                    Task(servo, period=1, name="b", address=0x100)])
    assert [r.name for r in q.routines] == ["WAIT"] and q.capacity == 1


def test_first_runs_that_do_not_fit_a_fixed_queue_are_refused():
    """On a queue of fixed capacity, more first runs than free slots are refused before anything is installed."""
    q = ReadyQueue(capacity=2)
    tasks = [Task(servo, period=1, name=n) for n in "abc"]
    with pytest.raises(ValueError, match="2 free slot"):
        install(q, tasks)
    assert [r.name for r in q.routines] == ["WAIT"]


# -- the general queue -----------------------------------------------------------------------


def test_general_queue_refuses_schedule_values_it_cannot_hold():
    """A 32-bit schedule variable takes 1..2**32-1: 0 (which 002's byte reads as 256) is refused."""
    q = ReadyQueue.general()
    q.add_periodic(None, "T", lambda: None, 70_000)
    with pytest.raises(ValueError, match=r"1\.\.4294967295"):
        q.schedule("T", 0)
    with pytest.raises(ValueError, match=r"1\.\.4294967295"):
        q.schedule("T", 2**32)
    q.schedule("T", 2**32 - 1)
    assert q.slots()[0] == (2**32 - 1, q.routine("T").address)


def test_a_general_queue_grows_with_its_routines_and_keeps_its_state():
    """Registering a routine adds a slot; what is on the queue, SYSCLKCNT and SYSCLKPD survive it."""
    q = ReadyQueue.general(divisor=3)
    q.add_periodic(None, "A", lambda: None, 5000)
    q.schedule("A", 4000)
    q.tick(1)
    q.add_periodic(None, "B", lambda: None, 7)
    assert q.capacity == 3 and q.divisor == 3
    assert q.slots()[0] == (4000, q.routine("A").address)
    q.tick(2)
    q.tick(3)  # the third tick checks the queue
    assert q.slots()[0] == (3999, q.routine("A").address)


def test_a_general_queue_of_fixed_capacity_faults_when_full():
    """capacity= gives a fixed size; scheduling past it is a QueueFullError as on 002's queue."""
    q = ReadyQueue.general(capacity=2)
    q.add_periodic(None, "A", lambda: None, 1000)
    q.schedule("A", 1)
    q.schedule("A", 2)
    with pytest.raises(QueueFullError, match="full"):
        q.schedule("A", 3)


def test_a_routine_that_sets_a_bad_period_faults_its_queue():
    """A callable period that reads 0 on a general queue is a fault of the routine, not a silent stop."""
    faults: list[tuple[str, str]] = []
    q = ReadyQueue.general()
    q.on_error = lambda cause, source, tb: faults.append((cause, source))
    install(q, [Task(servo, period=lambda: 0, first=1)])
    q.tick(1)
    assert q.halted and faults and "period of servo must be 1.." in faults[0][0]


def test_assigned_addresses_avoid_those_registered_and_on_the_queue():
    """The queue assigns the highest address no routine holds and no slot of Q shows."""
    q = ReadyQueue.general()
    q.register(0xFFFF, "TOP", lambda: None)
    q._q16[0] = 0xFFFE  # a word written into Q by hand (a monitor C, say)
    assert q.free_address() == 0xFFFD


@settings(max_examples=200, deadline=None)
@given(
    image=st.binary(min_size=60, max_size=128),
    capacity=st.integers(min_value=1, max_value=6),
    t_addr=st.integers(min_value=0, max_value=20),
    checks=st.integers(min_value=1, max_value=5),
)
def test_wide_c_check_equals_the_reference(image, capacity, t_addr, checks):
    """Any image and layout: the C check over 32-bit T words frees the same slots and leaves the same bytes as the reference."""
    q_addr = t_addr + 4 * capacity
    a, b = bytearray(image), bytearray(image)
    checker = QueueChecker(a, t_addr, q_addr, capacity, wide=True)
    for _ in range(checks):
        assert checker.check() == ref_check_wide(b, t_addr, q_addr, capacity)
        assert a == b


def test_wide_check_decrements_past_a_byte():
    """A T word of 0x0100 is 256 checks, not 0 (the byte queue would read its low byte)."""
    mem = bytearray(16)
    mem[0:4] = (0x100).to_bytes(4, "little")
    mem[4:6] = (0x1234).to_bytes(2, "little")
    checker = QueueChecker(mem, 0, 4, 1, wide=True)
    ready = [checker.check() for _ in range(256)]
    assert ready[:255] == [[]] * 255 and ready[255] == [0x1234]
