"""``pyrt export RUN.pj OUT.mcap``: a journal (a run's or a black box's) as an MCAP file.

MCAP is what ros2 bag writes by default; Foxglove, PlotJuggler and rerun open
it.  Every tick becomes a JSON message per board on ``/inputs/BOARD`` and
``/outputs/BOARD`` (the registers after the read and the write phase), one on
``/ticks`` (lateness, deadlines missed); each output written is a message on
``/writes`` (with the task that wrote it); requests, faults and other events
have ``/commands``, ``/faults`` and ``/events``.  Every channel has a JSON
schema; log times are the journal's tick times (the loop's clock, ns).  The
run's databases travel as attachments, its station and options as metadata.
Needs the ``mcap`` library: ``pip install 'pyrt[mcap]'``.

A damaged journal (a checksum that does not match) is refused, naming the
frame and its offset; ``--salvage`` exports every tick it can read around
the damage, the ticks lost as messages on ``/gaps``.  A name that does not
end ``.mcap`` is a usage error (exit status 2, nothing read); a journal that
cannot be read, or a file that cannot be written, exit status 1 (and nothing
is written).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from pyrt.errors import CommandError
from pyrt.journal import JournalError, JournalReader
from pyrt.scope.mcapfile import export_journal

__all__ = ["add_parser", "run"]


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("export", help="write a journal (--journal FILE, a black box) as "
                       "an MCAP file for Foxglove, PlotJuggler, rerun",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("journal", metavar="RUN.pj", help="a journal or a black box (.pj)")
    p.add_argument("out", metavar="OUT.mcap", help="the MCAP file to write")
    p.add_argument("--salvage", action="store_true",
                   help="read past damaged frames (the ticks lost go on /gaps)")
    p.set_defaults(run=run, usage=p.format_usage)


def run(args: argparse.Namespace) -> int:
    out = Path(args.out)
    if out.suffix.lower() != ".mcap":
        sys.stderr.write(args.usage())
        print(f"pyrt export: error: {args.out}: the output's name ends .mcap (the one format "
              "pyrt export writes)", file=sys.stderr)
        return 2
    if not out.parent.is_dir():
        sys.stderr.write(args.usage())
        print(f"pyrt export: error: {args.out}: there is no directory {out.parent}",
              file=sys.stderr)
        return 2
    try:
        done = export_journal(JournalReader(args.journal, salvage=args.salvage), out)
    except (JournalError, CommandError) as exc:
        print(f"pyrt export: {exc}", file=sys.stderr)
        return 1
    print(f"pyrt export: {done.line()}", flush=True)
    return 0
