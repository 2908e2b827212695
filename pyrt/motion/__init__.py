"""Arm motion for any kinematic chain: 001's motion records, joint and
Cartesian segments joined by Paul's transitions, moving frames, PLCopen's
buffer modes, stopping along the path, and the trajectory tick's evaluator.

Planning happens when a record is queued (:meth:`Evaluator.queue`, in the
caller's thread); the trajectory task calls :meth:`Evaluator.tick` once per
period and gets a :class:`Knot` (joint position, velocity, acceleration, T6,
progress, events).  Metres, radians, seconds.  ``docs/arm-motion.md`` is the
user's page.
"""

from pyrt.motion.evaluator import Evaluator, Knot, MotionFault
from pyrt.motion.planner import Limits, Planner, Segment
from pyrt.motion.record import (
    BufferMode,
    Comply,
    Mode,
    MotionSpec,
    Move,
    RecordError,
    Termination,
)

__all__ = [
    "BufferMode",
    "Comply",
    "Evaluator",
    "Knot",
    "Limits",
    "Mode",
    "MotionFault",
    "MotionSpec",
    "Move",
    "Planner",
    "RecordError",
    "Segment",
    "Termination",
]
