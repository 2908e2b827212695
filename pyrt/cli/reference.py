"""``pyrt reference [NAME ...]``: every station's commands and signals, from its records.

Builds each named installed station (default: every installed one) on
simulated time with its default options (in a temporary working
directory), walks its component tree and writes a Markdown reference: for
every object its commands (usage, help, argument ranges, whether it reads
only, moves or changes a setting, and whether any client may give it) and
its signals (units, display range and alarm levels); then the console's
words and the station's motion types.  Nothing is kept from the build.
``--output FILE`` writes the file (atomically); ``--check FILE`` exits 1
when FILE is not what would be written (the test suite keeps the shipped
reference current this way).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import sys
import tempfile
from collections.abc import Iterator, Sequence
from pathlib import Path

from pyrt.cli._station import station_parser
from pyrt.commands import RobotShell
from pyrt.component import Command, Component, Signal
from pyrt.errors import ConfigError
from pyrt.fileio import atomic_write
from pyrt.scheduler import Loop, SimClock
from pyrt.station.base import Station
from pyrt.station.factory import StationFactory, find_station, installed_stations

__all__ = ["add_parser", "reference", "run", "station_reference"]

TITLE = "# pyrt station reference"
INTRO = ("Generated from the command and signal records by `pyrt reference`; "
         "do not edit by hand.")


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "reference",
        help="write every station's commands and signals (Markdown), from the records",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("names", nargs="*", metavar="NAME",
                   help="installed stations (default: every installed one)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--output", metavar="FILE", help="write the reference to FILE")
    g.add_argument("--check", metavar="FILE",
                   help="exit 1 (saying so) when FILE is not the reference as it is now")
    p.set_defaults(run=run)


def _kind(rec: Command) -> str:
    if rec.reads_only:
        return "reads"
    if rec.reads_only_subcommands:
        return f"reads ({', '.join(sorted(rec.reads_only_subcommands))}); else changes"
    return "moves" if rec.moves else "setting"


def _cell(text: str) -> str:
    return " ".join(text.replace("|", "\\|").replace("``", "`").split())


def _command_lines(rec: Command) -> list[str]:
    doc = rec.help.splitlines()
    n = 0  # the first paragraph, whole (as help's summaries show it), then the rest
    while n < len(doc) and doc[n].strip() and not doc[n].startswith("Range: "):
        n += 1
    first = _cell(" ".join(doc[:n])) or rec.name
    rest = _cell(" ".join(doc[n:]))
    who = "anyone" if rec.anyone else "privileged"
    faulted = "" if rec.while_faulted else "; refused while faulted"
    aliases = f" (also {', '.join(rec.aliases)})" if rec.aliases else ""
    out = [f"* `{_cell(rec.usage)}`{aliases}: {first}",
           f"  *{_kind(rec)}; {who}{faulted}*"]
    if rest:
        out.append(f"  {rest}")
    return out


def _signal_line(sig: Signal) -> str:
    lim = f"; {sig.limits.text}" if sig.limits is not None else ""
    doc = f": {_cell(sig.doc)}" if sig.doc else ""
    return f"| `{sig.name}` | {sig.units}{lim} |{doc[1:] if doc else ''} |"


def _component(comp: Component) -> list[str]:
    out = [f"### `{comp.name}`", ""]
    recs = comp.commands()
    if recs:
        out.append("Commands:")
        out.append("")
        for rec in recs:
            out += _command_lines(rec)
        out.append("")
    sigs = comp.signals()
    if sigs:
        out += ["| signal | units; range and alarms | what |", "|---|---|---|"]
        out += [_signal_line(s) for s in sigs]
        out.append("")
    if not recs and not sigs:
        out += ["(no commands, no signals)", ""]
    return out


def station_reference(station: Station, title: str) -> str:
    """The Markdown reference of one built station."""
    shell = RobotShell(station, io.StringIO())
    out = [f"## {title}", ""]
    level = station.profile.level
    out.append(f"Objects: {', '.join(f'`{n}`' for n in station.names())}."
               + (f" The letters of `{level.name}` are typed bare at its prompt."
                  if level is not None else ""))
    out.append("")
    for comp in station.components():
        out += _component(comp)
    out += [f"### Console words of {title}", ""]
    for rec in shell.words():
        out += _command_lines(rec)
    out.append("")
    types = station.motion_types()
    out += [f"### Motion types of {title}", ""]
    out += ([f"* `{name}`: {_cell((cls.__doc__ or '').strip().splitlines()[0])}"
             for name, cls in types.items()] or ["(none)"])
    out.append("")
    return "\n".join(out)


@contextlib.contextmanager
def _scratch_home() -> Iterator[None]:
    """A temporary PYRT_HOME: a station's default working copy is made there."""
    old = os.environ.get("PYRT_HOME")
    with tempfile.TemporaryDirectory(prefix="pyrt-reference-") as home:
        os.environ["PYRT_HOME"] = home
        try:
            yield
        finally:
            if old is None:
                os.environ.pop("PYRT_HOME", None)
            else:
                os.environ["PYRT_HOME"] = old


def _build(factory: StationFactory) -> Station:
    args = station_parser(factory, f"pyrt {factory.name}").parse_args(["--speed", "max"])
    factory.configure(args, lambda _line: None)
    return factory.build(Loop(SimClock(), period_ns=args.tick_us * 1000), args)


def reference(names: Sequence[str]) -> str:
    """The reference of the installed stations ``names`` (ConfigError if one is not)."""
    parts = [TITLE, "", INTRO, ""]
    with _scratch_home():
        for name in names:
            factory = find_station(name)
            station = _build(factory)
            try:
                parts.append(station_reference(station, f"`pyrt {factory.name}`"))
            finally:
                station.close()
    return "\n".join(parts).rstrip() + "\n"


def run(args: argparse.Namespace) -> int:
    names = list(args.names) or list(installed_stations())
    text = reference(names)
    if args.check:
        path = Path(args.check)
        try:
            current = path.read_text(encoding="utf-8")
        except OSError as exc:
            raise ConfigError(f"cannot read it: {exc.strerror}", args.check) from None
        if current != text:
            print(f"pyrt reference: {path} is not current; write it again with 'pyrt reference "
                  f"{' '.join(names)} --output {path}'", file=sys.stderr)
            return 1
        print(f"{path} is current", file=sys.stdout)
        return 0
    if args.output:
        atomic_write(Path(args.output), text.encode("utf-8"))
        print(f"reference of {', '.join(names)} written to {args.output}", file=sys.stdout)
        return 0
    sys.stdout.write(text)
    return 0
