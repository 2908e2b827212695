"""A robot's joints as viewers take them: ``sensor_msgs/JointState`` and its URDF.

A root component that declares :attr:`pyrt.Component.joint_states` (a
:class:`JointStates`: the URDF's joint names, the signal giving each one's
position, and optionally its velocity and effort, and the URDF text) is shown
moving by Foxglove's 3D panel: ``scope foxglove`` serves ``/joint_states`` and
``/robot_description`` live, and ``pyrt export`` writes ``/joint_states`` into
the MCAP file of a journal of that station.

The messages are JSON shaped as ROS 2's ``sensor_msgs/msg/JointState``
(``header.stamp`` with ``sec`` and ``nsec``, ``name``, ``position``,
``velocity``, ``effort``), in SI units as ROS has them: a signal in ``deg``
is sent in rad, ``deg/s`` in rad/s, ``mm`` and ``cm`` in m (:func:`si_factor`).
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass

__all__ = ["JOINT_STATE_SCHEMA", "JOINT_STATE_SCHEMA_NAME", "ROBOT_DESCRIPTION_SCHEMA",
           "JointStates", "joint_state_json", "si_factor"]

#: The schema name Foxglove's 3D panel recognises for joint states.
JOINT_STATE_SCHEMA_NAME = "sensor_msgs/msg/JointState"

_NUMBERS = {"type": "array", "items": {"type": ["number", "null"]}}

#: ``sensor_msgs/JointState`` as a JSON schema.
JOINT_STATE_SCHEMA: dict = {
    "title": JOINT_STATE_SCHEMA_NAME,
    "type": "object",
    "description": "joint positions (rad or m), velocities (rad/s or m/s), efforts "
                   "(N m or N), as ROS 2's sensor_msgs/msg/JointState",
    "properties": {
        "header": {"type": "object", "properties": {
            "stamp": {"type": "object", "properties": {
                "sec": {"type": "integer"}, "nsec": {"type": "integer"}}},
            "frame_id": {"type": "string"}}},
        "name": {"type": "array", "items": {"type": "string"}},
        "position": _NUMBERS,
        "velocity": _NUMBERS,
        "effort": _NUMBERS,
    },
    "required": ["header", "name", "position", "velocity", "effort"],
}

#: ``std_msgs/String`` (the URDF on ``/robot_description``) as a JSON schema.
ROBOT_DESCRIPTION_SCHEMA: dict = {
    "title": "std_msgs/msg/String", "type": "object",
    "properties": {"data": {"type": "string"}}, "required": ["data"],
}

#: Factor to SI of the units a joint signal may have.
_SI = {"rad": 1.0, "rad/s": 1.0, "m": 1.0, "m/s": 1.0, "n": 1.0, "nm": 1.0, "n m": 1.0,
       "n*m": 1.0, "n.m": 1.0, "": 1.0,
       "deg": math.pi / 180, "deg/s": math.pi / 180, "mm": 1e-3, "mm/s": 1e-3,
       "cm": 1e-2, "cm/s": 1e-2}


def si_factor(units: str) -> float:
    """What a value in ``units`` is multiplied by to be in SI (rad, m, N m ...);
    ValueError for units a joint state cannot carry."""
    try:
        return _SI[units.strip().lower()]
    except KeyError:
        raise ValueError(f"a joint signal in {units!r} cannot be sent as a joint state "
                         f"(units one of rad, deg, m, mm, cm and their rates, N, N m)") from None


@dataclass(frozen=True)
class JointStates:
    """A robot's joints for viewers: ``names`` as the URDF names the joints;
    ``position`` the signal of each (``OBJECT.SIGNAL``, or a signal of the root
    by its name alone); ``velocity`` and ``effort`` likewise, or empty; ``urdf``
    the robot's description (URDF text), or ""."""

    names: tuple[str, ...]
    position: tuple[str, ...]
    velocity: tuple[str, ...] = ()
    effort: tuple[str, ...] = ()
    urdf: str = ""

    def __post_init__(self) -> None:
        n = len(self.names)
        if not n or len(self.position) != n:
            raise ValueError(f"JointStates: one position signal per joint ({n} names, "
                             f"{len(self.position)} positions)")
        for what in ("velocity", "effort"):
            if getattr(self, what) and len(getattr(self, what)) != n:
                raise ValueError(f"JointStates: {what} names one signal per joint, or none")

    def signals(self) -> list[str]:
        """Every signal it reads: the positions, then velocities, then efforts."""
        return [*self.position, *self.velocity, *self.effort]

    def split(self, values: Sequence[float]) -> tuple[list, list, list]:
        """Values in the order of :meth:`signals` as (position, velocity, effort)."""
        n = len(self.names)
        pos = list(values[:n])
        rest = list(values[n:])
        vel = rest[:n] if self.velocity else []
        eff = rest[n if self.velocity else 0:] if self.effort else []
        return pos, vel, eff


def _num(v: float) -> float | None:
    return v if math.isfinite(v) else None


def joint_state_json(stamp_ns: int, names: Sequence[str], position: Sequence[float],
                     velocity: Sequence[float] = (), effort: Sequence[float] = ()) -> bytes:
    """One ``sensor_msgs/JointState`` message as JSON text (values already in SI)."""
    sec, nsec = divmod(int(stamp_ns), 1_000_000_000)
    return json.dumps({
        "header": {"stamp": {"sec": sec, "nsec": nsec}, "frame_id": ""},
        "name": list(names),
        "position": [_num(float(v)) for v in position],
        "velocity": [_num(float(v)) for v in velocity],
        "effort": [_num(float(v)) for v in effort],
    }, separators=(",", ":")).encode()
