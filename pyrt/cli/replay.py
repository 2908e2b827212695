"""``pyrt replay FILE``: re-run a recorded run on virtual time and check every output.

The journal (``--journal FILE`` of any station) holds what entered the
controller: its commands, the inputs of its process image and the clock's
decisions, and the outputs it wrote.  The replay builds the same station
(the factory, options and databases the run had), feeds it the recorded
inputs and commands tick by tick at the recorded times, and compares every
output written, and every fault, with the recorded ones.  It ends with
"replayed N ticks, identical" (exit 0) or the first tick that differs: the
register, the recorded and the replayed value, and the task that wrote each
(exit 1).

``--until TICK`` stops after that tick and opens the console on the
controller as it stood then (read-only: nothing is moved; ``scope`` shows
what was sampled over the replayed ticks).  ``--scope CHANNELS`` samples any
signals over the replay, whether or not anybody watched them in the run;
``--scope-save FILE`` writes them (``.csv`` or ``.npz``; a plot as ``.png``,
``.svg`` or ``.pdf``).

Every option is checked before the first tick is replayed: an unknown
channel, a file name whose extension names no format, ``--scope-save``
without ``--scope`` or into a directory that is not there.  Such a usage
error ends as argparse ends one (the usage line, ``pyrt replay: error:
...`` on stderr, exit status 2) and replays nothing.  Exit status 1 is a
run that failed: a journal that cannot be read, a replay that differs, a
file that could not be written.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
from pathlib import Path
from typing import Any

from pyrt._version import __version__
from pyrt.cli._station import station_parser
from pyrt.commands import RobotShell
from pyrt.console import Console
from pyrt.errors import CommandError, ConfigError, PyrtError
from pyrt.journal import JournalError
from pyrt.scheduler import Loop
from pyrt.scope import (
    MAX_BUFFER_BYTES,
    MAX_LENGTH,
    PLOT_SUFFIXES,
    SAVE_SUFFIXES,
    Scope,
    check_plot_path,
    check_save_path,
    plot_frame,
    save_frame,
)
from pyrt.station.factory import find_station, load_factory
from pyrt.station.replay import Replay

__all__ = ["add_parser", "build_replayed", "run"]

#: Options of the run that a replay never takes over (it has its own clock,
#: boards, and no links).
_NOT_REPLAYED = {"boards", "journal", "black_box", "serve", "epics", "headless",
                 "timing_log", "history", "speed", "fifo", "timer_slack", "spin", "max_overruns",
                 "mlock", "run", "scope_dir"}


def _tick(text: str) -> int:
    try:
        value = int(text, 0)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a tick number, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"a tick number is >= 0, got {value}")
    return value


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "replay", help="re-run a journal (--journal FILE) on virtual time, checking every output",
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("file", metavar="FILE", help="a journal written by --journal")
    p.add_argument("--until", type=_tick, metavar="TICK",
                   help="stop after tick TICK and open a read-only console on the "
                        "controller as it stood then")
    p.add_argument("--scope", metavar="CHANNELS",
                   help="sample these signals (comma-separated, as 'scope add' names them) "
                        "over every replayed tick")
    p.add_argument("--factory", metavar="MODULE:FACTORY",
                   help="replay a journal recorded with 'pyrt run MODULE:FACTORY': the "
                        "factory it names is imported only when given here, the same")
    p.add_argument("--scope-save", metavar="FILE",
                   help=f"write the sampled signals to FILE ({', '.join(SAVE_SUFFIXES)}; or a "
                        f"plot, {', '.join(PLOT_SUFFIXES)}: needs matplotlib)")
    p.set_defaults(run=run, usage=p.format_usage)


class UsageError(Exception):
    """An option of ``pyrt replay`` that cannot be used (exit status 2)."""


def _check_options(args: argparse.Namespace) -> None:
    """The checks that need no journal: UsageError for the first that fails."""
    if args.scope_save is None:
        return
    path = Path(args.scope_save)
    check = check_plot_path if path.suffix.lower() in PLOT_SUFFIXES else check_save_path
    try:
        check(path)
    except CommandError:
        raise UsageError(f"--scope-save {args.scope_save}: use a file name ending "
                         f"{', '.join((*SAVE_SUFFIXES, *PLOT_SUFFIXES))}") from None
    if not _channels(args):
        raise UsageError("--scope-save needs --scope CHANNELS (the signals to write)")
    parent = path.parent
    if not parent.is_dir():
        raise UsageError(f"--scope-save {args.scope_save}: there is no directory {parent}")


def _channels(args: argparse.Namespace) -> list[str]:
    return [c.strip() for c in (args.scope or "").split(",") if c.strip()]


def _usage_error(args: argparse.Namespace, message: str) -> int:
    usage = getattr(args, "usage", None)
    if usage is not None:
        sys.stderr.write(usage())
    print(f"pyrt replay: error: {message}", file=sys.stderr)
    return 2


class FrozenRunner:
    """The runner of a stopped replay: a call runs at once (the loop does not
    run again); nothing that waits on ticks or moves is allowed."""

    virtual = True

    def __init__(self, station: Any):
        self.station = station
        self.loop = station.loop
        self.motion = station.runner.motion

    def call(self, fn: Any, *args: Any, timeout_s: float = 1.0, name: str = "",
             take_fault: bool = True) -> Any:
        return fn(*args)

    def statistics(self, timeout_s: float = 1.0, take_fault: bool = True) -> Any:
        return self.loop.statistics()

    def messages(self) -> list[str]:
        return []

    def take_faults(self) -> list[Any]:
        return []

    def take_fault(self, fault: Any) -> None:
        """Faults of a replay were the run's: nothing to take."""

    def poll(self, timeout_s: float = 1.0) -> None:
        """Nothing to wait for."""

    def _refuse(self, *args: Any, **kwargs: Any) -> Any:
        raise CommandError("the replay is stopped: nothing runs or moves (read-only)")

    wait_until = sleep = spawn = run_job = submit_motion = _refuse


class ReplayShell(RobotShell):
    """The console of a stopped replay: commands that only read (and the scope)."""

    _ALLOWED = {"scope", "help", "quit", "exit", "clear"}

    def onecmd(self, line: str) -> bool:
        words = line.split()
        if words and words[0].lower() not in self._ALLOWED:
            try:
                _comp, rec, args, _rest = self.resolve(line)
            except CommandError as exc:
                self.error(str(exc))
                return False
            if not rec.only_reads(args) and rec.name.lower() not in self._ALLOWED:
                self.error(f"{line.strip()[:40]!r} would change the controller: a replay "
                           "is read-only (status, get, scope and the robot's reading "
                           "commands work)")
                return False
        return super().onecmd(line)


def _arguments(replay: Replay, factory: Any, directory: str) -> argparse.Namespace:
    parser = station_parser(factory, "pyrt replay")
    args = parser.parse_args([])
    defaults = vars(args)
    actions = {a.dest: a for a in parser._actions}
    for key, value in replay.arguments.items():
        if key in defaults and key not in _NOT_REPLAYED:
            _check_option(replay.path, actions.get(key), key, value)
            setattr(args, key, value)
    args.boards = replay.url
    args.speed = None
    args.journal = None
    args.black_box = 0.0
    args.serve = None
    args.epics = None
    args.headless = False
    args.timing_log = None
    args.history = None
    if replay.write_databases(Path(directory)):
        factory.use_databases(args, directory)
    return args


def _add_channels(station: Any, scope: Scope, channels: list[str]) -> None:
    """Put ``channels`` on the replay's scope; UsageError naming the first that
    is not a signal of the station (or does not fit)."""
    for ch in channels:
        try:
            scope.add(ch, station.resolve_signal(ch).scope_source())
        except CommandError as exc:
            raise UsageError(f"--scope {ch}: {exc}") from None


def build_replayed(replay: Replay, directory: str, trusted: str | None = None) -> Any:
    """The station of ``replay``'s run (its factory, options and databases, the
    databases written into ``directory``), attached to the replay, not yet run;
    ConfigError if the factory is not installed or refuses the options.

    A journal never chooses code to run: a factory outside the installed
    stations (``MODULE:FACTORY``) is imported only when ``trusted`` names the
    same (``--factory``)."""
    spec = replay.factory
    if ":" in spec and trusted != spec:
        raise ConfigError(
            f"journal {replay.path} was recorded with the station factory {spec[:80]!r}, "
            "code outside pyrt's installed stations: a journal does not choose code to "
            f"run; if you trust it, give --factory {spec[:80]}")
    factory = load_factory(spec) if ":" in spec else find_station(spec)
    st_args = _arguments(replay, factory, directory)
    factory.configure(st_args, lambda line: None)
    if replay.header.period_ns % 1000 == 0:
        st_args.tick_us = replay.header.period_ns // 1000
    loop = Loop(replay.clock, period_ns=replay.header.period_ns, timing=True)
    with replay.building():
        station = factory.build(loop, st_args)
    replay.attach(station)
    return station


def _check_option(path: str, action: argparse.Action | None, key: str, value: Any) -> None:
    """ConfigError unless ``value`` is one the option's own parser could have given
    (a journal from elsewhere may hold anything: it is refused, not obeyed)."""
    if action is None or value is None or value == action.default:
        return
    many = action.nargs not in (None, 0, "?") or isinstance(action, argparse._AppendAction)
    values = value if isinstance(value, list) and many else [value]
    for v in values:
        if action.nargs == 0:  # a flag
            ok = isinstance(v, bool)
        elif isinstance(v, list) and action.type is not None:  # a type giving a tuple
            try:  # (the arm's --start Q0,Q1): its text is the items, comma-separated
                got = action.type(",".join(str(x) for x in v))  # type: ignore[operator]
                ok = isinstance(got, list | tuple) and list(got) == v
            except (TypeError, ValueError, argparse.ArgumentTypeError, PyrtError):
                ok = False
        elif isinstance(v, bool) or not isinstance(v, str | int | float):
            ok = False
        elif action.type is None:
            ok = isinstance(v, str)
        else:
            try:
                ok = action.type(str(v)) == v  # type: ignore[operator]
            except (TypeError, ValueError, argparse.ArgumentTypeError, PyrtError):
                ok = False
        if ok and action.choices is not None:
            ok = v in action.choices
        if not ok:
            raise ConfigError(f"journal {path}: its run's option {key} is {str(value)[:40]!r}, "
                              "which that option never takes (not a journal pyrt wrote); "
                              "not replayed")


def run(args: argparse.Namespace) -> int:
    out = sys.stdout

    def say(line: str) -> None:
        print(line, file=out, flush=True)

    try:
        _check_options(args)
    except UsageError as exc:
        return _usage_error(args, str(exc))
    try:
        replay = Replay(args.file)
    except JournalError as exc:
        print(f"pyrt replay: {exc}", file=sys.stderr)
        return 1
    spec = replay.factory
    tmp = tempfile.mkdtemp(prefix="pyrt-replay-")
    station = None
    try:
        station = build_replayed(replay, tmp, trusted=args.factory)
        shell = ReplayShell(station, out, runner=FrozenRunner(station))
        channels = _channels(args)
        s = replay.reader.summary()
        scope = station.scope
        try:
            _add_channels(station, scope, channels)
        except UsageError as exc:
            return _usage_error(args, str(exc))
        if channels:  # every replayed tick, as far as the scope's buffer goes
            ticks = s.ticks if args.until is None else min(s.ticks, args.until + 1)
            fits = MAX_BUFFER_BYTES // ((len(channels) + 1) * 8) - 64
            length = max(2, min(ticks, MAX_LENGTH, fits))
            scope.set_length(length)
            if length < ticks:
                say(f"scope: the last {length} of {ticks} ticks (the scope's buffer holds "
                    "no more)")
            scope.run("roll")
        say(f"pyrt replay: {args.file}: {replay.header.station} ({spec}), pyrt "
            f"{replay.header.version}, {s.ticks} ticks of {replay.header.period_ns / 1e6:g} ms"
            + (f", until tick {args.until}" if args.until is not None else ""))
        if replay.header.version and replay.header.version != __version__:
            say(f"note: recorded with pyrt {replay.header.version}, replayed with pyrt "
                f"{__version__}: a difference may be the change between them")
        result = replay.run(args.until)
        say(result.line())
        for note in result.notes:
            say(f"note: {note}")
        saved = True
        if channels:
            scope.stop()
            if args.scope_save:
                saved = _save(scope, args.scope_save, say)
        if args.until is not None and result.identical:
            say(f"the controller as it stood after tick {result.last_tick}: read-only "
                "commands; quit to leave")
            Console(shell, sys.stdin, out).run()
        return 0 if result.identical and saved else 1
    except (ConfigError, JournalError) as exc:
        print(f"pyrt replay: {exc}", file=sys.stderr)
        return 1
    finally:
        replay.close()
        if station is not None:
            station.close()
        shutil.rmtree(tmp, ignore_errors=True)


def _save(scope: Scope, name: str, say: Any) -> bool:
    """Write what the scope sampled to ``name`` (its extension checked already);
    False, said on stderr, if nothing was sampled or the file cannot be written."""
    frame = scope.read()
    if frame is None:
        print(f"pyrt replay: --scope-save {name}: nothing was sampled (no tick replayed)",
              file=sys.stderr)
        return False
    plot = Path(name).suffix.lower() in PLOT_SUFFIXES
    try:
        path = plot_frame(frame, name) if plot else save_frame(frame, name)
    except CommandError as exc:
        print(f"pyrt replay: --scope-save: {exc}", file=sys.stderr)
        return False
    n = frame.data.shape[0]
    say(f"{'plotted' if plot else 'saved'} {n} samples of {len(frame.channels)} "
        f"channel(s) to {path}")
    return True
