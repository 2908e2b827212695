"""The neck ring and the ropes that bear on it (csrc/neck.c; 000, section 5, ``neckIntersection``).

One model for the simulated world, the controller and any Python caller: a
straight rope segment from the carriage pulley ``q`` to its far end (the top
pulley, or the bottom attachment) that would cross the neck-ring plane
outside the ring bears on the ring instead; the ring is frictionless, so the
rope takes the shortest path over a point ``c`` of the rim, found in C by
Newton's method on the rim angle (see ``csrc/neck.h``).

:class:`NeckRing` is the ring with its frame (made by ``pyrt_neck_init``);
:meth:`NeckRing.contact` the rim point one segment bears on,
:meth:`NeckRing.rope_path` a whole rope with the segments a caller lets bear
(:data:`UPPER`, :data:`LOWER`).  :func:`ring_contact` is the one-call form
for a ring given as ``(centre, axis, radius)``.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from typing import NamedTuple

from pyrt.native._errors import NativeInputError, raise_for_status
from pyrt.native._lib import ffi, lib

__all__ = ["LOWER", "UPPER", "NeckRing", "Ring", "RopePath", "ring_contact"]

Vec = tuple[float, float, float]
#: (centre, unit axis pointing out of the vessel, interior radius), global cm.
Ring = tuple[Sequence[float], Sequence[float], float]

#: The upper segment of a rope (top pulley to carriage pulley).
UPPER: int = lib.PYRT_NECK_UPPER
#: The lower segment (carriage pulley to bottom attachment).
LOWER: int = lib.PYRT_NECK_LOWER

_NAN = math.nan
_NAN3 = (_NAN, _NAN, _NAN)


class RopePath(NamedTuple):
    """A rope with the carriage at one point: ``length`` beyond the top pulley
    (cm, over the ring where it bears on it) and the rim points its upper and
    lower segments bear on (None: straight)."""

    length: float
    upper: Vec | None
    lower: Vec | None


def _point(name: str, p: Sequence[float]) -> Vec:
    try:
        x, y, z = p
        return (float(x), float(y), float(z))
    except (TypeError, ValueError):
        raise NativeInputError(f"NeckRing: {name} must be a point (x, y, z), got {p!r}") from None


class NeckRing:
    """The neck ring: ``centre`` and ``axis`` (pointing out of the vessel; any
    length > 0) in global cm, interior ``radius`` (<= 0: no ring).

    ``centre``, ``axis`` (unit), ``e1`` and ``e2`` (the frame spanning the
    ring plane, ``e2 = axis x e1``) and ``radius`` are plain attributes; the
    C struct is bound once and passed to the kernels.
    """

    __slots__ = ("_c", "axis", "centre", "e1", "e2", "radius")

    def __init__(self, centre: Sequence[float], axis: Sequence[float], radius: float):
        c = ffi.new("pyrt_neck_ring *")
        try:
            r = float(radius)
        except (TypeError, ValueError):
            raise NativeInputError(f"NeckRing: radius must be a number, got {radius!r}") from None
        raise_for_status(lib.pyrt_neck_init(c, _point("centre", centre), _point("axis", axis), r),
                         "NeckRing (a finite centre, a non-zero axis and a radius)")
        self._c = c
        self.centre: Vec = tuple(c.centre)
        self.axis: Vec = tuple(c.axis)
        self.e1: Vec = tuple(c.e1)
        self.e2: Vec = tuple(c.e2)
        self.radius: float = c.radius

    def __repr__(self) -> str:
        return f"NeckRing({self.centre}, {self.axis}, {self.radius})"

    def contact(self, t: Sequence[float], q: Sequence[float], hint: float | None = None
                ) -> tuple[Vec, float] | None:
        """``(rim point, rim angle)`` the segment from the carriage pulley ``q``
        to its far end ``t`` bears on, or None when it runs straight; ``hint``:
        the rim angle to start from (the one found for this rope last time)."""
        out = ffi.new("pyrt_neck_segment *")
        rc = lib.pyrt_neck_contact(self._c, _point("far end", t), _point("carriage", q),
                                   _NAN if hint is None else float(hint), out)
        raise_for_status(rc, "NeckRing.contact")
        if not out.bears:
            return None
        p = out.point
        return (p[0], p[1], p[2]), out.phi

    def rope_path(self, top: Sequence[float], bottom: Sequence[float] | None,
                  q: Sequence[float], segments: int) -> RopePath:
        """The rope from ``top`` over the carriage pulley ``q`` to ``bottom`` (None:
        no bottom attachment), the segments in the mask ``segments``
        (:data:`UPPER` | :data:`LOWER`) bearing on the ring where they cross
        it outside."""
        out = ffi.new("pyrt_neck_rope *")
        b = _NAN3 if bottom is None else _point("bottom", bottom)
        rc = lib.pyrt_neck_rope_path(self._c, int(segments), _point("top", top), b,
                                     _point("carriage", q), ffi.NULL, out)
        raise_for_status(rc, "NeckRing.rope_path")
        up, lo = out.upper, out.lower
        return RopePath(out.length,
                        tuple(up.point) if up.bears else None,
                        tuple(lo.point) if lo.bears else None)


@functools.lru_cache(maxsize=16)
def _ring(centre: Vec, axis: Vec, radius: float) -> NeckRing:
    return NeckRing(centre, axis, radius)


def ring_contact(ring: Ring | NeckRing | None, t: Sequence[float], q: Sequence[float]
                 ) -> Vec | None:
    """The rim point the segment from the carriage pulley ``q`` to its far end
    ``t`` bears on, or None if it runs straight (or there is no ring)."""
    if ring is None:
        return None
    if not isinstance(ring, NeckRing):
        centre, axis, radius = ring
        if not float(radius) > 0.0:
            return None
        ring = _ring(_point("centre", centre), _point("axis", axis), float(radius))
    found = ring.contact(t, q)
    return None if found is None else found[0]
