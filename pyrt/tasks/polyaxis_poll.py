"""POLYAXIS (polyaxis-poll): the PolyAxis's co-ordinated control poll (000, section 5).

One run, in this order (the steps are the PolyAxis's, the sequence is here):

1. the time since the previous poll (``dt``; the poll period on the first);
2. ``measure()``: every loadcell and encoder read, the position found.  A
   position finder that fails (lengths that fix no position: a rope set to
   nonsense by hand, a broken encoder) keeps the last position and refuses
   moves; during a move it is a fault of the whole manipulator
   (``position_lost``), and the poll ends there;
   ``check_estimate()``: distErr beyond DIST_ERR_LIMIT, or rising while an
   encoder falls out of step with its motor, loses the estimate (a fault
   naming the axis; moves refused until it is re-established), moving or not;
3. ``step_motion(now_s)``: the motion executor starts the next queued
   motion record between moves and steps the running one, which sets the
   hare (a plug-in motion's hare is checked);
4. during a move, ``drive_motors(now_s, dt)``: error signals, one batched
   fuzzy call, every motor, the stop conditions;
5. the encoders of the ropes under PolyAxis control are polled (axis-poll
   skips those axes);
6. with ``debug`` on, a status line every second.

The routine reschedules itself with a period in queue checks; the time it
sees is the queue's tick time.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol, TextIO

from pyrt.errors import NativeError
from pyrt.tasks.axis_poll import POLYAXIS

__all__ = ["ADDRESS", "NAME", "PolledPolyAxis", "control_poll", "polyaxis_poll"]

#: The routine's address on the manipulator's ready queue, and its name there.
ADDRESS = 0x0100
NAME = "POLYAXIS"


class PolledPolyAxis(Protocol):
    """A PolyAxis as polyaxis-poll sees it."""

    axes: Sequence[Any]
    poll_s: float
    now_s: float
    dt: float
    polls: int
    last_poll_s: float | None
    position_error: str | None
    active: bool
    debug: bool
    debug_next: float
    stdout: TextIO | None

    def measure(self) -> None: ...

    def position_lost(self, cause: str) -> None: ...

    def check_estimate(self) -> None: ...

    def step_motion(self, now_s: float) -> None: ...

    def drive_motors(self, now_s: float, dt: float) -> None: ...

    def status_line(self) -> str: ...


def polyaxis_poll(pa: PolledPolyAxis, now_ns: int) -> None:
    """The routine: one control poll of ``pa`` at the tick time ``now_ns``."""
    control_poll(pa, now_ns * 1e-9)


def control_poll(pa: PolledPolyAxis, now_s: float) -> None:
    """One control poll of ``pa`` at ``now_s`` seconds (see the module text)."""
    pa.now_s = now_s
    last = pa.last_poll_s
    dt = pa.poll_s if last is None else max(0.0, now_s - last)
    pa.last_poll_s = now_s
    pa.polls += 1
    pa.dt = dt
    try:
        pa.measure()
    except NativeError as exc:
        pa.position_lost(f"position finder failed: {exc}")
        return
    pa.position_error = None
    pa.check_estimate()
    pa.step_motion(now_s)
    if pa.active:
        pa.drive_motors(now_s, dt)
    for a in pa.axes:
        if a.mode == POLYAXIS:
            a.encoder.poll(now_s)
    if pa.debug and now_s >= pa.debug_next and pa.stdout is not None:
        pa.debug_next = now_s + 1.0
        pa.stdout.write(pa.status_line() + "\n")
