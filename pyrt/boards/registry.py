"""Board back ends chosen by URL, as pySerial's ``serial_for_url`` chooses a port.

A station declares its boards, a name for each and its kind
(:class:`~pyrt.boards.registers.BoardKind`), and asks for them with one
call, never naming a back end class::

    boards = open_boards("sim:", "gripper", {"gripper": GRIPPER_CAGE}, cpu=cpu)
    boards = open_boards("tcp://127.0.0.1:5055", "prototype",
                         {"tio10": TIO10_KIND, "dc": DATACONCENTRATOR}, timeout=0.5)
    boards = open_boards(url, "arm", {"servo": SERVO})   # a kind of one's own

and gets a :class:`Boards`: a mapping of those names to the board objects
(``boards["tio10"]``) over one back end (:attr:`Boards.backend`, the
protocol of :mod:`pyrt.boards.backend`): ``read_phase(now_ns)`` to attach
to the loop before the ready queue, ``write_phase(now_ns)`` after
everything else, ``write_now()`` for the reflex, and ``close()`` (the
phases and the back-end contract: :mod:`pyrt.boards.image`).  A built-in
kind gives its typed board (:mod:`pyrt.boards.kinds`); a plain kind a
register view with ``read``/``write`` by name.  Every built-in scheme
reaches its boards through a process image: one tick shape.

Schemes built in:

* ``sim:`` -- every declared board built in this process
  (:meth:`BoardKind.sim <pyrt.boards.registers.BoardKind.sim>`), reached
  through a process image; :attr:`Boards.simulated` are the boards
  themselves, where the caller puts the physics (:mod:`pyrt.sim`);
* ``tcp://HOST:PORT[?timeout=S&connect_timeout=S&max_age=S]`` -- the boards
  of ``pyrt board-sim`` in another process (:mod:`pyrt.boards.tcp`,
  protocol in :mod:`pyrt.boards.wire`);
* ``modbus://HOST:PORT?map=FILE`` -- registers of Modbus TCP devices, placed
  by a register map (:mod:`pyrt.boards.modbus`; needs ``pyrt[modbus]``).

Options come from the URL's query and from keyword arguments (these win);
an option that a declared kind takes (:attr:`BoardKind.options
<pyrt.boards.registers.BoardKind.options>`, e.g. the gripper cage's
``cpu``) goes to that kind's builder.  Another back end registers its
scheme without touching pyrt, through the entry-point group
``pyrt.boards`` (name: the scheme, value: the factory)::

    [project.entry-points."pyrt.boards"]
    mylab = "mylab.boards:open_mylab"

A factory is called as ``factory(url: BoardURL, station: str, kinds:
dict[str, BoardKind], **options)`` and returns a :class:`Boards` holding a
board for every declared name over its back end (a
:class:`~pyrt.boards.backend.Backend`: the protocol every scheme
implements, usually an :class:`~pyrt.boards.image.ImageBackend`); it
raises :class:`~pyrt.errors.ConfigError` for an option or URL it cannot
use and :class:`~pyrt.errors.BoardError` when the boards cannot be
reached.  :func:`register_backend` does the same from code.  A built-in scheme cannot be replaced.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import re
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol
from urllib.parse import parse_qsl, urlsplit

from pyrt.boards.backend import Backend, WorldSide
from pyrt.boards.registers import (
    BoardKind,
    Registers,
    check_kinds,
    options_for,
    split_options,
)
from pyrt.errors import ConfigError

__all__ = [
    "DEFAULT_URL",
    "ENTRY_POINT_GROUP",
    "BackendFactory",
    "BoardURL",
    "Boards",
    "backend",
    "known_schemes",
    "open_boards",
    "open_sim",
    "parse_board_url",
    "register_backend",
    "unregister_backend",
]

#: The back end when none is asked for.
DEFAULT_URL = "sim:"
#: Entry-point group of third-party back ends (name: scheme, value: factory).
ENTRY_POINT_GROUP = "pyrt.boards"

_SCHEME = re.compile(r"[A-Za-z][A-Za-z0-9+.-]*")


@dataclass(frozen=True)
class BoardURL:
    """A parsed board URL: ``scheme:`` or ``scheme://host:port/path?key=value``.

    ``text`` is the URL as given; ``scheme`` is lower case; ``host``,
    ``port`` and ``path`` are empty/None when absent; ``options`` holds the
    query's keys and values (strings).
    """

    text: str
    scheme: str
    host: str = ""
    port: int | None = None
    path: str = ""
    options: dict[str, str] = field(default_factory=dict)

    def error(self, message: str) -> ConfigError:
        """A ConfigError naming this URL."""
        return ConfigError(f"board URL {self.text!r}: {message}")


class BackendFactory(Protocol):
    """Opens the declared boards of ``station`` at ``url`` (see the module text)."""

    def __call__(self, url: BoardURL, station: str, kinds: dict[str, BoardKind],
                 **options: Any) -> Boards: ...


class Boards(Mapping[str, Any]):
    """The boards one back end opened for one station: board name -> board.

    ``backend`` (a :class:`~pyrt.boards.backend.Backend`) is how they are
    reached: every phase, the reflex write, the tick, the link's state and
    close are its own, and a station asks it one question, :attr:`simulated`
    (the boards the world drives in this process, or None).  ``kinds`` are
    the declared kinds by name; :meth:`registers` the register view of a
    board (``views``: given by the back end; else the kind's view of the
    board).  ``world`` is what the back end says it drives (board-sim's
    station name), or "".  ConfigError if a declared board is missing.

    Without a ``backend``: boards called directly in this process
    (``in_process``, the world's side of ``sim:``: a
    :class:`~pyrt.boards.backend.WorldSide`), or reached by means of their
    own (a :class:`~pyrt.boards.backend.Backend` with nothing to exchange).
    """

    def __init__(
        self,
        url: str,
        station: str,
        boards: Mapping[str, Any],
        kinds: Mapping[str, BoardKind],
        backend: Backend | None = None,
        *,
        world: str = "",
        views: Mapping[str, Registers] | None = None,
        in_process: bool = False,
    ):
        missing = [name for name in kinds if name not in boards]
        if missing:
            raise ConfigError(f"board URL {url!r}: the back end opened no "
                              f"{', '.join(missing)} board")
        if backend is None:
            backend = WorldSide(url, kinds) if in_process else Backend(url, kinds)
        if not isinstance(backend, Backend):
            raise ConfigError(f"board URL {url!r}: {type(backend).__name__} is not a "
                              "pyrt.boards.Backend")
        if isinstance(backend, WorldSide):
            backend.simulated = self
        self.url = url
        self.station = station
        self.kinds: dict[str, BoardKind] = dict(kinds)
        self._boards: dict[str, Any] = {name: boards[name] for name in kinds}
        self._views = dict(views) if views is not None else {}
        self.world = world
        #: The back end: the protocol every scheme implements.
        self.backend = backend
        #: The read phase and the write phase (the back end's own: the station
        #: attaches them to its loop).
        self.read_phase: Callable[[int], None] = backend.read_phase
        self.write_phase: Callable[[int], None] = backend.write_phase
        #: Whether a phase can fail (a link that can go down): the station then
        #: catches its BoardError and trips the robot that owns the boards.
        self.can_fail = bool(backend.has_link)
        self.closed = False

    # -- the mapping -------------------------------------------------------------------

    def __getitem__(self, name: str) -> Any:
        try:
            return self._boards[name]
        except KeyError:
            raise KeyError(f"{self.station} declared no board {name!r}; boards: "
                           f"{', '.join(self._boards)}") from None

    def __iter__(self) -> Iterator[str]:
        return iter(self._boards)

    def __len__(self) -> int:
        return len(self._boards)

    def registers(self, name: str) -> Registers:
        """The register view of board ``name`` (read/write by register name)."""
        view = self._views.get(name)
        if view is None:
            view = self._views[name] = self.kinds[name].view(self[name])
        return view

    # -- what the station asks of the back end ---------------------------------------

    @property
    def simulated(self) -> Boards | None:
        """The in-process simulated boards the world drives (the world's side),
        or None when the world runs elsewhere: the one question a station asks."""
        return self.backend.simulated

    @property
    def in_process(self) -> bool:
        """Whether the world behind the boards is simulated in this process
        (:attr:`simulated` is not None)."""
        return self.backend.simulated is not None

    @property
    def image(self) -> Any:
        """The process image (:class:`~pyrt.boards.image.ImageBackend`) a journal
        records, or None."""
        return self.backend.image

    @property
    def replay(self) -> bool:
        """The inputs come from a journal being replayed, not from a world."""
        return self.backend.replay

    @property
    def realtime(self) -> bool:
        """The boards and their world run elsewhere at real time (a link)."""
        return self.backend.realtime

    def attach_world(self, step: Callable[[int], None]) -> bool:
        """Run the world's ``step(now_ns)`` at the start of every read phase
        (True; in a replay the world stands still: nothing is attached), or
        False: the back end does not step a world, the caller attaches it."""
        return self.backend.attach_world(step)

    # -- the back end ------------------------------------------------------------------

    def poll(self, now_ns: int) -> None:
        """Per tick, before the ready queue: bring the inputs of this tick in
        (and, for the gripper, raise the encoder interrupts that arrived).
        Raises :class:`~pyrt.errors.BoardError` when the boards cannot be reached."""
        self.backend.read_phase(now_ns)

    def read_inputs(self, now_ns: int) -> None:
        """Outside the ticks (a station being built): the inputs read into the
        image now, as the read phase reads them, without stepping the world
        (which steps in the loop's ticks alone).  BoardError as :meth:`poll`."""
        self.backend.read_inputs(now_ns)

    def flush(self, now_ns: int) -> None:
        """Per tick, last (after the mailbox): write the outputs the tick
        changed, one exchange per back end.  Raises
        :class:`~pyrt.errors.BoardError` when the boards cannot be reached."""
        self.backend.write_phase(now_ns)

    def write_now(self) -> None:
        """Write the outputs changed so far at once (after a reflex: not at the
        end of the tick).  BoardError if the write failed (a link that is down)."""
        self.backend.write_now()

    def set_tick(self, period_s: float) -> None:
        """The loop's tick period: the back end derives its timeouts from it."""
        self.backend.set_tick(period_s)

    @property
    def down(self) -> str | None:
        """Why the boards cannot be reached any more (a link that failed stays
        down), or None while they can."""
        return self.backend.down

    @property
    def has_info(self) -> bool:
        """Whether :meth:`info` can tell the state of the world behind the boards."""
        return self.backend.tells_world

    def info(self) -> dict[str, str]:
        """The world's state as the back end tells it (board-sim's ``INFO``: not
        a register access); ConfigError if this back end has none, BoardError
        if it cannot be reached."""
        return self.backend.info()

    def resync(self) -> None:
        """The controller's loop starts now: what the boards' watchdog did
        while nothing polled (the station was being built; nothing was
        driven) is not news to the next :meth:`poll`."""
        self.backend.resync()

    def close(self) -> None:
        """Release the back end (idempotent)."""
        if not self.closed:
            self.closed = True
            self.backend.close()

    def __enter__(self) -> Boards:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"<Boards {self.station} ({', '.join(self._boards)}) at {self.url}>"


# -- URLs -----------------------------------------------------------------------------


def parse_board_url(url: str) -> BoardURL:
    """Parse a board URL; ConfigError (naming the URL and the known schemes) if malformed."""

    def bad(why: str) -> ConfigError:
        return ConfigError(f"board URL {url!r} is malformed: {why}; expected SCHEME:... "
                           f"such as sim: or tcp://HOST:PORT (known schemes: "
                           f"{', '.join(known_schemes())})")

    if not isinstance(url, str):
        raise ConfigError(f"board URL must be text, got {url!r}")
    if not url or url != url.strip() or any(ord(c) < 33 or ord(c) == 127 for c in url):
        raise bad("empty, or spaces or control characters in it")
    scheme, colon, rest = url.partition(":")
    if not colon or not _SCHEME.fullmatch(scheme):
        raise bad("no scheme")
    if "#" in rest:
        raise bad("a fragment (#) is not allowed")
    try:
        parts = urlsplit(url)
        port = parts.port
    except ValueError as exc:
        raise bad(str(exc)) from None
    host = parts.hostname or ""
    if parts.username is not None or parts.password is not None:
        raise bad("user names and passwords are not allowed")
    try:
        options = parse_qsl(parts.query, keep_blank_values=True, strict_parsing=bool(parts.query))
    except ValueError:
        raise bad("the query is not KEY=VALUE&...") from None
    keys = [k for k, _ in options]
    if len(set(keys)) != len(keys):
        raise bad("an option is given twice")
    return BoardURL(url, scheme.lower(), host, port, parts.path, dict(options))


# -- the registry ----------------------------------------------------------------------

#: Built-in schemes -> "module:function" (imported when first used).
_BUILTIN = {"sim": "pyrt.boards.registry:open_sim", "tcp": "pyrt.boards.tcp:open_tcp",
            "modbus": "pyrt.boards.modbus:open_modbus"}
_registered: dict[str, BackendFactory] = {}


def register_backend(scheme: str, factory: BackendFactory) -> None:
    """Register ``factory`` for ``scheme`` from code (an entry point does the same)."""
    key = scheme.lower()
    if not _SCHEME.fullmatch(scheme):
        raise ConfigError(f"{scheme!r} is not a URL scheme")
    if key in _BUILTIN:
        raise ConfigError(f"board scheme {key!r} is built in and cannot be replaced")
    _registered[key] = factory


def unregister_backend(scheme: str) -> None:
    """Forget a back end :func:`register_backend` registered (nothing if none was)."""
    _registered.pop(scheme.lower(), None)


def _entry_points() -> dict[str, Any]:
    eps = importlib.metadata.entry_points(group=ENTRY_POINT_GROUP)
    return {ep.name.lower(): ep for ep in eps}


def known_schemes() -> list[str]:
    """Every scheme :func:`open_boards` accepts: built in, registered, entry points."""
    try:
        found = set(_entry_points())
    except Exception:  # a broken installation must not hide the built-in schemes
        found = set()
    return sorted(set(_BUILTIN) | set(_registered) | found)


def _load(spec: str) -> Any:
    module, _, attr = spec.partition(":")
    obj: Any = importlib.import_module(module)
    for part in attr.split("."):
        obj = getattr(obj, part)
    return obj


def backend(scheme: str, url: str | None = None) -> BackendFactory:
    """The factory of ``scheme``; ConfigError naming ``url`` (if given) and
    the known schemes if there is none."""
    key = scheme.lower()
    if key in _BUILTIN:
        return _load(_BUILTIN[key])
    if key in _registered:
        return _registered[key]
    where = f"board URL {url!r}: " if url is not None else ""
    ep = _entry_points().get(key)
    if ep is None:
        raise ConfigError(f"{where}no board back end for scheme {key!r}; known schemes: "
                          f"{', '.join(known_schemes())}")
    try:
        factory = ep.load()
    except Exception as exc:
        raise ConfigError(f"{where}board back end {key!r} (entry point {ep.value!r} in group "
                          f"{ENTRY_POINT_GROUP!r}) cannot be loaded: {exc}") from None
    if not callable(factory):
        raise ConfigError(f"{where}board back end {key!r} (entry point {ep.value!r}) "
                          "is not callable")
    return factory


def open_boards(url: str | None, station: str, kinds: Mapping[str, BoardKind],
                **options: Any) -> Boards:
    """Open the boards that ``station`` declares in ``kinds`` (board name ->
    :class:`~pyrt.boards.registers.BoardKind`) at ``url``.

    ``url`` None means :data:`DEFAULT_URL`.  Options: the URL's query, then
    ``options`` (which win); an option a declared kind takes goes to its
    builder (the gripper cage's ``cpu=``, the
    :class:`~pyrt.boards.i8031.I8031` to map it into; a new one if not
    given).  Raises ConfigError for a malformed URL, an unknown scheme, a
    declaration that is not one, or an option the back end does not take,
    and BoardError when the boards cannot be reached.
    """
    if not isinstance(station, str) or not station or not station.isascii() \
            or any(c.isspace() for c in station):
        raise ConfigError(f"a station's name is one ASCII word, got {station!r}")
    checked = check_kinds(kinds)
    parsed = parse_board_url(url if url is not None else DEFAULT_URL)
    factory = backend(parsed.scheme, parsed.text)
    merged: dict[str, Any] = {**parsed.options, **options}
    boards = factory(parsed, station, checked, **merged)
    if not isinstance(boards, Boards):
        raise ConfigError(f"board back end {parsed.scheme!r} returned {type(boards).__name__}, "
                          "not Boards")
    return boards


# -- sim: ------------------------------------------------------------------------------


def open_sim(url: BoardURL, station: str, kinds: dict[str, BoardKind],
             **options: Any) -> Boards:
    """The ``sim:`` back end: every declared board built in this process
    (:meth:`BoardKind.sim <pyrt.boards.registers.BoardKind.sim>`), the world's
    side (:attr:`Boards.simulated`, where the caller puts the physics), and
    the controller reaching them through a process image
    (:class:`~pyrt.boards.image.LocalImage`), as it reaches a link's: one
    tick shape whatever the back end.  It takes no host, path or option but
    those of the declared kinds."""
    if url.host or url.port is not None or url.path:
        raise url.error("sim: takes no host, port or path; write it as sim:")
    mine, rest = split_options(kinds, options)
    if rest:
        takes = sorted(set().union(*(k.options for k in kinds.values())))
        raise url.error(f"sim: takes no option {', '.join(sorted(rest))}"
                        + (f" (it takes {', '.join(takes)})" if takes else ""))
    # the boards behind the image are the world's: mapped into no controller's CPU
    behind = Boards(url.text, station, {name: kind.sim() for name, kind in kinds.items()},
                    kinds, in_process=True, world="sim")
    views = {name: behind.registers(name) for name in kinds}
    return image_boards(url.text, station, kinds, views, mine, simulated=behind)


def image_boards(url: str, station: str, kinds: Mapping[str, BoardKind],
                 views: Mapping[str, Registers] | None, options: Mapping[str, Any], *,
                 simulated: Boards | None = None, feed: Any = None,
                 outputs: Mapping[tuple[str, str, int], int] | None = None,
                 world: str = "sim", info: Callable[[], dict[str, str]] | None = None
                 ) -> Boards:
    """Boards reached through a :class:`~pyrt.boards.image.LocalImage` over
    ``views`` (in this process; ``simulated``: the world's side they view),
    or fed by ``feed`` (a replay: ``views`` None, ``outputs`` the outputs as
    they stood).  ``options``: those of the declared kinds (the gripper
    cage's ``cpu``)."""
    from pyrt.boards.image import ImageRegisters, LocalImage

    local = LocalImage(url, kinds, views, feed=feed, outputs=outputs, simulated=simulated,
                       info=info)
    local.open()
    regs = {name: ImageRegisters(local, name) for name in kinds}
    typed = {name: kind.remote(regs[name], **options_for(kind, options))
             for name, kind in kinds.items()}
    local.after_read.extend(
        b.poll for b in typed.values()
        if not isinstance(b, ImageRegisters) and callable(getattr(b, "poll", None)))
    return Boards(url, station, typed, kinds, local, world=world, views=regs)
