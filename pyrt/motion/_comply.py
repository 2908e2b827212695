"""The comply loop of the trajectory tick (a record's :class:`~pyrt.motion.Comply`).

:class:`ComplyLoop` is the evaluator's part that holds a force along the
tool frame's axes: each tick it turns the wrist's force into the tool frame
(the equation's TOOL), low-passes it, and moves an offset of the tool along
the complied axes by the admittance (gain x force error, within the
record's speed and travel); :meth:`ComplyLoop.apply` puts a planned T6's
tool there, the path's own motion along those axes left out.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

__all__ = ["COMPLY_FILTER", "ComplyLoop"]

Matrix = npt.NDArray[np.float64]
Vector = npt.NDArray[np.float64]

#: The low-pass on the wrist's force: the share of a new reading taken each
#: trajectory tick.
COMPLY_FILTER = 0.7


class ComplyLoop:
    """The running comply segment, the tool's offset from its path (tool frame,
    m) and the filtered force it exerts (tool frame, N)."""

    def __init__(self) -> None:
        self.seg: Any = None
        self.offset = np.zeros(3)
        self.force = np.zeros(3)
        self._path0: Vector | None = None

    def update(self, seg: Any, tool: Matrix, wrench: Any, dt: float) -> None:
        """One tick of the loop for segment ``seg`` (its record complies) with
        the equation's TOOL ``tool`` and the wrist's ``wrench`` (flange frame)."""
        c = seg.move.spec.comply
        felt = np.asarray(wrench, dtype=float)[:3]
        exerted = -(tool[:3, :3].T @ felt)  # the wrist feels the opposite, in the TOOL frame
        if seg is not self.seg:
            self.seg = seg
            self._path0 = None
            self.offset = np.zeros(3)
            self.force = exerted
        self.force = self.force + COMPLY_FILTER * (exerted - self.force)
        step = c.speed * dt
        for i, f in zip(c.index(), c.forces, strict=True):
            d = min(max(c.gain * (f - float(self.force[i])) * dt, -step), step)
            self.offset[i] = min(max(self.offset[i] + d, -c.travel), c.travel)

    def apply(self, t6: Matrix, tool: Matrix) -> Matrix:
        """``t6`` with the tool moved along the complied axes of its own frame: to
        where the segment's first sample had it along them (the path's motion
        there left out) and by the loop's offset."""
        world = t6 @ tool
        if self._path0 is None:
            self._path0 = world[:3, 3].copy()
        r = world[:3, :3]
        along = r.T @ (world[:3, 3] - self._path0)
        shift = np.zeros(3)
        for i in self.seg.move.spec.comply.index():
            shift[i] = self.offset[i] - along[i]
        out = world.copy()
        out[:3, 3] += r @ shift
        return out @ np.linalg.inv(tool)
