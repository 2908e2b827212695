"""The cell's ``pick X Y Z``: a sequence of both robots' moves that the loop runs.

``pick`` solves the arm's three poses at once, in the console's thread
against a copy of the arm's frames the loop takes, before anything moves (the
tool pointing down above the object, at it, and lifted: an unreachable one
refuses the pick, nothing moved); one mailbox call then starts the
sequence; the loop then runs it one step after another, each step started
when the one before has ended as it should:

1. **approach**: the arm to :data:`APPROACH_MM` above the object;
2. **open**: the jaws wide open (``P 0``);
3. **descend**: the arm to the object (the tool point at its centre);
4. **close**: the jaws close on it (``P`` towards closed): the move must
   end stopped short of closed with both inner-face proximity sensors on
   (the faces at the object); closed all the way means nothing was there,
   stopped with the sensors off that the jaws jammed or met something else;
5. **lift**: the arm :data:`LIFT_MM` up.

A fault of either robot, ``stop`` or a step that ends wrong ends the
sequence where it is (the cell's move-ended event says why); the arm then
holds where it stands.  Nothing here blocks: :meth:`PickSequence.step` is a
loop handler that looks once a tick.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from pyrt.boards.i8031 import PROX
from pyrt.component import Stale
from pyrt.errors import CommandError
from pyrt.kinematics import transform
from pyrt.station.gripper import AT_TARGET_COUNTS

if TYPE_CHECKING:
    from pyrt.station.cell import CellStation

__all__ = ["APPROACH_MM", "LIFT_MM", "TOOL_DOWN_DEG", "PickSequence"]

#: The approach and the retreat: this far above the object (mm).
APPROACH_MM = 100.0
#: The lift: this far above where the object was (mm).
LIFT_MM = 150.0
#: The tool's orientation for a pick (URDF rpy, degrees): pointing down.
TOOL_DOWN_DEG = (180.0, 0.0, 180.0)
#: The jaws' target for the close (an opening, mm): narrower than any object.
CLOSE_MM = 5.0

#: The inner-face proximity sensors in PROX (active low: left +Ya, right -Ya): both on
#: when the jaws' faces are at the object.
INNER_FACES = 0x11

_STEPS = ("approach", "open", "descend", "close", "lift")


@dataclass(frozen=True)
class PickSnapshot:
    """What solving a pick's poses needs of the arm: its COORD and TOOL (its own
    arrays, replaced, never changed in place) and where it is heading."""

    coord: np.ndarray
    tool: np.ndarray
    heading: np.ndarray


@dataclass(frozen=True)
class PickWork:
    """A pick solved in the caller's thread: the arm's three joint targets."""

    snapshot: PickSnapshot
    where: str
    targets: list[np.ndarray]


class PickSequence:
    """``pick``'s sequence of the cell ``cell`` (see the module text)."""

    def __init__(self, cell: CellStation) -> None:
        self.cell = cell
        self.running = False
        #: The step running (1 .. 5), or 0.
        self.step_index = 0
        #: How the last sequence ended ('' before any).
        self.last = ""
        self._targets: list[np.ndarray] = []
        self._where = ""

    # -- the command: checked and copied in the loop, solved in the caller's thread ------

    def _refusal(self) -> None:
        cell = self.cell
        for r in cell.robots:
            if r.fault is not None:
                raise CommandError(f"pick: refused: {r.name} is stopped by a fault "
                                   f"({r.fault.cause}); give 'ack {r.name}' first; nothing moved")
        if self.running or cell.busy():
            raise CommandError("pick: refused: a move runs; wait or stop first; nothing moved")

    def snapshot(self) -> PickSnapshot:
        """What solving the poses needs (the loop's side, bounded); refused with the
        reason if a robot is stopped by a fault or something moves."""
        self._refusal()
        arm = self.cell.arm
        return PickSnapshot(arm.coord_frame, arm.tool_frame, arm.heading())

    def prepare(self, snap: PickSnapshot, x: float, y: float, z: float) -> PickWork:
        """The three poses solved against ``snap`` (the caller's thread, the arm's
        preparation chain); CommandError with the reason if one is out of reach."""
        arm = self.cell.arm
        lock, chain = arm.planning()
        targets = []
        with lock:
            for what, dz in (("approach", APPROACH_MM), ("descend", 0.0), ("lift", LIFT_MM)):
                pose = transform(np.array([x, y, z + dz]) * 1e-3, np.radians(TOOL_DOWN_DEG))
                try:
                    q = arm.solve(snap.coord @ pose @ np.linalg.inv(snap.tool), None,
                                  snap.heading, chain)
                except CommandError as exc:
                    raise CommandError(f"pick: refused: the {what} pose ({x:g}, {y:g}, "
                                       f"{z + dz:g}) mm: {exc}") from None
                why = chain.limit_violation(q)
                if why:
                    raise CommandError(f"pick: refused: the {what} pose is beyond a joint "
                                       f"limit ({why}); nothing moved")
                targets.append(q)
        return PickWork(snap, f"({x:g}, {y:g}, {z:g}) mm", targets)

    def begin(self, work: PickWork) -> str:
        """Start the prepared pick (the loop's side): refused as :meth:`snapshot` is;
        :class:`~pyrt.component.Stale` if the arm's frames changed since."""
        self._refusal()
        arm = self.cell.arm
        if arm.coord_frame is not work.snapshot.coord or arm.tool_frame is not work.snapshot.tool:
            raise Stale("pick: the arm's frames changed while the poses were solved")
        self._targets = work.targets
        self._where = work.where
        self.running = True
        self.last = ""
        self._begin(1)
        return f"pick at {self._where}: approach, open, descend, close, lift"

    def start(self, x: float, y: float, z: float) -> str:
        """Solve and start a pick of the object at (x, y, z) mm in the calling thread;
        CommandError with the reason, nothing moved, if a robot is stopped by a
        fault, something moves, or a pose is out of reach."""
        return self.begin(self.prepare(self.snapshot(), x, y, z))

    # -- the loop -----------------------------------------------------------------------

    def _begin(self, index: int) -> None:
        self.step_index = index
        cell, arm = self.cell, self.cell.arm
        step = _STEPS[index - 1]
        if step in ("approach", "descend", "lift"):
            q = self._targets[{"approach": 0, "descend": 1, "lift": 2}[step]]
            arm.move_joints(*(q * arm.scales))
        elif step == "open":
            cell.controller.cmd_position("0")
        else:
            cell.controller.cmd_position(f"{CLOSE_MM:g}mm")

    def step(self, now_ns: int) -> None:
        """Loop handler ``sequence``: the running step ended? then check it and start
        the next (one look a tick)."""
        if not self.running:
            return
        cell = self.cell
        robot = cell.gripper if _STEPS[self.step_index - 1] in ("open", "close") else cell.puma
        if robot.busy() or robot.moving:  # its end is published first (the move watch)
            return
        bad = self._failed()
        if bad is not None:
            self._end(f"pick stopped at {_STEPS[self.step_index - 1]}: {bad}")
            return
        try:
            if self.step_index == len(_STEPS):
                self._end(f"picked: the object lifted from {self._where}")
                return
            self._begin(self.step_index + 1)
        except CommandError as exc:
            self._end(f"pick stopped before {_STEPS[self.step_index]}: {exc}")

    def _failed(self) -> str | None:
        """Why the step that has ended did not do what it should, or None."""
        cell = self.cell
        step = _STEPS[self.step_index - 1]
        if step in ("approach", "descend", "lift"):
            stop = cell.arm.last_stop
            return None if stop in ("", "at target") else f"the arm's move: {stop}"
        err = cell.jaw_error()
        if step == "open":
            return (None if abs(err) <= AT_TARGET_COUNTS
                    else f"the jaws did not open ({err:+d} counts from the target)")
        if abs(err) <= AT_TARGET_COUNTS:
            return "the jaws closed on nothing: no object between them"
        if cell.controller.ram[PROX] & INNER_FACES:
            return ("the jaws stopped short of the object (the inner-face proximity sensors "
                    "are off): jammed or blocked")
        return None

    def abort(self, why: str) -> None:
        """End the sequence now (a fault, ``stop``): no further step starts; the arm
        is braked to rest and holds (a move of its under way ends)."""
        if not self.running:
            return
        step = _STEPS[self.step_index - 1]
        if self.cell.puma.fault is None:
            self.cell.arm.stop()
        self._end(f"pick stopped at {step}: {why}")

    def _end(self, why: str) -> None:
        self.running = False
        self.step_index = 0
        self.last = why
        self.cell.end_move(why, [why])
