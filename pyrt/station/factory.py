"""How pyrt finds, configures and builds a station: :class:`StationFactory`.

A station kind (the gripper, the manipulator, a user's own robot) is made
known to pyrt by a factory, found by name through the entry-point group
:data:`ENTRY_POINT_GROUP` (``pyrt.stations``), or named directly as
``MODULE:FACTORY`` (``pyrt run mylab.arm:ArmFactory``)::

    [project.entry-points."pyrt.stations"]
    arm = "mylab.arm:ArmFactory"

Every station is then run the same way (:func:`pyrt.run_station`): the loop
options, ``--boards``, ``--serve``, ``--epics``, ``--headless``,
``--timing-log`` and ``--history`` come from pyrt; the factory adds its own
options (:meth:`StationFactory.add_arguments`), checks them before the loop
exists (:meth:`StationFactory.configure`) and builds the station on the loop
(:meth:`StationFactory.build`).

A factory is a :class:`StationFactory` instance or subclass, or a plain
function ``build(loop, args) -> Station`` (:func:`as_factory` wraps it: no
options of its own, defaults for the rest).
"""

from __future__ import annotations

import argparse
import importlib
import importlib.metadata
import inspect
import re
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING, Any

from pyrt.errors import ConfigError
from pyrt.sim.world import WorldFactory

if TYPE_CHECKING:
    from pyrt.scheduler import Loop
    from pyrt.station.base import Station

__all__ = [
    "ENTRY_POINT_GROUP",
    "StationFactory",
    "as_factory",
    "find_station",
    "installed_stations",
    "load_factory",
]

#: Entry-point group of installed stations (name: the sub-command, value: the factory).
ENTRY_POINT_GROUP = "pyrt.stations"

_NAME = re.compile(r"^[a-z][a-z0-9_-]*$")


class StationFactory(WorldFactory):
    """Builds one kind of station (see the module text).  Subclasses set
    :attr:`name` and override :meth:`build`; everything else has a default.
    It is a :class:`~pyrt.sim.world.WorldFactory` too: ``board_kinds``,
    ``add_world_arguments`` and ``world`` give ``pyrt board-sim NAME`` the
    station's simulated world."""

    #: The sub-command (``pyrt NAME``) and the name ``pyrt board-sim`` knows it by.
    name: str = ""
    #: One line for ``pyrt --help``.
    summary: str = ""
    #: The ``--help`` description (plain text; paragraphs kept as written).
    description: str = ""
    #: The base tick when ``--tick-us`` is not given, µs.
    default_tick_us: int = 1000
    #: ``--speed`` when not given: ``1`` (real time), ``N`` or ``max``.
    default_speed: str = "1"
    #: The longest tick this station's control can run on, µs (``--tick-us`` above it is
    #: refused, saying why); None: no bound beyond the loop's own.
    max_tick_us: int | None = None
    #: Why :attr:`max_tick_us` bounds the tick (said in the refusal).
    max_tick_why: str = ""

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        """Add the station's own options (none by default)."""

    def configure(self, args: argparse.Namespace, say: Callable[[str], None]) -> None:
        """Check and complete ``args`` before the loop exists (seed a database
        directory, say where it is); ConfigError refuses the run.  Nothing by default."""

    def use_databases(self, args: argparse.Namespace, directory: str) -> None:
        """Point ``args`` at ``directory``, which holds the station's database
        files as a journal recorded them (``pyrt replay`` builds the station
        from them).  Default: ``args.db`` (and no ``--init-db``)."""
        args.db = directory
        if hasattr(args, "init_db"):
            args.init_db = None

    def build(self, loop: Loop, args: argparse.Namespace) -> Station:
        """The station on ``loop``, not yet started (``args.boards`` is the board URL)."""
        raise NotImplementedError(f"{type(self).__name__}.build")

    def banner(self, station: Station, args: argparse.Namespace) -> str:
        """The line said when the station starts."""
        speed = ("max (simulated time)" if args.speed is None
                 else f"{args.speed:g}x real time")
        where = ("simulated boards"
                 if station.boards is None or station.boards.simulated is not None
                 else f"boards at {station.boards.url}")
        return (f"pyrt {self.name or station.name}: {station.name}, {where}; "
                f"tick {args.tick_us} µs, speed {speed}; {self.next_step(args)}")

    def next_step(self, args: argparse.Namespace) -> str:
        """The banner's last words: what the operator does next (a console: type
        help; ``--headless``: there is no console, the link serves the commands)."""
        if not getattr(args, "headless", False):
            return "type help"
        links = [w for w, on in (("the DAQ link", getattr(args, "serve", None)),
                                 ("EPICS", getattr(args, "epics", None))) if on]
        return (f"headless: no console; commands come over {' and '.join(links) or 'the link'}"
                "; SIGTERM or SIGINT stops every motor and ends the run")


class _FunctionFactory(StationFactory):
    """A plain ``build(loop, args)`` function as a factory."""

    def __init__(self, fn: Callable[..., Station], name: str):
        self._fn = fn
        self.name = name
        doc = inspect.getdoc(fn) or ""
        self.summary = doc.splitlines()[0] if doc else f"run the station built by {name}"
        self.description = doc

    def build(self, loop: Loop, args: argparse.Namespace) -> Station:
        return self._fn(loop, args)


def as_factory(obj: Any, name: str = "") -> StationFactory:
    """``obj`` as a :class:`StationFactory`: an instance as it is, a subclass
    instantiated, a function ``build(loop, args)`` wrapped; ConfigError otherwise."""
    if isinstance(obj, StationFactory):
        factory = obj
    elif isinstance(obj, type) and issubclass(obj, StationFactory):
        factory = obj()
    elif callable(obj):
        fn_name = getattr(obj, "__name__", "") or "station"
        factory = _FunctionFactory(obj, name or fn_name)
    else:
        raise ConfigError(f"{obj!r} is not a station factory: expected a StationFactory, a "
                          "subclass of it, or a function build(loop, args) -> Station")
    if name and not factory.name:
        factory.name = name
    return factory


def load_factory(spec: str) -> StationFactory:
    """The factory named by ``MODULE:FACTORY`` (``FACTORY`` may be dotted);
    ConfigError saying what is missing."""
    module, colon, attr = spec.partition(":")
    if not colon or not module or not attr:
        raise ConfigError(f"{spec!r}: expected MODULE:FACTORY, e.g. mylab.arm:ArmFactory")
    try:
        obj: Any = importlib.import_module(module)
    except ImportError as exc:
        raise ConfigError(f"{spec!r}: cannot import {module!r}: {exc}") from None
    for part in attr.split("."):
        try:
            obj = getattr(obj, part)
        except AttributeError:
            raise ConfigError(f"{spec!r}: {module} has no {attr!r}") from None
    return as_factory(obj, module.rsplit(".", 1)[-1].replace("_", "-"))


def installed_stations() -> dict[str, importlib.metadata.EntryPoint]:
    """The installed stations by name (entry-point group ``pyrt.stations``), unloaded."""
    found: dict[str, importlib.metadata.EntryPoint] = {}
    for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP):
        key = ep.name.lower()
        if _NAME.match(key) and key not in found:
            found[key] = ep
    return dict(sorted(found.items()))


def find_station(name: str, installed: Iterable[str] | None = None) -> StationFactory:
    """The installed station ``name``; ConfigError naming the installed ones if none."""
    eps = installed_stations()
    ep = eps.get(name.lower())
    if ep is None:
        known = ", ".join(installed if installed is not None else eps) or "none"
        raise ConfigError(f"no station named {name[:40]!r} is installed; installed: {known} "
                          "(or give MODULE:FACTORY to 'pyrt run')")
    try:
        obj = ep.load()
    except Exception as exc:
        raise ConfigError(f"station {ep.name!r} (entry point {ep.value!r} in group "
                          f"{ENTRY_POINT_GROUP!r}) cannot be loaded: "
                          f"{type(exc).__name__}: {exc}") from None
    return as_factory(obj, ep.name)
