"""``pyrt board-sim``: a station's simulated boards, served over TCP, their world at real time.

Runs the boards of one station with the physics behind them and serves
their declared registers on ``--listen HOST:PORT`` for a controller in
another process, which opens them with the board URL ``tcp://HOST:PORT``.
NAME is an installed station that gives a world (``gripper``: the cage and
the jaws; ``manipulator``: the TIO10 and dataConcentrator with the rope
world of a station, ``--station prototype|sno`` or ``--db DIR``; the
names ``prototype`` and ``sno`` are short for ``manipulator --station``
that station).  ``pyrt board-sim NAME --help`` lists the world's own
options.  The first line printed says where (port 0 picks a free port).
The wire protocol is in the module text of pyrt.boards.wire.

With ``--modbus HOST:PORT`` the boards are served as a Modbus TCP device
instead, their registers placed by the map shipped for the station
(pyrt/boards/maps/NAME.toml) or by ``--map FILE``; a controller opens them
with the URL board-sim prints, ``modbus://HOST:PORT?map=builtin:NAME``, and
any Modbus tool can read them (docs/hardware.md has the gripper's table).
An illegal value is exception 03 and changes nothing.

One controller owns the outputs (it claims them, or writes first); any
other client may read them, and its writes are refused (busy).  Watchdog:
when the owner makes no register access for ``--watchdog`` seconds, or
its connection closes, the outputs are turned off, whoever else is
connected: every output register that declares an off value gets it
(gripper: DAC to null 80; manipulator: every motor channel disarmed, all
windings off).  A reader never keeps them on.  At most ``--max-clients``
connections are held (a newcomer closes the reader idle longest, never
the owner) and one that completes no request for ``--idle`` seconds is
closed.

The manipulator's world starts with the source at the database POSITION,
held as the controller leaves it; give the controller the same ``--db DIR``
so that its encoders' zero lengths agree with the world.  board-sim only
reads the database.  SIGTERM or SIGINT turn the outputs off and end it.
The protocol has no authentication: serve on a loopback address unless the
network is a closed one.

A station of one's own gives its world through the methods its
StationFactory inherits from pyrt.sim.world.WorldFactory (board_kinds,
add_world_arguments, world): install it in the entry-point group
pyrt.stations, or name it as MODULE:FACTORY.
"""

from __future__ import annotations

import argparse
import ipaddress
import signal
import sys
from typing import Any, NoReturn, TextIO

from pyrt.boards.registry import open_boards
from pyrt.cli._help import Parser
from pyrt.cli._loopopts import _whole
from pyrt.errors import ConfigError, UsageError
from pyrt.sim.boardsim import (
    DEFAULT_IDLE_S,
    DEFAULT_MAX_CLIENTS,
    DEFAULT_WATCHDOG_S,
    BoardServer,
)
from pyrt.sim.world import World, WorldFactory
from pyrt.station.factory import find_station, installed_stations, load_factory

__all__ = ["add_parser", "find_world", "run", "worlds"]

def _world_factory(name: str, factory: WorldFactory) -> WorldFactory:
    """``factory`` if it gives a world (it declares boards); ConfigError otherwise."""
    if not factory.board_kinds():
        raise ConfigError(f"station {name!r} gives no world for board-sim (its factory "
                          "declares no boards: see pyrt.sim.world.WorldFactory)")
    return factory


def _factories() -> dict[str, WorldFactory]:
    """Every installed station that gives a world, by name."""
    out: dict[str, WorldFactory] = {}
    for name in installed_stations():
        try:
            out[name] = _world_factory(name, find_station(name))
        except ConfigError:
            continue
    return out


def worlds() -> list[str]:
    """The names board-sim serves: every installed station with a world and the
    names those worlds give (their ``world_aliases``)."""
    names: list[str] = []
    for name, factory in _factories().items():
        names += [name, *factory.world_aliases]
    return names


def find_world(name: str) -> tuple[WorldFactory, dict[str, Any]]:
    """The factory whose world ``name`` is (an installed station, a name its
    world gives, or ``MODULE:FACTORY``) and the option values it sets;
    ConfigError naming the worlds there are."""
    if ":" in name:
        return _world_factory(name, load_factory(name)), {}
    key = name.lower()
    if key in installed_stations():
        return _world_factory(key, find_station(key)), {}
    for factory in _factories().values():
        preset = factory.world_aliases.get(key)
        if preset is not None:
            return factory, dict(preset)
    raise UsageError(f"no station named {name[:40]!r} gives a world to serve; stations: "
                      f"{', '.join(worlds()) or 'none'}")


def _listen(text: str) -> tuple[str, int]:
    """``HOST:PORT``, ``[V6]:PORT`` or ``PORT`` (host 127.0.0.1)."""
    t = text.strip()
    if t.isascii() and t.isdigit():
        host, port_text = "127.0.0.1", t
    elif t.startswith("["):
        host, sep, port_text = t[1:].partition("]:")
        if not sep:
            raise argparse.ArgumentTypeError(f"expected [HOST]:PORT, got {text!r}")
    else:
        host, sep, port_text = t.rpartition(":")
        if not sep or not host:
            raise argparse.ArgumentTypeError(f"expected HOST:PORT or PORT, got {text!r}")
    if not (port_text.isascii() and port_text.isdigit()) or not 0 <= int(port_text) <= 65535:
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
_max_clients = _whole("--max-clients", "connections", 2, 1024)


def _idle_seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected seconds, got {text!r}") from None
    if not 0.01 <= value <= 86400:
        raise argparse.ArgumentTypeError(f"must be 0.01..86400 s, got {text!r}")
    return value


def _add_common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--listen", type=_listen, default=("127.0.0.1", 0), metavar="HOST:PORT",
                   help="address to serve on (default 127.0.0.1:0, any free port; "
                        "PORT alone means 127.0.0.1)")
    p.add_argument("--watchdog", type=_positive_seconds, default=DEFAULT_WATCHDOG_S,
                   metavar="S", help="outputs off after S seconds without a register access "
                                     f"of the owning controller (default {DEFAULT_WATCHDOG_S:g})")
    p.add_argument("--idle", type=_idle_seconds, default=DEFAULT_IDLE_S, metavar="S",
                   help="close a connection that completes no request for S seconds "
                        f"(default {DEFAULT_IDLE_S:g})")
    p.add_argument("--max-clients", type=_max_clients, default=DEFAULT_MAX_CLIENTS,
                   metavar="N", help="hold at most N connections, the owner's among them "
                                     f"(2..1024, default {DEFAULT_MAX_CLIENTS})")
    p.add_argument("--step-us", type=_step_us, default=1000, metavar="US",
                   help="step the world every US µs of real time (default 1000)")
    p.add_argument("--modbus", type=_listen, default=None, metavar="HOST:PORT",
                   help="serve the boards as a Modbus TCP server on HOST:PORT instead "
                        "(controllers open modbus://HOST:PORT?map=...)")
    p.add_argument("--map", default=None, metavar="FILE",
                   help="with --modbus: the register map (default: the one shipped for the "
                        "station, pyrt/boards/maps/NAME.toml)")


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "board-sim",
        help="serve a station's simulated boards over TCP (the tcp:// board back end)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        add_help=False,
    )
    _add_common(p)
    p.add_argument("world", metavar="NAME", nargs="?",
                   help="the station whose world to serve (an installed station, a name a "
                        "station gives its world, or MODULE:FACTORY; --help lists them)")
    p.add_argument("rest", nargs=argparse.REMAINDER, metavar="...",
                   help="board-sim's options (--listen, --watchdog, --step-us) and the "
                        "world's (pyrt board-sim NAME --help)")
    p.add_argument("-h", "--help", action="store_true", help="show this help (with NAME: "
                                                             "the world's options too)")
    p.set_defaults(run=run, board_sim_parser=p)


class _Parser(Parser):
    """An argument parser whose errors are one line (ConfigError), not an exit."""

    def error(self, message: str) -> NoReturn:
        raise UsageError(message)


def _world_parser(factory: WorldFactory, name: str) -> argparse.ArgumentParser:
    p = _Parser(prog=f"pyrt board-sim {name}", description=(__doc__ or "").split("\n\n")[0],
                formatter_class=argparse.RawDescriptionHelpFormatter)
    _add_common(p)
    factory.add_world_arguments(p)
    return p


def _parse(args: argparse.Namespace) -> tuple[WorldFactory, argparse.Namespace] | None:
    """The world's factory and every option; None after printing help."""
    if args.world is None:
        if args.help:
            args.board_sim_parser.print_help()
            sys.stdout.write("\nstations: " + ", ".join(worlds()) + "\n")
            return None
        raise UsageError("name the station whose world to serve: "
                          + ", ".join(worlds()))
    factory, preset = find_world(args.world)
    parser = _world_parser(factory, args.world)
    # board-sim's own options given before NAME, then an alias's presets
    parser.set_defaults(listen=args.listen, watchdog=args.watchdog, step_us=args.step_us,
                        idle=args.idle, max_clients=args.max_clients, modbus=args.modbus,
                        map=args.map, **preset)
    rest = list(args.rest)
    if args.help:
        rest.append("--help")
    return factory, parser.parse_args(rest)


def _loopback(host: str) -> bool:
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return host == "localhost"


def build_world(factory: WorldFactory, opts: argparse.Namespace) -> World:
    """The world of ``factory``: its boards opened in process, the world behind them."""
    kinds_of = getattr(factory, "board_kinds_of", None)  # a factory not derived: its defaults
    kinds = kinds_of(opts) if kinds_of is not None else factory.board_kinds()
    boards = open_boards("sim:", factory.name, kinds)
    try:
        world = factory.world(boards.simulated or boards, opts)
    except BaseException:
        boards.close()
        raise
    if not isinstance(world, World):
        raise ConfigError(f"station {factory.name!r}: world() returned "
                          f"{type(world).__name__}, not a pyrt.sim.world.World")
    return world


def _say_origin(factory: WorldFactory, out: TextIO) -> None:
    """The second line: which database the world was built from, when the
    factory says (``world_origin``: the manipulator's)."""
    origin = getattr(factory, "world_origin", "")
    if isinstance(origin, str) and origin:
        print(f"pyrt board-sim: {origin}", file=out, flush=True)


def _say(line: str) -> None:
    """A board-sim event line, on standard output at once."""
    sys.stdout.write(line + "\n")
    sys.stdout.flush()


def run(args: argparse.Namespace) -> int:
    out = sys.stdout
    parsed = _parse(args)
    if parsed is None:
        return 0
    factory, opts = parsed
    world = build_world(factory, opts)
    if opts.modbus is not None:
        return _run_modbus(factory, world, opts, out)
    if opts.map is not None:
        raise UsageError("--map goes with --modbus")
    host, port = opts.listen
    server = BoardServer(world, host, port, watchdog_s=opts.watchdog,
                         step_ns=opts.step_us * 1000, idle_s=opts.idle,
                         max_clients=opts.max_clients, say=_say)
    boards = " ".join(f"{n}={k.name}" for n, k in world.kinds.items())
    first = (f"pyrt board-sim: {factory.name} {world.name} on {server.url} (boards {boards}; "
             f"watchdog {opts.watchdog:g} s, world step {opts.step_us} µs)")
    return _serve(server, factory, first, "the protocol", out)


def _serve(server: Any, factory: WorldFactory, first: str, protocol: str, out: Any) -> int:
    """Say ``first`` (where the server listens), which database the world came
    from and, off the loopback, that ``protocol`` has no authentication; serve
    until SIGTERM or SIGINT; then turn the outputs off and say so.  The signals
    are taken before the first line, so a client that stops the server as soon
    as it has read the address gets the same orderly stop as any other."""

    def stop(signum: int, frame: object) -> None:
        server.stop()

    old = {s: signal.signal(s, stop) for s in (signal.SIGTERM, signal.SIGINT)}
    try:
        print(first, file=out, flush=True)
        _say_origin(factory, out)
        if not _loopback(server.host):
            print(f"pyrt board-sim: warning: serving on {server.host}: {protocol} has no "
                  "authentication; anyone who reaches the port drives the boards", file=out,
                  flush=True)
        server.serve_forever()
    finally:
        server.close()
        for s, h in old.items():
            signal.signal(s, h)
    print(f"pyrt board-sim: stopped, outputs off ({server.requests} requests, "
          f"{server.watchdog_trips} watchdog trips)", file=out, flush=True)
    return 0


def _run_modbus(factory: WorldFactory, world: World, opts: argparse.Namespace,
                out: Any) -> int:
    """Serve ``world`` over Modbus TCP (``--modbus``) until SIGTERM or SIGINT."""
    from pyrt.boards.modbus import builtin_map
    from pyrt.boards.modbusmap import load_map
    from pyrt.sim.modbusserver import ModbusBoardServer

    if opts.map is not None:
        path, shown = opts.map, opts.map
    else:
        path, shown = builtin_map(factory.name), f"builtin:{factory.name}"
    regmap = load_map(path, world.kinds)
    host, port = opts.modbus
    server = ModbusBoardServer(world, regmap, host, port, watchdog_s=opts.watchdog,
                               step_ns=opts.step_us * 1000, idle_s=opts.idle,
                               max_clients=opts.max_clients, say=_say)
    boards = " ".join(f"{n}={k.name}" for n, k in world.kinds.items())
    first = (f"pyrt board-sim: {factory.name} {world.name} on {server.url}?map={shown} "
             f"(Modbus TCP; boards {boards}; map {path}; watchdog {opts.watchdog:g} s, "
             f"world step {opts.step_us} µs)")
    return _serve(server, factory, first, "Modbus", out)
