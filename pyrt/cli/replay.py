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
``--scope-save FILE`` writes them (``.csv``, ``.npz`` or ``.png``).
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
from pyrt.scope.scope import MAX_BUFFER_BYTES, MAX_LENGTH
from pyrt.station.factory import find_station, load_factory
from pyrt.station.replay import Replay

__all__ = ["add_parser", "run"]

#: Options of the run that a replay never takes over (it has its own clock,
#: boards, and no links).
_NOT_REPLAYED = {"boards", "journal", "black_box", "serve", "epics", "headless",
                 "timing_log", "history", "speed", "fifo", "timer_slack", "max_overruns",
                 "mlock", "run"}


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
                   help="write the sampled signals to FILE (.csv, .npz, or .png: needs "
                        "matplotlib)")
    p.set_defaults(run=run)


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
        replay = Replay(args.file)
    except JournalError as exc:
        print(f"pyrt replay: {exc}", file=sys.stderr)
        return 1
    spec = replay.factory
    if ":" in spec:  # code outside the installed stations: never chosen by a journal
        if args.factory != spec:
            replay.close()
            print(f"pyrt replay: journal {args.file} was recorded with the station factory "
                  f"{spec[:80]!r}, code outside pyrt's installed stations: a journal does "
                  f"not choose code to run; if you trust it, give --factory {spec[:80]}",
                  file=sys.stderr)
            return 1
        factory = load_factory(spec)
    else:
        factory = find_station(spec)
    tmp = tempfile.mkdtemp(prefix="pyrt-replay-")
    station = None
    try:
        st_args = _arguments(replay, factory, tmp)
        factory.configure(st_args, lambda line: None)
        tick_us = replay.header.period_ns // 1000
        if replay.header.period_ns % 1000 == 0:
            st_args.tick_us = tick_us
        loop = Loop(replay.clock, period_ns=replay.header.period_ns, timing=True)
        with replay.building():
            station = factory.build(loop, st_args)
        replay.attach(station)
        shell = ReplayShell(station, out, runner=FrozenRunner(station))
        channels = [c.strip() for c in (args.scope or "").split(",") if c.strip()]
        s = replay.reader.summary()
        for ch in channels:
            shell.onecmd(f"scope add {ch}")
        if channels:  # every replayed tick, as far as the scope's buffer goes
            ticks = s.ticks if args.until is None else min(s.ticks, args.until + 1)
            fits = MAX_BUFFER_BYTES // ((len(channels) + 1) * 8) - 64
            length = max(2, min(ticks, MAX_LENGTH, fits))
            shell.onecmd(f"scope length {length}")
            if length < ticks:
                say(f"scope: the last {length} of {ticks} ticks (the scope's buffer holds "
                    "no more)")
            shell.onecmd("scope run roll")
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
        if channels:
            shell.onecmd("scope stop")
            if args.scope_save:
                verb = "plot" if args.scope_save.lower().endswith(".png") else "save"
                shell.onecmd(f"scope {verb} {args.scope_save}")
        if args.until is not None and result.identical:
            say(f"the controller as it stood after tick {result.last_tick}: read-only "
                "commands; quit to leave")
            Console(shell, sys.stdin, out).run()
        return 0 if result.identical else 1
    except (ConfigError, JournalError) as exc:
        print(f"pyrt replay: {exc}", file=sys.stderr)
        return 1
    finally:
        replay.close()
        if station is not None:
            station.close()
        shutil.rmtree(tmp, ignore_errors=True)
