"""``pyrt board-sim``: a robot's simulated boards, served over TCP, their world at real time.

Runs the boards of one robot with the physics behind them (``gripper``: the
cage and the jaws; ``prototype`` or ``sno``: the TIO10 and dataConcentrator
with the rope world of that station) and serves their registers on
``--listen HOST:PORT`` for a controller in another process, which opens
them with the board URL ``tcp://HOST:PORT``.  The first line printed says
where (port 0 picks a free port).  The wire protocol is in the module text
of pyrt.boards.wire.  One controller at a time.

Watchdog: when no register access comes for ``--watchdog`` seconds, or the
controller's connection closes, the outputs are turned off (gripper: DAC to
null 80; manipulator: every motor channel disarmed, all windings off).

The manipulator's world starts with the source at the database POSITION,
held as the controller leaves it; give the controller the same ``--db DIR``
so that its encoders' zero lengths agree with the world.  board-sim only
reads the database.  SIGTERM or SIGINT turn the outputs off and end it.
The protocol has no authentication: serve on a loopback address unless the
network is a closed one.
"""

from __future__ import annotations

import argparse
import ipaddress
import signal
import sys
from pathlib import Path

from pyrt.cli._loopopts import _whole
from pyrt.db import STATIONS, station_directory
from pyrt.errors import ConfigError
from pyrt.sim.boardsim import DEFAULT_WATCHDOG_S, BoardServer
from pyrt.sim.gripper import FAULTS, JawParameters
from pyrt.sim.sensors import Imperfections
from pyrt.sim.world import BoardWorld, GripperWorld, ManipulatorWorld
from pyrt.station.gripper import counts_type as _counts
from pyrt.station.manipulator import ManipulatorStation

__all__ = ["add_parser", "run"]

WORLDS = ("gripper", *STATIONS)


def _listen(text: str) -> tuple[str, int]:
    """``HOST:PORT``, ``[V6]:PORT`` or ``PORT`` (host 127.0.0.1)."""
    t = text.strip()
    if t.isdigit():
        host, port_text = "127.0.0.1", t
    elif t.startswith("["):
        host, sep, port_text = t[1:].partition("]:")
        if not sep:
            raise argparse.ArgumentTypeError(f"expected [HOST]:PORT, got {text!r}")
    else:
        host, sep, port_text = t.rpartition(":")
        if not sep or not host:
            raise argparse.ArgumentTypeError(f"expected HOST:PORT or PORT, got {text!r}")
    if not port_text.isdigit() or not 0 <= int(port_text) <= 65535:
        raise argparse.ArgumentTypeError(f"port must be 0..65535, got {port_text!r}")
    return host, int(port_text)


def _positive_seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected seconds, got {text!r}") from None
    if not 0.001 <= value <= 3600:
        raise argparse.ArgumentTypeError(f"must be 0.001..3600 s, got {text!r}")
    return value


_step_us = _whole("world step", "µs", 50, 100_000)


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "board-sim",
        help="serve a robot's simulated boards over TCP (the tcp:// board back end)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("world", choices=WORLDS,
                   help="gripper: the cage and jaws; prototype, sno: that station's manipulator")
    p.add_argument("--listen", type=_listen, default=("127.0.0.1", 0), metavar="HOST:PORT",
                   help="address to serve on (default 127.0.0.1:0, any free port; "
                        "PORT alone means 127.0.0.1)")
    p.add_argument("--watchdog", type=_positive_seconds, default=DEFAULT_WATCHDOG_S,
                   metavar="S", help="outputs off after S seconds without a register access "
                                     f"(default {DEFAULT_WATCHDOG_S:g})")
    p.add_argument("--step-us", type=_step_us, default=1000, metavar="US",
                   help="step the world every US µs of real time (default 1000)")
    g = p.add_argument_group("gripper")
    g.add_argument("--object", type=float, metavar="MM",
                   help=f"an object this wide between the jaws "
                        f"(0 < MM < {JawParameters().open_mm:g})")
    g.add_argument("--start", type=_counts, metavar="HEX",
                   help="jaw position at start, encoder counts from wide open (default F400)")
    g.add_argument("--fault", action="append", choices=[f for f in FAULTS if f != "port"],
                   help="inject a fault from the start: limit (sensor dead), jam (motor), "
                        "encoder (dead)")
    m = p.add_argument_group("manipulator")
    m.add_argument("--db", metavar="DIR",
                   help="station database to build the world from, read only "
                        "(default: the packaged station named by WORLD)")
    m.add_argument("--ideal-sensors", action="store_true",
                   help="switch off encoder quantisation and loadcell noise/offsets")
    p.set_defaults(run=run)


def _world(args: argparse.Namespace) -> BoardWorld:
    gripper_opts = [o for o, v in (("--object", args.object), ("--start", args.start),
                                   ("--fault", args.fault)) if v is not None]
    manip_opts = [o for o, v in (("--db", args.db), ("--ideal-sensors", args.ideal_sensors or None))
                  if v is not None]
    if args.world == "gripper":
        if manip_opts:
            raise ConfigError(f"{', '.join(manip_opts)}: only for a manipulator world")
        return GripperWorld(start=-0x0C00 if args.start is None else args.start,
                            object_mm=args.object, faults=args.fault or ())
    if gripper_opts:
        raise ConfigError(f"{', '.join(gripper_opts)}: only for the gripper world")
    directory = Path(args.db) if args.db else station_directory(args.world)
    imp = Imperfections.ideal() if args.ideal_sensors else None
    # The world's rope payouts come from the controller's own equilibrium at
    # the database POSITION (as the in-process station sets the encoders'
    # zero lengths), so build that station here and serve its world.
    station = ManipulatorStation(directory, writer="sync", imperfections=imp, lock=False)
    return ManipulatorWorld(station.plant, station.polyaxis.name)


def _loopback(host: str) -> bool:
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return host == "localhost"


def run(args: argparse.Namespace) -> int:
    out = sys.stdout
    world = _world(args)
    host, port = args.listen
    server = BoardServer(world, host, port, watchdog_s=args.watchdog,
                         step_ns=args.step_us * 1000, stdout=out)
    print(f"pyrt board-sim: {world.kind} {world.name} on {server.url} "
          f"(watchdog {args.watchdog:g} s, world step {args.step_us} µs)", file=out, flush=True)
    if not _loopback(server.host):
        print(f"pyrt board-sim: warning: serving on {server.host}: the protocol has no "
              "authentication; anyone who reaches the port drives the boards", file=out,
              flush=True)

    def stop(signum: int, frame: object) -> None:
        server.stop()

    old = {s: signal.signal(s, stop) for s in (signal.SIGTERM, signal.SIGINT)}
    try:
        server.serve_forever()
    finally:
        server.close()
        for s, h in old.items():
            signal.signal(s, h)
    print(f"pyrt board-sim: stopped, outputs off ({server.requests} requests, "
          f"{server.watchdog_trips} watchdog trips)", file=out, flush=True)
    return 0
