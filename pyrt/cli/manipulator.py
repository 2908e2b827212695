"""``pyrt manipulator``: the SNO source manipulator controller (000) on a simulated world.

Commands are addressed to named objects, as the document's
Hardware::doCommand: ``prototype to 0 0 150``, ``axis1 up 5``,
``axis0Motor maxspeed 3``, ``axis0Encoder read``, ``axis0Loadcell
calibrate``; plus ``quit``, ``log``, ``debug``, ``help [object]``, ``wait``,
``sleep``, ``stats``, ``status``, ``sim``, ``ack``.  Type ``help``.

Without ``--db DIR`` the packaged station (``--station``) is copied to a
working directory first (existing files there are kept: they carry the last
position), and the run says where; ``--init-db DIR`` seeds DIR from it the
same way and runs there; the database is written back while the
manipulator runs. One process at a time may run on a database directory (a
second is refused, naming the first one's pid); ``--station`` with ``--db``
names the station the database must hold. The base tick defaults to 5 ms for
this robot: the physics steps every tick (a motor at its 7.0 cm/s limit makes
1.4 half-steps a tick), the control poll is 50 ms and the standalone axis poll
10 ms, and ``--speed max`` then runs a move some 50 times faster than real
time.

With ``--boards tcp://HOST:PORT`` the controller drives the TIO10 and
dataConcentrator of a ``pyrt board-sim prototype|sno`` in another process
(give both the same ``--db DIR``; board-sim's first line names the URL):
the world moves there at real time, so only ``--speed 1`` is accepted,
``--ideal-sensors`` is board-sim's option, and its world must be this
station's.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from pyrt.cli._loopopts import (
    add_boards_option,
    add_loop_options,
    apply_rt_options,
    live_status,
    load_backend,
    make_loop,
)
from pyrt.cli._serve import add_serve_options, prepare_service
from pyrt.cli._shutdown import run_until_shutdown
from pyrt.commands import RobotShell
from pyrt.console import Console
from pyrt.db import FILES, STATIONS, copy_station, default_working_directory
from pyrt.errors import ConfigError, PyrtError
from pyrt.server import ServedStation
from pyrt.sim.sensors import Imperfections
from pyrt.station.manipulator import ManipulatorStation

__all__ = ["DEFAULT_TICK_US", "add_parser", "run"]

#: The manipulator's default base tick (see the module text).
DEFAULT_TICK_US = 5000


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "manipulator",
        help="run the 000 SNO source manipulator controller on a simulated world "
             "(or on pyrt board-sim's, --boards tcp://...)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--db", metavar="DIR", help="station database directory (written back)")
    p.add_argument("--init-db", metavar="DIR",
                   help="seed DIR with the packaged station (--station; database files "
                        "already there are kept), then run on it as --db DIR")
    p.add_argument("--station", choices=STATIONS, default=None,
                   help="packaged station to copy when no --db is given (default prototype); "
                        "with --db, the station the database must hold")
    add_boards_option(p, "prototype|sno")
    p.add_argument("--ideal-sensors", action="store_true",
                   help="switch off encoder quantisation and loadcell noise/offsets "
                        "(in-process world only)")
    p.add_argument("--history", metavar="FILE", help="keep the command history in FILE")
    add_loop_options(p, default_speed="1", default_tick_us=DEFAULT_TICK_US)
    add_serve_options(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    out = sys.stdout
    if args.db and args.init_db:
        raise ConfigError("give --db DIR (an existing database) or --init-db DIR (seed one), "
                          "not both")
    if args.init_db:
        args.station = args.station or "prototype"
        try:
            directory = copy_station(args.station, args.init_db)
        except OSError as exc:
            raise ConfigError(f"cannot seed a station database there: {exc.strerror}",
                              args.init_db) from None
        print(f"pyrt manipulator: {directory} seeded from the packaged {args.station} station "
              "(files already there kept)", file=out)
    elif args.db:
        directory = Path(args.db)
        if not (directory / FILES["POLYAXIS"]).is_file():
            what = "no such directory" if not directory.is_dir() else "no station database"
            raise ConfigError(f"{what}; seed it with 'pyrt manipulator --init-db {args.db} "
                              f"--station {'|'.join(STATIONS)}'", args.db)
    else:
        args.station = args.station or "prototype"
        directory = default_working_directory(args.station)
        copy_station(args.station, directory)
        print(f"pyrt manipulator: working copy of the {args.station} station in {directory}",
              file=out)
    apply_rt_options(args, lambda m: print(m, file=out))
    load_backend(args.boards)
    loop = make_loop(args)  # overrun lines: stderr, at most one a second
    imp = Imperfections.ideal() if args.ideal_sensors else None
    try:
        station = ManipulatorStation(directory, loop=loop, imperfections=imp,
                                     boards=args.boards, expect=args.station)
    except ConfigError as exc:
        if args.db or args.init_db:
            raise
        # The working copy keeps what earlier runs wrote, and may predate a
        # change to the packaged station: say how to start afresh.
        raise ConfigError(f"{exc.message}; this working copy may come from an earlier pyrt: "
                          f"move {directory} aside to start again from the packaged "
                          f"{args.station} station", exc.file, exc.line) from None
    station.close_report = lambda m: print(m, file=out, flush=True)
    runner = station.runner
    try:
        service = prepare_service(args, runner, ServedStation(station))
    except PyrtError:
        station.close()
        raise
    shell = RobotShell(station, out)
    console = Console(shell, sys.stdin, out, messages=shell.messages, history_file=args.history,
                      status=live_status(runner, station, args))
    speed = "max (simulated time)" if args.speed is None else f"{args.speed:g}x real time"
    where = "" if station.plant is not None else f", boards at {station.boards.url}"
    for note in station.startup_notes:  # what start-up did with ZEROLENGTH and LENGTH
        print(f"start-up: {note}", file=out)
    print(f"pyrt manipulator: {station.polyaxis.name}, {len(station.axes)} ropes, database "
          f"{directory}{where}; tick {args.tick_us} µs, speed {speed}; type help", file=out)
    wall0 = time.perf_counter()
    station.start()

    status = run_until_shutdown(station, console, service, headless=args.headless,
                                say=lambda m: print(m, file=out, flush=True),
                                what="pyrt manipulator")
    if args.timing_log:
        wall = time.perf_counter() - wall0
        print(f"timing log written to {args.timing_log} ({loop.tick_index} ticks, {wall:.2f} s)",
              file=out)
    return status
