"""The simulated arm behind ``pyrt urdf``'s board, and its component ``sim``.

:class:`UrdfPhysics` is the plant of the station's :class:`pyrt.World`: it
advances :class:`pyrt.sim.arm.ArmWorld` (the chain's forward dynamics with
gravity, the URDF's damping and friction, the motors' torque limits, end
stops, the table and the wrist sensor) by ``dt = now - last`` and answers
board-sim's ``INFO``.  :class:`UrdfSim` is the world as the operator sees it
in process: its truth (``sim show``, the signals ``sim.x`` ...) and the table
(``sim table Z``); never read by the controller.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from pyrt.component import Arg, Component, Signal, command
from pyrt.errors import CommandError, ConfigError
from pyrt.kinematics import rpy_of
from pyrt.sim.arm import ArmWorld

__all__ = ["UrdfPhysics", "UrdfSim"]


class UrdfPhysics:
    """The plant of the ``urdf`` world: ``step(now_ns)`` advances ``arm`` by the
    time since the last step (none on the first)."""

    def __init__(self, arm: ArmWorld) -> None:
        self.arm = arm
        #: What a station attaches as its world's step (the arm's own, one call less).
        self.step_to = arm.advance_to

    def step(self, now_ns: int) -> None:
        """Advance the arm to ``now_ns`` (dt = now - last; :meth:`ArmWorld.advance_to`)."""
        self.arm.advance_to(now_ns)

    def info(self) -> dict[str, object]:
        """The world's truth for board-sim's INFO (``sim show`` over tcp)."""
        return self.arm.info()


class UrdfSim(Component):
    """The simulated arm in this process: its truth and its table (``sim``)."""

    name = "sim"

    def __init__(self, arm: ArmWorld) -> None:
        self.arm = arm
        chain = arm.chain
        self._scales = [1e3 if j.kind == "prismatic" else 180.0 / math.pi for j in chain.joints]
        self._units = ["mm" if j.kind == "prismatic" else "deg" for j in chain.joints]

    def signals(self) -> list[Signal]:
        chain = self.arm.chain
        out = [Signal(f"q{i + 1}", u, self._reader(i), f"true joint {j.name}", ".4f")
               for i, (j, u) in enumerate(zip(chain.joints, self._units, strict=True))]
        out += [Signal(axis, "mm", self._reader(-1 - c), f"true tool {axis}", ".3f")
                for c, axis in enumerate("xyz")]
        out += [Signal(axis, "deg", self._reader(-4 - c),
                       f"true tool rotation about the base's {axis[1]}", ".3f")
                for c, axis in enumerate(("rx", "ry", "rz"))]
        out.append(Signal("fz", "N", lambda: float(self.arm.truth().contact[2]),
                          "the table's force on the tool (world z)", ".3f"))
        return out

    def _reader(self, i: int) -> Callable[[], float]:
        """Joint i (i >= 0, operator units); tool x y z (mm) for -1 -2 -3, rx ry rz (deg)
        for -4 -5 -6."""
        arm = self.arm
        if i >= 0:
            k = self._scales[i]
            return lambda: float(arm.truth().q[i]) * k
        c = -1 - i
        if c < 3:
            return lambda: float(arm.truth().tool[c, 3]) * 1e3
        return lambda: math.degrees(rpy_of(arm.truth().tool)[c - 3])

    @command(name="show", reads_only=True)
    def show(self) -> str:
        """sim show: the simulated arm's truth (joints, speeds, tool pose, table, contact)."""
        t = self.arm.truth()
        q = " ".join(f"{float(v) * k:.4f}" for v, k in zip(t.q, self._scales, strict=True))
        qd = " ".join(f"{float(v) * k:.3f}" for v, k in zip(t.qd, self._scales, strict=True))
        x, y, z = (t.tool[:3, 3] * 1e3).tolist()
        rx, ry, rz = (math.degrees(a) for a in rpy_of(t.tool))
        table = ("none" if self.arm.table_z is None
                 else f"{self.arm.table_z * 1e3:.1f} mm, contact {float(t.contact[2]):.2f} N")
        return (f"true joints {q}; speeds {qd}; tool ({x:.3f}, {y:.3f}, {z:.3f}) mm, "
                f"rpy ({rx:.4f}, {ry:.4f}, {rz:.4f}) deg; table {table}")

    @command(Arg("Z", str), name="table")
    def table(self, z: str) -> str:
        """sim table Z|off: the table's plane at height Z mm (world frame), or none."""
        if z.strip().lower() == "off":
            self.arm.set_table(None)
            return "sim: no table"
        try:
            v = float(z)
        except ValueError:
            raise CommandError(f"sim table: expected a height in mm or off, got {z[:40]!r}"
                               ) from None
        if not (math.isfinite(v) and abs(v) <= 1e4):
            raise CommandError(f"sim table: the height must be within +-10000 mm, got {z[:40]!r}")
        try:
            self.arm.set_table(v * 1e-3)
        except ConfigError as exc:
            raise CommandError(f"sim table: {exc}") from None
        return f"sim: the table at {v:g} mm"

    def truth_tool(self) -> np.ndarray:
        """The true tool pose (4, 4; m): for tests."""
        return self.arm.truth().tool
