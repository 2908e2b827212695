"""The manipulator's self-scheduling tasks: polyaxis-poll and axis-poll.

* ``POLYAXIS`` (polyaxis-poll): :meth:`pyrt.robots.polyaxis.PolyAxis.poll`,
  the whole co-ordinated control poll (sensors, position finder; the
  PolyAxis's motion executor starting the next queued motion record between
  moves and stepping the running motion, which sets the hare; error
  signals, one batched fuzzy call, the motors of every axis under PolyAxis
  control, the stop conditions).  An exception in a motion is a fault of
  the manipulator (the executor hands it to the PolyAxis, which trips the
  ready queue: the reflex stops every motor and drops the queue);
* ``AXES`` (axis-poll): :meth:`pyrt.robots.axis.Axis.poll` for every axis
  under standalone control (STEP_MODE moves of ``axis1 up 5`` and the like,
  encoder read loops).

Both reschedule themselves with a period in queue checks; the time they
see is the queue's tick time.
"""

from __future__ import annotations

from pyrt.robots.axis import POLYAXIS
from pyrt.robots.polyaxis import PolyAxis
from pyrt.scheduler import ReadyQueue, Routine

__all__ = ["AXES_ADDRESS", "POLYAXIS_ADDRESS", "attach_manipulator"]

#: Routine addresses on the manipulator's ready queue.
POLYAXIS_ADDRESS = 0x0100
AXES_ADDRESS = 0x0101


def attach_manipulator(queue: ReadyQueue, polyaxis: PolyAxis, *, poll_checks: int,
                       axis_poll_checks: int) -> tuple[Routine, Routine]:
    """Register and schedule the two routines; periods in queue checks (1..255)."""
    for label, n in (("poll_checks", poll_checks), ("axis_poll_checks", axis_poll_checks)):
        if not 1 <= n <= 255:
            raise ValueError(f"{label} must be 1..255 queue checks, got {n}")
    axes = polyaxis.axes

    def polyaxis_poll() -> None:
        polyaxis.poll(queue.now_ns * 1e-9)

    def axis_poll() -> None:
        now_s = queue.now_ns * 1e-9
        for a in axes:
            if a.mode != POLYAXIS:
                a.poll(now_s)

    r1 = queue.add_periodic(POLYAXIS_ADDRESS, "POLYAXIS", polyaxis_poll, poll_checks)
    r2 = queue.add_periodic(AXES_ADDRESS, "AXES", axis_poll, axis_poll_checks)
    queue.schedule(POLYAXIS_ADDRESS, poll_checks)
    queue.schedule(AXES_ADDRESS, axis_poll_checks)
    return r1, r2
