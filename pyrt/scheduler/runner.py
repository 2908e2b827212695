"""Where the application meets the loop: mailbox, motion queue, loop thread (004).

The application (a console, the DAQ server) never touches device objects
while the loop runs.  It writes a command to the **mailbox** and waits, with
a timeout, for the loop to take it; the loop empties the mailbox every tick
and runs each command to completion inside that tick.  **Motion** commands
go on a bounded motion queue instead; records are copied whole before they
are enqueued (001), so a record is never seen half written.

A fault recorded by the loop comes back as :class:`FaultError` from the next
mailbox write, exactly once (004's "asynchronous error raised at the next
mailbox write"); :meth:`Runner.poll` is the no-op round trip an application
uses to check before acting.

On a :class:`~pyrt.scheduler.clock.WallClock` the loop runs in its own
thread.  On a :class:`~pyrt.scheduler.clock.SimClock` there is no thread:
the loop runs in the caller's thread, and only while a runner call needs it
(a command is served at the next tick, ``wait_until`` and ``sleep`` advance
virtual time), so a script run is deterministic.
"""

from __future__ import annotations

import contextlib
import copy
import queue
import threading
import time
from collections import deque
from collections.abc import Callable, Generator
from typing import Any

from pyrt.errors import (
    Fault,
    FaultError,
    MailboxTimeout,
    PyrtError,
    PyrtInternalError,
    QueueFullError,
)
from pyrt.scheduler.loop import Job, Loop
from pyrt.scheduler.stats import LoopStatistics

__all__ = ["FaultMessage", "MotionQueue", "Runner"]


class FaultMessage(str):
    """The asynchronous line of a fault event (``FAULT <fault>``), carrying the
    :class:`~pyrt.errors.Fault` so that a reader can show each event once, by its id."""

    fault: Fault

    def __new__(cls, fault: Fault) -> FaultMessage:
        line = super().__new__(cls, f"FAULT {fault}")
        line.fault = fault
        return line


class MotionQueue:
    """A bounded FIFO of motion records, filled by the mailbox and emptied by
    the robot's motion task, both in the loop thread."""

    def __init__(self, capacity: int = 16):
        if capacity < 1:
            raise ValueError(f"motion queue capacity must be >= 1, got {capacity}")
        self.capacity = capacity
        self._q: deque[Any] = deque()

    def put(self, record: Any) -> None:
        """Append a copy of ``record``; a full queue raises :class:`QueueFullError`."""
        if len(self._q) >= self.capacity:
            raise QueueFullError(
                f"motion queue full ({self.capacity} records): wait for a move to finish"
            )
        self._q.append(copy.deepcopy(record))

    def get(self) -> Any | None:
        """The oldest record, removed; None when the queue is empty."""
        return self._q.popleft() if self._q else None

    def peek(self) -> Any | None:
        """The oldest record without removing it; None when empty."""
        return self._q[0] if self._q else None

    def clear(self) -> int:
        """Drop every queued record (a reflex action does); return how many."""
        n = len(self._q)
        self._q.clear()
        return n

    def __len__(self) -> int:
        return len(self._q)


class _Request:
    __slots__ = ("args", "done", "error", "event", "fn", "motion", "name", "result", "taken")

    def __init__(self, name: str, fn: Callable[..., Any] | None, args: tuple, motion: Any = None):
        self.name = name
        self.fn = fn
        self.args = args
        self.motion = motion
        self.taken = False
        self.done = False
        self.result: Any = None
        self.error: BaseException | None = None
        self.event = threading.Event()


class _Waiter:
    """A ``wait_until`` in progress: its predicate, the event that ends the
    wait, and the exception the predicate raised (handed to the waiter)."""

    __slots__ = ("error", "event", "predicate")

    def __init__(self, predicate: Callable[[], bool]):
        self.predicate = predicate
        self.event = threading.Event()
        self.error: BaseException | None = None


class Runner:
    """Owns a :class:`Loop` for the application: mailbox calls, waits, the loop thread.

    Create it after the robots' handlers are attached: the mailbox is served
    after them in each tick.  ``mailbox_size`` bounds the commands waiting to
    be taken; ``motion_queue`` is the robot's motion queue (a default one is
    made).
    """

    def __init__(
        self,
        loop: Loop,
        *,
        mailbox_size: int = 64,
        motion_queue: MotionQueue | None = None,
    ):
        self.loop = loop
        self.virtual = loop.clock.virtual
        self.mailbox_size = mailbox_size
        self.motion = motion_queue if motion_queue is not None else MotionQueue()
        self._mailbox: deque[_Request] = deque()
        self._lock = threading.Lock()
        self._drive_lock = threading.Lock()
        self._driver: int | None = None
        self._waiters: list[_Waiter] = []
        self._messages: queue.SimpleQueue[str] = queue.SimpleQueue()
        self._thread: threading.Thread | None = None
        self._started = False
        self.crashed: BaseException | None = None
        #: Sees every request as the mailbox applies it (a journal's recorder):
        #: ``request_tap(name, fn, args, motion)``, in the loop thread, or None.
        self.request_tap: Callable[[str, Callable[..., Any] | None, tuple, Any], None] | None = None
        self._replayed: Callable[[], list[Callable[[], Any]]] | None = None
        # The mailbox handler runs only while there is something to serve: a
        # request, a waiter, a replay (switched on and off under _lock).
        self._serving = False
        loop.attach(self._service, name="mailbox", enabled=False)
        loop.fault_listeners.append(self._on_fault)

    @property
    def replayed(self) -> Callable[[], list[Callable[[], Any]]] | None:
        """A replay's requests of this tick: a callable giving the calls to make
        (in order, before the mailbox's own), or None."""
        return self._replayed

    @replayed.setter
    def replayed(self, requests: Callable[[], list[Callable[[], Any]]] | None) -> None:
        with self._lock:
            self._replayed = requests
            self._serve(requests is not None or bool(self._mailbox or self._waiters))

    def _serve(self, on: bool) -> None:
        """Switch the mailbox handler on or off (hold _lock)."""
        if on != self._serving:
            self._serving = on
            self.loop.enable(self._service, on)

    # -- life cycle ----------------------------------------------------------

    @property
    def running(self) -> bool:
        """True between :meth:`start` and :meth:`stop` (and the thread is alive)."""
        if not self._started:
            return False
        return self.virtual or (self._thread is not None and self._thread.is_alive())

    def start(self) -> None:
        """Start serving: on a wall clock, start the loop thread."""
        if self._started:
            return
        self._started = True
        if not self.virtual:
            self._thread = threading.Thread(target=self._thread_main, name="pyrt-loop", daemon=True)
            self._thread.start()

    def stop(self, timeout_s: float = 2.0) -> None:
        """Stop serving; on a wall clock, stop the loop and join its thread."""
        self._started = False
        if self._thread is not None:
            self.loop.stop()
            self._thread.join(timeout_s)
            self._thread = None

    def __enter__(self) -> Runner:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _thread_main(self) -> None:
        try:
            self.loop.run()
        except BaseException as exc:  # a bug in pyrt or a handler outside any queue
            self.crashed = exc
            try:
                self.loop.fault_all(f"control loop crashed: {type(exc).__name__}: {exc}")
            finally:
                self.post(f"FATAL: control loop stopped: {type(exc).__name__}: {exc}")

    # -- the mailbox (application side) --------------------------------------

    def call(
        self,
        fn: Callable[..., Any],
        *args: Any,
        timeout_s: float = 1.0,
        name: str = "",
        take_fault: bool = True,
    ) -> Any:
        """Run ``fn(*args)`` in the loop at its next tick and return the result.

        A pending fault is raised first, as :class:`FaultError`, and the
        command is not sent.  :class:`MailboxTimeout` if the loop does not
        take the command within ``timeout_s`` (of loop time on a SimClock).
        Exceptions raised by ``fn`` propagate to the caller.  An observer
        that must not consume the application's fault report (a read-only
        network client) passes ``take_fault=False``: a pending fault is then
        left for the next caller that takes it.
        """
        return self._submit(
            _Request(name or getattr(fn, "__name__", "command"), fn, args), timeout_s, take_fault
        )

    def poll(self, timeout_s: float = 1.0) -> None:
        """A no-op round trip: raises a pending fault, or a timeout if the loop is stuck."""
        self._submit(_Request("poll", None, ()), timeout_s)

    def submit_motion(self, record: Any, timeout_s: float = 1.0) -> int:
        """Put a copy of ``record`` on the motion queue; returns the queue length.
        A full queue raises :class:`QueueFullError`."""
        return self._submit(_Request("motion", None, (), motion=copy.deepcopy(record)), timeout_s)

    def spawn(self, name: str, gen: Generator[Any, None, Any], timeout_s: float = 1.0) -> Job:
        """Start a foreground job in the loop; returns its :class:`Job`."""
        return self.call(self.loop.spawn, name, gen, timeout_s=timeout_s, name=f"spawn {name}")

    def run_job(self, name: str, gen: Generator[Any, None, Any], timeout_s: float) -> Any:
        """Start a foreground job and wait for it; its result or its exception.
        A job still running after ``timeout_s`` is cancelled and times out."""
        job = self.spawn(name, gen)
        if not self.wait_until(lambda: job.done, timeout_s):
            self.call(job.cancel, name=f"cancel {name}")
            raise MailboxTimeout(f"{name} did not finish within {timeout_s:g} s")
        return job.value()

    def _submit(self, req: _Request, timeout_s: float, take_fault: bool = True) -> Any:
        if take_fault:
            self._raise_fault()
        if self.crashed is not None:
            raise PyrtInternalError(f"the control loop has stopped: {self.crashed!r}")
        with self._lock:
            if len(self._mailbox) >= self.mailbox_size:
                raise QueueFullError(
                    f"mailbox full ({self.mailbox_size} commands waiting): {req.name} not sent"
                )
            self._mailbox.append(req)
            self._serve(True)
        if self.virtual:
            self._drive(lambda: req.done, timeout_s)
        else:
            req.event.wait(timeout_s)
        with self._lock:
            if not req.taken:
                with contextlib.suppress(ValueError):
                    self._mailbox.remove(req)
                raise MailboxTimeout(
                    f"the control loop did not take {req.name!r} within {timeout_s:g} s"
                    + ("" if self.running else " (the loop is not running)")
                )
        if not req.done:  # taken: it completes within the same tick
            req.event.wait()
        if req.error is not None:
            raise req.error
        return req.result

    def _drive(self, predicate: Callable[[], bool], timeout_s: float) -> None:
        """SimClock: run the loop in this thread until ``predicate`` or the timeout."""
        if not self._started:
            return
        if self._driver == threading.get_ident():
            raise PyrtInternalError("a runner call was made from inside the control loop")
        max_ticks = max(1, int(timeout_s * 1e9 / self.loop.period_ns))
        with self._drive_lock:
            self._driver = threading.get_ident()
            try:
                if not predicate():
                    self.loop.run(max_ticks, until=predicate)
            finally:
                self._driver = None

    def take_faults(self) -> list[Fault]:
        """Every fault report still pending, oldest first, taken (an acknowledgement
        shows them, then acknowledges with ``call(..., take_fault=False)``)."""
        out = []
        while (fault := self.loop.take_fault()) is not None:
            out.append(fault)
        return out

    def take_fault(self, fault: Fault) -> None:
        """``fault`` has been shown to the operator: the next call does not raise it."""
        self.loop.take_fault(fault)

    def _raise_fault(self) -> None:
        fault = self.loop.take_fault()
        if fault is not None:
            raise FaultError(fault)

    def statistics(self, timeout_s: float = 1.0, take_fault: bool = True) -> LoopStatistics:
        """The loop's timing statistics, built outside the loop thread: the
        loop only hands over its raw samples (O(1)), so looking does not
        cause an overrun.  ``take_fault`` as for :meth:`call`."""
        taken = self.call(
            self.loop.take_samples,
            timeout_s=timeout_s,
            name="stats",
            take_fault=take_fault,
        )
        self.loop.fold_samples(taken)
        return self.loop.statistics(fold=False)

    # -- waiting -----------------------------------------------------------

    def wait_until(self, predicate: Callable[[], bool], timeout_s: float) -> bool:
        """Wait until ``predicate()`` holds, evaluated in the loop after each
        tick; False after ``timeout_s`` (loop time on a SimClock).  A fault
        while waiting ends the wait with :class:`FaultError`; an exception
        raised by ``predicate`` ends it with that exception (never as "done")."""
        if timeout_s < 0:
            raise ValueError(f"timeout must be >= 0, got {timeout_s}")
        self._raise_fault()
        if self.virtual:
            held = [False]

            faults = self.loop.pending_faults  # the loop's own deque: no call a tick

            def done() -> bool:
                if predicate():
                    held[0] = True
                    return True
                return bool(faults)

            self._drive(done, timeout_s)
            self._raise_fault()
            return held[0]
        entry = _Waiter(predicate)
        event = entry.event
        with self._lock:
            self._waiters.append(entry)
            self._serve(True)
        try:
            deadline = time.monotonic() + timeout_s
            while not event.wait(min(0.05, max(0.0, deadline - time.monotonic()))):
                if self.loop.has_fault():
                    self._raise_fault()
                if time.monotonic() >= deadline or not self.running:
                    return False
            if entry.error is not None:
                raise entry.error
            return True
        finally:
            with self._lock:
                if entry in self._waiters:
                    self._waiters.remove(entry)

    def sleep(self, seconds: float) -> None:
        """Let ``seconds`` of loop time pass (SimClock: runs the loop that long)."""
        if not seconds >= 0 or seconds != seconds:
            raise ValueError(f"sleep time must be >= 0 seconds, got {seconds!r}")
        if self.virtual:
            if self._started and seconds > 0:
                if self._driver == threading.get_ident():
                    raise PyrtInternalError("sleep was called from inside the control loop")
                with self._drive_lock:
                    self._driver = threading.get_ident()
                    try:
                        self.loop.run(duration_ns=int(seconds * 1e9))
                    finally:
                        self._driver = None
        else:
            time.sleep(seconds)

    # -- asynchronous output -------------------------------------------------

    def post(self, line: str) -> None:
        """Queue an asynchronous message for the application (any thread)."""
        self._messages.put(line)

    def messages(self) -> list[str]:
        """Drain the queued asynchronous messages, oldest first."""
        out = []
        while True:
            try:
                out.append(self._messages.get_nowait())
            except queue.Empty:
                return out

    def _on_fault(self, fault: Fault) -> None:
        self.post(FaultMessage(fault))

    # -- the loop side ---------------------------------------------------------

    def _service(self, now_ns: int) -> None:
        """Loop handler: empty the mailbox, then evaluate the waiters; switched
        off once neither has anything left (a request or a waiter switches it
        on again)."""
        if self._replayed is not None:
            for fn in self._replayed():
                # as the request did then: its error was its own, never the loop's
                with contextlib.suppress(Exception):
                    fn()
        if self._mailbox:
            with self._lock:
                batch = list(self._mailbox)
                self._mailbox.clear()
                for req in batch:
                    req.taken = True
            tap = self.request_tap
            for req in batch:
                if tap is not None:
                    tap(req.name, req.fn, req.args, req.motion)
                try:
                    if req.motion is not None:
                        self.motion.put(req.motion)
                        req.result = len(self.motion)
                    elif req.fn is not None:
                        req.result = req.fn(*req.args)
                except PyrtError as exc:
                    req.error = exc
                except Exception as exc:  # a command's bug must not kill the loop
                    req.error = exc
                req.done = True
                req.event.set()
        if self._waiters:
            with self._lock:
                waiters = list(self._waiters)
            for w in waiters:
                if w.event.is_set():
                    continue
                try:
                    if w.predicate():
                        w.event.set()
                except Exception as exc:  # the waiter raises it; the loop goes on
                    w.error = exc
                    w.event.set()
        if not self._mailbox and not self._waiters and self._replayed is None:
            with self._lock:  # what another thread sends now switches it on again
                if not self._mailbox and not self._waiters and self._replayed is None:
                    self._serve(False)
