"""``pyrt gripper``: the 002 parallel-jaw gripper controller on simulated jaws.

At start the controller does what the 8031 does at power-up: it loads its
RAM variables, starts its three self-scheduling routines and runs I (drive
the jaws wide open, zero the encoder), then prompts ``CMD: ``.  The
commands are the report's (C E I M P S T W X; the monitor's C D I L N Q S),
hexadecimal, lower case accepted; type ``help``.  Every P move is
supervised (settle and stall bounds from the distance, the speed and the
schedule in RAM; oscillation about the target): a move that fails them is
a fault, the drive nulled at once.  ``stop``, Ctrl-C, SIGTERM and SIGHUP
stop the jaws and say where they are; ``wait`` says whether the move
ended at the target, short of it (and why) or in a fault.  Power-up scales
002's schedule values to ``--tick-us``.  Pipe a file in to run it
as a script; with ``--speed max`` time advances only while commands run,
``wait`` or ``sleep``, so a script's output is the same on every run.

With ``--boards tcp://HOST:PORT`` the controller drives the boards of a
``pyrt board-sim gripper`` in another process (start it first; its first
line names the URL): the jaws move there at real time, so only ``--speed
1`` is accepted and the simulation options are board-sim's.
"""

from __future__ import annotations

import argparse
import re
import sys
import time

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
from pyrt.server import ServedStation
from pyrt.sim.gripper import FAULTS, JawParameters
from pyrt.station.gripper import build_gripper

__all__ = ["add_parser", "run"]

def _counts(text: str) -> int:
    """A start position: hex counts, two's complement (F400) or negative (-0C00)."""
    t = text.strip()
    try:
        value = -int(t[1:], 16) if t.startswith("-") else int(t, 16)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected hex encoder counts, got {text!r}") from None
    if value > 0x7FFF:
        value -= 0x10000
    if not -0x2A00 <= value <= 0:
        raise argparse.ArgumentTypeError("start position must be 0000 (wide open) .. D600 (closed)")
    return value


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "gripper",
        help="run the 002 parallel-jaw gripper controller (CMD: and monitor) on simulated jaws "
             "(or on pyrt board-sim's, --boards tcp://...)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_boards_option(p, "gripper")
    g = p.add_argument_group("simulation (sim: boards only; board-sim takes the same options)")
    g.add_argument(
        "--object", type=float, metavar="MM",
        help=f"an object this wide between the jaws (0 < MM < {JawParameters().open_mm:g})",
    )
    g.add_argument(
        "--start", type=_counts, metavar="HEX",
        help="jaw position at power-up, encoder counts from wide open: F400 or -0C00 "
             "(the default)",
    )
    g.add_argument(
        "--fault", action="append", choices=[f for f in FAULTS if f != "port"],
        help="inject a fault from the start: limit (sensor dead), jam (motor), encoder (dead)",
    )
    c = p.add_argument_group("console")
    c.add_argument("--no-init", action="store_true", help="do not run I at power-up")
    c.add_argument("--history", metavar="FILE", help="keep the command history in FILE")
    add_loop_options(p, default_speed="1")
    add_serve_options(p)
    # "--start -0C00": argparse takes a word that starts with "-" for an
    # option unless it looks like a negative number; hexadecimal counts are
    # numbers here (no option of this command looks like one).
    p._negative_number_matcher = re.compile(r"^-[0-9A-Fa-f]+$|^-\d*\.\d+$")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    out = sys.stdout
    apply_rt_options(args, lambda m: print(m, file=out))
    load_backend(args.boards)
    loop = make_loop(args)  # overrun lines: stderr, at most one a second
    station = build_gripper(loop, boards=args.boards, start=args.start, object_mm=args.object,
                            faults=args.fault or ())
    station.close_report = lambda m: print(m, file=out, flush=True)
    runner = station.runner
    service = prepare_service(args, runner, ServedStation(station))
    shell = RobotShell(station, out)
    console = Console(shell, sys.stdin, out, messages=shell.messages, history_file=args.history,
                      status=live_status(runner, station, args))
    speed = "max (simulated time)" if args.speed is None else f"{args.speed:g}x real time"
    jaws = ("simulated jaws" if station.plant is not None
            else f"boards at {station.boards.url} ({station.boards.world})")
    print(
        f"pyrt gripper: 002 parallel-jaw controller, {jaws}; tick {args.tick_us} µs, "
        f"speed {speed}; type help",
        file=out,
    )
    wall0 = time.perf_counter()
    station.start()

    status = run_until_shutdown(
        station, console, service, headless=args.headless, what="pyrt gripper",
        say=lambda m: print(m, file=out, flush=True),
        first=None if args.no_init else lambda: shell.onecmd("I"))
    if args.timing_log:
        wall = time.perf_counter() - wall0
        print(f"timing log written to {args.timing_log} ({loop.tick_index} ticks, {wall:.2f} s)",
              file=out)
    return status
