"""The loop's schedule: rate groups released by a plan per phase of their common cycle,
handlers switched on and off, and the loop's state as a snapshot keeps it."""

from __future__ import annotations

import pytest
from _clocks import MS, WorkClock
from hypothesis import given, settings
from hypothesis import strategies as st

from pyrt.errors import PyrtError
from pyrt.scheduler import Loop, RateGroup, ReadyQueue, SimClock, Task, _schedule
from pyrt.scheduler.runner import Runner
from pyrt.scope import Scope
from pyrt.scope.sources import Source


def countdown_reference(ticks: list[int], lefts: list[int], run: int,
                        skips: dict[int, int]) -> tuple[list[list[int]], list[int]]:
    """What each group's own countdown (the loop before schedules) released: per
    group the ticks (0-based) it was released in, and the releases each missed;
    ``skips[i]``: deadlines skipped after tick ``i``."""
    left = list(lefts)
    released: list[list[int]] = [[] for _ in ticks]
    missed = [0] * len(ticks)
    for i in range(run):
        for g, k in enumerate(ticks):
            left[g] -= 1
            if not left[g]:
                left[g] = k
                released[g].append(i)
        s = skips.get(i, 0)
        for g, k in enumerate(ticks):
            rest = left[g] - s
            if rest > 0:
                left[g] = rest
            else:
                missed[g] += -rest // k + 1
                left[g] = rest % k or k
    return released, missed


def grouped_loop(ticks: list[int], clock=None) -> tuple[Loop, list[RateGroup], list[list[int]]]:
    """A 1 ms loop with a group of each period (in ticks), each recording the ticks it ran in."""
    loop = Loop(clock if clock is not None else SimClock(), period_ns=MS)
    groups, seen = [], []
    for n, k in enumerate(ticks):
        ran: list[int] = []
        group = RateGroup(f"g{n}", period_ns=k * MS)
        group.attach(lambda now, ran=ran: ran.append(loop.tick_index), name=f"h{n}")
        loop.attach(group)
        groups.append(group)
        seen.append(ran)
    return loop, groups, seen


@settings(max_examples=60, deadline=None)
@given(st.lists(st.integers(1, 12), min_size=1, max_size=4), st.data())
def test_the_schedule_releases_each_group_when_its_own_countdown_did(ticks, data):
    """Over random periods and restored states, each group runs in exactly the ticks its countdown released it."""
    lefts = [data.draw(st.integers(1, k)) for k in ticks]
    loop, groups, seen = grouped_loop(ticks)
    for g, left in zip(groups, lefts, strict=True):
        g.restore_state([g.name, left, -1])
    loop.run(7)
    loop.run(53)  # two runs: the phase carries over
    want, _ = countdown_reference(ticks, lefts, 60, {})
    assert seen == want
    assert [g.left for g in groups] == [_left_after(k, left, 60)
                                        for k, left in zip(ticks, lefts, strict=True)]


def _left_after(k: int, left: int, run: int) -> int:
    """A countdown's ticks to the next release after ``run`` ticks."""
    for _ in range(run):
        left -= 1
        if not left:
            left = k
    return left


@settings(max_examples=40, deadline=None)
@given(st.lists(st.integers(1, 10), min_size=1, max_size=3),
       st.dictionaries(st.integers(3, 38), st.integers(1, 25), max_size=4))
def test_skipped_deadlines_keep_each_groups_grid(ticks, slow):
    """A tick that overruns by some deadlines: the releases among them are missed, counted, and the grids kept."""
    clock = WorkClock()
    loop, groups, seen = grouped_loop(ticks, clock)
    tick_work = {i: n * MS + MS // 2 for i, n in slow.items()}  # ends n deadlines late

    def work(now):
        clock.work(tick_work.get(loop.tick_index, 0))
    loop.attach(work, name="work")
    loop.run(40)  # tick 0 is on time: start-up is over, every overrun counts
    want, missed = countdown_reference(ticks, list(ticks), 40, slow)
    assert seen == want
    counted = loop.statistics().groups
    assert [counted[g.name].missed for g in groups] == missed
    assert [g.left for g in groups] == [_left_after(k, k, 40 + sum(slow.values())) for k in ticks]


def test_a_group_beyond_the_longest_cycle_counts_down_itself(monkeypatch):
    """Groups whose periods would make the cycle too long still release on their grids (the slowest counts down)."""
    monkeypatch.setattr(_schedule, "MAX_CYCLE", 12)
    loop, groups, seen = grouped_loop([4, 6, 5])
    loop.run(70)
    assert [g.name for g in loop._schedule.flat] == ["g0", "g1"]
    assert seen == countdown_reference([4, 6, 5], [4, 6, 5], 70, {})[0]
    assert [g.left for g in groups] == [_left_after(k, k, 70) for k in (4, 6, 5)]


def test_a_group_state_round_trips_and_a_bad_one_is_refused():
    """snapshot_state/restore_state carry a group's next release; a wrong name or count changes nothing."""
    loop, (g,), _ = grouped_loop([10])
    loop.run(13)
    state = g.snapshot_state()
    assert state == ["g0", 7, 9 * MS + MS]
    other, (h,), seen2 = grouped_loop([10])
    h.restore_state(state)
    other.run(7)
    assert seen2 == [[6]] and h.released_at == 7 * MS
    for bad in (["g1", 3, 0], ["g0", 0, 0], ["g0", 11, 0]):
        with pytest.raises(ValueError):
            h.restore_state(bad)
    assert h.snapshot_state() == ["g0", 10, 7 * MS]


def test_the_loop_state_round_trips():
    """A loop restored from another's snapshot_state goes on as that loop does: same tick, releases and queue."""
    def build() -> tuple[Loop, list[int]]:
        loop = Loop(SimClock(), period_ns=MS)
        ran: list[int] = []
        g = RateGroup("slow", period_ns=3 * MS)
        g.new_queue("arm", [Task(lambda: ran.append(loop.tick_index), period=2, name="t")])
        loop.attach(g)
        return loop, ran
    a, ran_a = build()
    a.run(8)
    state = a.snapshot_state()
    assert state["tick"] == 8 and state["groups"][0][:2] == ["slow", 1]
    b, ran_b = build()
    b.restore_state(state)
    a.run(20)
    b.run(20)
    assert ran_a[-len(ran_b):] == ran_b and ran_b
    with pytest.raises(ValueError, match="not the loop's"):
        b.restore_state({**state, "groups": [["slow", 1, 0], ["fast", 1, 0]]})
    before = b.snapshot_state()
    with pytest.raises(ValueError, match=r"outside 1\.\.3"):
        b.restore_state({**state, "tick": 99, "groups": [["slow", 4, 0]]})
    assert b.snapshot_state() == before  # refused whole: nothing changed


def test_a_handler_switched_off_is_neither_called_nor_timed():
    """enable(handler, False) leaves it out of the ticks; on again, it runs from the next tick."""
    loop = Loop(SimClock())
    calls: list[int] = []

    def h(now):
        calls.append(loop.tick_index)
    loop.attach(h, name="h")
    loop.attach(lambda now: loop.enable("h", loop.tick_index >= 4), name="switch")
    loop.run(8)
    # the switch runs after h: its change is taken at the next tick
    assert calls == [0, 5, 6, 7]
    assert loop.statistics().tasks["h"].calls == 4
    assert loop.enabled(h) and loop.enabled("switch")
    with pytest.raises(KeyError):
        loop.enable("nothing")


def test_a_job_spawned_in_a_tick_steps_in_that_tick():
    """A foreground job started by a handler (a mailbox command) takes its first step in the same tick."""
    loop = Loop(SimClock())
    steps: list[int] = []

    def job():
        while True:
            steps.append(loop.tick_index)
            yield

    loop.attach(lambda now: loop.tick_index == 2 and loop.spawn("j", job()), name="start")
    loop.run(5)
    assert steps == [2, 3, 4]


def test_the_scope_samples_only_while_it_acquires():
    """A scope at rest is no handler of the loop's ticks; running it switches its sampling on, stopping off."""
    loop = Loop(SimClock())
    scope = Scope()
    scope.attach_to(loop)
    scope.add("t", Source.call(lambda: float(loop.tick_index)))
    loop.run(3)
    assert not loop.enabled("scope") and loop.statistics().tasks["scope"].calls == 0
    scope.run("roll")
    loop.run(5)
    assert loop.enabled("scope") and loop.statistics().tasks["scope"].calls == 5
    scope.stop()
    loop.run(5)
    assert not loop.enabled("scope") and loop.statistics().tasks["scope"].calls == 5
    assert list(scope.read().column("t")) == [3.0, 4.0, 5.0, 6.0, 7.0]


def test_the_mailbox_runs_only_while_it_has_something_to_serve():
    """Between requests the mailbox is no handler of the ticks; a call is served all the same."""
    loop = Loop(SimClock())
    runner = Runner(loop)
    runner.start()
    runner.sleep(0.005)
    assert not loop.enabled(runner._service)
    assert runner.call(lambda: loop.tick_index) == 5
    assert not loop.enabled(runner._service)
    runner.sleep(0.003)
    assert loop.statistics().tasks["mailbox"].calls == 1


def test_restoring_a_group_while_its_loop_runs_is_refused():
    """A group's state is put back with the loop stopped (a PyrtError inside a tick)."""
    loop, (g,), _ = grouped_loop([2])
    errors: list[Exception] = []

    def restore(now):
        try:
            g.restore_state(["g0", 1, 0])
        except PyrtError as exc:
            errors.append(exc)
    loop.attach(restore, name="restore")
    loop.run(1)
    assert errors and "stopped" in str(errors[0])


def test_a_job_spawned_on_a_loop_of_queues_alone_is_timed_from_the_next_run():
    """The first plain handler (a job a routine spawned) of a loop that timed only routines is timed from the next run."""
    loop = Loop(SimClock())

    def job():
        while True:
            yield

    def spawn():
        if loop.tick_index == 1:
            loop.spawn("j", job())
    queue = ReadyQueue.general("arm")
    queue.add_periodic(None, "spawner", spawn, 1)
    queue.schedule("spawner", 1)
    loop.attach(queue)
    loop.run(3)  # spawned in tick 1: it steps in ticks 1 and 2, untimed (no clock reads this run)
    assert loop.statistics().tasks["jobs"].calls == 0
    loop.run(4)
    assert loop.statistics().tasks["jobs"].calls == 4
