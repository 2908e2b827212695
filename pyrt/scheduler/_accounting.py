"""The loop's accounting: rate groups joined, overruns charged, statistics built.

These are parts of :class:`~pyrt.scheduler.loop.Loop` kept apart from its
tick: what happens when a group is attached, when a tick overruns (which
task and group it is charged to, which groups' releases it made them miss)
and how a snapshot of the timing is built.  Nothing here runs on a tick
that ends on time.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from pyrt.errors import ConfigError
from pyrt.scheduler.gcwatch import attribute
from pyrt.scheduler.rategroup import GroupTiming, RateGroup
from pyrt.scheduler.readyqueue import ReadyQueue
from pyrt.scheduler.stats import (
    Accumulator,
    GroupStatistics,
    LoopStatistics,
    TaskStatistics,
)

if TYPE_CHECKING:
    from pyrt.scheduler.loop import Loop

__all__ = ["attach_group", "group_name", "join_member", "record_overrun", "skip_groups",
           "statistics"]


def group_name(loop: Loop, name: str) -> str:
    """``name`` for a group of a queue attached alone (a second gets ``#2``)."""
    taken = {g.name for g in loop._groups}
    key, n = name, 1
    while key in taken:
        n += 1
        key = f"{name} #{n}"
    return key


def attach_group(loop: Loop, group: RateGroup) -> None:
    """Attach ``group`` to ``loop``: its period checked against the tick, its
    members joined, its place in the rate-monotonic order taken."""
    if group._loop is not None:
        raise ConfigError(f"rate group {group.name} is already attached to a loop")
    if any(g.name == group.name for g in loop._groups):
        raise ConfigError(f"a rate group named {group.name!r} is already on this loop")
    group.bind(loop.period_ns)
    group._loop = loop
    group.set_timer(loop.clock.timer if loop.timing else None)
    loop.rate_groups.append(group)
    loop._groups.append(group.timing)
    for name, member in group.members:
        join_member(loop, group, name, member)
    loop._add(group.period_ns, group.name, group.tick, loop._times.sink.append, group)


def join_member(loop: Loop, group: RateGroup, name: str, member: Any) -> None:
    """``member`` of ``group`` runs at its releases: a queue is the loop's
    (faults, timing) in that group; a handler is timed as an entry."""
    if isinstance(member, ReadyQueue):
        loop._take_queue(member, group.timing)
        group.add_run(member.tick, loop._times.sink.append, name, own=False)
        group.order.append(member)
    else:
        entry = loop._times.add(name)
        loop._entry_group[entry.name] = group.timing
        group.add_run(member, entry.samples.append, entry.name)
        group.order.append(entry)
    loop._changed()


def skip_groups(loop: Loop, skipped: int, count: bool = True) -> dict[str, int]:
    """``skipped`` deadlines passed: each group's releases among them are
    missed (counted with ``count``; start-up ticks are not); returns the
    groups that missed releases and how many."""
    missed: dict[str, int] = {}
    own = set()
    for rg in loop.rate_groups:
        own.add(id(rg.timing))
        n = rg.skip(skipped)
        if n and count:
            rg.timing.missed += n
            missed[rg.name] = n
    if count and skipped:
        for g in loop._groups:
            if id(g) not in own:  # a queue attached alone: every tick is a release
                g.missed += skipped
                missed[g.name] = skipped
    return missed


def _ran_in_tick(loop: Loop, start: int) -> tuple[list[tuple[str, int]], list[Any],
                                                  list[GroupTiming | None]]:
    """What ran in the tick that started at ``start``, in order: names and
    durations, who keeps their count, and their groups."""
    tasks: list[tuple[str, int]] = []
    owners: list[Any] = []
    groups: list[GroupTiming | None] = []
    timed = loop._timing_handlers
    keys = loop._entry_keys() if timed else {}
    tick = loop.tick_index - 1

    def queue(q: ReadyQueue, g: GroupTiming) -> None:
        ran = q.tasks_in_tick(start)
        tasks.extend(ran)
        owners.extend([q] * len(ran))
        groups.extend([g] * len(ran))

    def entry(e: Any, g: GroupTiming | None) -> None:
        d = loop._times.last_duration(e, tick) if timed else None
        if d is not None:
            tasks.append((keys[e.name], d))
            owners.append(e)
            groups.append(g)

    for item in loop._order:
        if isinstance(item, ReadyQueue):
            queue(item, loop._group_of[id(item)])
        elif isinstance(item, RateGroup):
            if item.released_at == start:
                for m in item.order:
                    if isinstance(m, ReadyQueue):
                        queue(m, item.timing)
                    else:
                        entry(m, item.timing)
        else:
            entry(item, None)
    return tasks, owners, groups


def record_overrun(loop: Loop, deadline: int, start: int, end: int, skipped: int) -> None:
    """The tick that started at ``start`` ended at ``end``, after the next
    deadline: count it, charge it to the task that ran longest and to its
    group, count the releases it made each group miss, log it, warn."""
    loop._starting = False
    loop.overruns += 1
    loop.missed += skipped
    loop.consecutive_overruns += 1
    tick = loop.tick_index - 1
    tasks, owners, groups = _ran_in_tick(loop, start)
    pauses = loop._gc.pauses_in(tick)
    if pauses:  # a collection inside the tick: its pause is an entry of its own
        tasks = attribute(tasks, pauses)
        owners.append(loop._gc)
        groups.append(None)
    culprit = ""
    charged: GroupTiming | None = None
    if tasks:
        i = max(range(len(tasks)), key=lambda k: tasks[k][1])
        culprit, owner, charged = tasks[i][0], owners[i], groups[i]
        if isinstance(owner, ReadyQueue):
            owner.count_overrun(culprit)
        else:
            owner.acc.overruns += 1
        if charged is not None:
            charged.acc.overruns += 1
    missed = skip_groups(loop, skipped)
    lateness = end - deadline - loop.period_ns
    if loop.timing_log is not None:
        loop.timing_log.overrun(
            tick=tick,
            deadline_ns=deadline,
            start_ns=start,
            end_ns=end,
            lateness_ns=start - deadline,
            overrun_ns=lateness,
            missed=skipped,
            group=charged.name if charged is not None else None,
            missed_releases=missed,
            tasks=tasks,
            task_groups=[g.name if g is not None else "" for g in groups],
        )
    label = f"{culprit} [{charged.name}]" if charged is not None and loop.rate_groups else culprit
    loop._warnings.overrun(start, lateness, tick, label)
    limit = loop.max_consecutive_overruns
    if limit is not None and loop.consecutive_overruns >= limit:
        loop.fault_all(
            f"{loop.consecutive_overruns} consecutive overruns "
            f"(limit {limit}, tick {loop.period_ns / 1e3:g} µs)",
            source="loop",
        )
        loop.consecutive_overruns = 0


def take_groups(loop: Loop) -> list[tuple[GroupTiming, list[int]]]:
    """Hand over each group's release times recorded so far (loop thread)."""
    taken = []
    for g in loop._groups:
        s = g.samples
        if s:
            taken.append((g, s[:]))
            s.clear()  # the same list: a queue's group records into it
    return taken


def _task_statistics(name: str, acc: Accumulator, kind: str, group: str = "") -> TaskStatistics:
    dist = acc.distribution()
    return TaskStatistics(name=name, calls=acc.calls, mean_ns=dist.mean_ns, max_ns=acc.max,
                          p99_ns=dist.p99_ns, overruns=acc.overruns, distribution=dist,
                          kind=kind, group=group)


def groups_in_order(loop: Loop) -> list[GroupTiming]:
    """The groups as they run: fastest first, equal periods as attached."""
    return sorted(loop._groups, key=lambda g: g.period_ns)


def statistics(loop: Loop, fold: bool) -> LoopStatistics:
    """The snapshot :meth:`Loop.statistics` returns (see there)."""
    tasks: dict[str, TaskStatistics] = {}
    members: dict[int, list[str]] = {id(g): [] for g in loop._groups}
    for q in loop.queues:
        g = loop._group_of[id(q)]
        for acc in q.accumulators(fold=fold):
            key = acc.name if acc.name not in tasks else f"{acc.name} ({g.name})"
            tasks[key] = _task_statistics(key, acc, "task", g.name)
            members[id(g)].append(key)
    if loop.timing:
        if fold:
            loop._times.fold(loop._times.take(loop.tick_index), take_groups(loop))
        keys = loop._entry_keys()
        with loop._times.lock:
            for e in loop._times.entries:
                eg = loop._entry_group.get(e.name)
                key = keys[e.name]
                tasks[key] = _task_statistics(key, e.acc, "handler",
                                              eg.name if eg is not None else "")
                if eg is not None:
                    members[id(eg)].append(key)
    gcw = loop._gc
    for acc in (gcw.acc, gcw.idle_acc):
        if acc.calls:  # collections: inside ticks (blamed for overruns), idle
            tasks[acc.name] = _task_statistics(acc.name, acc, "gc")
    own = {id(rg.timing) for rg in loop.rate_groups}
    groups = {}
    with loop._times.lock:
        for g in groups_in_order(loop):
            dist = g.acc.distribution()
            groups[g.name] = GroupStatistics(
                name=g.name, period_ns=g.period_ns,
                releases=g.releases if id(g) in own else loop.tick_index,
                mean_ns=dist.mean_ns, max_ns=g.acc.max, p99_ns=dist.p99_ns,
                overruns=g.acc.overruns, missed=g.missed, distribution=dist,
                tasks=tuple(members[id(g)]))
    with loop._times.lock:  # a fold in another thread (a timing log's) updates them
        lateness, work = loop._lateness.distribution(), loop._work.distribution()
    return LoopStatistics(
        period_ns=loop.period_ns,
        ticks=loop.tick_index,
        overruns=loop.overruns,
        missed=loop.missed,
        consecutive_overruns=loop.consecutive_overruns,
        startup_overruns=loop.startup_overruns,
        startup_worst_ns=loop.startup_worst_ns,
        lateness=lateness,
        work=work,
        tasks=tasks,
        groups=groups,
    )


def group_table(loop: Loop) -> list[dict[str, Any]]:
    """The groups for the timing log's header: name, period, task names."""
    keys = loop._entry_keys() if loop.timing else {}
    out = []
    for g in groups_in_order(loop):
        names = [r.name for q in loop.queues if loop._group_of[id(q)] is g
                 for r in q.routines]
        names += [keys.get(n, n) for n, eg in loop._entry_group.items() if eg is g]
        out.append({"name": g.name, "period_ns": g.period_ns, "tasks": names})
    return out
