"""The PolyAxis's status line and state log.

The status line says where the source is, how consistent the estimate is,
the residual net force, the tensions, the time and how the last move ended
(or that the position is unknown or not trusted); with ``debug`` on, the
PolyAxis says it once a second.  The state log, switched by the station's
``log`` command while running, takes one line at a time: ``TO``/``MOTION``
when a move starts, ``STOP`` when it ends, and every poll of a move ``P``
(position, distErr, hare, net force), ``S`` (per rope: length, tension,
errors, velocity, dv, desired tension, free) and ``R`` (per rope: the ten
fuzzy rules' outputs).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from pyrt.robots.polyaxis import PolyAxis

__all__ = ["PolyAxisStatus"]


class PolyAxisStatus:
    """The status line and the state log of one PolyAxis (see the module text)."""

    def __init__(self, pa: PolyAxis):
        self.pa = pa
        #: Where the state log goes (one line at a time), or None.
        self.log: Callable[[str], object] | None = None
        #: Say the status line once a second.
        self.debug = False
        self.debug_next = 0.0

    def line(self, text: str) -> None:
        """One line of the state log, if it is on."""
        if self.log is not None:
            self.log(text)

    def state(self, now_s: float, dvs: Sequence[float]) -> None:
        """The state of a poll of a move: the P, S and R lines."""
        log = self.log
        assert log is not None
        pa = self.pa
        mv = pa.mover
        x = pa.position
        h = mv.hare_position or x
        log(f"P {now_s:.3f} {x[0]:.4f} {x[1]:.4f} {x[2]:.4f} {pa.dist_err:.4f} "
            f"{h[0]:.4f} {h[1]:.4f} {h[2]:.4f} {pa.net_force_magnitude:.3f}")
        rules = pa.batch.rules
        lengths, tensions = pa.lengths, pa.tensions
        for i, a in enumerate(pa.axes):
            log(f"S {now_s:.3f} {i} {lengths[i]:.4f} {tensions[i]:.3f} "
                f"{mv.error_lengths[i]:.4f} {mv.error_tensions[i]:.3f} "
                f"{a.motor.velocity:.4f} {dvs[i]:.4f} {mv.desired_tensions[i]:.2f} "
                f"{mv.free[i]:.0f}")
            log(f"R {now_s:.3f} {i} " + " ".join(f"{v:.5f}" for v in rules[i].tolist()))

    def poll(self, now_s: float) -> None:
        """At the end of a control poll: the status line, if debugging and due."""
        if self.debug and now_s >= self.debug_next:
            self.debug_next = now_s + 1.0
            self.pa.say(self.status_line())

    def status_line(self) -> str:
        """Source position, distErr, residual net force, tensions and time."""
        pa = self.pa
        x = pa.position
        t = " ".join(f"{v:.1f}" for v in pa.tensions)
        last = pa.mover.last_stop
        state = "moving" if pa.active else (last.reason.value if last else "idle")
        if pa.position_error is not None:
            state += f"  POSITION UNKNOWN: {pa.position_error}"
        elif pa.estimate_lost is not None:
            state += "  POSITION NOT TRUSTED ('survey' or 'setpos X Y Z')"
        return (f"t={pa.now_s:9.2f} s  pos ({x[0]:8.2f} {x[1]:8.2f} {x[2]:8.2f}) cm  "
                f"distErr {pa.dist_err:.3f} cm  net {pa.net_force_magnitude:6.2f} N  "
                f"T [{t}] N  {state}")
