"""Patterns of endpoints (000, section 5): the file, the run, the log.

A pattern file names its log file on the first line (relative to the
pattern file), then one endpoint ``x y z`` per line (blank lines and ``//``
comments skipped).  ``pattern FILE`` reads and checks it on the console's
side (:func:`read_pattern`, the command's grammar: never in the loop
thread); the run is a foreground job of the loop (:func:`run_pattern`):
move to each endpoint, pause about 10 s, go on.

The log records where each move stopped and why; a refused endpoint is
logged and skipped; a stop other than ENDPOINT_STOP/STUCK_STOP, an operator
stop or a fault abandons the pattern and the log says after which endpoint.
The loop thread never opens the log: each line is handed to a
:class:`~pyrt.tasks.writeback.Writer` over a :class:`PatternLog`, a
:class:`~pyrt.tasks.writeback.ThreadWriter` that appends on its own thread
(``"thread"``), or a :class:`~pyrt.tasks.writeback.SyncWriter` that appends
at once (``"sync"``: deterministic, for simulated-clock runs and tests).
"""

from __future__ import annotations

from collections.abc import Callable, Generator, Mapping, Sequence
from pathlib import Path
from typing import Any, Protocol

from pyrt.db import read_regular_file
from pyrt.errors import CommandError, ConfigError, DiskError
from pyrt.robots.stops import StopReason, StopRecord
from pyrt.tasks.writeback import SyncWriter, ThreadWriter, Writer
from pyrt.units import UnitError, parse_number

__all__ = [
    "MAX_PATTERN_BYTES",
    "PATTERN_PAUSE_S",
    "PatternLog",
    "log_writer",
    "parse_pattern",
    "read_pattern",
    "run_pattern",
]

#: 000, section 5: the pattern pauses "about 10 seconds" at each endpoint.
PATTERN_PAUSE_S = 10.0
#: Longest pattern file read (bytes); a pattern is a few hundred endpoints.
MAX_PATTERN_BYTES = 1 << 20

Vec = tuple[float, float, float]


# -- the file (console side) -----------------------------------------------------------


def read_pattern(text: str) -> tuple[Path, list[Vec], str]:
    """The grammar of ``pattern FILE``: the file read and checked on the
    console's side (never in the loop thread); its log file made writable."""
    log, points = parse_pattern(text)
    try:
        log.parent.mkdir(parents=True, exist_ok=True)
        log.open("a", encoding="utf-8").close()
    except OSError as exc:  # the name is the file's line 1: not echoed
        raise CommandError(f"pattern {text.strip()[:200]}:1: cannot write the log file named "
                           f"on that line: {exc.strerror}") from None
    return log, points, text


def parse_pattern(path: str | Path) -> tuple[Path, list[Vec]]:
    """A pattern file: first line the log file (relative to the pattern file),
    then one endpoint ``x y z`` per line (blank lines and ``//`` comments
    skipped), each coordinate a decimal number in cm (ASCII digits, as every
    number: :func:`pyrt.units.parse_number`).

    A refusal names the file and the line and says what was expected, never
    what the line holds: ``pattern FILE`` may name any readable file, and
    its answer goes to whoever asked (a network client too)."""
    p = Path(path)
    try:  # a regular file of bounded size: never /dev/zero, a FIFO or a growing log
        text = read_regular_file(p, MAX_PATTERN_BYTES).decode("utf-8")
    except ConfigError as exc:
        raise CommandError(f"pattern: {str(p)!r}: {exc.message}") from None
    except OSError as exc:
        raise CommandError(f"pattern: cannot read {str(p)!r}: {exc.strerror}") from None
    except UnicodeDecodeError as exc:
        raise CommandError(f"pattern: cannot read {str(p)!r}: not UTF-8 text (byte "
                           f"{exc.start})") from None
    lines = [(n, ln.split("//", 1)[0].strip()) for n, ln in enumerate(text.splitlines(), 1)]
    lines = [(n, ln) for n, ln in lines if ln]
    if not lines:
        raise CommandError(f"pattern {p}: empty; the first line names the log file")
    log = Path(lines[0][1])
    if not log.is_absolute():
        log = p.parent / log
    points: list[Vec] = []
    for n, ln in lines[1:]:
        parts = ln.replace(",", " ").split()
        if len(parts) != 3:
            raise CommandError(f"pattern {p}:{n}: expected an endpoint 'x y z' (three numbers, "
                               "cm); nothing moved")
        try:
            v = tuple(parse_number(c) for c in parts)
        except UnitError:
            raise CommandError(f"pattern {p}:{n}: expected an endpoint 'x y z' of three "
                               "finite decimal numbers (cm, ASCII digits); nothing "
                               "moved") from None
        points.append(v)  # type: ignore[arg-type]
    if not points:
        raise CommandError(f"pattern {p}: no endpoints after the log file line")
    return log, points


# -- the log (off the loop thread) -----------------------------------------------------


class PatternLog:
    """The pattern's log file as a writer's sink: a batch ``{n: line}`` is
    appended in the order of ``n`` (the writer keeps every key: no line is lost)."""

    def __init__(self, path: str | Path):
        self.path = Path(path)

    def write_back(self, changes: Mapping[int, str]) -> None:
        with open(self.path, "a", encoding="utf-8") as fh:
            for n in sorted(changes):
                fh.write(changes[n] + "\n")
            fh.flush()


def log_writer(path: str | Path, kind: str = "thread") -> Writer:
    """A writer appending to the log at ``path``: ``"thread"`` (on its own
    thread: the loop never waits for the disk) or ``"sync"`` (at once)."""
    sink = PatternLog(path)
    if kind == "sync":
        return SyncWriter(sink, what=f"pattern log {path}")
    if kind == "thread":
        return ThreadWriter(sink, name="pyrt-pattern-log", what=f"pattern log {path}")
    raise ValueError(f"pattern log writer must be 'sync' or 'thread', got {kind!r}")


# -- the run (a foreground job of the loop) --------------------------------------------


class PatternRobot(Protocol):
    """What a pattern drives (the PolyAxis)."""

    name: str
    active: bool
    last_stop: StopRecord | None

    @property
    def position(self) -> Vec: ...

    def to(self, target: Sequence[float]) -> Any: ...


def run_pattern(robot: PatternRobot, points: Sequence[Vec], open_log: Callable[[], Writer],
                time_s: Callable[[], float], pause_s: float = PATTERN_PAUSE_S
                ) -> Generator[None, None, list[StopRecord | str]]:
    """A foreground job: move to each endpoint, pause, go on; the log (a
    writer from ``open_log()`` at the first step, closed at the end without
    waiting) records where each move stopped and why.  A log the disk refuses
    ends the pattern where the last move ended (no move is made that the log
    cannot record) and is said as the robot's message (``say``).  Returns the records."""
    results: list[StopRecord | str] = []
    writer = open_log()
    seq = [0]
    failed: list[DiskError] = []

    def write(line: str) -> None:
        if failed:
            return
        try:
            writer.submit({seq[0]: line})
        except DiskError as exc:  # the log cannot be written: the pattern ends, said
            failed.append(exc)
            say = getattr(robot, "say", None)
            if say is not None:
                say(f"{robot.name}: pattern abandoned: {exc}; the robot is stopped "
                    "where its last move ended", "error")
        seq[0] += 1

    def ended(k: int, p: Vec) -> StopRecord | None:
        rec = robot.last_stop
        x = robot.position
        write(f"{k} {p[0]:g} {p[1]:g} {p[2]:g} {rec.reason.value if rec else 'STOP'} "
              f"at {x[0]:.3f} {x[1]:.3f} {x[2]:.3f} t={time_s():.2f} "
              f"{rec.detail if rec else ''}")
        results.append(rec if rec is not None else "STOP")
        return rec

    try:
        write(f"# pattern of {len(points)} endpoints, {robot.name}")
        k, moving = 0, False
        try:
            for k, p in enumerate(points, 1):
                if failed:  # no move is made that the log cannot record
                    return results
                try:
                    robot.to(p)
                except CommandError as exc:
                    write(f"{k} {p[0]:g} {p[1]:g} {p[2]:g} REFUSED {exc}")
                    results.append(f"REFUSED {exc}")
                    continue
                moving = True
                while robot.active:
                    yield
                moving = False
                rec = ended(k, p)
                if failed:
                    return results
                if rec is not None and rec.reason not in (StopReason.ENDPOINT_STOP,
                                                          StopReason.STUCK_STOP):
                    write(f"# pattern abandoned after endpoint {k}: {rec.reason.value}")
                    return results
                until = time_s() + pause_s
                while time_s() < until:
                    yield
        except GeneratorExit:
            # a stop or a fault ended the pattern: the log says where and why
            rec = ended(k, points[k - 1]) if moving else robot.last_stop
            why = rec.reason.value if rec is not None else "STOP"
            write(f"# pattern abandoned after endpoint {k}: {why}")
            raise
        write("# pattern complete")
        return results
    finally:
        writer.close(wait=False)
