"""A quintic point-to-point move: the reference the servo law is tested against.

``q(t) = q_start + D s(t/T)`` with ``s(u) = 10 u^3 - 15 u^4 + 6 u^5``: it starts and
ends at rest with zero acceleration.  Its peak velocity is ``15/8 D/T`` (at the middle)
and its peak acceleration ``10/sqrt(3) D/T^2``; :func:`quintic_duration` gives the
shortest ``T`` that keeps both within limits.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["PEAK_ACCELERATION", "PEAK_VELOCITY", "Quintic", "quintic_duration"]

#: Peak velocity of a quintic move, times ``T / D``.
PEAK_VELOCITY = 15.0 / 8.0
#: Peak acceleration of a quintic move, times ``T^2 / D``.
PEAK_ACCELERATION = 10.0 / math.sqrt(3.0)


def quintic_duration(distance: float, v_max: float, a_max: float) -> float:
    """The shortest duration of a quintic move over ``distance`` whose velocity stays
    within ``v_max`` and acceleration within ``a_max`` (0 for no distance)."""
    if not (math.isfinite(v_max) and v_max > 0.0 and math.isfinite(a_max) and a_max > 0.0):
        raise ValueError(f"v_max and a_max must be positive, got {v_max!r}, {a_max!r}")
    if not math.isfinite(distance):
        raise ValueError(f"distance must be a finite number, got {distance!r}")
    d = abs(distance)
    return max(PEAK_VELOCITY * d / v_max, math.sqrt(PEAK_ACCELERATION * d / a_max))


@dataclass(frozen=True)
class Quintic:
    """A quintic move from ``start`` to ``end`` over ``duration_s`` seconds (> 0)."""

    start: float
    end: float
    duration_s: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.start) and math.isfinite(self.end)):
            raise ValueError(f"start and end must be finite, got {self.start!r}, {self.end!r}")
        if not (math.isfinite(self.duration_s) and self.duration_s > 0.0):
            raise ValueError(f"duration_s must be positive, got {self.duration_s!r}")

    def at(self, t_s: float) -> tuple[float, float, float]:
        """Position, velocity and acceleration at ``t_s`` (held at the ends outside the
        move)."""
        t_end = self.duration_s
        u = min(max(t_s / t_end, 0.0), 1.0)
        d = self.end - self.start
        s = u * u * u * (10.0 + u * (-15.0 + 6.0 * u))
        ds = 30.0 * u * u * (1.0 - u) * (1.0 - u)
        dds = 60.0 * u * (1.0 - u) * (1.0 - 2.0 * u)
        return self.start + d * s, d * ds / t_end, d * dds / (t_end * t_end)
