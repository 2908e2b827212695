"""A station's simulated boards with the world behind them, as board-sim serves them.

A :class:`World` is a station's in-process boards (a
:class:`~pyrt.boards.Boards` from ``sim:``) and the plant that plays the
world behind them: ``step(now_ns)`` advances it, :meth:`World.outputs_off`
is what the boards' watchdog does (every output register that declares an
``off`` value is written with it), :meth:`World.info` tells its state.  It
knows nothing of sockets or time: :mod:`pyrt.sim.boardsim` serves any world
with the wire protocol of :mod:`pyrt.boards.wire`, answering every declared
register's reads and writes against its boards, and steps it.

A robot of one's own gives ``pyrt board-sim`` its world through a
:class:`WorldFactory` (a station factory inherits it): the kinds of its
boards, the world's command-line options, and the world behind in-process
boards::

    class ArmFactory(StationFactory):          # a WorldFactory too
        name = "arm"

        def board_kinds(self):
            return {"servo": SERVO}

        def add_world_arguments(self, parser):
            parser.add_argument("--payload", type=float, default=0.0)

        def world(self, boards, args):
            return World("arm", boards, ArmPlant(boards["servo"], payload=args.payload))

The built-in worlds are such worlds too:

* :class:`GripperWorld`: the gripper cage's register file (board
  ``gripper``) with a :class:`~pyrt.sim.gripper.JawPlant` behind it.  The
  plant counts the encoder's pulses (the ``up``/``down`` registers) and the
  controller's side raises their interrupts.
* :class:`ManipulatorWorld`: the register files of a TIO10 (board
  ``tio10``) and a dataConcentrator (board ``dc``) with a
  :class:`~pyrt.sim.manipulator.ManipulatorPlant` behind them.
"""

from __future__ import annotations

import argparse
from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING, Any, Protocol

from pyrt.boards.dataconcentrator import DATACONCENTRATOR, DataConcentrator
from pyrt.boards.gripper import GRIPPER_CAGE
from pyrt.boards.registers import BoardKind, RegisterBoard, Registers
from pyrt.boards.registers import outputs_are_off as _outputs_are_off
from pyrt.boards.registers import outputs_off as _outputs_off
from pyrt.boards.registry import Boards, open_boards
from pyrt.boards.tio10 import AWO_BITS, CHANNELS, RTC_CHANNELS, TIO10, TIO10_KIND
from pyrt.errors import ConfigError
from pyrt.sim.gripper import JawParameters, JawPlant
from pyrt.sim.manipulator import ManipulatorPlant, rig_from_station

if TYPE_CHECKING:
    from pyrt.db import Station
    from pyrt.sim.sensors import Imperfections

__all__ = [
    "GRIPPER_BOARDS",
    "MANIPULATOR_BOARDS",
    "BoardWorld",
    "GripperWorld",
    "ManipulatorWorld",
    "Plant",
    "World",
    "WorldFactory",
]

_MOTOR_CHANNELS = tuple(c for c in CHANNELS if c not in RTC_CHANNELS)

#: The gripper station's boards: the cage, mapped into the 8031.
GRIPPER_BOARDS: dict[str, BoardKind] = {"gripper": GRIPPER_CAGE}
#: A manipulator station's boards: the TIO10 and the dataConcentrator.
MANIPULATOR_BOARDS: dict[str, BoardKind] = {"tio10": TIO10_KIND, "dc": DATACONCENTRATOR}


class Plant(Protocol):
    """The physics behind a world's boards: it reads their outputs and sets
    their inputs each step (``info()``, if it has one, tells its state)."""

    def step(self, now_ns: int) -> None:
        """Advance the world to ``now_ns`` (dt = now - last)."""


class World:
    """A station's in-process boards and the plant behind them (see the module text).

    ``name`` is the station whose world this is (the greeting's STATION);
    ``boards`` in-process boards (``sim:``); ``plant`` what :meth:`step`
    advances (None: the boards alone, their inputs set by whoever holds
    them).  ConfigError for a name that is not one ASCII word or boards
    that are not in process.
    """

    def __init__(self, name: str, boards: Boards, plant: Plant | None = None):
        if not isinstance(name, str) or not name or any(c.isspace() for c in name) \
                or not name.isascii():
            raise ConfigError(f"world name must be one ASCII word, got {name!r}")
        side = boards.simulated if isinstance(boards, Boards) else None
        if side is None:
            raise ConfigError(f"a world serves in-process boards (sim:), got {boards!r}")
        boards = side  # the world's side of sim: (not the controller's image)
        #: The station's name (the greeting's STATION).
        self.name = name
        self.boards = boards
        self.plant = plant
        #: Watchdog trips so far (the server counts them; every SNAP reports them).
        self.trips = 0

    @property
    def kinds(self) -> dict[str, BoardKind]:
        """The boards served: name -> kind, in declared order."""
        return self.boards.kinds

    def registers(self, board: str) -> Registers:
        """The register view of ``board`` (what the wire protocol reads and writes)."""
        return self.boards.registers(board)

    def step(self, now_ns: int) -> None:
        """Advance the world to ``now_ns`` (dt = now - last): the plant's step."""
        if self.plant is not None:
            self.plant.step(now_ns)

    def outputs_off(self) -> None:
        """Turn every output off, as the boards' watchdog does: each output
        register's declared ``off`` value, board by board in declared order."""
        for name, kind in self.kinds.items():
            _outputs_off(kind, self.registers(name))

    def outputs_are_off(self) -> bool:
        """Whether every output that declares an ``off`` value holds it."""
        return all(_outputs_are_off(kind, self.registers(name))
                   for name, kind in self.kinds.items())

    def info(self) -> dict[str, object]:
        """The world's state for ``INFO`` (one word per value): the plant's
        ``info()`` if it has one, else nothing."""
        info = getattr(self.plant, "info", None)
        return dict(info()) if callable(info) else {}


#: The name this class had before worlds were generic.
BoardWorld = World


class WorldFactory:
    """What ``pyrt board-sim NAME`` needs of a station to serve its world.

    A station factory inherits it (or implements the three methods); the
    defaults serve the declared boards with no plant behind them.
    ``board-sim`` calls :meth:`add_world_arguments` on its parser, opens
    :meth:`board_kinds` with ``sim:``, and serves :meth:`world` of them.
    """

    #: The station's name (``pyrt board-sim NAME``).
    name: str = ""
    #: Other names board-sim knows this world by, each with the option values
    #: it sets (``{"sno": {"station": "sno"}}``: ``board-sim sno`` is
    #: ``board-sim manipulator --station sno``).
    world_aliases: dict[str, dict[str, Any]] = {}

    def board_kinds(self) -> dict[str, BoardKind]:
        """The station's boards: name -> kind (none by default: nothing to serve)."""
        return {}

    def board_kinds_of(self, args: argparse.Namespace) -> dict[str, BoardKind]:
        """The boards of the world the parsed options ``args`` ask for (a station whose
        options choose its boards says so here); by default :meth:`board_kinds`."""
        return self.board_kinds()

    def add_world_arguments(self, parser: argparse.ArgumentParser) -> None:
        """Add the world's options (a start position, an object, faults ...); none by default."""

    def world(self, boards: Boards, args: argparse.Namespace) -> World:
        """The world behind ``boards`` (this station's, opened in process);
        default: the boards alone, no plant."""
        return World(self.name or "station", boards)


class GripperWorld(World):
    """The gripper cage and the jaws (``start``, ``object_mm``, ``faults`` as
    :class:`~pyrt.sim.gripper.JawPlant` takes them; ConfigError if refused),
    on ``boards`` (in-process, declared as :data:`GRIPPER_BOARDS`; new ones
    if not given)."""

    def __init__(
        self,
        *,
        start: float = -0x0C00,
        object_mm: float | None = None,
        faults: Iterable[str] = (),
        params: JawParameters | None = None,
        name: str = "gripper",
        boards: Boards | None = None,
    ):
        if boards is None:
            boards = open_boards("sim:", name, GRIPPER_BOARDS)
        side = boards.simulated
        if side is None:
            raise ConfigError(f"a world serves in-process boards (sim:), got {boards!r}")
        self.board: RegisterBoard = side["gripper"]
        try:
            plant = JawPlant(self.board, start=start, params=params)
            plant.set_object(object_mm)
            for fault in faults:
                plant.inject(fault)
        except ValueError as exc:
            raise ConfigError(str(exc)) from None
        super().__init__(name, boards, plant)
        self.plant: JawPlant = plant

    def info(self) -> dict[str, object]:
        p = self.plant
        up, down = p.pulse_counts()
        return {
            "x": f"{p.x:.1f}", "v": f"{p.v:.1f}", "opening_mm": f"{p.opening_mm:.2f}",
            "dac": p.dac, "current": p.current, "up": up, "down": down,
            "object_mm": "none" if p.object_mm is None else f"{p.object_mm:g}",
            "squeeze": f"{p.squeeze:.1f}", "jog": p.jog_state,
            "faults": ",".join(sorted(p.faults)) or "none",
        }


class ManipulatorWorld(World):
    """A manipulator's TIO10 and dataConcentrator with the rope world behind them.

    ``plant`` is a :class:`~pyrt.sim.manipulator.ManipulatorPlant` over the
    two cards' register files; at start every output is turned off.
    :attr:`tio10` and :attr:`dc` read them as the cards' views.
    """

    def __init__(self, plant: ManipulatorPlant, name: str):
        self.tio10 = TIO10(plant.tio10)
        self.dc = DataConcentrator(plant.dc)
        boards = Boards("sim:", name, {"tio10": plant.tio10, "dc": plant.dc},
                        MANIPULATOR_BOARDS, in_process=True, world="sim")
        super().__init__(name, boards, plant)
        self.plant: ManipulatorPlant = plant
        self.outputs_off()

    @classmethod
    def from_station(
        cls,
        station: Station,
        *,
        payouts: Sequence[float] | None = None,
        imperfections: Imperfections | None = None,
        liquid_level: float | str | None = "neck",
    ) -> ManipulatorWorld:
        """The world of a :class:`pyrt.db.Station` with the source at its POSITION.

        ``payouts`` default to the plant's own equilibrium
        (:meth:`~pyrt.sim.manipulator.ManipulatorPlant.settle_payouts`); a
        controller that sets its encoders' zero lengths from its own
        equilibrium should pass those (``pyrt board-sim`` does).
        """
        pa = station.polyaxis()
        rig = rig_from_station(station, liquid_level=liquid_level)
        plant = ManipulatorPlant(rig, RegisterBoard(TIO10_KIND), RegisterBoard(DATACONCENTRATOR),
                                 imperfections=imperfections, payouts=payouts)
        return cls(plant, pa.name.lower())

    def info(self) -> dict[str, object]:
        p = self.plant
        out: dict[str, object] = {
            "x": f"{p.position[0]:.3f}", "y": f"{p.position[1]:.3f}",
            "z": f"{p.position[2]:.3f}",
        }
        for i, t in enumerate(p.tensions()):
            out[f"tension{i}"] = f"{t:.3f}"
        for i in range(len(p.ropes)):
            out[f"payout{i}"] = f"{p.payout(i):.4f}"
        out["armed"] = ",".join(str(c) for c in _MOTOR_CHANNELS if self.tio10.armed(c)) or "none"
        out["windings_off"] = int(all(self.tio10.bit(*AWO_BITS[c]) for c in _MOTOR_CHANNELS))
        return out
