"""Rope-and-source statics (csrc/statics.c): the equilibrium of the source carriage.

:class:`StaticsSolver` binds one problem's arrays once (the C struct keeps
pointers into memory this object owns); a caller stepping in time then only
rewrites the payed-out lengths and calls :meth:`StaticsSolver.solve`, which
warm-starts from the previous equilibrium.  Ropes bear on the neck ring by
the one model of csrc/neck.h (:class:`~pyrt.native.NeckRing`), both
segments of a rope (``PYRT_STATICS_RING_SEGMENTS``).  Inputs are checked
here; the C status codes become :class:`~pyrt.errors.NativeError`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from pyrt.native._errors import converged, raise_for_status
from pyrt.native._lib import ffi, lib
from pyrt.native._neck import NeckRing, Ring

__all__ = ["StaticsSolver"]

#: A point (x, y, z): a sequence of three numbers or a numpy array of three.
Point = Sequence[float] | npt.NDArray[np.floating[Any]]

MAX_ROPES: int = lib.PYRT_STATICS_MAX_ROPES
_NO_RING = NeckRing((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 0.0)


def _point(p: Point, what: str) -> tuple[float, float, float]:
    if p is None or len(p) != 3:
        raise ValueError(f"{what} must be a point (x, y, z), got {p!r}")
    x, y, z = (float(v) for v in p)
    return x, y, z


class StaticsSolver:
    """The source equilibrium for ``n`` ropes (see csrc/statics.h for the model).

    ``tops``, ``offsets``: n points; ``bottoms``: n points or ``None`` for a
    central rope; ``dead``: spindle-to-top-pulley lengths (cm);
    ``compliance``: strain per newton of each rope; ``ring``: the neck ring,
    a :class:`~pyrt.native.NeckRing` or ``(centre, axis, radius)``, or
    ``None``; ``weight``: net downward force on the source (N, gravity less
    buoyancy); ``floor_z``: the lowest z the source can reach.
    ``position``: the first warm start.  ``tol``, ``max_step`` (cm) and
    ``max_iter`` default to ``csrc/statics.h``'s.
    """

    #: The segments of a rope the world lets bear on the neck ring
    #: (:data:`~pyrt.native.NECK_UPPER` | :data:`~pyrt.native.NECK_LOWER`).
    RING_SEGMENTS: ClassVar[int] = lib.PYRT_STATICS_RING_SEGMENTS

    def __init__(
        self,
        tops: Sequence[Sequence[float]],
        bottoms: Sequence[Sequence[float] | None],
        offsets: Sequence[Sequence[float]] | None,
        dead: Sequence[float],
        compliance: Sequence[float],
        payout: Sequence[float],
        *,
        ring: NeckRing | Ring | None = None,
        weight: float = 0.0,
        floor_z: float = -1e9,
        position: Sequence[float] = (0.0, 0.0, 0.0),
        tol: float = lib.PYRT_STATICS_DEFAULT_TOL,
        max_step: float = lib.PYRT_STATICS_DEFAULT_MAX_STEP,
        max_iter: int = lib.PYRT_STATICS_DEFAULT_MAX_ITER,
    ):
        n = len(tops)
        if not 1 <= n <= MAX_ROPES:
            raise ValueError(f"statics needs 1..{MAX_ROPES} ropes, got {n}")
        for name, seq in (("bottoms", bottoms), ("dead", dead), ("compliance", compliance),
                          ("payout", payout)):
            if len(seq) != n:
                raise ValueError(f"{name} has {len(seq)} entries for {n} ropes")
        if offsets is not None and len(offsets) != n:
            raise ValueError(f"offsets has {len(offsets)} entries for {n} ropes")
        self.n = n
        nan = math.nan
        self._tops = ffi.new("double[]", [c for t in tops for c in _point(t, "top")])
        self._bottoms = ffi.new(
            "double[]",
            [c for b in bottoms for c in ((nan, nan, nan) if b is None else _point(b, "bottom"))],
        )
        self._offsets = ffi.new(
            "double[]",
            [c for o in (offsets or [(0.0, 0.0, 0.0)] * n) for c in _point(o, "offset")],
        )
        self._payout = ffi.new("double[]", [float(v) for v in payout])
        self._dead = ffi.new("double[]", [float(v) for v in dead])
        self._compliance = ffi.new("double[]", [float(v) for v in compliance])
        self._intact = ffi.new("int32_t[]", [1] * n)
        self._position = ffi.new("double[3]", list(_point(position, "position")))
        self._tension = ffi.new("double[]", n)
        self._wrapped = ffi.new("int32_t[]", n)
        self._g = ffi.new("double[]", n)
        self._p = ffi.new("pyrt_statics_problem *", {
            "n": n, "tops": self._tops, "bottoms": self._bottoms, "offsets": self._offsets,
            "payout": self._payout, "dead": self._dead, "compliance": self._compliance,
            "intact": self._intact, "position": self._position, "tension": self._tension,
            "wrapped": self._wrapped, "tol": float(tol), "max_step": float(max_step),
            "max_iter": int(max_iter), "floor_z": float(floor_z), "weight": float(weight),
        })
        self._what = f"StaticsSolver ({n} ropes)"
        self.set_ring(ring)

    # -- inputs --------------------------------------------------------------

    def set_ring(self, ring: NeckRing | Ring | None) -> None:
        """Set (or, with ``None``, remove) the neck ring the ropes may bear on."""
        if ring is None:
            ring = _NO_RING
        elif not isinstance(ring, NeckRing):
            ring = NeckRing(*ring)
        self._p.ring = ring._c[0]

    @property
    def weight(self) -> float:
        """Net downward force on the source (N)."""
        return self._p.weight

    @weight.setter
    def weight(self, value: float) -> None:
        self._p.weight = float(value)

    @property
    def floor_z(self) -> float:
        return self._p.floor_z

    def set_payout(self, i: int, length: float) -> None:
        """Unstretched rope ``i`` payed out from the spindle (cm, > 0)."""
        self._payout[i] = length

    def set_payouts(self, lengths: Sequence[float]) -> None:
        """All payed-out lengths at once."""
        pay = self._payout
        for i in range(self.n):
            pay[i] = lengths[i]

    def payout(self, i: int) -> float:
        return self._payout[i]

    def set_intact(self, i: int, intact: bool) -> None:
        """A broken rope (``False``) carries no tension."""
        self._intact[i] = 1 if intact else 0

    def set_position(self, position: Point) -> None:
        """Replace the warm start."""
        for k, v in enumerate(_point(position, "position")):
            self._position[k] = v

    # -- solving -------------------------------------------------------------

    def solve(self) -> bool:
        """Move to the equilibrium; ``False`` if the iteration limit was hit
        (the position is then the best point reached; the next call continues)."""
        return converged(lib.pyrt_statics_solve(self._p), self._what)

    def evaluate(self, position: Point) -> tuple[list[float], list[float], list[bool]]:
        """Rope geometry (cm beyond the top pulley), tensions and ring contact
        at ``position``, without solving."""
        pos = ffi.new("double[3]", list(_point(position, "position")))
        rc = lib.pyrt_statics_evaluate(self._p, pos, self._g, self._tension, self._wrapped)
        raise_for_status(rc, f"{self._what}.evaluate")
        n = self.n
        return (
            [self._g[i] for i in range(n)],
            [self._tension[i] for i in range(n)],
            [bool(self._wrapped[i]) for i in range(n)],
        )

    # -- outputs -------------------------------------------------------------

    @property
    def position(self) -> tuple[float, float, float]:
        p = self._position
        return (p[0], p[1], p[2])

    def tensions(self) -> list[float]:
        t = self._tension
        return [t[i] for i in range(self.n)]

    def tension(self, i: int) -> float:
        return self._tension[i]

    def wrapped(self) -> list[bool]:
        w = self._wrapped
        return [bool(w[i]) for i in range(self.n)]

    @property
    def iterations(self) -> int:
        return self._p.iterations

    @property
    def residual(self) -> float:
        """Net force on the source at the last solution (N; floor reaction excluded)."""
        return self._p.residual
