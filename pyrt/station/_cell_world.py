"""The world of ``pyrt cell``: the object on the table and the component ``sim``.

:class:`CellWorld` plays the object: it rests on the table where ``sim
object X Y Z`` put it until the jaws (the gripper's plant, at the arm's tool
point in the simulated arm's truth) hold it.  It is between the jaws when
the tool point is within :data:`CAPTURE_MM` of it across and
:data:`CAPTURE_Z_MM` along the vertical (the jaws' plant then has it, and
closing the jaws squeezes it); it is held while the jaws squeeze it, and
then moves with the tool (its place in the tool's frame kept from the
moment of the grasp); let go, it falls back to the table below it.  The
controller never reads any of this.

:class:`CellSim` is that world as the operator sees it: ``sim show``, ``sim
object X Y Z [W]``, ``sim fault`` (the jaws' faults), the jaws' truth;
its part ``object`` has the object's truth (``sim.object.x`` / ``y`` / ``z``
/ ``held``), its part ``armsim`` the arm's.
"""

from __future__ import annotations

import math

import numpy as np

from pyrt.component import Arg, Component, Signal, command, finite
from pyrt.errors import CommandError
from pyrt.sim.arm import ArmWorld
from pyrt.sim.gripper import JawPlant

__all__ = ["CAPTURE_MM", "CAPTURE_Z_MM", "CellObject", "CellSim", "CellWorld"]

#: The object is between the jaws when the tool point is this close across (mm) ...
CAPTURE_MM = 10.0
#: ... and this close along the vertical (mm).
CAPTURE_Z_MM = 15.0
#: Beyond this from the object (mm) the tool is looked for only every FAR_SKIP_TICKS + 1
#: ticks (it moves less than a metre a second: it cannot come within reach sooner).
FAR_MM = 60.0
FAR_SKIP_TICKS = 9
#: The object's width when none is given (mm).
DEFAULT_WIDTH_MM = 30.0
#: Where the object is at start (mm): on the table below the PUMA's start pose.
DEFAULT_OBJECT_MM = (600.0, -150.0, 400.0)


class CellWorld:
    """The object and the jaws at the arm's tool (see the module text)."""

    def __init__(self, arm: ArmWorld, jaws: JawPlant) -> None:
        self.arm = arm
        self.jaws = jaws
        #: The object's position when it is not held (m, world frame), or None.
        self._resting: np.ndarray | None = np.array(DEFAULT_OBJECT_MM) * 1e-3
        #: Ticks before the next look for the tool (far from the object: it cannot
        #: come within reach sooner).
        self._skip = 0
        self.width_mm = DEFAULT_WIDTH_MM
        #: The table height under the object (m): where it rests when let go.
        self.rest_z = float(DEFAULT_OBJECT_MM[2]) * 1e-3
        #: The object in the tool's frame while held (4,), or None.
        self._grasp: np.ndarray | None = None

    @property
    def position(self) -> np.ndarray | None:
        """The object's true position (m, world frame), or None: no object."""
        if self._grasp is not None:
            return (self.arm.truth().tool @ self._grasp)[:3]
        return self._resting

    @property
    def held(self) -> bool:
        """The jaws hold the object."""
        return self._grasp is not None

    def place(self, x_mm: float, y_mm: float, z_mm: float, width_mm: float) -> None:
        """The object at (x, y, z) mm on the table, ``width_mm`` wide; ValueError
        while the jaws hold one."""
        if self.held:
            raise ValueError("the jaws hold the object: open them first")
        if self.jaws.object_mm is not None:
            self.jaws.set_object(None)
        self._resting = np.array([x_mm, y_mm, z_mm]) * 1e-3
        self.rest_z = z_mm * 1e-3
        self._skip = 0
        self.width_mm = width_mm

    def remove(self) -> None:
        """No object (ValueError while the jaws hold it)."""
        if self.held:
            raise ValueError("the jaws hold the object: open them first")
        if self.jaws.object_mm is not None:
            self.jaws.set_object(None)
        self._resting = None

    def step(self, now_ns: int) -> None:
        """After the arm and the jaws moved: whether the jaws have the object, hold
        it (it moves with the tool: :attr:`position`) or let it fall."""
        jaws = self.jaws
        if self._grasp is not None:
            if jaws.squeeze > 0.0:
                return
            p = self.position  # let go: it falls onto the table below it
            assert p is not None
            self._grasp = None
            self._resting = np.array([p[0], p[1], self.rest_z])
            self._skip = 0
        p = self._resting
        if p is None:
            return
        if self._skip > 0:
            self._skip -= 1
            return
        tool = self.arm.truth().tool
        d = (p - tool[:3, 3]) * 1e3
        across, along = math.hypot(d[0], d[1]), abs(d[2])
        between = across <= CAPTURE_MM and along <= CAPTURE_Z_MM
        if between and jaws.object_mm is None:
            try:
                jaws.set_object(self.width_mm)
            except ValueError:  # the jaws are narrower than the object: not between them
                return
        elif not between:
            if jaws.object_mm is not None:
                jaws.set_object(None)
            if max(across, along) > FAR_MM:
                self._skip = FAR_SKIP_TICKS
            return
        if jaws.squeeze > 0.0:
            self._grasp = np.linalg.solve(tool, np.append(p, 1.0))

    def axis(self, i: int) -> float:
        """The object's true x, y or z (mm); nan with no object."""
        p = self.position
        return float(p[i]) * 1e3 if p is not None else math.nan


class CellObject(Component):
    """The object's truth (``sim.object.x`` ...: a part of ``sim``)."""

    name = "object"

    def __init__(self, world: CellWorld) -> None:
        self.world = world

    def signals(self) -> list[Signal]:
        w = self.world
        return [
            Signal("x", "mm", lambda: w.axis(0), "the object's true x", ".3f"),
            Signal("y", "mm", lambda: w.axis(1), "the object's true y", ".3f"),
            Signal("z", "mm", lambda: w.axis(2), "the object's true z", ".3f"),
            Signal("held", "bool", lambda: w.held, "the jaws hold the object", "d"),
        ]


class CellSim(Component):
    """The cell's simulated world as a component (``sim``; see the module text)."""

    name = "sim"

    def __init__(self, world: CellWorld, armsim: Component) -> None:
        self.world = world
        self.armsim = armsim
        self.object = CellObject(world)

    def children(self) -> list[Component]:
        return [self.object, self.armsim]

    def signals(self) -> list[Signal]:
        jaws = self.world.jaws
        return [
            Signal.attr("jaws", "counts", jaws, "x", "true jaw position"),
            Signal.attr("squeeze", "force", jaws, "squeeze", "squeeze on the object"),
        ]

    @command(name="show", reads_only=True)
    def show(self) -> str:
        """sim: the simulated world: the object, the jaws (the arm: armsim show)."""
        w = self.world
        if w.position is None:
            obj = "no object"
        else:
            x, y, z = (w.position * 1e3).tolist()
            obj = (f"object {w.width_mm:g} mm at ({x:.1f}, {y:.1f}, {z:.1f}) mm, "
                   + ("held by the jaws" if w.held else "not held"))
        return f"{obj}; {w.jaws.status()}"

    @command(Arg("X", finite("x", -2000.0, 2000.0), units="mm", optional=True),
             Arg("Y", finite("y", -2000.0, 2000.0), units="mm", optional=True),
             Arg("Z", finite("z", -2000.0, 2000.0), units="mm", optional=True),
             Arg("W", finite("width", 1.0, 70.0), units="mm", optional=True), name="object")
    def set_object(self, x: float | None = None, y: float | None = None,
                   z: float | None = None, width: float | None = None) -> str:
        """sim object X Y Z [W] | sim object: put an object W mm wide (default 30) on the
        table at X Y Z mm (its centre); alone: take it away."""
        w = self.world
        try:
            if x is None:
                w.remove()
                return "sim: no object"
            if y is None or z is None:
                raise CommandError("sim object X Y Z [W]: give all three of X Y Z (mm)")
            w.place(x, y, z, DEFAULT_WIDTH_MM if width is None else width)
        except ValueError as exc:
            raise CommandError(f"sim object: {exc}; nothing changed") from None
        return f"sim: an object {w.width_mm:g} mm wide at ({x:g}, {y:g}, {z:g}) mm"

    @command(Arg("NAME", str.lower, choices=("limit", "jam", "encoder", "none")), name="fault")
    def fault(self, what: str) -> str:
        """sim fault limit|jam|encoder|none: a fault of the jaws (none: clear them all).

        limit (sensor dead), jam (the motor), encoder (dead)."""
        try:
            if what == "none":
                self.world.jaws.clear_faults()
            else:
                self.world.jaws.inject(what)
        except ValueError as exc:
            raise CommandError(str(exc)) from None
        return f"sim: jaws fault {what}"
