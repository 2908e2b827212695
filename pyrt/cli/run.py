"""``pyrt run MODULE:FACTORY [options]``: run a station from any importable module.

``FACTORY`` is a :class:`~pyrt.station.factory.StationFactory` (an instance
or the class) or a function ``build(loop, args) -> Station`` in ``MODULE``
(``pyrt run mylab.arm:ArmFactory --speed max``).  The options are every
station's (``pyrt run MODULE:FACTORY --help`` lists them with the factory's
own).  A station installed through the entry-point group ``pyrt.stations``
is also its own sub-command, ``pyrt NAME``.
"""

from __future__ import annotations

import argparse
import sys

from pyrt.cli._station import run_factory, station_parser
from pyrt.station.factory import load_factory

__all__ = ["add_parser", "run"]


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "run",
        help="run a station from any importable module: pyrt run MODULE:FACTORY [options]",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        add_help=False,
    )
    p.add_argument("factory", metavar="MODULE:FACTORY", nargs="?",
                   help="the station's factory, e.g. mylab.arm:ArmFactory")
    p.add_argument("options", nargs=argparse.REMAINDER,
                   help="the station's options (MODULE:FACTORY --help lists them)")
    p.add_argument("-h", "--help", action="store_true", help="show this help and exit")
    p.set_defaults(run=run, _parser=p)


def run(args: argparse.Namespace) -> int:
    if args.factory is None:
        args._parser.print_help()
        return 0 if args.help else 2
    if args.help:  # 'pyrt run --help X': the station's help
        args.options = ["--help", *args.options]
    factory = load_factory(args.factory)
    if not factory.name:
        factory.name = args.factory.rpartition(":")[2]
    parser = station_parser(factory, f"pyrt run {args.factory}")
    station_args = parser.parse_args(args.options)
    station_args._factory = args.factory  # what a journal's replay builds again
    sys.stdout.flush()
    return run_factory(factory, station_args)
