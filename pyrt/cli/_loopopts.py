"""Loop options shared by every sub-command that runs a loop."""

from __future__ import annotations

import argparse
import queue
import re
import sys
import threading
import time
from collections.abc import Callable
from typing import Any

from pyrt._version import __version__
from pyrt.boards import DEFAULT_URL, parse_board_url
from pyrt.boards.registry import backend
from pyrt.errors import ConfigError, UsageError
from pyrt.scheduler import Loop, SimClock, TimingLog, WallClock
from pyrt.scheduler import rt as _rt

__all__ = ["OverrunLines", "add_boards_option", "add_loop_options", "load_backend", "make_loop",
           "parse_speed"]


def add_boards_option(parser: argparse.ArgumentParser, world: str) -> None:
    """Add ``--boards URL`` (the board back end; ``world``: what to give
    ``pyrt board-sim`` for this robot)."""
    parser.add_argument(
        "--boards",
        metavar="URL",
        default=DEFAULT_URL,
        help=(
            f"where the robot's boards are: {DEFAULT_URL} (default) simulates them and the "
            "world in this process; tcp://HOST:PORT drives the boards of a 'pyrt board-sim "
            f"{world} --listen HOST:PORT' in another process (its world at real time: "
            "only --speed 1, and the simulation's options are board-sim's)"
        ),
    )


def parse_speed(text: str) -> float | None:
    """``--speed`` value: ``max`` (None: virtual time, as fast as it goes) or a factor > 0."""
    if text.strip().lower() == "max":
        return None
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"speed must be a number > 0 or 'max', got {text!r}"
        ) from None
    if not value > 0 or value != value or value == float("inf"):
        raise argparse.ArgumentTypeError(f"speed must be a number > 0 or 'max', got {text!r}")
    return value


def _whole(what: str, unit: str, lo: int, hi: int) -> Callable[[str], int]:
    """An argparse type: a whole number of ``unit`` in lo..hi, or one clear error."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"{what} must be a whole number of {unit}, got {text!r}") from None
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"{what} must be {lo}..{hi} {unit}, got {value}")
        return value
    return parse


_tick_us = _whole("tick", "µs", 50, 1_000_000)
_slack_ns = _whole("timer slack", "ns", 1, 1_000_000_000)


def add_loop_options(
    parser: argparse.ArgumentParser, default_speed: str = "1", default_tick_us: int = 1000
) -> None:
    """Add --speed, --tick-us, --timing-log and the real-time knobs."""
    g = parser.add_argument_group("loop")
    g.add_argument(
        "--speed",
        type=parse_speed,
        default=parse_speed(default_speed),
        metavar="1|N|max",
        help=(
            f"1 = real time (default {default_speed}); N = N times faster than real time; max = "
            "virtual time, as fast as the CPU goes (scripts, tests)"
        ),
    )
    g.add_argument(
        "--tick-us",
        type=_tick_us,
        default=default_tick_us,
        metavar="US",
        help=f"base tick in µs (default {default_tick_us})",
    )
    g.add_argument(
        "--timing-log",
        metavar="FILE",
        help=(
            "write JSON Lines timing records (overruns, per-task summaries); "
            "read with 'pyrt overruns'"
        ),
    )
    g.add_argument(
        "--max-overruns",
        type=int,
        metavar="N",
        help="fault every robot after N consecutive overruns (default: never)",
    )
    g.add_argument(
        "--quiet-overruns",
        action="store_true",
        help=(
            "no overrun lines (stats, --timing-log and --max-overruns still count them); "
            "without it: the first line of a burst, then at most one summary every "
            f"{OverrunLines.WINDOW_S:g} s"
        ),
    )
    g.add_argument(
        "--timer-slack",
        type=_slack_ns,
        nargs="?",
        const=1,
        metavar="NS",
        help=(
            "the loop thread's timer slack in ns (Linux prctl PR_SET_TIMERSLACK; the "
            "kernel's default is 50000; NS left out: 1): sleeps wake closer to each "
            "deadline, so the loop spins less before it"
        ),
    )
    g.add_argument(
        "--spin",
        choices=WallClock.SPIN_POLICIES,
        default="moving",
        help=(
            "when the loop spins the last stretch before each deadline (so that the "
            "sleep's wake-up error does not make the tick late): while a robot moves "
            "(the default; at rest it sleeps to the deadline and an idle controller "
            "holds no core), always, or never"
        ),
    )
    g.add_argument(
        "--fifo", type=int, metavar="PRIO", help="run under SCHED_FIFO at PRIO (needs CAP_SYS_NICE)"
    )
    g.add_argument(
        "--mlock", action="store_true", help="lock memory (mlockall; needs RLIMIT_MEMLOCK)"
    )


def load_backend(url: str) -> None:
    """Load the back end of the board URL ``url`` now (ConfigError for a
    malformed URL or an unknown scheme), before the loop's clock starts, so
    that importing it does not make the first ticks late."""
    backend(parse_board_url(url).scheme, url)


def apply_rt_options(args: argparse.Namespace, say: Callable[[str], None]) -> None:
    """Apply the real-time knobs the user asked for; say what happened to each."""
    slack = args.timer_slack
    fifo = args.fifo
    if fifo is not None and getattr(args, "speed", 1.0) is None:
        say(f"--fifo {fifo} not applied: with --speed max the loop never sleeps, so a "
            "real-time priority would only take the CPU from everything else")
        fifo = None
    for wanted, fn in (
        # set here too, so that every thread started from now on inherits it;
        # the loop's clock sets it again in the loop thread (make_loop)
        (slack is not None, lambda: _rt.set_timer_slack(slack)),
        (fifo is not None, lambda: _rt.set_fifo(fifo)),
        (args.mlock, _rt.lock_memory),
    ):
        if wanted:
            try:
                say(fn())
            except (OSError, ValueError) as exc:
                say(f"warning: {exc.args[-1] if exc.args else exc}")


class StderrLines:
    """Lines for stderr, handed over by the loop thread and written by a
    thread of their own: a stderr that blocks (a full pipe, a slow
    terminal) never holds up a tick.  ``sys.stderr`` is looked up at each
    write, so a console that redirects it (prompt_toolkit prints such lines
    above the line being typed) gets them."""

    def __init__(self) -> None:
        self._lines: queue.SimpleQueue[str] = queue.SimpleQueue()
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()

    def put(self, line: str) -> None:
        """Queue ``line`` (any thread; never blocks)."""
        self._lines.put(line)
        if self._thread is None:
            with self._lock:
                if self._thread is None:
                    self._thread = threading.Thread(target=self._write, name="pyrt-stderr",
                                                    daemon=True)
                    self._thread.start()

    def _write(self) -> None:
        while True:
            line = self._lines.get()
            try:
                print(line, file=sys.stderr, flush=True)
            except (OSError, ValueError):  # stderr closed: the lines have nowhere to go
                return


_TICKS = re.compile(r"overrun: (\d+) tick")


class OverrunLines:
    """The loop's overrun lines as an operator gets them: the first line of
    a burst as it comes, then the overruns of the next :data:`WINDOW_S`
    counted and said in one summary (``overrun: 37 more overruns in the
    last 10 s; see stats``), so that a loaded machine is not flooded.

    The lines go to ``sink`` (stderr, by a thread of its own) until a
    console attaches (:meth:`attach`): then they are the console's messages
    (:meth:`messages`), printed on a line of their own before a prompt
    (above the typed line on a terminal), never after a prompt on its line.
    ``quiet``: no lines at all (``stats`` and the timing log still count)."""

    #: The window of one summary, seconds (monotonic).
    WINDOW_S = 10.0

    def __init__(self, sink: Callable[[str], None] | None = None, *, quiet: bool = False,
                 clock: Callable[[], float] = time.monotonic,
                 window_s: float = WINDOW_S) -> None:
        self._sink = sink if sink is not None else StderrLines().put
        self.quiet = quiet
        self._clock = clock
        self.window_s = window_s
        self._lock = threading.Lock()
        self._since: float | None = None  # when the window opened
        self._more = 0  # overruns counted in it, not shown
        self._held: list[str] | None = None  # a console's lines, once attached

    def attach(self) -> None:
        """From now on the lines are :meth:`messages` (a console prints them)."""
        with self._lock:
            if self._held is None:
                self._held = []

    def put(self, line: str) -> None:
        """One line from the loop (any thread; never blocks)."""
        if self.quiet:
            return
        m = _TICKS.match(line)
        count = int(m.group(1)) if m else 1
        now = self._clock()
        with self._lock:
            out = self._due(now)
            if self._since is None:
                self._since = now
                out.append(line)
            else:
                self._more += count
            self._emit(out)

    def _due(self, now: float) -> list[str]:
        """The summary of a window that is over (and the window closed), or []."""
        if self._since is None or now - self._since < self.window_s:
            return []
        out = []
        if self._more:
            s = now - self._since
            what = "overrun" if self._more == 1 else "overruns"
            out.append(f"overrun: {self._more} more {what} in the last {s:.0f} s; see stats")
            self._since = now  # a summary opens the next window
        else:
            self._since = None  # quiet for a window: the next overrun is shown as it comes
        self._more = 0
        return out

    def _emit(self, lines: list[str]) -> None:
        if self._held is not None:
            self._held.extend(lines)
        else:
            for line in lines:
                self._sink(line)

    def messages(self) -> list[str]:
        """The lines for an attached console (a window that is over is summed up first)."""
        with self._lock:
            if self._held is None:
                return []
            self._emit(self._due(self._clock()))
            out, self._held = self._held, []
        return out


def make_loop(args: argparse.Namespace, warn: Callable[[str], None] | None = None) -> Loop:
    """A loop configured from the options of :func:`add_loop_options`; its
    overrun lines go to ``warn`` (default: an :class:`OverrunLines` to stderr)."""
    if args.max_overruns is not None and args.max_overruns < 1:
        raise UsageError(f"--max-overruns must be >= 1, got {args.max_overruns}")
    clock = (SimClock() if args.speed is None
             else WallClock(speed=args.speed, timer_slack_ns=args.timer_slack,
                            spin=getattr(args, "spin", "moving")))
    log = None
    if args.timing_log:
        try:
            log = TimingLog(args.timing_log, version=__version__)
        except OSError as exc:
            raise ConfigError(f"cannot write timing log: {exc.strerror}", args.timing_log) from None
    if warn is None:
        warn = OverrunLines(quiet=getattr(args, "quiet_overruns", False)).put
    return Loop(
        clock,
        period_ns=args.tick_us * 1000,
        timing=True,
        timing_log=log,
        max_consecutive_overruns=args.max_overruns,
        warn=warn,
    )


def live_status(runner: Any, station: Any, args: argparse.Namespace) -> Callable[[], str] | None:
    """The console's live status line at real time (the station's status line,
    read without taking a fault the operator has not seen); None on simulated
    time, where nothing changes between commands."""
    if getattr(args, "speed", None) is None:
        return None
    return lambda: runner.call(station.status, name="status line", take_fault=False)
