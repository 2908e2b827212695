"""The back-end protocol: what every board scheme implements, and nothing else.

A :class:`Backend` is how a station's boards are reached (pySerial's
``SerialBase``, which every URL handler implements; ros2_control's
hardware interface).  ``sim:``, ``tcp://``, ``modbus://`` and ``replay:``
implement it, and so does a scheme of one's own
(:mod:`pyrt.boards.registry`): a
:class:`~pyrt.boards.registry.Boards` is the station's named boards over
one back end, and a station calls the back end through it and never asks
what kind of back end it is.

=====================  ==========================================================
``open()``             reach the boards: the inputs and the readable outputs once
``read_phase(now)``    the tick's first phase: every input, one exchange
``write_phase(now)``   the tick's last phase: the outputs the tick changed
``write_now()``        the reflex: the changed outputs at once, in the tick that tripped
``close()``            release the boards (idempotent)
``down``               why the boards cannot be reached any more, or None
``set_tick(period)``   the loop's tick: the back end derives its timeouts from it
``resync()``           the loop starts: what was written while building goes out
``info()``             the world's state as the back end tells it (``sim show``)
``simulated``          the boards the world drives in this process, or None: the
                       one question a station asks of its back end
``attach_world(step)`` run the world's ``step(now)`` at the start of every read
                       phase; False if the world is not this process's to step
=====================  ==========================================================

:class:`~pyrt.boards.image.ImageBackend` implements it with a process image
(the phases and their contract are written there); the base class here is a
back end with nothing to exchange (boards called directly in this process,
the world's side of ``sim:``: its phases do nothing).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

from pyrt.boards.registers import BoardKind
from pyrt.errors import ConfigError

if TYPE_CHECKING:
    from pyrt.boards.registry import Boards

__all__ = ["Backend", "WorldSide"]


class Backend:
    """The back-end protocol (see the module text); this base exchanges nothing.

    ``url`` names it in every error; ``kinds`` are the declared boards (name
    -> kind).  A back end whose boards and world run in another process at
    real time says so (:attr:`realtime`): a station refuses virtual time on it.
    """

    #: The boards and their world run elsewhere at real time (a link): a loop on
    #: virtual time, or at another speed, is refused.
    realtime: bool = False
    #: The inputs come from a journal being replayed, not from a world.
    replay: bool = False
    #: Whether :meth:`down` can ever be other than None (a link that can fail):
    #: a station catches the BoardError of its phases only then.
    has_link: bool = False

    def __init__(self, url: str, kinds: Mapping[str, BoardKind]):
        self.url = url
        self.kinds: dict[str, BoardKind] = dict(kinds)
        #: The in-process boards the world drives (the world's side), or None
        #: when the world is elsewhere.
        self.simulated: Boards | None = None
        #: The process image a journal records (the back end itself when it is
        #: one), or None.
        self.image: Any = None

    def open(self) -> None:
        """Reach the boards (nothing to read here)."""

    def read_phase(self, now_ns: int) -> None:
        """The tick's read phase (nothing to read here)."""

    def read_inputs(self, now_ns: int) -> None:
        """The read phase outside the ticks (a station being built): the inputs
        now, without stepping the world (nothing to read here)."""

    def write_phase(self, now_ns: int) -> None:
        """The tick's write phase (nothing to write here)."""

    def write_now(self) -> None:
        """Write the changed outputs at once (nothing is held here)."""

    def close(self) -> None:
        """Release the boards (idempotent; nothing to release here)."""

    @property
    def down(self) -> str | None:
        """Why the boards cannot be reached any more, or None while they can."""
        return None

    def set_tick(self, period_s: float) -> None:
        """The loop's tick period (nothing derives from it here)."""

    def resync(self) -> None:
        """The station's loop starts (nothing to catch up here)."""

    def info(self) -> dict[str, str]:
        """The world's state as the back end tells it; ConfigError if it tells nothing."""
        raise ConfigError(f"board URL {self.url!r}: this back end tells nothing of the world")

    @property
    def tells_world(self) -> bool:
        """Whether :meth:`info` says anything (a subclass that overrides it does)."""
        return type(self).info is not Backend.info

    def attach_world(self, step: Callable[[int], None]) -> bool:
        """Run the world's ``step(now_ns)`` at the start of every read phase
        (True), or say that it is not this back end's to step (False: the
        caller attaches it to the loop itself)."""
        return False


class WorldSide(Backend):
    """The world's side of ``sim:``: the simulated boards themselves, which the
    world drives and ``pyrt board-sim`` serves (:attr:`simulated` is the
    Boards over it)."""
