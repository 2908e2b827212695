"""The ``pyrt`` command: one sub-command per job, and one per installed station.

Each tool lives in its own module with ``add_parser(subparsers)`` and
``run(args) -> int``.  Stations are not named here: every station installed
through the entry-point group ``pyrt.stations`` is a sub-command
(``pyrt NAME``), and ``pyrt run MODULE:FACTORY`` runs one from any
importable module (:mod:`pyrt.cli._station`).  Errors that are the user's (a
bad file, a bad option) end with one line on stderr and a non-zero exit,
never a traceback.
"""

from __future__ import annotations

import argparse
import signal
import sys
from collections.abc import Sequence

from pyrt._version import __version__
from pyrt.cli import (
    boardsim,
    connect,
    demo,
    export,
    forcemap,
    logsort,
    overruns,
    reference,
    replay,
    run,
    send,
    top,
)
from pyrt.cli._help import Parser
from pyrt.cli._pipe import PipeGuard
from pyrt.cli._station import add_station_parser
from pyrt.console import ReaderGone, silence
from pyrt.errors import ConfigError, PyrtError, UsageError
from pyrt.station.factory import find_station, installed_stations

__all__ = ["build_parser", "entry", "main"]

_COMMANDS = [demo, overruns, logsort, forcemap, send, connect, top, boardsim, run, replay,
             export, reference]
#: The tools' names: an installed station cannot take one of them.
_TOOLS = ("demo", "overruns", "logsort", "forcemap", "send", "connect", "top", "board-sim",
          "run", "replay", "export", "reference")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``pyrt`` and all its sub-commands."""
    parser = Parser(
        prog="pyrt",
        description=(
            "pyrt: an embedded-style control runtime. A periodic tick drives an "
            "8031-style ready queue of self-scheduling tasks, with overrun "
            "detection and per-task timing."
        ),
        epilog=(
            "A console whose input is not a terminal runs a script: it stops at the first "
            "line that fails (an error, a FAULT), names it on stderr and exits 1; -k runs "
            "on and exits 1 at the end. The same for 'pyrt send -f FILE' and a piped "
            "'pyrt connect'. See docs/scripts.md."
        ),
    )
    parser.add_argument("--version", action="version", version=f"pyrt {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in installed_stations():
        if name in _TOOLS:
            continue  # a tool's name: reachable through 'pyrt run' only
        try:
            factory = find_station(name)
        except ConfigError as exc:  # a broken installation must not break pyrt
            sub.add_parser(name, help=f"(cannot be loaded: {exc})")
            continue
        add_station_parser(sub, factory)
    for module in _COMMANDS:
        module.add_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``pyrt`` command; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 2
    try:
        return int(args.run(args) or 0)
    except UsageError as exc:  # a command line that cannot be used: as argparse ends one
        print(f"pyrt {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except PyrtError as exc:
        print(f"pyrt {args.command}: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"pyrt {args.command}: interrupted", file=sys.stderr)
        return 130


def entry() -> None:
    """The ``pyrt`` program (console script and ``python -m pyrt``): :func:`main`,
    then the interpreter's exit with its status.  Whatever ran is closed by
    then (a robot's motors stopped, its databases written back), and Python
    puts the default signal actions back while it finalizes: a SIGTERM or
    SIGHUP that comes late (the second of two sent together) is ignored from
    here on, so the process ends with its status instead of being killed.
    A reader of stdout that has gone (``| head``) ends any command quietly,
    status 0."""
    status: int | str | None
    stdout = sys.stdout
    if stdout is not None and not isinstance(stdout, PipeGuard):
        sys.stdout = PipeGuard(stdout)  # type: ignore[assignment]
    try:
        try:
            status = main()
        except SystemExit as exc:  # argparse: --help, --version, a usage error
            status = exc.code
        sys.stdout.flush()  # here, not in the interpreter's exit, where EPIPE would be loud
    except (BrokenPipeError, ReaderGone):
        # the reader of stdout has gone (`pyrt overruns F --json | head`): it has
        # what it wanted; end quietly, as `pyrt send` does
        silence(stdout)
        status = 0
    for name in ("SIGTERM", "SIGHUP"):
        sig = getattr(signal, name, None)
        if sig is not None:
            signal.signal(sig, signal.SIG_IGN)
    sys.exit(status)


if __name__ == "__main__":  # pragma: no cover
    entry()
