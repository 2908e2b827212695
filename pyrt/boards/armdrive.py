"""A serial arm's motion-control board (004's hardware (a)), declared register by register.

One board serves every joint of one arm as a drive in cyclic synchronous
position mode with interpolation does: the controller writes a position
setpoint per joint at the trajectory rate (100 Hz) and strobes ``sync``;
the board interpolates between setpoints in joint space and closes the
servo loop itself at its own rate (1 kHz; the law and the interpolation are
csrc/drive.h's), watches each joint's following error against its limit,
and reports a status word.  Per joint ``j`` of ``n``:

==============  ======  ====================  ================================================
register        dir     width                 meaning
==============  ======  ====================  ================================================
``setpoint[j]`` output  32-bit signed, off 0  position setpoint, encoder counts (the middle
                                              of count s), wrapping as the counter does
``velocity[j]`` output  32-bit signed, off 0  velocity at the setpoint, counts/s
``torque[j]``   output  16-bit signed, off 0  torque offset (the dynamics feed-forward),
                                              DAC counts: +-:data:`DAC_FULL_SCALE` is full
                                              scale
``felim[j]``    output  32-bit signed, off 0  following-error limit, counts (> 0 to enable)
``enable``      output  1 bit, off 0          the power stage (0: every amplifier off; a
                                              fault is cleared by writing 0)
``sync``        output  16-bit, off 0         the setpoint strobe: written after the
                                              setpoints, the board takes them when it changes
``period_us``   output  32-bit, off 0         the interpolation period, microseconds
``count[j]``    input   32-bit signed         the encoder's counter; it wraps at 32 bits
``status``      input   16-bit                :data:`ENABLED` :data:`FAULT` :data:`LATE`
                                              :data:`REFUSED`; bits 8..15 the joint (1-based)
                                              whose following error tripped the board
``ferr[j]``     input   32-bit signed         following error, counts (reference - measured)
``ft[k]``       input   32-bit signed         the wrist sensor, k = fx fy fz tx ty tz
                                              (:data:`FT_CHANNELS`), counts
==============  ======  ====================  ================================================

A following error beyond its limit switches every amplifier of the board
off in the board's tick it is seen in (the board's own reflex) and sets
FAULT until the controller writes enable 0.  ``off`` (the watchdog of
``pyrt board-sim``, a lost link) is enable 0: the power stage off.
"""

from __future__ import annotations

from pyrt.boards.armservo import DAC_FULL_SCALE, FT_CHANNELS, MAX_JOINTS
from pyrt.boards.registers import OUTPUT, BoardKind, Register

__all__ = [
    "DAC_FULL_SCALE",
    "ENABLED",
    "FAULT",
    "FT_CHANNELS",
    "JOINT_SHIFT",
    "LATE",
    "REFUSED",
    "arm_drive_kind",
]

#: The status word's bits: the power stage is on (the board servos the arm) ...
ENABLED = 0x0001
#: ... a following error tripped it (off until enable is written 0) ...
FAULT = 0x0002
#: ... no new setpoint came within the interpolation period (the last one held) ...
LATE = 0x0004
#: ... enable refused: a following-error limit or the period is not > 0.
REFUSED = 0x0008
#: The tripped joint (1-based; 0: none) is ``status >> JOINT_SHIFT``.
JOINT_SHIFT = 8


def arm_drive_kind(n: int) -> BoardKind:
    """The motion-control board of an ``n``-joint arm (see the module text);
    ValueError for a joint count outside 1 .. :data:`MAX_JOINTS`."""
    if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= MAX_JOINTS:
        raise ValueError(f"an arm drive board serves 1 to {MAX_JOINTS} joints, got {n!r}")
    return BoardKind("arm-drive", (
        Register("setpoint", count=n, width=32, signed=True, direction=OUTPUT, off=0,
                 units="counts", doc="position setpoint, per joint (the middle of the count)"),
        Register("velocity", count=n, width=32, signed=True, direction=OUTPUT, off=0,
                 units="counts/s", doc="velocity at the setpoint, per joint"),
        Register("torque", count=n, width=16, signed=True, direction=OUTPUT, off=0,
                 units="DAC counts",
                 doc=f"torque offset, per joint: +-{DAC_FULL_SCALE} is full scale"),
        Register("felim", count=n, width=32, signed=True, direction=OUTPUT, off=0,
                 units="counts", doc="following-error limit, per joint (> 0 to enable)"),
        Register("enable", width=1, direction=OUTPUT, off=0,
                 doc="the power stage; writing 0 clears a fault"),
        Register("sync", width=16, direction=OUTPUT, off=0,
                 doc="setpoint strobe: the setpoints are taken when it changes"),
        Register("period_us", width=32, direction=OUTPUT, off=0, units="us",
                 doc="interpolation period"),
        Register("count", count=n, width=32, signed=True, units="counts",
                 doc="incremental encoder counter, per joint (wraps at 32 bits)"),
        Register("status", width=16,
                 doc="1 enabled, 2 fault, 4 late, 8 refused; bits 8..15 the tripped joint"),
        Register("ferr", count=n, width=32, signed=True, units="counts",
                 doc="following error, per joint"),
        Register("ft", count=len(FT_CHANNELS), width=32, signed=True, units="counts",
                 doc="wrist force/torque fx fy fz tx ty tz, sensor frame"),
    ), doc=f"{n}-joint motion-control board: setpoints at the trajectory rate, "
           "interpolation and servo on the board, encoders, wrist F/T")
