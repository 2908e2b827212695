"""Database write-back: the values a restart needs, written while the robot runs.

000 keeps the state of the manipulator in its object databases:

* Axis ``LENGTH`` and PolyAxis ``POSITION``: every 1 s while moving, every
  10 s while stationary (sections 5 and 6);
* Encoder ``ZEROLENGTH``: once a second while the length changes, not at all
  otherwise.  The value is the encoder's *current* (unstretched) length: the
  counter is reset to zero at start-up, so the length now is the zero length
  of the next start (section 9);
* Loadcell ``SLOPE``/``OFFSET``: once, after a calibration (section 10).

:class:`WriteBack` is generic: it knows the station database and a set of
value sources (callables returning the current value, and whether the
object moves), never the robot.  Call :meth:`WriteBack.poll` with the loop
time (attach it to a :class:`~pyrt.scheduler.Loop` as a handler), or put
:meth:`WriteBack.attach` on a ready queue as a self-scheduling routine.

Where the file is written: ``poll`` only compares due times and hands the
changed values to a writer.  :class:`ThreadWriter` (the default) writes on
a background thread: the tick never waits for a disk (an atomic rewrite
costs an fsync of the file and of its directory, milliseconds on a real
disk, which would overrun a 1 ms tick).  It coalesces pending values (the
latest value of each key wins), so the pending set is bounded by the
number of written keys, and a failed write is raised at the next
``poll`` (every poll asks the writer, not only one that hands over values),
where the station turns it into a fault.  :class:`SyncWriter` writes in the
caller: deterministic, for SimClock runs and tests.

A write the disk refuses (``ENOSPC``, any ``OSError``) is one
:class:`~pyrt.errors.DiskError` from either writer, said the same way at
every speed (``database write-back failed: cannot write /db/AXIS.dat: No
space left on device (the disk is full)``); the values it held are not
lost: they are written with the next batch (and a calibration's values,
refused in a command, come back at the next poll as that poll's failure).  Both
write to any :class:`Sink` (``write_back(changes)``): the station database,
or a log file that appends its lines in key order (a pattern's log,
:mod:`pyrt.robots.pattern`).
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Protocol

from pyrt.db import Station
from pyrt.errors import ConfigError, DiskError, PyrtError, QueueFullError
from pyrt.fileio import disk_error, restate
from pyrt.scheduler import Clock, ReadyQueue, Routine

__all__ = [
    "MOVING_PERIOD_NS",
    "STATIONARY_PERIOD_NS",
    "ZEROLENGTH_PERIOD_NS",
    "SyncWriter",
    "ThreadWriter",
    "Watch",
    "WriteBack",
    "Writer",
]

#: 000: written once per second while moving ...
MOVING_PERIOD_NS = 1_000_000_000
#: ... and once every ten seconds while stationary.
STATIONARY_PERIOD_NS = 10_000_000_000
#: ZEROLENGTH: once per second while the length changes.
ZEROLENGTH_PERIOD_NS = 1_000_000_000

Key = tuple[str, str, str]


class Sink(Protocol):
    """Where a writer's batches end up: the station database
    (:meth:`pyrt.db.Station.write_back`) or anything with the same method."""

    def write_back(self, changes: Mapping[Any, Any]) -> Any: ...


class Writer(Protocol):
    """Where a batch of ``{(TYPE, name, KEY): value}`` goes.  A writer may also have
    ``check()``, raising a failure found since the last one (:class:`ThreadWriter`);
    :meth:`WriteBack.poll` calls it every poll."""

    def submit(self, changes: Mapping[Any, Any]) -> None: ...

    def flush(self, timeout: float | None = None) -> None: ...

    def close(self, wait: bool = True) -> None: ...


def _failure(what: str, exc: BaseException) -> PyrtError:
    """A sink's exception as the writer reports it: a disk's as DiskError."""
    if isinstance(exc, DiskError):
        return restate(what, exc)
    if isinstance(exc, OSError):
        return disk_error(what, None, exc)
    return ConfigError(f"{what} failed: {exc}")


class SyncWriter:
    """Writes each batch at once, in the caller (deterministic).  A batch the
    disk refuses raises DiskError (as :class:`ThreadWriter` reports it)."""

    def __init__(self, station: Station | Sink, what: str = "database write-back"):
        self.station = station
        self.what = what
        self.batches = 0

    def submit(self, changes: Mapping[Any, Any]) -> None:
        try:
            self.station.write_back(changes)
        except (DiskError, OSError) as exc:
            raise _failure(self.what, exc) from exc
        self.batches += 1

    def check(self) -> None:
        """Nothing is ever pending: nothing to report."""

    def flush(self, timeout: float | None = None) -> None:
        """Nothing is ever pending."""

    def close(self, wait: bool = True) -> None:
        """Nothing to stop."""


class ThreadWriter:
    """Writes batches on a background thread; ``submit`` never waits for a disk.

    Pending values are coalesced by key (the latest wins), so at most
    ``max_pending`` distinct keys wait; more raises QueueFullError.  A write
    that fails is raised at the next :meth:`check`, ``submit`` or ``flush``
    (DiskError when the disk refused it, ConfigError otherwise); its values
    go out again with the next batch (newer values of the same keys win).
    ``what`` names the writer in its errors.
    """

    def __init__(self, station: Station | Sink, max_pending: int = 256,
                 name: str = "pyrt-writeback", what: str = "database write-back"):
        self.station = station
        self.what = what
        self.max_pending = max_pending
        self.batches = 0
        self._cond = threading.Condition()
        self._pending: dict[Any, Any] = {}
        self._busy = False
        self._closed = False
        self._error: BaseException | None = None
        self._failed: dict[Any, Any] = {}  # a refused batch, written with the next one
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def _raise_error(self) -> None:
        error, self._error = self._error, None
        if error is not None:
            raise _failure(self.what, error) from error

    @property
    def unwritten(self) -> bool:
        """Whether a refused batch waits to be written again (with the next submit)."""
        return bool(self._failed)

    def check(self) -> None:
        """Raise a write that failed since the last report (the loop's poll, every
        time: a lock only when there is one)."""
        if self._error is not None:
            with self._cond:
                self._raise_error()

    def submit(self, changes: Mapping[Any, Any]) -> None:
        with self._cond:
            self._raise_error()
            if self._closed:
                raise ConfigError(f"{self.what} is closed")
            fresh = [k for k in changes if k not in self._pending]
            if len(self._pending) + len(fresh) > self.max_pending:
                raise QueueFullError(
                    f"{self.what}: more than {self.max_pending} values pending")
            if self._failed:  # a refused batch goes again, under the newer values
                self._pending = {**self._failed, **self._pending}
                self._failed = {}
            self._pending.update(changes)
            self._cond.notify()

    def _run(self) -> None:
        while True:
            with self._cond:
                while not self._pending and not self._closed:
                    self._cond.wait()
                if not self._pending:
                    return
                batch, self._pending = self._pending, {}
                self._busy = True
            try:
                self.station.write_back(batch)
            except Exception as e:  # reported at the next check/submit/flush
                with self._cond:
                    self._error = e
                    self._failed = {**batch, **self._failed}
            finally:
                with self._cond:
                    self._busy = False
                    self.batches += 1
                    self._cond.notify_all()

    def flush(self, timeout: float | None = None) -> None:
        """Wait until every submitted value is on disk (or ``timeout`` s pass)."""
        with self._cond:
            self._cond.wait_for(lambda: not self._pending and not self._busy, timeout)
            self._raise_error()

    def close(self, wait: bool = True) -> None:
        """Write what is pending (a batch refused earlier once more), then stop
        the thread.  Without ``wait`` (the loop thread, which must not wait for
        a disk) the thread writes what is pending and ends on its own; a
        failure then is not reported."""
        with self._cond:
            if self._failed and not self._closed:
                self._pending = {**self._failed, **self._pending}
                self._failed = {}
            self._closed = True
            self._cond.notify_all()
        if not wait:
            return
        self._thread.join()
        with self._cond:
            self._raise_error()


@dataclass
class Watch:
    """One database value kept up to date from a source.

    ``read()`` returns ``(value, moving)``.  At each due time the value is
    handed to the writer if it differs from the last one written (an
    unchanged value costs no write); the next due time is
    ``moving_period_ns`` or ``stationary_period_ns`` later.
    """

    type: str
    name: str
    key: str
    read: Callable[[], tuple[Any, bool]]
    moving_period_ns: int
    stationary_period_ns: int
    last: Any = None
    due_ns: int | None = None
    writes: int = 0

    @property
    def target(self) -> Key:
        return (self.type, self.name, self.key)


class WriteBack:
    """Keeps the station's LENGTH, POSITION and ZEROLENGTH values current.

    Register sources with :meth:`watch_length`, :meth:`watch_position`,
    :meth:`watch_zerolength` (or :meth:`watch` for anything writable), then
    call :meth:`poll` with the loop time.  The first poll evaluates every
    watch; values equal to the file's are not written.
    """

    def __init__(self, station: Station, writer: Writer | None = None, *,
                 moving_period_ns: int = MOVING_PERIOD_NS,
                 stationary_period_ns: int = STATIONARY_PERIOD_NS,
                 zerolength_period_ns: int = ZEROLENGTH_PERIOD_NS,
                 history: int = 256):
        if min(moving_period_ns, stationary_period_ns, zerolength_period_ns) <= 0:
            raise ValueError("write-back periods must be positive")
        self.station = station
        self.writer: Writer = writer if writer is not None else ThreadWriter(station)
        self.moving_period_ns = moving_period_ns
        self.stationary_period_ns = stationary_period_ns
        self.zerolength_period_ns = zerolength_period_ns
        self.watches: list[Watch] = []
        #: (now_ns, TYPE, name, KEY, value) of the latest submissions
        self.history: deque[tuple[int, str, str, str, Any]] = deque(maxlen=history)
        self._next_due = 0
        self._check = getattr(self.writer, "check", None)
        #: A calibration's batch the writer refused: raised at the next poll,
        #: handed over again with the next batch.
        self._refused: PyrtError | None = None
        self._unwritten: dict[Key, Any] = {}

    # -- sources -------------------------------------------------------------

    def watch(self, type_: str, name: str, key: str, read: Callable[[], tuple[Any, bool]],
              moving_period_ns: int, stationary_period_ns: int) -> Watch:
        """Keep ``TYPE name KEY`` current from ``read() -> (value, moving)``."""
        record = self.station.record(type_, name)  # UnknownNameError if absent
        t, k = type_.upper(), key.upper()
        if not self.station.writable(t, k):
            raise ValueError(f"{t} {k} is not a written-back key")
        if any(w.target == (t, record.name, k) for w in self.watches):
            raise ValueError(f"{t} {record.name} {k} is already watched")
        w = Watch(t, record.name, k, read, moving_period_ns, stationary_period_ns,
                  last=getattr(record, k.lower()))
        self.watches.append(w)
        self._next_due = 0
        return w

    def watch_length(self, axis: str, read: Callable[[], tuple[float, bool]]) -> Watch:
        """Axis LENGTH (cm): every 1 s moving, every 10 s stationary."""
        return self.watch("AXIS", axis, "LENGTH", read, self.moving_period_ns,
                          self.stationary_period_ns)

    def watch_position(self, polyaxis: str,
                       read: Callable[[], tuple[tuple[float, float, float], bool]]) -> Watch:
        """PolyAxis POSITION (cm): every 1 s moving, every 10 s stationary."""
        return self.watch("POLYAXIS", polyaxis, "POSITION", read, self.moving_period_ns,
                          self.stationary_period_ns)

    def watch_zerolength(self, encoder: str, current_length: Callable[[], float]) -> Watch:
        """Encoder ZEROLENGTH := the encoder's current length, once a second while
        it changes and never otherwise (the counter restarts at zero, so the
        current length is the next start's zero length)."""

        def read() -> tuple[float, bool]:
            value = current_length()
            return value, value != w.last

        w = self.watch("ENCODER", encoder, "ZEROLENGTH", read, self.zerolength_period_ns,
                       self.zerolength_period_ns)
        return w

    # -- the task ------------------------------------------------------------

    def poll(self, now_ns: int) -> int:
        """Hand every due, changed value to the writer; returns how many.  A write
        that failed since the last poll (any writer, any speed) is raised here."""
        if self._refused is not None:
            refused, self._refused = self._refused, None
            raise refused
        if self._check is not None:
            self._check()
        if now_ns < self._next_due:
            return 0
        batch: dict[Key, Any] = {}
        changed: list[tuple[Watch, Any]] = []
        next_due: int | None = None
        for w in self.watches:
            if w.due_ns is None or now_ns >= w.due_ns:
                value, moving = w.read()
                value = _plain(value)
                if value != w.last:
                    batch[w.target] = value
                    changed.append((w, value))
                w.due_ns = now_ns + (w.moving_period_ns if moving else w.stationary_period_ns)
            if next_due is None or w.due_ns < next_due:
                next_due = w.due_ns
        self._next_due = next_due if next_due is not None else now_ns + self.moving_period_ns
        if self._unwritten:
            batch = {**self._unwritten, **batch}
        if not batch and getattr(self.writer, "unwritten", False):
            self.writer.submit({})  # a refused batch, tried again at the write-back's pace
        if batch:
            # a refused batch raises here and leaves ``last`` alone: retried when next due
            self.writer.submit(batch)
            self._unwritten = {}
            for w, value in changed:
                w.last = value
                w.writes += 1
                self.history.append((now_ns, w.type, w.name, w.key, value))
        return len(batch)

    def loadcell_calibrated(self, loadcell: str, slope: float, offset: float,
                            date: str | None = None, now_ns: int = 0,
                            points: str | None = None) -> None:
        """Write a calibration's SLOPE and OFFSET (and DATE and CALIBRATIONPOINT,
        the points it was fitted to, if given) once, in one batch.  A disk that
        refuses it is not the calibrating command's error: it is raised at the
        next :meth:`poll`, as every write-back failure is."""
        record = self.station.loadcell(loadcell)
        batch: dict[Key, Any] = {("LOADCELL", record.name, "SLOPE"): slope,
                                 ("LOADCELL", record.name, "OFFSET"): offset}
        if date is not None:
            batch[("LOADCELL", record.name, "DATE")] = date
        if points is not None:
            batch[("LOADCELL", record.name, "CALIBRATIONPOINT")] = points
        for (t, n, k), v in batch.items():
            self.history.append((now_ns, t, n, k, v))
        try:
            self.writer.submit(batch)
        except DiskError as exc:
            self._refused = exc
            self._unwritten.update(batch)

    def attach(self, queue: ReadyQueue, address: int, period: int | Callable[[], int],
               clock: Clock | None = None, name: str = "WRITEBACK") -> Routine:
        """Run as a self-scheduling routine on ``queue`` every ``period`` queue
        checks (scheduled at once).  The time is the queue's tick time, or
        ``clock``'s when given."""
        if clock is not None:
            def run() -> None:
                self.poll(clock.now_ns())
        else:
            def run() -> None:
                self.poll(queue.now_ns)
        routine = queue.add_periodic(address, name, run, period)
        queue.schedule(address, period() if callable(period) else int(period))
        return routine

    def flush(self, timeout: float | None = None) -> None:
        """Wait until everything handed to the writer is on disk."""
        self.writer.flush(timeout)

    def close(self) -> PyrtError | None:
        """Write what is pending and stop the writer.  Returns what could not be
        written (a refused batch, the disk's refusal now), or None: the way out
        goes on and says it; it is not raised."""
        failure, self._refused = self._refused, None
        try:
            if self._unwritten:
                self.writer.submit(self._unwritten)
                self._unwritten = {}
        except PyrtError as exc:
            failure = exc
        try:
            self.writer.close()
        except PyrtError as exc:
            failure = exc
        return failure


def _plain(value: Any) -> Any:
    """Floats and tuples of floats (a numpy vector compares element-wise)."""
    if isinstance(value, str):
        return value
    if hasattr(value, "__len__"):
        return tuple(float(x) for x in value)
    return float(value)
