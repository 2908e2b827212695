"""Board back ends chosen by URL, as pySerial's ``serial_for_url`` chooses a port.

A station asks for its robot's boards with one call and never names a back
end class::

    boards = open_boards("sim:", "gripper", cpu=cpu)         # in process (the default)
    boards = open_boards("tcp://127.0.0.1:5055", "manipulator", timeout=0.5)

and gets a :class:`Boards`: the register-level board objects of that robot
(``gripper`` mapped into ``cpu``, or ``tio10`` and ``dc``), ``poll(now_ns)``
to attach to the loop before the ready queue, and ``close()``.

Schemes built in:

* ``sim:`` -- the in-process simulated boards
  (:class:`~pyrt.boards.gripper.SimGripperBoard`,
  :class:`~pyrt.boards.simboards.SimTIO10` and
  :class:`~pyrt.boards.simboards.SimDataConcentrator`); ``in_process`` is
  true and the caller puts the physics (:mod:`pyrt.sim`) behind them;
* ``tcp://HOST:PORT[?timeout=S&connect_timeout=S&max_age=S]`` -- the boards
  of ``pyrt board-sim`` in another process (:mod:`pyrt.boards.tcp`,
  protocol in :mod:`pyrt.boards.wire`).

Options come from the URL's query and from keyword arguments (these win).
Another back end registers its scheme without touching pyrt, through the
entry-point group ``pyrt.boards`` (name: the scheme, value: the factory)::

    [project.entry-points."pyrt.boards"]
    mylab = "mylab.boards:open_mylab"

A factory is called as ``factory(url: BoardURL, robot: str, **options)``
and returns a :class:`Boards`; it raises :class:`~pyrt.errors.ConfigError`
for an option or URL it cannot use and :class:`~pyrt.errors.BoardError`
when the boards cannot be reached.  :func:`register_backend` does the same
from code.  A built-in scheme cannot be replaced.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol
from urllib.parse import parse_qsl, urlsplit

from pyrt.boards.dataconcentrator import DataConcentrator
from pyrt.boards.gripper import GripperBoard, SimGripperBoard
from pyrt.boards.i8031 import I8031
from pyrt.boards.simboards import SimDataConcentrator, SimTIO10
from pyrt.boards.tio10 import TIO10
from pyrt.errors import ConfigError

__all__ = [
    "DEFAULT_URL",
    "ENTRY_POINT_GROUP",
    "ROBOTS",
    "BackendFactory",
    "BoardURL",
    "Boards",
    "backend",
    "known_schemes",
    "open_boards",
    "open_sim",
    "parse_board_url",
    "register_backend",
]

#: The back end when none is asked for.
DEFAULT_URL = "sim:"
#: Entry-point group of third-party back ends (name: scheme, value: factory).
ENTRY_POINT_GROUP = "pyrt.boards"
#: The robots whose boards a back end opens.
ROBOTS = ("gripper", "manipulator")

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
    """Opens the boards of ``robot`` at ``url`` (see the module text)."""

    def __call__(self, url: BoardURL, robot: str, **options: Any) -> Boards: ...


class Boards:
    """The boards a back end opened for one robot.

    ``gripper`` (with the ``cpu`` it is mapped into) for the gripper;
    ``tio10`` and ``dc`` for the manipulator.  ``in_process``: the boards
    are simulated in this process and the caller puts the world behind them
    (``sim:``); otherwise the world is elsewhere.  ``world`` is what the
    back end says it drives (board-sim's world name), or "".
    """

    def __init__(
        self,
        url: str,
        robot: str,
        *,
        in_process: bool,
        gripper: GripperBoard | None = None,
        cpu: I8031 | None = None,
        tio10: TIO10 | None = None,
        dc: DataConcentrator | None = None,
        world: str = "",
        poll: Callable[[int], None] | None = None,
        close: Callable[[], None] | None = None,
        down: Callable[[], str | None] | None = None,
        info: Callable[[], dict[str, str]] | None = None,
        resync: Callable[[], None] | None = None,
    ):
        if robot == "gripper" and (gripper is None or cpu is None):
            raise ConfigError(f"board URL {url!r}: the back end opened no gripper board")
        if robot == "manipulator" and (tio10 is None or dc is None):
            raise ConfigError(f"board URL {url!r}: the back end opened no TIO10/dataConcentrator")
        self.url = url
        self.robot = robot
        self.in_process = in_process
        self.gripper = gripper
        self.cpu = cpu
        self.tio10 = tio10
        self.dc = dc
        self.world = world
        self._poll = poll
        self._close = close
        self._down = down
        self._info = info
        self._resync = resync
        self.closed = False

    def poll(self, now_ns: int) -> None:
        """Per tick, before the ready queue: bring the inputs of this tick in
        (and, for the gripper, raise the encoder interrupts that arrived).
        Raises :class:`~pyrt.errors.BoardError` when the boards cannot be reached."""
        if self._poll is not None:
            self._poll(now_ns)

    @property
    def polls(self) -> bool:
        """Whether :meth:`poll` does anything (attach it to the loop if so)."""
        return self._poll is not None

    @property
    def down(self) -> str | None:
        """Why the boards cannot be reached any more (a link that failed stays
        down), or None while they can."""
        return self._down() if self._down is not None else None

    @property
    def has_info(self) -> bool:
        """Whether :meth:`info` can tell the state of the world behind the boards."""
        return self._info is not None

    def info(self) -> dict[str, str]:
        """The world's state as the back end tells it (board-sim's ``INFO``: not
        a register access); ConfigError if this back end has none, BoardError
        if it cannot be reached."""
        if self._info is None:
            raise ConfigError(f"board URL {self.url!r}: this back end tells nothing of the world")
        return self._info()

    def resync(self) -> None:
        """The controller's loop starts now: what the boards' watchdog did
        while nothing polled (the station was being built; nothing was
        driven) is not news to the next :meth:`poll`."""
        if self._resync is not None:
            self._resync()

    def close(self) -> None:
        """Release the back end (idempotent)."""
        if not self.closed:
            self.closed = True
            if self._close is not None:
                self._close()

    def __enter__(self) -> Boards:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"<Boards {self.robot} at {self.url}>"


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
_BUILTIN = {"sim": "pyrt.boards.registry:open_sim", "tcp": "pyrt.boards.tcp:open_tcp"}
_registered: dict[str, BackendFactory] = {}


def register_backend(scheme: str, factory: BackendFactory) -> None:
    """Register ``factory`` for ``scheme`` from code (an entry point does the same)."""
    key = scheme.lower()
    if not _SCHEME.fullmatch(scheme):
        raise ConfigError(f"{scheme!r} is not a URL scheme")
    if key in _BUILTIN:
        raise ConfigError(f"board scheme {key!r} is built in and cannot be replaced")
    _registered[key] = factory


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


def open_boards(url: str | None, robot: str, **options: Any) -> Boards:
    """Open the boards of ``robot`` (``gripper`` or ``manipulator``) at ``url``.

    ``url`` None means :data:`DEFAULT_URL`.  Options: the URL's query, then
    ``options`` (which win); for the gripper, ``cpu=`` the
    :class:`~pyrt.boards.i8031.I8031` to map the board into (a new one if
    not given).  Raises ConfigError for a malformed URL, an unknown scheme,
    or an option the back end does not take, and BoardError when the boards
    cannot be reached.
    """
    if robot not in ROBOTS:
        raise ConfigError(f"no boards for robot {robot!r}; robots: {', '.join(ROBOTS)}")
    parsed = parse_board_url(url if url is not None else DEFAULT_URL)
    factory = backend(parsed.scheme, parsed.text)
    merged: dict[str, Any] = {**parsed.options, **options}
    boards = factory(parsed, robot, **merged)
    if not isinstance(boards, Boards):
        raise ConfigError(f"board back end {parsed.scheme!r} returned {type(boards).__name__}, "
                          "not Boards")
    return boards


# -- sim: ------------------------------------------------------------------------------


def open_sim(url: BoardURL, robot: str, *, cpu: I8031 | None = None, **options: Any) -> Boards:
    """The ``sim:`` back end: register files in this process; the caller
    attaches the physics.  It takes no host, path or option but ``cpu``."""
    if url.host or url.port is not None or url.path:
        raise url.error("sim: takes no host, port or path; write it as sim:")
    if options:
        raise url.error(f"sim: takes no option {', '.join(sorted(options))}")
    if robot == "gripper":
        cpu = cpu if cpu is not None else I8031()
        return Boards(url.text, robot, in_process=True, gripper=SimGripperBoard(cpu), cpu=cpu,
                      world="sim")
    return Boards(url.text, robot, in_process=True, tio10=SimTIO10(), dc=SimDataConcentrator(),
                  world="sim")
