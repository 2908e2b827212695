"""Running any station: ``pyrt NAME`` (installed), ``pyrt run MODULE:FACTORY``,
and :func:`run_station` for a script of one's own.

Every station gets the same options and the same life: the loop options,
``--boards``, ``--serve``/``--epics``/``--headless``, ``--timing-log`` and
``--history``; then the factory's own options
(:meth:`~pyrt.station.factory.StationFactory.add_arguments`).  The run
checks them (:meth:`~pyrt.station.factory.StationFactory.configure`),
applies the real-time knobs, builds the loop and the station, serves it if
asked, runs the station's start-up commands and its console (or, headless,
the service alone) until ``quit``, end of input or a signal, and closes it:
every motor stopped, databases written back, one line saying so.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Sequence

from pyrt.cli._help import Parser
from pyrt.cli._journal import add_journal_options, prepare_journal, start_recorder
from pyrt.cli._loopopts import (
    OverrunLines,
    add_boards_option,
    add_loop_options,
    apply_rt_options,
    live_status,
    load_backend,
    make_loop,
)
from pyrt.cli._serve import add_serve_options, prepare_service
from pyrt.cli._shutdown import run_until_shutdown
from pyrt.cli._stream import add_stream_options, stream_commands
from pyrt.commands import RobotShell
from pyrt.commands.robot import WAIT_PROGRESS_S
from pyrt.console import Console
from pyrt.errors import PyrtError, UsageError
from pyrt.server import ServedStation
from pyrt.station.factory import StationFactory, as_factory

__all__ = ["add_station_arguments", "add_station_parser", "run_factory", "run_station"]


def _progress_seconds(text: str) -> float:
    """``--wait-progress``: seconds, 0 or more (0: never)."""
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not 0.0 <= value < float("inf"):
        raise argparse.ArgumentTypeError(f"{text[:40]!r}: seconds, 0 or more (0: never)")
    return value


def _on_terminal(stream: object) -> bool:
    try:
        return bool(stream.isatty())  # type: ignore[attr-defined]
    except (AttributeError, ValueError):
        return False


def add_station_arguments(parser: argparse.ArgumentParser, factory: StationFactory) -> None:
    """Every station's options, then the factory's own, on ``parser``."""
    add_boards_option(parser, factory.name or "NAME")
    factory.add_arguments(parser)
    c = parser.add_argument_group("console")
    c.add_argument("--history", metavar="FILE", help="keep the command history in FILE")
    c.add_argument("-k", "--keep-going", action="store_true",
                   help="a script (stdin not a terminal) runs on after a line that failed "
                        "and still exits 1; without it the script stops at the first "
                        "(docs/scripts.md)")
    c.add_argument("--wait-progress", metavar="SECONDS", type=_progress_seconds,
                   default=WAIT_PROGRESS_S,
                   help="a script (stdin not a terminal): a long 'wait' says where the robot "
                        f"is every SECONDS of the station's clock (default {WAIT_PROGRESS_S:g}; "
                        "0: never)")
    c.add_argument("--scope-dir", metavar="DIR",
                   help="the directory 'scope save' and 'scope plot' write into, and no "
                        "other (default: the working directory)")
    add_loop_options(parser, default_speed=factory.default_speed,
                     default_tick_us=factory.default_tick_us)
    add_serve_options(parser)
    add_journal_options(parser)
    add_stream_options(parser)
    parser.set_defaults(run=lambda args: run_factory(factory, args))


def add_station_parser(sub: argparse._SubParsersAction, factory: StationFactory
                       ) -> argparse.ArgumentParser:
    """The sub-command ``pyrt NAME`` of an installed station."""
    p = sub.add_parser(factory.name, help=factory.summary or f"run the {factory.name} station",
                       description=factory.description or factory.summary,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    add_station_arguments(p, factory)
    return p


def station_parser(factory: StationFactory, prog: str) -> argparse.ArgumentParser:
    """A parser of its own for ``factory`` (``pyrt run`` and :func:`run_station`)."""
    p = Parser(prog=prog, description=factory.description or factory.summary,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    add_station_arguments(p, factory)
    return p


def _check_tick(factory: StationFactory, args: argparse.Namespace) -> None:
    hi = factory.max_tick_us
    if hi is not None and args.tick_us > hi:
        why = f" ({factory.max_tick_why})" if factory.max_tick_why else ""
        raise UsageError(f"--tick-us {args.tick_us}: this station runs on ticks of at most "
                          f"{hi} µs{why}")


def run_factory(factory: StationFactory, args: argparse.Namespace) -> int:
    """Run the station ``factory`` builds, with parsed ``args`` (see the module text);
    returns the exit status."""
    out = sys.stdout

    def say(line: str) -> None:
        print(line, file=out, flush=True)

    what = f"pyrt {factory.name}".rstrip()
    _check_tick(factory, args)
    factory.configure(args, say)
    apply_rt_options(args, say)
    prepare_journal(args)
    load_backend(args.boards)
    # overrun lines: stderr until the console runs, then its messages (never on
    # the prompt's line); the first of a burst, then a summary every 10 s
    overruns = OverrunLines(quiet=args.quiet_overruns)
    loop = make_loop(args, warn=overruns.put)
    scope_dir = _scope_dir(getattr(args, "scope_dir", None))
    station = factory.build(loop, args)
    station.close_report = say
    station.scope.directory = scope_dir
    runner = station.runner
    recorder = None
    try:
        streaming = stream_commands(args, station)
        recorder = start_recorder(station, args, getattr(args, "_factory", "") or factory.name,
                                  say)
        served = ServedStation(station)
        service = prepare_service(args, runner, served)
    except PyrtError:
        station.close()
        if recorder is not None:
            recorder.close()
        raise
    if service is not None:  # commands come from elsewhere too: keep their trail
        try:
            say(f"audit log (remote commands): {served.open_audit_log()}")
        except OSError as exc:
            say(f"warning: no audit log: {exc}")
    shell = RobotShell(station, out)
    if not _on_terminal(sys.stdin):  # a script's log shows a long move going
        shell.wait_progress_s = args.wait_progress
    if not args.headless:
        overruns.attach()

    def messages() -> list[str]:
        return overruns.messages() + shell.messages()

    console = Console(shell, sys.stdin, out, messages=messages,
                      history_file=args.history, status=live_status(runner, station, args),
                      keep_going=args.keep_going, what=what)
    for note in station.startup_notes:
        say(f"start-up: {note}")
    say(factory.banner(station, args))
    wall0 = time.perf_counter()
    timing_log = loop.timing_log  # the loop lets go of it when it closes
    station.start()
    first = [*streaming, *station.profile.startup_commands]

    def run_first() -> None:
        for line in first:
            shell.onecmd(line)

    try:
        status = run_until_shutdown(station, console, service,
                                    headless=args.headless, what=what, say=say,
                                    first=run_first if first else None)
    finally:
        served.close_audit_log()
        if recorder is not None:
            recorder.close()
            journal = recorder.journal
            if journal.path is not None:
                gaps = (f", {len(journal.gaps)} gap(s) where the writer fell behind"
                        if journal.gaps else "")
                say(f"journal: {journal.recorded} ticks in {journal.path}{gaps}; "
                    f"'pyrt replay {journal.path}' re-runs them")
    if args.timing_log:
        wall = time.perf_counter() - wall0
        failed = getattr(timing_log, "failed", None)
        if failed is not None:
            why = getattr(failed, "strerror", None) or failed
            say(f"timing log {args.timing_log}: ended early, a write was refused ({why}); "
                "the records before it are in the file")
        else:
            say(f"timing log written to {args.timing_log} ({loop.tick_index} ticks, "
                f"{wall:.2f} s)")
    return status


def _scope_dir(name: str | None) -> str | None:
    """``--scope-dir``'s directory, absolute (None: the working directory);
    ConfigError if it is not there."""
    if name is None:
        return None
    if not os.path.isdir(name):
        raise UsageError(f"--scope-dir {name}: there is no such directory")
    return os.path.abspath(name)


def run_station(factory: object, argv: Sequence[str] | None = None, *, prog: str = "") -> int:
    """Run a station from a script of one's own: parse ``argv`` (default
    ``sys.argv[1:]``) with every station option and the factory's own, run
    it, and return the exit status (errors that are the user's: one line
    on stderr, status 1).  ``factory`` is a StationFactory (instance or
    class) or a function ``build(loop, args) -> Station``."""
    fac = as_factory(factory)
    name = prog or (f"pyrt {fac.name}" if fac.name else "pyrt")
    parser = station_parser(fac, name)
    args = parser.parse_args(list(argv) if argv is not None else None)
    try:
        return run_factory(fac, args)
    except UsageError as exc:
        print(f"{name}: error: {exc}", file=sys.stderr)
        return 2
    except PyrtError as exc:
        print(f"{name}: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"{name}: interrupted", file=sys.stderr)
        return 130
