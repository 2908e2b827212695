"""The black box written on every fault: a station's last seconds, as a journal and as signals.

A :class:`FaultBox` rides on a :class:`~pyrt.station.recording.Recorder`
whose journal has a :class:`~pyrt.journal.BlackBox` (the last ``N`` seconds
of the station's inputs, commands, clock and outputs).  Beside it, it keeps
every signal of the station (:meth:`Station.signals`) in a ring of its own
(:class:`SignalRing`): sampled every few ticks (at most
:data:`SIGNAL_RATE_HZ`), numbers in preallocated numpy arrays, within
:data:`SIGNAL_BUDGET` bytes whatever the span and the number of signals (the
sampling rate is lowered to fit).  Both rings together stay within
:data:`TOTAL_BUDGET`.

On a fault (the first of an episode: a fault that comes while the black box
of another is still to be written is in that one; each fault id once) it
posts one line to the application, right after the fault's own::

    black box of fault 3: /station/prototype-fault-3-20261125T031500.pj (+ .csv, .png)

and :data:`AFTER_S` of ticks later (so that the aftermath is in it; at once
if the recorder is closed first) writes, beside the station's databases
(``station.directory``) or else in the working directory:

* ``NAME-fault-ID-TIME.pj``: the journal's ring, a journal file readable on
  its own (:class:`~pyrt.journal.JournalReader`; its first tick is a
  keyframe), dumped by the journal's thread, with the first snapshot of the
  controller that falls within its ticks (:mod:`pyrt.station.snapshot`)
  right after its header, so that ``pyrt replay`` resumes from it; a station
  that could not give one has the reason there instead.  The loop thread
  takes a snapshot at the end of a tick every :data:`SNAPSHOT_S` of loop
  time or more: further apart when that would cost the loop thread more
  than :data:`SNAPSHOT_SHARE` of its CPU time (:func:`snapshot_interval`),
  but never more than :data:`MAX_SNAPSHOT_SPAN` of the black box's span
  apart, so that every black box holds one; it keeps the few the span
  needs;
* ``.csv``: a header ``t_s,OBJECT.SIGNAL [UNITS],...`` and one row per sample, the
  time in seconds from the fault, the ``N`` seconds before it and what came
  after;
* ``.png``: the signals around the fault, a few to a subplot, the fault
  marked (when matplotlib is installed: ``pip install 'pyrt[plot]'``;
  without it the first line says so).

Files that cannot be written (a full disk) are said in a line naming each
one and the reason, and are a fault of the station (source ``BLACKBOX``,
tripped by the loop at its next record).  Closing writes every black box
still due at once (the operator quit right after a fault) and says what it
could not write through the station's ``close_report``, the console being
gone by then.

The CSV and the PNG are written atomically, never by the loop: the loop
thread only samples, and at the due tick hands the work over to a thread of
the black box's own (at a lower priority), which formats the CSV a few rows
at a time and has the PNG drawn by a child process at the lowest priority
(matplotlib would otherwise hold the interpreter for a second or two, and
the loop's ticks with it).  The loop's share: a call per tick, every few
ticks one compiled read of every signal into a row of the ring (at 20 Hz:
a read every 50 ticks of the gripper at 1 kHz, every 10 of the manipulator
at 200 Hz), and the snapshots.  Signals that give text
rather than numbers are left out; a signal whose read fails gives ``nan``
for that sample.
"""

from __future__ import annotations

import collections
import contextlib
import importlib.util
import io
import math
import os
import queue
import re
import struct
import subprocess
import sys
import textwrap
import threading
import time
from collections.abc import Callable, Sequence
from concurrent.futures import Future
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from pyrt.component import Signal
from pyrt.errors import ConfigError, Fault
from pyrt.fileio import atomic_write
from pyrt.journal import DEFAULT_BUDGET, BlackBox, JournalError, JournalReader
from pyrt.journal.format import HEADER_SIZE, KIND_SNAPSHOT, frame, snapshot_payload
from pyrt.scope import Source, compile_sources
from pyrt.scope.sources import compile_sampler
from pyrt.station.recording import Recorder
from pyrt.station.snapshot import Snapshot, compress_snapshot, take_snapshot

if TYPE_CHECKING:
    from pyrt.station.base import Station

__all__ = [
    "AFTER_S",
    "MAX_SNAPSHOT_SPAN",
    "SIGNAL_BUDGET",
    "SIGNAL_RATE_HZ",
    "SNAPSHOT_S",
    "SNAPSHOT_SHARE",
    "TOTAL_BUDGET",
    "FaultBox",
    "FaultDump",
    "FaultRecorder",
    "SignalRing",
    "plotting_available",
    "snapshot_interval",
    "with_snapshot",
]

#: The fastest a signal is sampled into the ring, per second: 20 Hz, the rate of
#: the controllers' own control (the manipulator's poll is 50 ms, the gripper's
#: MVJAWS runs every 48 ms).  What changes faster is in the journal's ring at every
#: tick, and a black box replays: ``pyrt replay BOX.pj --scope SIGNALS`` gives any
#: signal at every tick.  (At 100 Hz the manipulator's 45 signals cost a fifth of
#: its tick's work.)
SIGNAL_RATE_HZ = 20.0
#: The signal ring's memory, at most (8 MiB): the rate is lowered to keep it.
SIGNAL_BUDGET = 8 << 20
#: Both rings of a black box, at most: the journal's and the signals'.
TOTAL_BUDGET = DEFAULT_BUDGET + SIGNAL_BUDGET
#: Loop time kept after a fault before the black box is written.
AFTER_S = 0.5
#: Loop time between two snapshots of the controller, at least (a black box
#: replays from the first one in it: all but at most the interval of its span) ...
SNAPSHOT_S = 2.0
#: What snapshots may cost the loop thread: this share of its CPU time (the
#: manipulator's take ~2M instructions, 0.3-0.7 ms, at the end of a 5 ms tick
#: whose work is ~156k, ~35 µs: one every 6 s or so; the gripper's ~0.2 ms against
#: ~7 µs ticks of 1 ms: one every 2-3 s) ...
SNAPSHOT_SHARE = 0.01
#: ... but never more than this share of the black box's span apart (7.5 s of a
#: 10 s box): every box holds a snapshot, and replays at least the rest.
MAX_SNAPSHOT_SPAN = 0.75
#: Loop time the ring holds beyond what a black box needs, so that the thread
#: copying a window out of it is never overtaken by the loop.
SLACK_S = 1.0
#: Signals drawn in one subplot, at most.
PER_PLOT = 4
#: How much nicer than the loop the writing thread runs (Linux) ...
NICE = 5
#: ... and the plotting process: it takes a core for a second or two, the loop
#: must not lose it.
PLOT_NICE = 19
#: How long :meth:`FaultBox.close` waits for the files, seconds.
CLOSE_TIMEOUT_S = 90.0
#: How long the plotting process may take, seconds.
PLOT_TIMEOUT_S = 60.0
#: CSV rows formatted between two hand-overs of the interpreter.
CSV_ROWS = 64

_ROW = 8  # bytes per value (float64) and per time (int64)


def snapshot_interval(cost_ns: float, work_ns: float, least: int, most: int) -> int:
    """Ticks between two snapshots that cost ``cost_ns`` of the loop thread's CPU
    each, on ticks of ``work_ns`` each: as few as keep them within
    :data:`SNAPSHOT_SHARE` of the loop's work, within ``least..most``."""
    if work_ns <= 0:
        return most
    return max(least, min(most, math.ceil(cost_ns / (SNAPSHOT_SHARE * work_ns) - 1e-9)))


def plotting_available() -> bool:
    """Whether matplotlib can be imported (looked up, not imported)."""
    try:
        return importlib.util.find_spec("matplotlib") is not None
    except (ImportError, ValueError):
        return False


# -- the signals' ring -------------------------------------------------------------------

#: What a sample packs in a text signal's column.
_NAN = Source.attr(math, "nan")


class SignalRing:
    """Every one of ``signals`` (``(name, signal)``), sampled every :attr:`every`
    ticks of ``period_ns`` (at most ``rate_hz``) into a ring of :attr:`rows`
    samples that covers ``seconds`` plus ``extra_s``, within ``budget_bytes``
    (the rate is lowered when the budget would not hold that span).

    :meth:`tick` runs in the loop thread; :meth:`window` copies the samples
    out from any thread.
    """

    def __init__(self, signals: Sequence[tuple[str, Signal]], seconds: float, period_ns: int,
                 *, rate_hz: float = SIGNAL_RATE_HZ, budget_bytes: int = SIGNAL_BUDGET,
                 extra_s: float = AFTER_S + SLACK_S):
        if not seconds > 0 or not rate_hz > 0 or period_ns <= 0 or extra_s < 0:
            raise ConfigError(f"signal ring: bad span {seconds!r} s, rate {rate_hz!r} Hz or "
                              f"tick {period_ns!r} ns")
        self.names = [name for name, _ in signals]
        self.units = [sig.units for _, sig in signals]
        self._signals = [sig for _, sig in signals]
        n = len(self.names)
        per_row = _ROW * (n + 1)
        span = seconds + extra_s
        rate = min(rate_hz, 1e9 / period_ns, budget_bytes / (span * per_row))
        if budget_bytes // per_row < 2 or rate <= 0:
            raise ConfigError(f"signal ring: {n} signals do not fit in {budget_bytes} bytes")
        #: Ticks between two samples.
        self.every = max(1, math.ceil(1e9 / (rate * period_ns) - 1e-9))
        #: Samples a second.
        self.rate_hz = 1e9 / (self.every * period_ns)
        #: Samples held.
        self.rows = min(math.ceil(span * self.rate_hz) + 1, budget_bytes // per_row)
        self.budget_bytes = budget_bytes
        # one buffer of rows (the time, then every value), seen by numpy as two
        # views; a sample packs a row straight into it (one C call, no tuple)
        self._row_bytes = per_row
        self._buf = bytearray(self.rows * per_row)
        rows = np.frombuffer(self._buf, dtype=np.dtype([("t", "<i8"), ("v", "<f8", (n,))]))
        self._t: np.ndarray = rows["t"]
        self._v: np.ndarray = rows["v"]
        self._v[:] = np.nan
        #: Samples taken so far.
        self.samples = 0
        self._countdown = 1
        #: Signals left out: they give text, not numbers (text signals from the start).
        self.text: set[int] = {c for c, sig in enumerate(self._signals) if sig.is_text}
        self._slow: list[int] = []  # read one by one, each guarded
        self._fast: list[int] = [c for c in range(n) if c not in self.text]
        self._read_fast: Callable[[], tuple] = self._compile(self._fast) if self._fast else tuple
        #: ``pack(buf, offset, now_ns)``: every signal read and packed into a row
        #: (a text signal's column NaN, as the slow path leaves it), while every
        #: other signal is a number (None once one is not: the slow path).
        self._pack: Callable[[bytearray, int, int], None] | None = compile_sampler(
            [_NAN if c in self.text else sig.scope_source()
             for c, sig in enumerate(self._signals)], struct.Struct("<q" + "d" * n).pack_into)

    def _compile(self, cols: list[int]) -> Callable[[], tuple]:
        return compile_sources([self._signals[c].scope_source() for c in cols])

    @property
    def nbytes(self) -> int:
        """The ring's memory (both arrays), bytes."""
        return int(self._t.nbytes + self._v.nbytes)

    @property
    def columns(self) -> list[int]:
        """The signals kept (the text ones left out), in order."""
        return [c for c in range(len(self.names)) if c not in self.text]

    def tick(self, now_ns: int) -> None:
        """Loop thread, every tick: a sample every :attr:`every` ticks."""
        self._countdown -= 1
        if self._countdown <= 0:
            self._countdown = self.every
            self.sample(now_ns)

    def sample(self, now_ns: int) -> None:
        """Take one sample now (loop thread)."""
        g = self.samples
        i = g % self.rows
        pack = self._pack
        if pack is not None:
            try:
                pack(self._buf, i * self._row_bytes, now_ns)
                self.samples = g + 1
                return
            except Exception:
                pass  # a read that failed, or a value that is not a number: sorted out below
        row = self._v[i]
        self._t[i] = now_ns
        try:
            if self._slow or self.text:
                row[self._fast] = self._read_fast()
            else:
                row[:] = self._read_fast()
        except Exception:
            self._sort_out(row)
        for c in self._slow:
            try:
                row[c] = float(self._signals[c].read())
            except Exception:
                row[c] = math.nan
        if self._slow or self.text:
            self._pack = None  # not every signal packs as a number: column by column
        self.samples = g + 1

    def _sort_out(self, row: np.ndarray) -> None:
        """The fast read failed: read each of its signals alone; those that fail
        (or give text) are read one by one from now on (or left out)."""
        keep = []
        for c in self._fast:
            value: Any = None
            try:
                value = self._signals[c].read()
                row[c] = float(value)
            except Exception:
                row[c] = math.nan
                if isinstance(value, str):
                    self.text.add(c)
                else:
                    self._slow.append(c)
                continue
            keep.append(c)
        if len(keep) != len(self._fast):  # else a read that failed once: no new getter
            self._fast = keep
            self._read_fast = self._compile(keep) if keep else tuple

    def window(self, end: int, since_ns: int | None = None
               ) -> tuple[np.ndarray, np.ndarray, list[int]]:
        """The samples before sample number ``end`` (at most the ring's; those at or after
        ``since_ns``, loop time): times (ns), values (samples x columns) and the columns
        (:attr:`columns`: the signals' indices).  Any thread: samples the loop overwrote
        while they were copied are left out."""
        cols = self.columns
        end = min(end, self.samples)
        first = max(0, end - self.rows + 1)
        index = np.arange(first, end) % self.rows
        t = self._t[index]
        v = self._v[index]
        valid = self.samples - self.rows + 1  # the oldest sample surely not overwritten
        if valid > first:
            t, v = t[valid - first:], v[valid - first:]
        if since_ns is not None:
            keep = t >= since_ns
            t, v = t[keep], v[keep]
        if len(cols) != len(self.names):
            v = v[:, cols]
        return t, v, cols


# -- one fault's black box ---------------------------------------------------------------


@dataclass
class FaultDump:
    """One fault's black box: where it goes and, once :attr:`done` is set, what was written."""

    fault: Fault
    #: The files' common path, without the suffix.
    stem: Path
    #: The tick at which it is written.
    due_tick: int
    plot: bool
    #: The samples of the signal ring up to the one it is written at.
    end: int = 0
    journal: Future[int] | None = None
    #: The files written.
    written: list[Path] = field(default_factory=list)
    #: What could not be written, and why.
    errors: list[str] = field(default_factory=list)
    #: Tick records in the journal file and rows in the CSV.
    ticks: int = 0
    rows: int = 0
    #: The journal's ring as the journal's thread dumps it (the snapshot goes in after).
    buffer: io.BytesIO = field(default_factory=io.BytesIO)
    #: The snapshots of the controller that may fall within it, and why none
    #: could be taken lately ('').
    snapshots: list[Snapshot] = field(default_factory=list)
    refused: str = ""
    done: threading.Event = field(default_factory=threading.Event)

    def path(self, suffix: str) -> Path:
        """The file with ``suffix`` (``.pj``, ``.csv``, ``.png``)."""
        return self.stem.with_name(self.stem.name + suffix)

    def wait(self, timeout: float | None = None) -> bool:
        """Wait until the files are written (or failed); False on timeout."""
        return self.done.wait(timeout)


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("._") or "station"


class FaultBox:
    """Writes a black box on every fault of ``recorder``'s station (see the
    module text).  ``seconds``: the span kept before a fault (default: the
    journal's black box's); ``directory``: where the files go (default: the
    station's ``directory``, else the working directory); ``plot``: write the
    PNG (default: when matplotlib is installed).  Build it with the recorder,
    before the loop starts; :meth:`close` writes what is due and stops.
    """

    def __init__(self, recorder: Recorder, *, seconds: float | None = None,
                 after_s: float = AFTER_S, directory: str | Path | None = None,
                 plot: bool | None = None, rate_hz: float = SIGNAL_RATE_HZ,
                 budget_bytes: int = SIGNAL_BUDGET):
        box = recorder.journal.black_box
        if box is None:
            raise ConfigError("a fault's black box needs a journal with a black box")
        if after_s < 0:
            raise ConfigError(f"black box: the time kept after a fault must be >= 0, "
                              f"got {after_s!r}")
        station: Station = recorder.station
        self.recorder = recorder
        self.station = station
        self.black_box: BlackBox = box
        self.seconds = float(seconds if seconds is not None else box.seconds)
        loop = recorder.loop
        self.after_ticks = math.ceil(after_s * 1e9 / loop.period_ns - 1e-9)
        where = directory if directory is not None else getattr(station, "directory", None)
        self.directory = Path(where if where is not None else Path.cwd()).resolve()
        self.plot = plotting_available() if plot is None else bool(plot)
        self._said_no_plot = False
        self.ring = SignalRing(station.signals(), self.seconds, loop.period_ns,
                               rate_hz=rate_hz, budget_bytes=budget_bytes,
                               extra_s=after_s + SLACK_S)
        #: Ticks between two snapshots of the controller (:data:`SNAPSHOT_S`), and
        #: the snapshots that the black box's span may still need (oldest first).
        self.snapshot_every = self._min_every = max(1, math.ceil(SNAPSHOT_S * 1e9
                                                                  / loop.period_ns - 1e-9))
        self._max_every = max(self._min_every, int(MAX_SNAPSHOT_SPAN * self.seconds * 1e9
                                                   / loop.period_ns))
        #: The loop thread's CPU clock and tick at the end of the last snapshot, and
        #: the CPU time the last one taken cost (None: none yet).
        self._since: tuple[int, int] | None = None
        self._cost_ns: int | None = None
        span = self.seconds + after_s + SLACK_S
        self.snapshots: collections.deque[Snapshot] = collections.deque(
            maxlen=math.ceil(span / SNAPSHOT_S) + 2)
        #: Why the station could not be snapshot the last time it was asked ('': it could).
        self.snapshot_refused = ""
        #: The next ticks at which the signals are sampled and the controller snapshot.
        self._next_sample = 0
        self._next_snapshot = 0
        #: Every fault's black box, in order.
        self.dumps: list[FaultDump] = []
        self._seen: set[int] = set()
        self._pending: dict[int, FaultDump] = {}
        self._lock = threading.Lock()
        #: The writing thread's work: a black box to write, a snapshot to free, None: stop.
        self._jobs: queue.SimpleQueue[FaultDump | Snapshot | None] = queue.SimpleQueue()
        # once before the loop runs: the first snapshot of a process learns how the
        # objects of each class are read (tens of ms), which no tick should carry
        take_snapshot(station, [], [])
        # started now, idle until a fault: starting a thread waits for it to run,
        # which the loop thread must not do
        self._thread = threading.Thread(target=self._work, name="pyrt-black-box", daemon=True)
        self._thread.start()
        self._closed = False
        loop.fault_listeners.append(self._fault)
        recorder.tick_listeners.append(self._tick)

    @property
    def nbytes(self) -> int:
        """Both rings' memory now: the journal's and the signals'."""
        return self.black_box.nbytes + self.ring.nbytes

    def _post(self, line: str) -> None:
        """A line to the application: through the runner while the station runs;
        once it is closing (the loop stopped, the console gone), to the station's
        ``close_report`` (the command line's output), so that it is still said."""
        station = self.station
        runner = station.runner
        report = getattr(station, "close_report", None)
        if report is not None and (self._closed or runner is None or not runner.running):
            report(line)
        elif runner is not None:
            runner.post(line)

    # -- loop thread -----------------------------------------------------------------------

    def _fault(self, fault: Fault) -> None:
        if self._closed or fault.id in self._seen:
            return
        self._seen.add(fault.id)
        with self._lock:
            under_way = next(iter(self._pending.values()), None)
            if under_way is None:
                stamp = time.strftime("%Y%m%dT%H%M%S")
                name = f"{_safe(self.station.name)}-fault-{fault.id}-{stamp}"
                dump = FaultDump(fault, self.directory / name,
                                 due_tick=fault.tick + self.after_ticks, plot=self.plot)
                self._pending[fault.id] = dump
                self.dumps.append(dump)
                self.recorder.listen_at(dump.due_tick)
        if under_way is not None:
            self._post(f"black box of fault {fault.id}: in that of fault "
                       f"{under_way.fault.id}, {under_way.path('.pj')}")
            return
        if self.plot:
            more = "(+ .csv, .png)"
        elif not self._said_no_plot:
            self._said_no_plot = True
            more = "(+ .csv; no PNG: matplotlib is not installed)"
        else:
            more = "(+ .csv)"
        self._post(f"black box of fault {fault.id}: {dump.path('.pj')} {more}")

    def _tick(self, tick: int, now_ns: int) -> int:
        # called at the ticks it asks for (the recorder's tick listeners): a sample
        # of the signals every ring.every ticks, a snapshot every snapshot_every,
        # and every tick while a fault's box waits for its last ticks
        if tick >= self._next_sample:
            self._next_sample = tick + self.ring.every
            self.ring.sample(now_ns)
        if tick >= self._next_snapshot and self._snapshot_due(tick):
            self._snapshot(tick)
        due = min(self._next_sample, self._next_snapshot)
        if self._pending:
            for dump in list(self._pending.values()):
                if tick >= dump.due_tick:
                    self._write(dump)
                else:
                    due = min(due, dump.due_tick)
        return due

    def _snapshot_due(self, tick: int) -> bool:
        """Whether the snapshot asked for at ``tick`` is taken now: its interval
        is checked first against the loop's work since the last one (so the
        first interval too, and a loop whose work dropped), and when that is not
        yet done, the next is asked for at its end.  After a refusal, at once
        (the station is asked again a tenth of the interval later)."""
        since, cost = self._since, self._cost_ns
        if since is None or cost is None or tick <= since[1] or self.snapshot_refused:
            return True
        work = (time.thread_time_ns() - since[0]) / (tick - since[1])
        self.snapshot_every = snapshot_interval(cost, work, self._min_every, self._max_every)
        if tick >= since[1] + self.snapshot_every:
            return True
        self._next_snapshot = since[1] + self.snapshot_every
        return False

    def _snapshot(self, tick: int) -> None:
        """The controller's state before the next tick, kept for the black boxes to come;
        a station that cannot give it is asked again a tenth of the interval later."""
        image = self.recorder.image
        inputs = image.last_inputs
        if inputs is None:
            inputs = self.recorder._inputs
        start = time.thread_time_ns()
        snap = take_snapshot(self.station, inputs, image.output_values())
        end = time.thread_time_ns()
        since, self._since = self._since, (end, tick)
        if snap.refused:
            self.snapshot_refused = snap.refused
            self._next_snapshot = tick + max(1, self._min_every // 10)
            return
        self.snapshot_refused = ""
        snapshots = self.snapshots
        if len(snapshots) == snapshots.maxlen:
            # the oldest, which no black box needs any more, is freed by the box's
            # thread: a snapshot is thousands of objects, and freeing them is work
            self._jobs.put(snapshots[0])
        snapshots.append(snap)
        self._cost_ns = end - start
        if since is not None and tick > since[1]:
            # the loop thread's CPU a tick since the last snapshot (this one not in it)
            work = (start - since[0]) / (tick - since[1])
            self.snapshot_every = snapshot_interval(end - start, work, self._min_every,
                                                    self._max_every)
        self._next_snapshot = tick + self.snapshot_every

    def _write(self, dump: FaultDump) -> None:
        """Hand ``dump`` over: the journal's thread writes the ring, ours the rest."""
        with self._lock:
            if self._pending.pop(dump.fault.id, None) is None:
                return
            dump.end = self.ring.samples
            dump.snapshots = list(self.snapshots)
            dump.refused = self.snapshot_refused
            try:
                dump.journal = self.recorder.journal.dump_black_box(dump.buffer)
            except JournalError as exc:
                dump.errors.append(f"{dump.path('.pj').name}: {exc}")
            self._jobs.put(dump)

    # -- any thread ------------------------------------------------------------------------

    def close(self, timeout: float = CLOSE_TIMEOUT_S) -> None:
        """Write every black box still due now, wait for the files (at most
        ``timeout`` seconds), stop listening.  Idempotent."""
        if self._closed:
            return
        self._closed = True
        with contextlib.suppress(ValueError):
            self.recorder.loop.fault_listeners.remove(self._fault)
        with contextlib.suppress(ValueError):
            self.recorder.tick_listeners.remove(self._tick)
        for dump in list(self._pending.values()):
            self._write(dump)
        self._jobs.put(None)
        self._thread.join(timeout)
        for dump in self.dumps:
            if not dump.done.is_set():
                self._post(f"black box of fault {dump.fault.id}: not written within "
                           f"{timeout:g} s of closing; {dump.path('.pj')} may be missing "
                           "or incomplete")

    # -- the writing thread ----------------------------------------------------------------

    def _work(self) -> None:
        if NICE > 0 and hasattr(os, "setpriority"):
            with contextlib.suppress(OSError, AttributeError):
                tid = threading.get_native_id()
                os.setpriority(os.PRIO_PROCESS, tid,
                               min(19, os.getpriority(os.PRIO_PROCESS, tid) + NICE))
        while True:
            dump = self._jobs.get()
            if dump is None:
                return
            if not isinstance(dump, FaultDump):
                del dump  # a snapshot no black box needs: freed here
                continue
            try:
                self._files(dump)
            except Exception as exc:  # never lose the thread: say it, go on
                dump.errors.append(f"{type(exc).__name__}: {exc}")
            finally:
                if dump.errors:
                    line = (f"black box of fault {dump.fault.id}: not all written: "
                            + "; ".join(dump.errors))
                    self._post(line)
                    if not self._closed:  # a write error is a fault (the loop trips it)
                        self.recorder.disk_fault(line, "BLACKBOX")
                dump.done.set()

    def _files(self, dump: FaultDump) -> None:
        fault = dump.fault
        ring = self.ring
        t_ns, values, cols = ring.window(dump.end, fault.time_ns - int(self.seconds * 1e9))
        t_s = (t_ns - fault.time_ns) / 1e9
        names = [ring.names[c] for c in cols]
        units = [ring.units[c] for c in cols]
        dump.rows = len(t_s)
        csv = dump.path(".csv")
        try:
            atomic_write(csv, _csv(t_s, values, names, units))
            dump.written.append(csv)
        except OSError as exc:
            dump.errors.append(f"{csv.name}: {exc.strerror or exc}")
        if dump.plot:
            png = dump.path(".png")
            failed = _plot_elsewhere(png, t_s, values, names, units, str(fault))
            if failed:
                dump.errors.append(f"{png.name}: {failed}")
            else:
                dump.written.append(png)
        if dump.journal is not None:
            pj = dump.path(".pj")
            try:
                dump.ticks = dump.journal.result(CLOSE_TIMEOUT_S)
                atomic_write(pj, with_snapshot(dump.buffer.getvalue(), dump.snapshots,
                                               dump.refused or self.station.name))
                dump.written.append(pj)
            except JournalError as exc:
                dump.errors.append(f"{pj.name}: {exc}")
            except OSError as exc:
                dump.errors.append(f"{pj.name}: {exc.strerror or exc}")
            except TimeoutError:
                dump.errors.append(f"{pj.name}: the journal did not write it within "
                                   f"{CLOSE_TIMEOUT_S:g} s")


def with_snapshot(data: bytes, snapshots: Sequence[Snapshot], refused: str) -> bytes:
    """A black box's journal ``data`` with the first of ``snapshots`` that falls
    within its ticks as an ``S`` frame right after its header; without one, an
    ``S`` frame that says why (``refused``: what the station said, or its name)."""
    reader = JournalReader(data)
    summary = reader.summary()
    first, last = summary.first_tick, summary.last_tick
    snap = next((s for s in snapshots if first is not None and last is not None
                 and first <= s.tick <= last), None)
    if snap is None:
        if refused.startswith("cannot snapshot"):
            why = refused
        elif snapshots:
            why = (f"cannot snapshot: no snapshot of {refused} falls within the black box's "
                   f"ticks {first}..{last}")
        else:
            why = f"cannot snapshot: {refused} gave no snapshot during the black box's span"
        snap = Snapshot(reader.header.station, tick=first or 0, refused=why)
    end = HEADER_SIZE + int.from_bytes(data[5:9], "little")
    record = frame(KIND_SNAPSHOT, snapshot_payload(snap.tick, compress_snapshot(snap)))
    return data[:end] + record + data[end:]


def _csv(t_s: np.ndarray, values: np.ndarray, names: list[str],
         units: list[str] | None = None) -> bytes:
    """The CSV's bytes, formatted a few rows at a time with the interpreter handed
    back between them (the loop thread never waits long for it).  The header
    names each column with its units, as the scope's CSV does (``gripper.dac [byte]``)."""
    text = io.StringIO()
    shown = [f"{n} [{u}]" if u else n for n, u in zip(names, units or [""] * len(names),
                                                         strict=True)]
    text.write(",".join(["t_s", *shown]) + "\n")
    table = np.column_stack([t_s, values]) if names else t_s.reshape(-1, 1)
    for k in range(0, len(table), CSV_ROWS):
        np.savetxt(text, table[k:k + CSV_ROWS], delimiter=",", fmt="%.9g")
        time.sleep(0)
    return text.getvalue().encode("utf-8")


def _plot_elsewhere(png: Path, t_s: np.ndarray, values: np.ndarray, names: list[str],
                    units: list[str], title: str) -> str:
    """Draw the PNG in a child process (matplotlib would hold this interpreter's lock
    for a second or more: the loop's ticks would wait); '' or what went wrong."""
    buf = io.BytesIO()
    np.savez(buf, t_s=t_s, values=values, names=np.array(names, dtype=str),
             units=np.array(units, dtype=str), title=np.array(title))
    root = str(Path(__file__).resolve().parent.parent.parent)  # where pyrt is imported from
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (root, env.get("PYTHONPATH", "")) if p)
    try:
        done = subprocess.run([sys.executable, "-c", _CHILD, str(png)], input=buf.getvalue(),
                              capture_output=True, timeout=PLOT_TIMEOUT_S, env=env, check=False)
    except subprocess.TimeoutExpired:
        return f"not drawn within {PLOT_TIMEOUT_S:g} s"
    except OSError as exc:
        return f"no plotting process: {exc.strerror or exc}"
    if done.returncode == 0:
        return ""
    said = done.stderr.decode("utf-8", "replace").strip().splitlines()
    return said[-1] if said else f"the plotting process ended with status {done.returncode}"


#: The plotting process: nicer first (its imports take a core too), then :func:`_plot_main`.
_CHILD = (f"import os\n"
          f"try: os.nice({PLOT_NICE})\n"
          f"except (OSError, AttributeError): pass\n"
          f"import sys\n"
          f"from pyrt.station.blackbox import _plot_main\n"
          f"sys.exit(_plot_main(sys.argv[1:]))\n")


def _plot_main(argv: list[str]) -> int:
    """The child's side of :func:`_plot_elsewhere`: the arrays on stdin, PNG path argv[0]."""
    if len(argv) != 1:
        sys.stderr.write("usage: _plot_main PNG < ARRAYS.npz\n")
        return 2
    if not plotting_available():
        sys.stderr.write("no PNG: matplotlib is not installed\n")
        return 3
    with np.load(io.BytesIO(sys.stdin.buffer.read()), allow_pickle=False) as data:
        png = _png(data["t_s"], data["values"], [str(n) for n in data["names"]],
                   [str(u) for u in data["units"]], str(data["title"]))
    try:
        atomic_write(Path(argv[0]), png)
    except OSError as exc:
        sys.stderr.write(f"{exc.strerror or exc}\n")
        return 1
    return 0


def _groups(names: list[str]) -> list[list[int]]:
    """Signal indices a subplot each: an object's signals together, at most :data:`PER_PLOT`."""
    groups: list[list[int]] = []
    owner = None
    for k, name in enumerate(names):
        who = name.partition(".")[0]
        if groups and who == owner and len(groups[-1]) < PER_PLOT:
            groups[-1].append(k)
        else:
            groups.append([k])
        owner = who
    return groups


#: The longest line of a PNG's title (characters): the fault's whole text is
#: wrapped to lines of this width, which fit the figure's 10 inches at 90 dpi.
TITLE_CHARS = 130


def _title(text: str) -> str:
    """The fault's text as the PNG's title: whole, wrapped on words."""
    return textwrap.fill(text, TITLE_CHARS, break_long_words=True)


def _png(t_s: np.ndarray, values: np.ndarray, names: list[str], units: list[str],
         title: str) -> bytes:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    groups = _groups(names) or [[]]
    fig = Figure(figsize=(10, 0.6 + 1.7 * len(groups)), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(len(groups), 1, sharex=True, squeeze=False)[:, 0]
    for ax, group in zip(axes, groups, strict=True):
        for k in group:
            ax.plot(t_s, values[:, k], linewidth=0.9,
                    label=f"{names[k]} [{units[k]}]" if units[k] else names[k])
        ax.axvline(0.0, color="red", linestyle="--", linewidth=1.0)
        ax.grid(True, alpha=0.3)
        if group:
            ax.legend(loc="upper left", fontsize="x-small", framealpha=0.7)
    axes[-1].set_xlabel("time from the fault [s]")
    fig.suptitle(_title(title), fontsize="small")
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    return buf.getvalue()


# -- a recorder with its black box -------------------------------------------------------


class FaultRecorder(Recorder):
    """A :class:`Recorder` that writes its black box on every fault (a
    :class:`FaultBox`, :attr:`fault_box`); ``seconds``: the span kept before a
    fault (default: the black box's).  :meth:`close` writes what is due first."""

    def __init__(self, station: Station, path: str | Path | None, *, black_box: BlackBox,
                 seconds: float | None = None, **kw: Any):
        super().__init__(station, path, black_box=black_box, **kw)
        try:
            self.fault_box = FaultBox(self, seconds=seconds)
        except BaseException:
            super().close()
            raise

    def close(self) -> None:
        """Write the black boxes still due, then end the journal; idempotent."""
        try:
            self.fault_box.close()
        finally:
            super().close()

