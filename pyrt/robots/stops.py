"""When a PolyAxis move ends: the five stop conditions of 000, section 5.

* ``ENDPOINT_STOP``: the source is within the lesser of END_ERROR and
  distErr (the RMS length residual) of the endpoint, but the condition is
  never tighter than FIND_TOLERANCE (0.1 cm); and (beyond 000) distErr
  itself is within END_ERROR, the station's endpoint tolerance, so that an
  estimate whose rope lengths disagree never claims the endpoint.  The
  limit the message prints is END_ERROR;
* ``STUCK_STOP``: the source is more than half way to the endpoint and has
  not got any closer for STUCK_TIME (10 s);
* ``NET_FORCE_STOP``: the residual net force on the source exceeds
  NET_FORCELIMIT;
* ``LOW_TENSION_STOP``: a tension is below LOW_TENSION on an Axis;
* ``HIGH_TENSION_STOP``: a tension is above MAX_TENSION on an Axis.

The two tension stops can be switched off (``tensionStop`` toggles them;
every ``to`` switches them on again).  The safety stops (tension and net
force) are checked first: a move that ends at its endpoint with a rope out
of bounds is a tension stop.  ``STOP`` is the operator's ``stop`` command,
``DONE`` a motion type that ended by itself (its reason in the detail) and
``FAULT`` anything else that stopped the manipulator.

Every motion is checked, built-in or plug-in: a motion without an endpoint
(``endpoint=None``: a plug-in that ends by itself) has no ENDPOINT_STOP or
STUCK_STOP, but the three safety stops always apply.

"Closer" for STUCK_STOP means closer by more than :data:`STUCK_PROGRESS`
(the position finder's resolution is far coarser than floating point).
"""

from __future__ import annotations

import enum
import math
from collections.abc import Sequence
from dataclasses import dataclass

__all__ = [
    "SAFETY_STOPS",
    "STUCK_PROGRESS",
    "StopCheck",
    "StopReason",
    "StopRecord",
]

#: Progress (cm) that counts as "getting closer" for STUCK_STOP.
STUCK_PROGRESS = 0.01


class StopReason(enum.Enum):
    """Why a move ended."""

    ENDPOINT_STOP = "ENDPOINT_STOP"
    STUCK_STOP = "STUCK_STOP"
    NET_FORCE_STOP = "NET_FORCE_STOP"
    LOW_TENSION_STOP = "LOW_TENSION_STOP"
    HIGH_TENSION_STOP = "HIGH_TENSION_STOP"
    STOP = "STOP"
    DONE = "DONE"
    FAULT = "FAULT"


#: Stops that are faults of the manipulator (reflex, then acknowledge).
SAFETY_STOPS = frozenset({StopReason.NET_FORCE_STOP, StopReason.LOW_TENSION_STOP,
                          StopReason.HIGH_TENSION_STOP})


@dataclass(frozen=True)
class StopRecord:
    """One stop: why, where the source was, at what time, and the detail."""

    reason: StopReason
    detail: str
    position: tuple[float, float, float]
    time_s: float
    endpoint: tuple[float, float, float] | None = None

    def __str__(self) -> str:
        x, y, z = self.position
        return (f"{self.reason.value}: {self.detail}; source at ({x:.2f}, {y:.2f}, {z:.2f}) "
                f"at t={self.time_s:.2f} s")


class StopCheck:
    """The five conditions for one move (see the module text)."""

    def __init__(self, start: Sequence[float], endpoint: Sequence[float] | None, *,
                 end_error: float,
                 find_tolerance: float, stuck_time: float, low_tension: float,
                 max_tension: float, net_force_limit: float, tension_stops: bool = True):
        self.start = tuple(float(c) for c in start)
        self.endpoint = None if endpoint is None else tuple(float(c) for c in endpoint)
        self.end_error = end_error
        self.find_tolerance = find_tolerance
        self.stuck_time = stuck_time
        self.low_tension = low_tension
        self.max_tension = max_tension
        self.net_force_limit = net_force_limit
        self.tension_stops = tension_stops
        self.total = math.inf if self.endpoint is None else _dist(self.start, self.endpoint)
        self.best = math.inf
        self.best_time: float | None = None

    def endpoint_radius(self, dist_err: float) -> float:
        """Lesser of END_ERROR and distErr, never under FIND_TOLERANCE."""
        return max(self.find_tolerance, min(self.end_error, dist_err))

    def check(self, now_s: float, position: Sequence[float], dist_err: float,
              tensions: Sequence[float], net_force: float,
              names: Sequence[str]) -> tuple[StopReason, str] | None:
        """The condition that holds now, safety first; None to go on."""
        if self.tension_stops and (min(tensions) < self.low_tension
                                   or max(tensions) > self.max_tension):
            for name, t in zip(names, tensions, strict=True):
                if t < self.low_tension:
                    return (StopReason.LOW_TENSION_STOP,
                            f"{name} tension {t:.2f} N below LOW_TENSION {self.low_tension:g} N")
            for name, t in zip(names, tensions, strict=True):
                if t > self.max_tension:
                    return (StopReason.HIGH_TENSION_STOP,
                            f"{name} tension {t:.2f} N above MAX_TENSION {self.max_tension:g} N")
        if net_force > self.net_force_limit:
            return (StopReason.NET_FORCE_STOP,
                    f"net force {net_force:.2f} N above NET_FORCELIMIT "
                    f"{self.net_force_limit:g} N")
        if self.endpoint is None:
            return None
        d = _dist(position, self.endpoint)
        radius = self.endpoint_radius(dist_err)
        if d <= radius and dist_err <= self.end_error:
            return (StopReason.ENDPOINT_STOP,
                    f"within {d:.3f} cm of the endpoint (limit {self.end_error:g} cm; "
                    f"distErr {dist_err:.3f} cm)")
        if self.best_time is None or d < self.best - STUCK_PROGRESS:
            self.best = d
            self.best_time = now_s
        elif d < 0.5 * self.total and now_s - self.best_time >= self.stuck_time:
            return (StopReason.STUCK_STOP,
                    f"past half way and no closer than {self.best:.3f} cm for "
                    f"{now_s - self.best_time:.1f} s")
        return None


def _dist(a: Sequence[float], b: Sequence[float]) -> float:
    return math.sqrt((a[0] - b[0]) ** 2 + (a[1] - b[1]) ** 2 + (a[2] - b[2]) ** 2)
