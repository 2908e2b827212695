"""The timing log: JSON Lines written by the loop, read back by ``pyrt overruns``.

Records, one JSON object per line, each with a ``type``:

* ``header``: format version, pyrt version, tick period, clock, task names
  (the ready queues' routines, then the timed loop handlers), handler names,
  and the rate groups as they run (``[{name, period_ns, tasks}, ...]``);
* ``overrun``: tick index, deadline, start, end, lateness (start - deadline),
  overrun (end - next deadline), deadlines missed, the tasks run in that
  tick with their durations (``[[name, ns], ...]``, in the order they ran:
  routines and loop handlers such as ``boards`` alike) and their groups
  (``task_groups``, one per task; "" for a loop handler outside groups),
  the group the overrun is charged
  to (``group``: that of the task that ran longest; null for a loop
  handler) and the releases each group missed (``missed_releases``);
* ``summary``: cumulative counts since the start: ticks, overruns, missed,
  lateness and work distributions, per task calls, mean, max, p99, kind
  (``task`` or ``handler``), group and the sparse log-spaced histogram
  (``[[bin, count], ...]``; see :mod:`pyrt.scheduler.stats` for the bins),
  and per group its period, releases, time per release (mean, max, p99,
  histogram), overruns charged and releases missed.

Format ``pyrt-timing/2``; logs of ``pyrt-timing/1`` (before rate groups:
no groups) are still read, their tasks in no group.

All times are integers in nanoseconds of the loop's clock.  Overrun
records are buffered in memory; summaries are built and everything is
written by a background thread (:meth:`TimingLog.defer`), so a tick never
waits on the disk or on the statistics.
"""

from __future__ import annotations

import json
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import IO, Any

from pyrt.errors import ConfigError
from pyrt.scheduler.stats import Distribution, LoopStatistics

__all__ = ["FORMAT", "READABLE", "GroupReport", "TimingLog", "TimingReport", "read_timing_log"]

FORMAT = "pyrt-timing/2"
#: Formats read back: the current one, and the one before rate groups.
READABLE = ("pyrt-timing/1", FORMAT)


def _dist_json(d: Distribution) -> dict[str, Any]:
    return {
        "count": d.count,
        "total_ns": d.total_ns,
        "mean_ns": round(d.mean_ns, 1),
        "max_ns": d.max_ns,
        "p50_ns": d.p50_ns,
        "p99_ns": d.p99_ns,
        "p999_ns": d.p999_ns,
        "hist": [list(p) for p in d.hist],
    }


class TimingLog:
    """Writes the timing log to ``path`` (or an open text stream)."""

    def __init__(self, path: str | IO[str], version: str = ""):
        if isinstance(path, str):
            self._fh: IO[str] = open(path, "w", encoding="utf-8")  # noqa: SIM115
            self._owned = True
        else:
            self._fh = path
            self._owned = False
        self.path = path if isinstance(path, str) else getattr(path, "name", "<stream>")
        self.version = version
        self._buf: list[str] = []
        self._lock = threading.Lock()
        self._jobs: queue.SimpleQueue[Callable[[], None] | None] = queue.SimpleQueue()
        self._worker: threading.Thread | None = None
        self.error: BaseException | None = None
        #: The write error that ended the log early, or None.
        self.failed: BaseException | None = None

    def _emit(self, record: dict[str, Any]) -> None:
        line = json.dumps(record, separators=(",", ":"))
        with self._lock:
            self._buf.append(line)

    def defer(self, job: Callable[[], None]) -> None:
        """Run ``job`` (build a summary, write) in the log's background thread."""
        if self._worker is None:
            self._worker = threading.Thread(target=self._work, name="pyrt-timing-log", daemon=True)
            self._worker.start()
        self._jobs.put(job)

    def _work(self) -> None:
        while True:
            job = self._jobs.get()
            if job is None:
                return
            try:
                job()
            except BaseException as exc:  # keep the first error; the log is best effort
                if self.error is None:
                    self.error = exc

    def header(self, *, period_ns: int, clock: str, tasks: list[str], handlers: list[str],
               groups: list[dict[str, Any]] | None = None) -> None:
        """Write the header record (once, before anything else)."""
        self._emit(
            {
                "type": "header",
                "format": FORMAT,
                "version": self.version,
                "period_ns": period_ns,
                "clock": clock,
                "tasks": tasks,
                "handlers": handlers,
                "groups": groups or [],
                "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
            }
        )
        self.flush()

    def overrun(self, **fields: Any) -> None:
        """Record one overrun (fields as listed in the module docstring)."""
        fields["tasks"] = [[n, d] for n, d in fields["tasks"]]
        self._emit({"type": "overrun", **fields})

    def summary(self, now_ns: int, stats: LoopStatistics) -> None:
        """Record cumulative statistics and write everything buffered."""
        self._emit(
            {
                "type": "summary",
                "time_ns": now_ns,
                "ticks": stats.ticks,
                "overruns": stats.overruns,
                "missed": stats.missed,
                "startup_overruns": stats.startup_overruns,
                "startup_worst_ns": stats.startup_worst_ns,
                "lateness": _dist_json(stats.lateness),
                "work": _dist_json(stats.work),
                "tasks": {
                    name: {
                        "calls": t.calls,
                        "mean_ns": round(t.mean_ns, 1),
                        "max_ns": t.max_ns,
                        "p99_ns": t.p99_ns,
                        "overruns": t.overruns,
                        "kind": t.kind,
                        "group": t.group,
                        "hist": [list(p) for p in t.distribution.hist],
                    }
                    for name, t in stats.tasks.items()
                },
                "groups": {
                    name: {
                        "period_ns": g.period_ns,
                        "releases": g.releases,
                        "mean_ns": round(g.mean_ns, 1),
                        "max_ns": g.max_ns,
                        "p99_ns": g.p99_ns,
                        "overruns": g.overruns,
                        "missed": g.missed,
                        "tasks": list(g.tasks),
                        "hist": [list(p) for p in g.distribution.hist],
                    }
                    for name, g in stats.groups.items()
                },
            }
        )
        self.flush()

    def flush(self) -> None:
        """Write buffered records to the file.  A write the file refuses (a full
        disk) ends the log there: the error is kept (:attr:`error`) and said when
        the run ends; the run itself goes on (the log is a diagnostic, not a
        record a robot depends on)."""
        with self._lock:
            lines, self._buf = self._buf, []
            if self.failed is not None:
                return
            try:
                if lines:
                    self._fh.write("\n".join(lines) + "\n")
                self._fh.flush()
            except (OSError, ValueError) as exc:
                self.failed = exc
                if self.error is None:
                    self.error = exc

    def drain(self) -> None:
        """Wait for the deferred work (summaries) to be done."""
        if self._worker is not None:
            self._jobs.put(None)
            self._worker.join()
            self._worker = None

    def close(self) -> None:
        """Finish deferred work, flush and close (a stream passed in is flushed, not closed)."""
        self.drain()
        self.flush()
        if self._owned:
            try:
                self._fh.close()
            except OSError as exc:
                if self.failed is None:
                    self.failed = exc


@dataclass
class TaskReport:
    """What the log says about one task."""

    name: str
    calls: int = 0
    mean_ns: float = 0.0
    p99_ns: int = 0
    max_ns: int = 0
    #: Overruns in which this task ran longest.
    overruns: int = 0
    #: Overruns in which this task ran at all.
    present: int = 0
    #: ``"task"`` (a ready-queue routine) or ``"handler"`` (a loop handler).
    kind: str = "task"
    #: Its rate group ("": a loop handler outside groups, or a log before groups).
    group: str = ""


@dataclass
class GroupReport:
    """What the log says about one rate group."""

    name: str
    period_ns: int
    releases: int = 0
    mean_ns: float = 0.0
    p99_ns: int = 0
    max_ns: int = 0
    #: Overruns charged to the group (its task ran longest in the tick).
    overruns: int = 0
    #: Its releases that the loop was too busy to run.
    missed: int = 0
    tasks: list[str] = field(default_factory=list)


@dataclass
class TimingReport:
    """A timing log, read back and checked."""

    path: str
    header: dict[str, Any]
    summary: dict[str, Any] | None
    overruns: list[dict[str, Any]] = field(default_factory=list)
    tasks: dict[str, TaskReport] = field(default_factory=dict)
    #: Per rate group, as they run (empty for a log before rate groups).
    groups: dict[str, GroupReport] = field(default_factory=dict)

    @property
    def format(self) -> str:
        return str(self.header["format"])

    @property
    def period_ns(self) -> int:
        return int(self.header["period_ns"])

    def worst(self, n: int = 10) -> list[dict[str, Any]]:
        """The ``n`` overruns that ended furthest past their next deadline."""
        return sorted(self.overruns, key=lambda r: r["overrun_ns"], reverse=True)[:n]


_OVERRUN_KEYS = ("tick", "deadline_ns", "start_ns", "end_ns", "lateness_ns", "overrun_ns", "tasks")


def read_timing_log(path: str) -> TimingReport:
    """Read and check a timing log; raise :class:`ConfigError` naming the
    file and line for a missing, empty, truncated or malformed file."""
    try:
        with open(path, encoding="utf-8") as fh:
            text = fh.read()
    except FileNotFoundError:
        raise ConfigError("no such file", path) from None
    except IsADirectoryError:
        raise ConfigError("is a directory, not a timing log", path) from None
    except UnicodeDecodeError:
        raise ConfigError("not a timing log (not UTF-8 text)", path) from None
    except OSError as exc:
        raise ConfigError(f"cannot read: {exc.strerror}", path) from None
    if not text.strip():
        raise ConfigError("empty file: no timing records", path)
    lines = text.split("\n")
    if lines[-1] != "":
        raise ConfigError(
            "truncated: the last record has no end of line (was the writer killed?)",
            path,
            len(lines),
        )
    header: dict[str, Any] | None = None
    summary: dict[str, Any] | None = None
    overruns: list[dict[str, Any]] = []
    for lineno, line in enumerate(lines[:-1], start=1):
        if not line.strip():
            continue
        try:
            rec = json.loads(line)
        except json.JSONDecodeError as exc:
            raise ConfigError(f"not a JSON record ({exc.msg})", path, lineno) from None
        if not isinstance(rec, dict) or "type" not in rec:
            raise ConfigError("not a timing record (no 'type' field)", path, lineno)
        kind = rec["type"]
        if header is None:
            if kind != "header" or not str(rec.get("format", "")).startswith("pyrt-timing/"):
                raise ConfigError(
                    f"not a pyrt timing log: first record must be a {FORMAT} header", path, lineno
                )
            if rec["format"] not in READABLE:
                raise ConfigError(
                    f"timing log format {rec['format']} is not one this pyrt reads "
                    f"({', '.join(READABLE)}): read it with the pyrt that wrote it "
                    f"(version {rec.get('version') or 'unknown'})", path, lineno)
            if not isinstance(rec.get("period_ns"), int) or rec["period_ns"] <= 0:
                raise ConfigError("header has no valid period_ns", path, lineno)
            header = rec
        elif kind == "overrun":
            missing = [k for k in _OVERRUN_KEYS if k not in rec]
            if missing:
                raise ConfigError(f"overrun record lacks {', '.join(missing)}", path, lineno)
            overruns.append(rec)
        elif kind == "summary":
            if not isinstance(rec.get("tasks"), dict):
                raise ConfigError("summary record has no task table", path, lineno)
            summary = rec
        elif kind == "header":
            raise ConfigError("second header record", path, lineno)
        else:
            raise ConfigError(f"unknown record type {kind!r}", path, lineno)
    assert header is not None
    report = TimingReport(path=path, header=header, summary=summary, overruns=overruns)
    handlers = set(header.get("handlers", []))
    for name in header.get("tasks", []):
        report.tasks[name] = TaskReport(name, kind="handler" if name in handlers else "task")
    for g in header.get("groups", []):
        report.groups[g["name"]] = GroupReport(g["name"], int(g["period_ns"]),
                                               tasks=list(g.get("tasks", [])))
        for name in g.get("tasks", []):
            if name in report.tasks:
                report.tasks[name].group = g["name"]
    if summary is not None:
        for name, t in summary["tasks"].items():
            tr = report.tasks.setdefault(name, TaskReport(name))
            tr.calls = int(t.get("calls", 0))
            tr.mean_ns = float(t.get("mean_ns", 0.0))
            tr.p99_ns = int(t.get("p99_ns", 0))
            tr.max_ns = int(t.get("max_ns", 0))
            tr.kind = str(t.get("kind", "task"))
            tr.group = str(t.get("group", tr.group))
        for name, g in summary.get("groups", {}).items():
            gr = report.groups.setdefault(name, GroupReport(name, int(g.get("period_ns", 0))))
            gr.releases = int(g.get("releases", 0))
            gr.mean_ns = float(g.get("mean_ns", 0.0))
            gr.p99_ns = int(g.get("p99_ns", 0))
            gr.max_ns = int(g.get("max_ns", 0))
            gr.missed = int(g.get("missed", 0))
    for rec in overruns:
        tasks = rec["tasks"]
        if not tasks:
            continue
        for (name, _), group in zip(tasks, rec.get("task_groups") or [""] * len(tasks),
                                    strict=False):
            tr = report.tasks.setdefault(name, TaskReport(name))
            tr.present += 1
            if group:
                tr.group = str(group)
        culprit = max(tasks, key=lambda t: t[1])[0]
        report.tasks[culprit].overruns += 1
        charged = rec.get("group")
        if charged in report.groups:
            report.groups[charged].overruns += 1
    return report
