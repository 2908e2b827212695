"""The simulated boards with their world behind them, as board-sim serves them.

A :class:`BoardWorld` owns a robot's simulated boards and the plant that
plays the world behind them, and answers the register requests of the wire
protocol (:mod:`pyrt.boards.wire`) on the boards' driver side, exactly as
a controller in the same process would reach them.  It knows nothing of
sockets or time: :mod:`pyrt.sim.boardsim` serves it and steps it.

* :class:`GripperWorld`: an 8031's external data space with a
  :class:`~pyrt.boards.gripper.SimGripperBoard` mapped into it and a
  :class:`~pyrt.sim.gripper.JawPlant` behind it.  The encoder interrupts
  have no handler here; the board counts them (``SNAP``'s UP/DOWN) and the
  controller's side raises them.
* :class:`ManipulatorWorld`: a :class:`~pyrt.boards.simboards.SimTIO10` and
  :class:`~pyrt.boards.simboards.SimDataConcentrator` with a
  :class:`~pyrt.sim.manipulator.ManipulatorPlant` behind them.

:meth:`BoardWorld.outputs_off` is what the board's watchdog does.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING

from pyrt.boards.gripper import DAC, DAC_NULL, SimGripperBoard
from pyrt.boards.i8031 import I8031
from pyrt.boards.simboards import SimDataConcentrator, SimTIO10
from pyrt.boards.tio10 import AWO_BITS, CHANNELS, RTC_CHANNELS
from pyrt.boards.wire import GRIPPER_VERBS, MANIPULATOR_VERBS, WireError, ok_line
from pyrt.errors import ConfigError
from pyrt.sim.gripper import JawParameters, JawPlant
from pyrt.sim.manipulator import ManipulatorPlant, rig_from_station
from pyrt.sim.sensors import Imperfections

if TYPE_CHECKING:
    from pyrt.db import Station

__all__ = ["BoardWorld", "GripperWorld", "ManipulatorWorld"]

_MOTOR_CHANNELS = tuple(c for c in CHANNELS if c not in RTC_CHANNELS)


class BoardWorld(ABC):
    """A robot's simulated boards and the world behind them (see the module text)."""

    #: ``gripper`` or ``manipulator`` (the greeting's KIND).
    kind: str
    #: The request verbs this board answers, with their argument counts.
    verbs: dict[str, tuple[int, ...]]

    def __init__(self, name: str):
        if not name or any(c.isspace() for c in name) or not name.isascii():
            raise ConfigError(f"world name must be one ASCII word, got {name!r}")
        #: The world's name (the greeting's NAME).
        self.name = name
        #: Watchdog trips so far (the server counts them; every SNAP reports them).
        self.trips = 0

    @abstractmethod
    def step(self, now_ns: int) -> None:
        """Advance the world to ``now_ns`` (dt = now - last)."""

    @abstractmethod
    def handle(self, verb: str, args: list[int]) -> bytes:
        """The reply line to a register request (ValueError: the board refuses it)."""

    @abstractmethod
    def outputs_off(self) -> None:
        """Turn every output off, as the board's watchdog does."""

    @abstractmethod
    def outputs_are_off(self) -> bool:
        """Whether every output is off."""

    @abstractmethod
    def info(self) -> dict[str, object]:
        """The world's state for ``INFO`` (one word per value)."""


class GripperWorld(BoardWorld):
    """The gripper cage and the jaws (``start``, ``object_mm``, ``faults`` as
    :class:`~pyrt.sim.gripper.JawPlant` takes them; ConfigError if refused)."""

    kind = "gripper"
    verbs = GRIPPER_VERBS

    def __init__(
        self,
        *,
        start: float = -0x0C00,
        object_mm: float | None = None,
        faults: Iterable[str] = (),
        params: JawParameters | None = None,
        name: str = "gripper",
    ):
        super().__init__(name)
        self.cpu = I8031()
        self.board = SimGripperBoard(self.cpu)
        try:
            self.plant = JawPlant(self.board, start=start, params=params)
            self.plant.set_object(object_mm)
            for fault in faults:
                self.plant.inject(fault)
        except ValueError as exc:
            raise ConfigError(str(exc)) from None

    def step(self, now_ns: int) -> None:
        self.plant.step(now_ns)

    def handle(self, verb: str, args: list[int]) -> bytes:
        board = self.board
        if verb == "R":
            return ok_line(board.read(args[0]))
        if verb == "W":
            board.write(args[0], args[1])
            return b"OK\n"
        if verb == "SNAP":
            up, down = board.pulse_counts()
            return ok_line(self.trips, up, down, *board.register_file())
        raise WireError("syntax", f"{verb} is not a gripper request")

    def outputs_off(self) -> None:
        self.board.write(DAC, DAC_NULL)

    def outputs_are_off(self) -> bool:
        return self.board.dac == DAC_NULL

    def info(self) -> dict[str, object]:
        p = self.plant
        up, down = self.board.pulse_counts()
        return {
            "x": f"{p.x:.1f}", "v": f"{p.v:.1f}", "opening_mm": f"{p.opening_mm:.2f}",
            "dac": self.board.dac, "current": p.current, "up": up, "down": down,
            "object_mm": "none" if p.object_mm is None else f"{p.object_mm:g}",
            "squeeze": f"{p.squeeze:.1f}", "jog": p.jog_state,
            "faults": ",".join(sorted(p.faults)) or "none",
        }


class ManipulatorWorld(BoardWorld):
    """A manipulator's TIO10 and dataConcentrator with the rope world behind them.

    ``plant`` is a :class:`~pyrt.sim.manipulator.ManipulatorPlant` over a
    SimTIO10 and SimDataConcentrator; at start every output is turned off.
    """

    kind = "manipulator"
    verbs = MANIPULATOR_VERBS

    def __init__(self, plant: ManipulatorPlant, name: str):
        super().__init__(name)
        self.plant = plant
        self.tio10: SimTIO10 = plant.tio10
        self.dc: SimDataConcentrator = plant.dc
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
        plant = ManipulatorPlant(rig, SimTIO10(), SimDataConcentrator(),
                                 imperfections=imperfections, payouts=payouts)
        return cls(plant, pa.name.lower())

    def step(self, now_ns: int) -> None:
        self.plant.step(now_ns)

    def handle(self, verb: str, args: list[int]) -> bytes:
        tio = self.tio10
        dc = self.dc
        if verb == "SNAP":
            return ok_line(self.trips, *tio.register_file(), *dc.adc_codes(),
                           *(dc.read_counter(a) for a in args))
        if verb == "SRC":
            if len(args) == 1:
                return ok_line(tio.source(args[0]))
            tio.select_source(args[0], args[1])
        elif verb == "PER":
            if len(args) == 1:
                return ok_line(tio.period(args[0]))
            tio.load_period(args[0], args[1])
        elif verb == "ARM":
            tio.arm(args[0])
        elif verb == "DISARM":
            tio.disarm(args[0])
        elif verb == "ARMED":
            return ok_line(int(tio.armed(args[0])))
        elif verb == "PULSES":
            return ok_line(tio.pulses(args[0]))
        elif verb == "PORT":
            if len(args) == 1:
                return ok_line(tio.read_port(args[0]))
            tio.write_port(args[0], args[1])
        elif verb == "RTC":
            return ok_line(tio.rtc_ticks())
        elif verb == "CNT":
            return ok_line(dc.read_counter(args[0]))
        elif verb == "CLR":
            dc.clear_counter(args[0])
        elif verb == "ADC":
            return ok_line(dc.read_adc(args[0]))
        else:
            raise WireError("syntax", f"{verb} is not a manipulator request")
        return b"OK\n"

    def outputs_off(self) -> None:
        tio = self.tio10
        for ch in _MOTOR_CHANNELS:
            if tio.armed(ch):
                tio.disarm(ch)
        for port, bit in AWO_BITS.values():
            tio.set_bit(port, bit, True)

    def outputs_are_off(self) -> bool:
        tio = self.tio10
        return (not any(tio.armed(ch) for ch in _MOTOR_CHANNELS)
                and all(tio.bit(port, bit) for port, bit in AWO_BITS.values()))

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
