"""The runner: mailbox with timeout, motion queue, faults at the next call, the loop thread."""

from __future__ import annotations

import threading
from dataclasses import dataclass

import pytest

from pyrt.errors import FaultError, MailboxTimeout, QueueFullError
from pyrt.scheduler import Loop, ReadyQueue, SimClock, WallClock
from pyrt.scheduler.runner import MotionQueue, Runner


def sim_runner(**kw) -> tuple[Runner, ReadyQueue]:
    loop = Loop(SimClock())
    queue = ReadyQueue(divisor=1, name="bot")
    loop.attach(queue)
    runner = Runner(loop, **kw)
    runner.start()
    return runner, queue


@dataclass
class Move:
    target: list


def test_command_is_served_within_one_tick_on_simclock():
    """A mailbox call on a SimClock is taken and answered at the very next tick."""
    runner, _ = sim_runner()
    before = runner.loop.tick_index
    assert runner.call(lambda: runner.loop.tick_index) == before
    assert runner.loop.tick_index == before + 1


def test_mailbox_times_out_when_the_loop_is_stopped():
    """A call to a stopped runner raises MailboxTimeout naming the command, and leaves nothing queued."""
    runner, _ = sim_runner()
    runner.stop()
    with pytest.raises(MailboxTimeout, match="read_position"):
        runner.call(lambda: 1, name="read_position", timeout_s=0.01)
    assert not runner._mailbox


def test_mailbox_times_out_on_a_stopped_wallclock_loop():
    """Against a wall-clock loop that is not running, a call times out after its timeout."""
    loop = Loop(WallClock())
    runner = Runner(loop)
    with pytest.raises(MailboxTimeout, match="not running"):
        runner.call(lambda: 1, timeout_s=0.05)


def test_fault_is_reported_by_the_next_call_exactly_once():
    """A routine's exception comes back as FaultError from the next call, once; the queue stays stopped until ack."""
    runner, queue = sim_runner()
    runs = [0]

    def task():
        runs[0] += 1
        if runs[0] == 2:
            raise RuntimeError("encoder lost")

    queue.add_periodic(0x10, "POLL", task, 1)
    runner.call(queue.schedule, 0x10, 1)
    runner.sleep(0.01)
    with pytest.raises(FaultError, match="encoder lost") as err:
        runner.call(lambda: "move")
    assert err.value.fault.source == "POLL"
    assert runner.call(lambda: "again") == "again"  # reported once only
    runner.sleep(0.01)
    assert runs[0] == 2 and queue.halted  # nothing dispatched while faulted
    runner.call(queue.resume)
    runner.sleep(0.005)
    assert runs[0] > 2
    assert any("encoder lost" in m for m in runner.messages())


def test_poll_raises_a_pending_fault():
    """poll() is a no-op round trip that raises a pending fault."""
    runner, _queue = sim_runner()
    runner.call(runner.loop.fault_all, "limit switch", "check")
    with pytest.raises(FaultError, match="limit switch"):
        runner.poll()
    runner.poll()


def test_motion_records_are_copied_and_a_full_queue_refuses():
    """Motion records are copied whole before enqueueing; a full motion queue refuses with QueueFullError."""
    runner, _ = sim_runner(motion_queue=MotionQueue(capacity=2))
    record = Move([1.0, 2.0, 3.0])
    assert runner.submit_motion(record) == 1
    record.target[0] = 99.0  # the caller reuses its record
    assert runner.submit_motion(record) == 2
    with pytest.raises(QueueFullError, match="motion queue full"):
        runner.submit_motion(record)
    first = runner.call(runner.motion.get)
    assert first.target == [1.0, 2.0, 3.0]
    assert runner.call(runner.motion.get).target[0] == 99.0


def test_command_exception_propagates_and_the_loop_survives():
    """An exception raised by a command reaches the caller; the loop keeps serving."""
    runner, _ = sim_runner()
    with pytest.raises(ZeroDivisionError):
        runner.call(lambda: 1 / 0)
    assert runner.call(lambda: 5) == 5


def test_wait_until_and_sleep_advance_virtual_time():
    """wait_until runs the loop until the predicate holds or the timeout (loop time) passes."""
    runner, _ = sim_runner()
    t0 = runner.loop.now_ns
    assert runner.wait_until(lambda: runner.loop.now_ns - t0 >= 50_000_000, 1.0)
    assert not runner.wait_until(lambda: False, 0.2)
    runner.sleep(0.5)
    assert runner.loop.now_ns - t0 == pytest.approx(0.05e9 + 0.2e9 + 0.5e9, abs=3e6)


def test_wait_until_ends_with_the_fault():
    """A fault while waiting ends the wait with FaultError."""
    runner, queue = sim_runner()
    queue.register(0x20, "TRIP", lambda: runner.loop.fault_all("stall", "TRIP"))
    runner.call(queue.schedule, 0x20, 5)
    with pytest.raises(FaultError, match="stall"):
        runner.wait_until(lambda: False, 10.0)
    assert runner.loop.now_ns < 1e9


def test_run_job_returns_the_job_result():
    """A foreground job started through the runner runs to completion in loop time."""
    runner, queue = sim_runner()

    def job():
        yield from queue.wait(10)
        return 42

    def forever():
        while True:
            yield

    assert runner.run_job("init", job(), timeout_s=1.0) == 42
    with pytest.raises(MailboxTimeout, match="forever"):
        runner.run_job("forever", forever(), timeout_s=0.05)
    assert runner.loop.jobs == []


@pytest.mark.wallclock
def test_concurrent_callers_lose_or_duplicate_no_command():
    """Several threads calling a 1 kHz wall-clock loop: every command runs exactly once."""
    loop = Loop(WallClock())
    runner = Runner(loop)
    seen: list[tuple[int, int]] = []
    with runner:
        errors = []

        def client(k: int) -> None:
            try:
                for i in range(150):
                    # the mailbox's timeout a bound for a hang only (a loaded machine)
                    runner.call(seen.append, (k, i), timeout_s=30.0)
            except Exception as exc:  # pragma: no cover - reported below
                errors.append(exc)

        threads = [threading.Thread(target=client, args=(k,)) for k in range(4)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(120)
    assert not errors
    assert sorted(seen) == [(k, i) for k in range(4) for i in range(150)]
    for k in range(4):
        assert [i for kk, i in seen if kk == k] == list(range(150))


def test_statistics_are_built_outside_the_loop_and_lose_no_sample():
    """runner.statistics(): the loop only hands its samples over; every dispatch is counted once."""
    runner, queue = sim_runner()
    queue.add_periodic(0x30, "WORK", lambda: None, 1)
    runner.call(queue.schedule, 0x30, 1)
    runner.sleep(3.0)  # more than one fold's worth of samples
    first = runner.statistics().tasks["WORK"].calls
    ticks = runner.loop.tick_index
    assert ticks - 2 <= first <= ticks
    runner.sleep(0.5)
    second = runner.statistics().tasks["WORK"].calls
    assert runner.loop.tick_index - 2 <= second <= runner.loop.tick_index
    runner.stop()
    assert runner.loop.statistics().tasks["WORK"].calls == runner.loop.tick_index - 1


def test_a_raising_predicate_surfaces_to_the_waiter_on_simclock():
    """wait_until on a SimClock: a predicate that raises ends the wait with that exception, not as done."""
    runner, _ = sim_runner()
    calls = [0]

    def predicate() -> bool:
        calls[0] += 1
        if calls[0] > 3:
            raise KeyError("bad predicate")
        return False

    with pytest.raises(KeyError, match="bad predicate"):
        runner.wait_until(predicate, 1.0)
    assert runner.call(lambda: "alive") == "alive"


def test_a_raising_predicate_surfaces_to_the_waiter_on_a_wallclock_loop():
    """wait_until against a running wall-clock loop: the predicate's exception reaches the waiting caller; the loop goes on."""
    loop = Loop(WallClock())
    runner = Runner(loop)
    runner.start()
    try:
        calls = [0]

        def predicate() -> bool:
            calls[0] += 1
            if calls[0] > 3:
                raise ZeroDivisionError("bad predicate")
            return False

        with pytest.raises(ZeroDivisionError, match="bad predicate"):
            runner.wait_until(predicate, 5.0)
        assert not runner._waiters
        assert runner.call(lambda: "alive", timeout_s=2.0) == "alive"
        assert runner.wait_until(lambda: True, 2.0) is True
    finally:
        runner.stop()
