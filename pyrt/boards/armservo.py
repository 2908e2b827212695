"""A serial arm's passive servo board (004's hardware (b)), declared register by register.

One board serves every joint of one arm: the controller writes a motor
current per joint at the servo rate and reads back each joint's incremental
encoder and the wrist force/torque sensor.  The board closes no loop of its
own (a passive board: the servo is the controller's).  Per joint ``j`` of
``n``:

===============  ======  ====================  ==============================================
register         dir     width                 meaning
===============  ======  ====================  ==============================================
``dac[j]``       output  16-bit signed, off 0  the amplifier's current command, DAC counts:
                                               +-:data:`DAC_FULL_SCALE` is full-scale current
``enable[j]``    output  1 bit, off 0          the amplifier's enable (0: no current)
``release[j]``   output  1 bit, off 0          the joint's brake released (0: the brake
                                               holds the joint; fail-safe)
``count[j]``     input   32-bit signed         the encoder's counter; it wraps at 32 bits
``ft[k]``        input   32-bit signed         the wrist sensor, k = fx fy fz tx ty tz
                                               (:data:`FT_CHANNELS`), counts
===============  ======  ====================  ==============================================

``off`` is what the board's watchdog (``pyrt board-sim``) and a lost link
leave an output at: no current, amplifiers disabled, brakes engaged.  The
number of joints is part of the kind: an arm of six joints and one of seven have boards of
different fingerprints, and a controller refuses a board that is not its own.
"""

from __future__ import annotations

from pyrt.boards.registers import OUTPUT, BoardKind, Register

__all__ = ["DAC_FULL_SCALE", "FT_CHANNELS", "MAX_JOINTS", "arm_servo_kind"]

#: DAC counts of full-scale current (the 16-bit DAC's largest value).
DAC_FULL_SCALE = 32767
#: The wrist sensor's channels, in register order.
FT_CHANNELS = ("fx", "fy", "fz", "tx", "ty", "tz")
#: The most joints one board serves.
MAX_JOINTS = 32


def arm_servo_kind(n: int) -> BoardKind:
    """The passive servo board of an ``n``-joint arm (see the module text);
    ValueError for a joint count outside 1 .. :data:`MAX_JOINTS`."""
    if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= MAX_JOINTS:
        raise ValueError(f"an arm servo board serves 1 to {MAX_JOINTS} joints, got {n!r}")
    return BoardKind("arm-servo", (
        Register("dac", count=n, width=16, signed=True, direction=OUTPUT, off=0,
                 units="DAC counts",
                 doc=f"motor current command, per joint: +-{DAC_FULL_SCALE} is full scale"),
        Register("enable", count=n, width=1, direction=OUTPUT, off=0,
                 doc="amplifier enable, per joint"),
        Register("release", count=n, width=1, direction=OUTPUT, off=0,
                 doc="brake release, per joint (0: the brake holds the joint)"),
        Register("count", count=n, width=32, signed=True, units="counts",
                 doc="incremental encoder counter, per joint (wraps at 32 bits)"),
        Register("ft", count=len(FT_CHANNELS), width=32, signed=True, units="counts",
                 doc="wrist force/torque fx fy fz tx ty tz, sensor frame"),
    ), doc=f"{n}-joint passive servo board: DACs, amplifier enables, brake releases, "
           "encoders, wrist F/T")
