"""The arm's servo board, declared register by register, and the world behind it.

The control code talks to the arm only through the registers of one board of
kind :data:`SERVO` (board name ``servo``), per joint ``j`` (0: shoulder q0,
1: elbow q1):

=============  ======  ==========================  =========================================
register       dir     width                       meaning
=============  ======  ==========================  =========================================
``count[j]``   input   32-bit signed               the incremental encoder's counter
``amp_ok[j]``  input   1 bit                       the amplifier's status: 1 while it is
                                                   enabled and its motor has power
``drive[j]``   output  16-bit signed, off 0        the amplifier's command, DAC counts:
                                                   +-:data:`DRIVE_FULL_SCALE` is full scale
``enable[j]``  output  1 bit, off 0                the amplifier's enable
=============  ======  ==========================  =========================================

``off`` is what the board's watchdog (``pyrt board-sim``) and a lost link leave
an output at: no drive, amplifiers disabled.

The world behind the board is :class:`ArmPhysics`: each ``step(now_ns)``
advances the simulated arm (:class:`pyrt_arm.plant.Plant`: pyrt's rigid-body
world of the arm's URDF, its step one call of C) by ``dt = now - last``; the
arm reads the outputs and sets the inputs (a register only when it changes)
within that call.  The world integrates in internal steps of one servo period
(:data:`WORLD_STEP_S`, 1 ms): under the servo the true joints stay within one
encoder count of where 0.2 ms steps put them (a test compares the two).
:func:`arm_world` makes the :class:`pyrt.World` of it, for ``sim:`` boards in
process and for ``pyrt board-sim arm`` alike; :class:`ArmSim` is the
component ``sim`` that shows its truth and injects its faults.
"""

from __future__ import annotations

from collections.abc import Sequence

from pyrt import (
    OUTPUT,
    Arg,
    BoardKind,
    Boards,
    CommandError,
    Component,
    Register,
    Signal,
    World,
    command,
)

from pyrt_arm.plant import JOINTS, MAX_STEP_S, Plant

__all__ = [
    "ARM_BOARDS",
    "DEFAULT_START_DEG",
    "DRIVE_FULL_SCALE",
    "SERVO",
    "WORLD_STEP_S",
    "ArmPhysics",
    "ArmSim",
    "arm_world",
    "drive_counts",
]

#: DAC counts of a full-scale drive (the 16-bit DAC's largest value).
DRIVE_FULL_SCALE = 32767

#: The arm's servo board (see the module text).
SERVO = BoardKind("arm-servo", (
    Register("count", count=2, width=32, signed=True, units="counts",
             doc="incremental encoder counter, per joint"),
    Register("amp_ok", count=2, width=1,
             doc="amplifier status, per joint: 1 while enabled and powered"),
    Register("drive", count=2, width=16, signed=True, direction=OUTPUT, off=0,
             units="DAC counts", doc="amplifier command, per joint (+-32767 full scale)"),
    Register("enable", count=2, width=1, direction=OUTPUT, off=0,
             doc="amplifier enable, per joint"),
), doc="two-joint DC servo board: encoder counters, DACs, amplifier enables")

#: The arm station's boards: name -> kind.
ARM_BOARDS: dict[str, BoardKind] = {"servo": SERVO}

#: The world's longest internal integration step (s): one servo period (see the module text).
WORLD_STEP_S = MAX_STEP_S

#: Where the simulated arm starts (deg): the elbow bent a right angle.
DEFAULT_START_DEG = (0.0, 90.0)


def drive_counts(drive: float) -> int:
    """A drive of -1 .. 1 of full scale (clamped) as DAC counts."""
    d = max(-1.0, min(1.0, drive))
    return round(d * DRIVE_FULL_SCALE)


class ArmPhysics:
    """The simulated arm behind its servo board (a :class:`pyrt.World`'s plant):
    ``step(now_ns)`` advances :attr:`plant` by the time since the last step (none
    on the first); the plant reads the board's outputs and sets its inputs."""

    def __init__(self, plant: Plant) -> None:
        self.plant = plant
        self.board = plant.board
        #: ``step`` itself, bound once (the world's :meth:`~pyrt.sim.arm.ArmWorld.advance_to`):
        #: what the station's read phase calls every tick.
        self.stepper = plant.world.advance_to

    def step(self, now_ns: int) -> None:
        """Advance the arm to ``now_ns`` (dt = now - last; nothing on the first call or
        for a time not later than the last)."""
        self.stepper(now_ns)

    def info(self) -> dict[str, object]:
        """The world's truth for ``sim show`` over tcp (board-sim's INFO)."""
        p = self.plant
        (q0, q1), (x, y) = p.q_deg, p.tip_mm
        v0, v1 = p.qd_deg_s
        return {"q0": f"{q0:.4f}", "q1": f"{q1:.4f}", "qd0": f"{v0:.3f}", "qd1": f"{v1:.3f}",
                "x": f"{x:.3f}", "y": f"{y:.3f}",
                "faults": ",".join(f.replace(" ", "_") for f in p.active_faults()) or "none"}


def arm_world(boards: Boards, start_deg: Sequence[float] = DEFAULT_START_DEG,
              name: str = "arm", max_step_s: float = WORLD_STEP_S) -> World:
    """The arm's world: the simulated arm at ``start_deg`` behind ``boards``
    (in process, declared as :data:`ARM_BOARDS`), integrating in internal steps of
    at most ``max_step_s``.  ValueError for a start beyond the end stops."""
    plant = Plant(boards["servo"], q_deg=(float(start_deg[0]), float(start_deg[1])),
                  max_step_s=max_step_s)
    return World(name, boards, ArmPhysics(plant))


class ArmSim(Component):
    """The simulated arm in this process: its truth and its faults (``sim``)."""

    name = "sim"

    def __init__(self, plant: Plant) -> None:
        self.plant = plant

    def signals(self) -> list[Signal]:
        p = self.plant
        return [
            Signal("q0", "deg", lambda: p.q_deg[0], "true shoulder angle", ".4f"),
            Signal("q1", "deg", lambda: p.q_deg[1], "true elbow angle", ".4f"),
            Signal("qd0", "deg/s", lambda: p.qd_deg_s[0], "true shoulder speed", ".3f"),
            Signal("qd1", "deg/s", lambda: p.qd_deg_s[1], "true elbow speed", ".3f"),
            Signal("x", "mm", lambda: p.tip_mm[0], "true tip x", ".3f"),
            Signal("y", "mm", lambda: p.tip_mm[1], "true tip y", ".3f"),
        ]

    @command(name="show", reads_only=True)
    def show(self) -> str:
        """sim show: the simulated arm's truth (true joints, speeds and tip, faults)."""
        p = self.plant
        (q0, q1), (v0, v1), (x, y) = p.q_deg, p.qd_deg_s, p.tip_mm
        faults = ", ".join(p.active_faults()) or "none"
        return (f"true q0 {q0:.4f} deg, q1 {q1:.4f} deg; speed {v0:.3f}, {v1:.3f} deg/s; "
                f"tip ({x:.3f}, {y:.3f}) mm; faults: {faults}")

    @command(Arg("KIND", str.lower, choices=("jam", "encoder", "motor", "none")),
             Arg("JOINT", str.lower, optional=True, choices=JOINTS), name="fault")
    def fault(self, kind: str, joint: str | None = None) -> str:
        """sim fault jam|encoder|motor q0|q1, or sim fault none: inject a fault.

        jam (the joint is braked where it is), encoder (its counter freezes),
        motor (its power is cut); none clears them all."""
        p = self.plant
        if kind == "none":
            if joint is not None:
                raise CommandError("sim fault none takes no joint")
            p.clear_faults()
            return "sim: every fault cleared"
        if joint is None:
            raise CommandError(f"sim fault {kind}: which joint? q0 or q1")
        j = JOINTS.index(joint)
        {"jam": p.jam, "encoder": p.disconnect_encoder, "motor": p.motor_off}[kind](j)
        return f"sim: {', '.join(p.active_faults())}"
