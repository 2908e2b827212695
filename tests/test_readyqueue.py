"""The ready queue against hand-worked sequences from 002 ("The Ready Queue", Appendix A/B)."""

from __future__ import annotations

import pytest

from pyrt.errors import FaultError, QueueFullError
from pyrt.scheduler import ByteImage, Loop, ReadyQueue, SimClock

MVJAWS, SENSORS, WATCHJAW = 0x04C2, 0x0473, 0x0541


def make(divisor: int = 1, capacity: int = 6) -> tuple[Loop, ReadyQueue, list[tuple[int, str]]]:
    loop = Loop(SimClock(), period_ns=1_000_000)
    queue = ReadyQueue(capacity=capacity, divisor=divisor, name="test")
    log: list[tuple[int, str]] = []
    loop.attach(queue)
    return loop, queue, log


def periodic(loop: Loop, queue: ReadyQueue, log, address: int, name: str, period) -> None:
    queue.add_periodic(address, name, lambda: log.append((loop.tick_index + 1, name)), period)


def test_period_one_runs_on_every_queue_check():
    """A period-1 routine runs at every queue check (divisor 1: every tick)."""
    loop, queue, log = make(divisor=1)
    periodic(loop, queue, log, WATCHJAW, "WATCHJAW", 1)
    queue.schedule(WATCHJAW, 1)
    loop.run(10)
    assert [t for t, _ in log] == list(range(1, 11))


def test_period_0c_runs_every_twelfth_check():
    """A period-0C routine runs on checks 12, 24, 36 ..."""
    loop, queue, log = make(divisor=1)
    periodic(loop, queue, log, MVJAWS, "MVJAWS", 0x0C)
    queue.schedule(MVJAWS, 0x0C)
    loop.run(50)
    assert [t for t, _ in log] == [12, 24, 36, 48]


def test_divisor_four_checks_once_per_four_ticks():
    """SYSCLKPD 04: the queue is checked on ticks 4, 8, 12 ... and nowhere else."""
    loop, queue, log = make(divisor=4)
    periodic(loop, queue, log, WATCHJAW, "WATCHJAW", 1)
    queue.schedule(WATCHJAW, 1)
    loop.run(20)
    assert [t for t, _ in log] == [4, 8, 12, 16, 20]


def test_the_three_gripper_routines_hand_worked():
    """MVJAWS 0C, SENSORS 0A, WATCHJAW 01 at divisor 04: 002's default schedule, in slot order."""
    loop, queue, log = make(divisor=4)
    for addr, name, period in ((MVJAWS, "MVJAWS", 0x0C), (SENSORS, "SENSORS", 0x0A),
                               (WATCHJAW, "WATCHJAW", 0x01)):
        periodic(loop, queue, log, addr, name, period)
        queue.schedule(addr, period)
    loop.run(240)
    # Worked by hand: checks happen every 4th tick; WATCHJAW at every check,
    # SENSORS at checks 10, 20, ...; MVJAWS at checks 12, 24, ...; routines
    # ready at one check run in slot order MVJAWS, SENSORS, WATCHJAW.
    expected = []
    for check in range(1, 61):
        tick = 4 * check
        if check % 12 == 0:
            expected.append((tick, "MVJAWS"))
        if check % 10 == 0:
            expected.append((tick, "SENSORS"))
        expected.append((tick, "WATCHJAW"))
    assert log == expected
    assert log[:3] == [(4, "WATCHJAW"), (8, "WATCHJAW"), (12, "WATCHJAW")]
    assert (240, "MVJAWS") in log and log[-3:] == [(240, "MVJAWS"), (240, "SENSORS"),
                                                   (240, "WATCHJAW")]


def test_disabled_interrupts_freeze_the_queue():
    """With the clock interrupt disabled nothing runs and T and SYSCLKCNT keep their values."""
    loop, queue, log = make(divisor=4)
    periodic(loop, queue, log, MVJAWS, "MVJAWS", 0x0C)
    queue.schedule(MVJAWS, 0x0C)
    loop.run(6)  # one check done, SYSCLKCNT now 2
    before = bytes(queue.image.mem)
    queue.interrupts_enabled = False
    loop.run(1000)
    assert bytes(queue.image.mem) == before and log == []
    queue.interrupts_enabled = True
    loop.run(48 - 6)  # the 12th check falls on the 48th enabled tick
    assert log == [(1048, "MVJAWS")]


def test_period_variable_changed_mid_run():
    """A self-scheduling routine picks up a new period from its period variable at its next reschedule."""
    ram = bytearray([0x0C])
    loop, queue, log = make(divisor=1)
    periodic(loop, queue, log, MVJAWS, "MVJAWS", lambda: ram[0])
    queue.schedule(MVJAWS, ram[0])
    loop.run(30)  # runs at 12 and 24, rescheduled for 36
    ram[0] = 0x03
    loop.run(20)
    assert [t for t, _ in log] == [12, 24, 36, 39, 42, 45, 48]


def test_schedule_value_zero_means_256_checks():
    """8031 arithmetic: a schedule value of 00 decrements to FF first, so it runs after 256 checks."""
    loop, queue, log = make(divisor=1)
    queue.register(0x0100, "ONCE", lambda: log.append((loop.tick_index + 1, "ONCE")))
    queue.schedule(0x0100, 0)
    loop.run(300)
    assert log == [(256, "ONCE")]


def test_rescheduled_routine_never_runs_twice_in_one_check():
    """Snapshot rule: a routine scheduled with 1 while the ready ones run waits for the next check."""
    loop, queue, log = make(divisor=1)

    def first():
        log.append((loop.tick_index + 1, "FIRST"))
        queue.schedule(0x0200, 1)

    queue.register(0x0100, "FIRST", first)
    queue.register(0x0200, "SECOND", lambda: log.append((loop.tick_index + 1, "SECOND")))
    queue.schedule(0x0100, 1)
    loop.run(3)
    assert log == [(1, "FIRST"), (2, "SECOND")]


def test_queue_state_lives_in_an_external_byte_image():
    """T and Q sit in the caller's RAM (gripper: 2F and 35, little-endian addresses); writes there take effect."""
    ram = bytearray(128)
    image = ByteImage(ram, t_addr=0x2F, q_addr=0x35, cnt_addr=0x41, pd_addr=0x42, sema=(0x2C, 1))
    loop = Loop(SimClock())
    queue = ReadyQueue(capacity=6, divisor=4, image=image, name="gripper")
    loop.attach(queue)
    runs = []
    queue.add_periodic(MVJAWS, "MVJAWS", lambda: runs.append(loop.tick_index + 1), 0x0C)
    queue.schedule(MVJAWS, 0x0C)
    assert ram[0x2F] == 0x0C and ram[0x35] == 0xC2 and ram[0x36] == 0x04
    assert ram[0x41] == 4 and ram[0x42] == 4
    ram[0x2F] = 0x02  # the monitor's "C 2F 02": two checks to go
    loop.run(8)
    assert runs == [8]
    assert ram[0x2F] == 0x0C and (ram[0x35], ram[0x36]) == (0xC2, 0x04)


def test_wait_routine_sets_the_semaphore_after_n_checks():
    """002's wait: a foreground job clears SEMA, schedules WAIT, and resumes n checks later."""
    loop, queue, _ = make(divisor=4)
    marks = []

    def job():
        marks.append(loop.tick_index)
        yield from queue.wait(3)
        marks.append(loop.tick_index)
        return "done"

    j = loop.spawn("init", job())
    loop.run_until(lambda: j.done, 100)
    assert j.value() == "done"
    assert marks[1] - marks[0] <= 12 + 1 and marks[1] - marks[0] >= 12 - 4


def test_full_queue_refuses_outside_the_loop():
    """Scheduling into a full queue raises QueueFullError naming the routine."""
    _, queue, _ = make(capacity=2)
    queue.register(0x10, "A", lambda: None)
    queue.schedule(0x10, 5)
    queue.schedule(0x10, 6)
    with pytest.raises(QueueFullError, match="A"):
        queue.schedule(0x10, 7)


def test_full_queue_inside_a_tick_is_a_fault_with_reflex():
    """A routine that overfills the queue: the queue halts and tells its owner in the same tick; FaultError once."""
    loop, queue, _ = make(divisor=1, capacity=2)
    reflexes = []
    report = queue.on_error

    def owner(cause, source, tb):
        reflexes.append(loop.tick_index)
        report(cause, source, tb)

    queue.on_error = owner
    queue.register(0x20, "FILLER", lambda: None)

    def greedy():
        for _ in range(3):
            queue.schedule(0x20, 50)

    queue.register(0x10, "GREEDY", greedy)
    queue.schedule(0x10, 3)
    loop.run(10)
    assert reflexes == [2] and queue.halted  # the third tick has index 2
    with pytest.raises(FaultError) as err:
        loop.raise_pending()
    assert err.value.fault.source == "GREEDY" and "full" in err.value.fault.cause
    assert err.value.fault.tick == 2
    loop.raise_pending()  # reported exactly once


def test_raising_routine_stops_only_its_robot():
    """An exception in one robot's routine stops that queue; another robot's queue keeps running."""
    loop = Loop(SimClock())
    bad = ReadyQueue(divisor=1, name="bad")
    good = ReadyQueue(divisor=1, name="good")
    loop.attach(bad)
    loop.attach(good)
    counts = {"bad": 0, "good": 0}

    def crash():
        counts["bad"] += 1
        if counts["bad"] == 3:
            raise ZeroDivisionError("boom")

    bad.add_periodic(0x10, "CRASH", crash, 1)
    bad.schedule(0x10, 1)
    good.add_periodic(0x10, "FINE", lambda: counts.__setitem__("good", counts["good"] + 1), 1)
    good.schedule(0x10, 1)
    loop.run(10)
    assert counts == {"bad": 3, "good": 10}
    fault = loop.take_fault()
    assert fault is not None and fault.robot == "bad" and "ZeroDivisionError" in fault.cause
    assert "Traceback" in fault.traceback and fault.source == "CRASH"
    bad.resume()
    loop.run(5)
    assert counts == {"bad": 8, "good": 15}


def test_corrupted_q_address_is_a_fault_not_a_crash():
    """A Q slot holding an address with no routine (a bad monitor write) faults the robot cleanly."""
    loop, queue, _ = make(divisor=1)
    mem = queue.image.mem
    mem[queue.image.t_addr] = 1
    mem[queue.image.q_addr] = 0x34
    mem[queue.image.q_addr + 1] = 0x12
    loop.run(2)
    fault = loop.take_fault()
    assert fault is not None and "1234" in fault.cause


def test_bad_arguments_are_refused():
    """Schedule values outside a byte, unknown routines and bad addresses raise clear errors."""
    _, queue, _ = make()
    queue.register(0x10, "A", lambda: None)
    with pytest.raises(ValueError, match=r"00\.\.FF"):
        queue.schedule(0x10, 256)
    with pytest.raises(KeyError):
        queue.schedule("NOPE", 1)
    with pytest.raises(ValueError):
        queue.register(0, "ZERO", lambda: None)
    with pytest.raises(ValueError, match="already"):
        queue.register(0x10, "B", lambda: None)
    assert queue.pending() == []


def test_a_queue_sized_to_its_routines_keeps_timing_and_dispatch_as_it_grows():
    """A general queue that grows with each routine registered after timing was
    turned on still dispatches and times every routine, in C and in Python."""
    for native in (True, False):
        q = ReadyQueue(None, 1, name="g", wide=True, native=native)
        q.enable_timing(True)
        ran: list[str] = []
        for i in range(5):
            q.add_periodic(None, f"R{i}", lambda i=i, ran=ran: ran.append(f"R{i}"), i + 1)
            q.schedule(f"R{i}", 1)
        assert q.capacity == 6
        for t in range(1, 13):
            q.tick(t)
        calls = {a.name: a.calls for a in q.accumulators()}
        assert {f"R{i}": calls[f"R{i}"] for i in range(5)} == {
            f"R{i}": ran.count(f"R{i}") for i in range(5)}
        assert ran.count("R0") == 12 and ran.count("R4") == 3
