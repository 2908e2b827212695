"""The tick loop: deadlines, lateness, overruns, handlers and foreground jobs.

Rate groups (:mod:`pyrt.scheduler.rategroup`) are released at their own
periods, fastest first; a queue attached directly is a group of the tick.
Which groups a tick releases is worked out before the loop runs
(:mod:`pyrt.scheduler._schedule`): each tick takes the plan of its phase in
the groups' common cycle and runs it, the released groups' members in their
groups' places.

One tick: wait for the deadline; record lateness; call each handler with the
tick's time (the plant, then each robot's clock interrupt, then the mailbox
and foreground jobs: whatever was attached, in attachment order); record the
work time.  An **overrun** is a tick whose work ends after the next deadline.
Deadlines that have already passed are counted as missed and skipped, never
run back to back.

On a :class:`~pyrt.scheduler.clock.SimClock` nothing of this costs real time
and no tick can overrun; the same code runs deterministically in the caller's
thread.  Timing statistics are optional and cost nothing when off.

With timing on, every handler that is not a ready queue (board polls,
physics, the motion executor, the scope, the mailbox, foreground jobs) is
timed as an entry of its own, beside the queues' routines: the clock is read
once between handlers (the end of one is the start of the next), each
duration is appended to the handler's sample list, and the lists are folded
into histograms in bulk, off the tick (:meth:`Loop.take_samples`).  A rate
group's release is the sum of its members' durations.  An overrun is
attributed to whichever entry, routine or handler, took longest in its tick.
A handler can be switched off (:meth:`Loop.enable`; the scope while it does
not acquire): it is left out of the ticks until switched on, untimed.

On real time the loop keeps the garbage collector out of its ticks
(:mod:`pyrt.scheduler.gcwatch`): the start-up heap frozen, automatic
collection off while it runs, collections in the idle part of a tick, and
any collection inside a tick counted (the entry ``gc``) and blamed for the
overrun it causes.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Callable, Generator
from gc import get_count as gc_count
from itertools import count
from threading import get_ident
from typing import Any

from pyrt.errors import Fault, FaultError, PyrtError
from pyrt.scheduler import _accounting
from pyrt.scheduler._composition import LoopComposition
from pyrt.scheduler._handlertiming import TakenSamples
from pyrt.scheduler.clock import Clock, SimClock, WallClock
from pyrt.scheduler.gcwatch import GcWatch
from pyrt.scheduler.rategroup import GroupTiming, RateGroup
from pyrt.scheduler.readyqueue import ReadyQueue
from pyrt.scheduler.stats import LoopStatistics

__all__ = ["Job", "Loop", "TakenSamples", "overrun_line"]

#: A loop time no run reaches (a run without ``duration_ns`` ends there).
_NEVER = 1 << 126

Handler = Callable[[int], None]


class Job:
    """A foreground job: a generator stepped once per tick by the loop.

    This is where command sequences run that the 8031 ran in its main
    program between interrupts (``init``, ``fullopen``): they ``yield`` to
    let time pass (``yield from queue.wait(n)``) and end by returning a value.
    """

    __slots__ = ("_gen", "done", "error", "name", "result")

    def __init__(self, name: str, gen: Generator[Any, None, Any]):
        self.name = name
        self._gen = gen
        self.done = False
        self.result: Any = None
        self.error: BaseException | None = None

    def step(self) -> bool:
        """Advance one step; return True once the job has finished."""
        if self.done:
            return True
        try:
            next(self._gen)
        except StopIteration as stop:
            self.result = stop.value
            self.done = True
        except Exception as exc:
            self.error = exc
            self.done = True
        return self.done

    def cancel(self) -> None:
        """Stop the job where it is (its ``finally`` blocks run)."""
        if not self.done:
            self._gen.close()
            self.done = True

    def value(self) -> Any:
        """The job's return value; re-raises what the job raised."""
        if not self.done:
            raise PyrtError(f"job {self.name} has not finished")
        if self.error is not None:
            raise self.error
        return self.result


class Loop(LoopComposition):
    """A periodic tick loop.

    ``clock`` is a :class:`SimClock` or :class:`WallClock`; ``period_ns`` the
    tick (1 ms by default).  ``timing`` turns on per-tick lateness/work and
    per-task execution statistics.  ``max_consecutive_overruns`` (OROCOS's
    maxOverRun): that many overruns in a row fault every attached robot.
    ``warn`` receives at most one overrun summary line per second of loop
    time (one line of at most :attr:`WARN_WIDTH` characters, with the count);
    the full detail goes to ``timing_log`` and :meth:`statistics`.
    ``gc_control`` (on a :class:`WallClock`): freeze the start-up heap, switch
    automatic garbage collection off while running and collect in the idle
    part of ticks (see :mod:`pyrt.scheduler.gcwatch`); collections inside
    ticks are counted either way.

    **Start-up**: the first ticks a loop ever runs execute its code for the
    first time (imports, caches, the first command); until the first tick
    that ends on time, at most :attr:`STARTUP_TICKS` of them, their overruns
    are counted apart (``startup_overruns``, ``startup_worst_ns``), not as
    overruns: no warning, no timing-log record, no consecutive-overrun fault.
    Their passed deadlines are skipped as always (not counted as missed).
    """

    #: At most this many ticks at the start of a loop's life count as start-up.
    STARTUP_TICKS = 3
    #: An overrun warning line is never wider than this (a terminal's width).
    WARN_WIDTH = 80

    def __init__(
        self,
        clock: Clock | None = None,
        period_ns: int = 1_000_000,
        *,
        timing: bool = True,
        timing_log: Any = None,
        max_consecutive_overruns: int | None = None,
        warn: Callable[[str], None] | None = None,
        summary_interval_ns: int = 1_000_000_000,
        gc_control: bool = True,
    ):
        if period_ns <= 0:
            raise ValueError(f"tick period must be positive, got {period_ns} ns")
        if max_consecutive_overruns is not None and max_consecutive_overruns < 1:
            raise ValueError("max_consecutive_overruns must be >= 1 or None")
        self.clock: Clock = clock if clock is not None else SimClock()
        self.period_ns = int(period_ns)
        self.timing = timing
        self.timing_log = timing_log
        self.max_consecutive_overruns = max_consecutive_overruns
        self.warn = warn
        self.summary_interval_ns = int(summary_interval_ns)

        self._init_composition()
        # The rate groups (a queue attached alone is one), the RateGroups, and
        # the group of each queue (by id).
        self._groups: list[GroupTiming] = []
        self.rate_groups: list[RateGroup] = []
        self._group_of: dict[int, GroupTiming] = {}
        self.queues: list[ReadyQueue] = []
        self._jobs: deque[Job] = deque()
        self._jobs_attached = False
        self._faults: deque[Fault] = deque()
        self._fault_ids = 0
        #: Called (in the loop thread) with each fault as it is recorded.
        self.fault_listeners: list[Callable[[Fault], None]] = []
        #: ``trip(cause, source)`` of each station on this loop (see :meth:`fault_all`).
        self.trip_handlers: list[Callable[[str, str], Any]] = []
        self._bare_queues: list[ReadyQueue] = []
        self._fault_lock = threading.Lock()
        self._stopping = False
        self.running = False
        #: The name of the handler (or foreground job) running now in the loop's
        #: thread: ``"loop"`` between its handlers while a run lasts, ``""``
        #: outside one.  A ready queue says which routine (:attr:`ReadyQueue.running`);
        #: :meth:`writer` puts the two together.
        self.current = ""
        self._thread_id: int | None = None

        self.tick_index = 0
        self.now_ns = self.clock.now_ns()
        self._deadline = self.now_ns + self.period_ns
        self.overruns = 0
        self.missed = 0
        self.consecutive_overruns = 0
        #: Overruns of start-up ticks (not counted in ``overruns``), and the worst (ns over).
        self.startup_overruns = 0
        self.startup_worst_ns = 0
        self._starting = True
        # each tick's lateness and work: appended to sample lists as the
        # handlers' durations are, folded with them off the tick
        self._lateness = self._times.lateness.acc
        self._work = self._times.work.acc
        self._late_sample = self._times.lateness.samples.append
        self._work_sample = self._times.work.samples.append
        self._next_summary = self.now_ns + self.summary_interval_ns
        self._warnings = _OverrunWarnings(self)
        self._log_started = False
        self.gc_control = gc_control
        self._gc = GcWatch(lambda: self.tick_index, self.clock.timer)

    @property
    def deadline_ns(self) -> int:
        """The deadline of the tick being run (in a handler: its lateness is
        ``now_ns - deadline_ns``), or of the next one between ticks."""
        return self._deadline

    def resume_at(self, now_ns: int, deadline_ns: int) -> None:
        """Between runs: the loop's time is ``now_ns`` and the next tick's deadline
        ``deadline_ns`` (a replay resuming a run mid-way, from a snapshot)."""
        if self.running:
            raise PyrtError("set the loop's time while it is stopped")
        self.now_ns = int(now_ns)
        self._deadline = int(deadline_ns)

    # -- foreground jobs -----------------------------------------------------

    def spawn(self, name: str, gen: Generator[Any, None, Any]) -> Job:
        """Run ``gen`` as a foreground job, one step per tick after the handlers."""
        job = Job(name, gen)
        self._jobs.append(job)
        if not self._jobs_attached:
            self._attach_timed(self._step_jobs, "jobs")
            self._jobs_attached = True
        return job

    def _step_jobs(self, now_ns: int) -> None:
        jobs = self._jobs
        for _ in range(len(jobs)):
            job = jobs.popleft()
            self.current = job.name
            if not job.step():
                jobs.append(job)
        self.current = "jobs"

    @property
    def handler_names(self) -> list[str]:
        """The names of the handlers, in the order a tick runs them."""
        return list(self._handler_names)

    def writer(self) -> str:
        """Who is running now, by name, as a journal stamps an output write: the
        routine a ready queue is dispatching (its name), else the loop's handler
        or foreground job (:attr:`current`; ``"loop"`` for the loop's own work
        between handlers, the reflex of a consecutive-overrun fault), else
        ``"outside a task"`` (no run, or a thread other than the loop's).  Two
        attribute reads per queue: no stack is walked."""
        if self._thread_id != get_ident():
            return "outside a task"
        for q in self.queues:
            name = q.running
            if name is not None:
                return name
        return self.current or "outside a task"

    def writer_names(self) -> list[str]:
        """The names :meth:`writer` gives that are known before a run: every
        routine of every queue and every handler that is not a queue, sorted
        (a journal's table of writers starts with them)."""
        names = {r.name for q in self.queues for r in q.routines}
        names.update(n for n, item in zip(self._handler_names, self._order, strict=False)
                     if not isinstance(item, ReadyQueue))
        return sorted(names)

    @property
    def jobs(self) -> list[Job]:
        """Foreground jobs that have not finished."""
        return list(self._jobs)

    # -- faults --------------------------------------------------------------

    def make_fault(self, robot: str, cause: str, source: str = "", tb: str = "") -> Fault:
        """A fault record stamped with this tick and loop time and the next event id."""
        self._fault_ids += 1
        return Fault(robot=robot, cause=cause, source=source, tick=self.tick_index,
                     time_ns=self.now_ns, traceback=tb, id=self._fault_ids)

    def report_fault(self, fault: Fault) -> None:
        """Queue ``fault`` for the application: the next mailbox call raises it
        (each fault once), and the listeners hear of it now (loop thread)."""
        with self._fault_lock:
            self._faults.append(fault)
        for listener in self.fault_listeners:
            listener(fault)

    def has_fault(self) -> bool:
        """True while a fault waits to be reported."""
        return bool(self._faults)

    @property
    def pending_faults(self) -> deque[Fault]:
        """The faults waiting to be reported, oldest first: the loop's own queue
        (the same object for the loop's life; read it, take with :meth:`take_fault`)."""
        return self._faults

    def take_fault(self, fault: Fault | None = None) -> Fault | None:
        """The oldest fault not yet reported, removed from the pending list; or,
        given ``fault`` (shown to the operator another way), that one removed."""
        with self._fault_lock:
            if fault is None:
                return self._faults.popleft() if self._faults else None
            for pending in self._faults:
                if pending is fault:
                    self._faults.remove(pending)
                    return pending
            return None

    def raise_pending(self) -> None:
        """Raise :class:`FaultError` for the oldest unreported fault (each once)."""
        fault = self.take_fault()
        if fault is not None:
            raise FaultError(fault)

    def fault_all(self, cause: str, source: str = "loop") -> None:
        """Trip every robot on this loop (their reflex actions run now): the
        owners in :attr:`trip_handlers`, and any ready queue no station owns."""
        for trip in list(self.trip_handlers):
            trip(cause, source)
        for q in self._bare_queues:
            if not q.halted:
                q.halt()
                self.report_fault(self.make_fault(q.name, cause, source))

    # -- running -------------------------------------------------------------

    def stop(self) -> None:
        """Ask the loop to return after the current tick (thread-safe)."""
        self._stopping = True

    def run(
        self,
        ticks: int | None = None,
        *,
        until: Callable[[], bool] | None = None,
        duration_ns: int | None = None,
    ) -> int:
        """Run ticks until ``ticks`` have run, ``until()`` is true after a tick,
        ``duration_ns`` of loop time has passed, or :meth:`stop` is called.
        With none of these it runs until stopped.  Returns the ticks run."""
        if self.running:
            raise PyrtError("the loop is already running")
        if ticks is not None and ticks < 0:
            raise ValueError(f"ticks must be >= 0, got {ticks}")
        self._stopping = False
        if not self.clock.virtual:
            # Time while the loop was not running (building the station,
            # between runs) is nobody's lateness: the first deadline is now.
            now = self.clock.now_ns()
            if self._deadline < now:
                self._deadline = now
        end_ns = self.now_ns + duration_ns if duration_ns is not None else None
        if self._dirty:
            self.reschedule()
        elif self._timing_handlers != self._timed_now():
            # a job spawned in the last run is the loop's first handler: timed from now on
            with self._plan_lock:
                self._timing_handlers = self._timed_now()
                self._schedule.plan(self._attached, self._timing_handlers, self._off)
        self.running = True
        self._thread_id = get_ident()
        self.current = "loop"
        try:
            self._gc.begin(self.gc_control and isinstance(self.clock, WallClock))
            self._start_log()
            return self._run(ticks, until, end_ns)
        finally:
            self._gc.end()
            self.running = False
            self.current = ""
            self._thread_id = None
            if self.timing_log is not None:
                self.timing_log.flush()

    def run_until(self, predicate: Callable[[], bool], max_ticks: int) -> bool:
        """Run until ``predicate()`` holds (checked after each tick) or
        ``max_ticks`` ticks have run; return whether the predicate held."""
        if predicate():
            return True
        self.run(max_ticks, until=predicate)
        return predicate()

    def _run(self, ticks: int | None, until: Callable[[], bool] | None,
             end_ns: int | None) -> int:
        """The tick loop, one for every clock: wait for the deadline (the clock
        decides how: virtual time moves there, real time sleeps and spins),
        call the handlers, and close the tick.  On real time, closing it
        measures lateness and work, detects an overrun (the passed deadlines
        skipped) and collects garbage in the idle rest of the tick; virtual
        time has nothing to measure."""
        clock = self.clock
        start_tick = clock.start_tick
        measured = not clock.virtual
        schedule = self._schedule
        keys = schedule.keys  # groups are not attached while the loop runs
        cycle_len = len(keys)
        phase = self._phase
        timed = self._timing_handlers
        timer = clock.timer
        period = self.period_ns
        deadline = self._deadline
        summary_at = self._next_summary
        end = end_ns if end_ns is not None else _NEVER
        # virtual time as SimClock keeps it: moved to the deadline here, no call
        sim = clock if (isinstance(clock, SimClock)
                        and type(clock).start_tick is SimClock.start_tick) else None
        first = self.tick_index
        for _ in count() if ticks is None else range(ticks):
            if sim is not None:
                if deadline > sim._now:
                    sim._now = deadline
                start = deadline
            else:
                start = start_tick(deadline)
            self.now_ns = start
            # the plan of the tick's phase (read each tick: a handler switched on
            # or off makes new plans), the phase of the next tick
            entries, released = schedule.plans[keys[phase]]
            phase += 1
            if phase == cycle_len:
                phase = 0
            self._phase = phase
            for group, gt in released:
                group.released_at = start
                gt.releases += 1
            # each handler is named in `current` as it runs (who writes an output)
            if timed:
                t0 = timer()
                for h, record, name in entries:
                    self.current = name
                    h(start)
                    t1 = timer()
                    record(t1 - t0)  # type: ignore[misc]  # timed: every entry records
                    t0 = t1
            else:
                for h, _, name in entries:
                    self.current = name
                    h(start)
            self.current = "loop"
            self.tick_index += 1
            if measured:
                deadline = self._close_tick(deadline, start)
                phase = self._phase  # an overrun skipped ticks: their phases too
            else:
                deadline += period
            self._deadline = deadline
            if start >= summary_at:
                self._summary(start)
                summary_at = self._next_summary
            if self._stopping or (until is not None and until()) or deadline > end:
                break
        return self.tick_index - first

    def _close_tick(self, deadline: int, start: int) -> int:
        """The end of a tick on real time: its lateness and work recorded, an
        overrun detected (the deadlines it passed counted and skipped), an idle
        collection if half a tick is left; returns the next deadline."""
        clock = self.clock
        period = self.period_ns
        nxt = deadline + period
        end = clock.now_ns()
        if self.timing:
            self._late_sample(start - deadline)
            self._work_sample(end - start)
        if end > nxt:
            skipped = (end - nxt + period - 1) // period
            if self._starting and self.tick_index <= self.STARTUP_TICKS:
                self._startup_overrun(end - nxt, skipped)
            else:
                self._overrun(deadline, start, end, skipped)
            nxt += skipped * period
            # the groups (asked above what they missed) keep their grids
            self._phase = (self._phase + skipped) % self._schedule.length
        else:
            self.consecutive_overruns = 0
            self._starting = False
        gcw = self._gc
        if gcw.controlling and gc_count()[0] >= gcw.threshold and (
                nxt - clock.now_ns() > period // 2 or gcw.forced()):
            gcw.collect_idle()
        return nxt

    # -- overruns ------------------------------------------------------------

    def _startup_overrun(self, over_ns: int, skipped: int) -> None:
        if self.rate_groups:  # their grids keep to time; nothing is counted
            _accounting.skip_groups(self, skipped, count=False)
        self.startup_overruns += 1
        if over_ns > self.startup_worst_ns:
            self.startup_worst_ns = over_ns

    def _overrun(self, deadline: int, start: int, end: int, skipped: int) -> None:
        _accounting.record_overrun(self, deadline, start, end, skipped)

    def _summary(self, now: int) -> None:
        self._next_summary = now + self.summary_interval_ns
        self._warnings.due(now)
        log = self.timing_log
        if log is not None:
            # Hand the raw samples over (O(1)); fold, build and write elsewhere.
            taken = self.take_samples()

            def write_summary() -> None:
                self.fold_samples(taken)
                log.summary(now, self.statistics(fold=False))

            log.defer(write_summary)
        elif self.timing:
            self._times.fold(self._times.take(self.tick_index), _accounting.take_groups(self))

    def _start_log(self) -> None:
        if self.timing_log is not None and not self._log_started:
            names = [r.name for q in self.queues for r in q.routines]
            if self.timing:
                names += list(self._entry_keys().values())
            self.timing_log.header(
                period_ns=self.period_ns,
                clock=type(self.clock).__name__,
                tasks=names,
                handlers=list(self._handler_names),
                groups=_accounting.group_table(self),
            )
            self._log_started = True

    def close(self) -> None:
        """Write a final summary and close the timing log, if there is one."""
        if self.timing_log is not None:
            self._start_log()
            log, self.timing_log = self.timing_log, None
            log.drain()  # the deferred summaries first, then the final one
            log.summary(self.now_ns, self.statistics())
            log.close()

    # -- statistics ----------------------------------------------------------

    def _entry_keys(self) -> dict[str, str]:
        return self._times.keys({r.name for q in self.queues for r in q.routines})

    def take_samples(self) -> TakenSamples:
        """Hand over the timing samples recorded so far, of every queue and
        handler (call it in the loop thread; O(queues + handlers) plus a copy
        of the handlers' lists), to be folded by :meth:`fold_samples` in
        any thread."""
        return TakenSamples([(q, q.take_samples()) for q in self.queues],
                            self._times.take(self.tick_index), _accounting.take_groups(self))

    def fold_samples(self, taken: TakenSamples) -> None:
        """Fold samples handed over by :meth:`take_samples` (any thread)."""
        for q, samples in taken.queues:
            q.fold_into_accumulators(samples)
        self._times.fold(taken.handlers, taken.groups)

    def statistics(self, fold: bool = True) -> LoopStatistics:
        """A frozen snapshot of lateness, work time and per-task timing: the
        ready queues' routines and, as entries of their own
        (``kind="handler"``), the other handlers; and per rate group
        (``groups``) its releases, time per release and overruns.

        With ``fold`` (call it in the loop thread, or with the loop stopped)
        the samples recorded since the last fold are included; a runner builds
        the snapshot outside the loop thread instead
        (:meth:`~pyrt.scheduler.runner.Runner.statistics`)."""
        return _accounting.statistics(self, fold)

    def reset_statistics(self) -> None:
        """Forget timing recorded so far (LinuxCNC's tmax reset); counts too."""
        self._lateness.reset()
        self._work.reset()
        for q in self.queues:
            for acc in q.accumulators():
                acc.reset()
        self._times.reset()
        for g in self._groups:
            g.reset()
        self._gc.reset()
        self.overruns = self.missed = self.consecutive_overruns = 0
        self.startup_overruns = self.startup_worst_ns = 0


class _OverrunWarnings:
    """At most one overrun line a second for :attr:`Loop.warn`: how many
    ticks overran since the last line, and the worst of them."""

    INTERVAL_NS = 1_000_000_000

    def __init__(self, loop: Loop):
        self._loop = loop
        self._pending = 0
        self._worst: tuple[int, int, str] | None = None
        self._last_ns: int | None = None

    def overrun(self, now: int, over_ns: int, tick: int, culprit: str) -> None:
        """Tick ``tick`` ended ``over_ns`` past its next deadline (at ``now``)."""
        self._pending += 1
        if self._worst is None or over_ns > self._worst[0]:
            self._worst = (over_ns, tick, culprit)
        if self._last_ns is None or now - self._last_ns >= self.INTERVAL_NS:
            self._flush(now)

    def due(self, now: int) -> None:
        """Say what is pending if the last line is a second old."""
        if self._last_ns is not None and now - self._last_ns >= self.INTERVAL_NS:
            self._flush(now)

    def _flush(self, now: int) -> None:
        if not self._pending or self._worst is None:
            return
        worst, tick, culprit = self._worst
        loop = self._loop
        if loop.warn is not None:
            loop.warn(overrun_line(self._pending, worst, tick, culprit, loop.WARN_WIDTH))
        self._pending = 0
        self._worst = None
        self._last_ns = now


def overrun_line(count: int, worst_ns: int, tick: int, culprit: str = "", width: int = 80) -> str:
    """The one-line overrun warning: how many ticks overran since the last
    line, the worst (ms past its next deadline), where, and where to look;
    never wider than ``width`` (the culprit's name is cut first)."""
    ticks = "tick" if count == 1 else "ticks"
    worst = (f"{worst_ns / 1e6:.2f} ms" if worst_ns >= 10_000
             else f"{worst_ns / 1e3:.1f} µs")  # 0.00 ms would say nothing
    head = f"overrun: {count} {ticks}, worst {worst} over at tick {tick}"
    tail = "; see stats"
    if culprit:
        room = width - len(head) - len(tail) - len(" in ")
        if room >= 4:
            name = culprit if len(culprit) <= room else culprit[: room - 1] + "…"
            head += f" in {name}"
    line = head + tail
    return line if len(line) <= width else line[: width - 1] + "…"

