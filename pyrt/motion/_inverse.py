"""A planner's prepared closed-form inverse: one pose at a time, in one thread.

A chain's closed form may offer a prepared inverse of its own
(:meth:`~pyrt.kinematics.puma.PaulInverse.solver`: its pose, seed and result
arrays bound once, so a call is the C call alone).  :class:`PreparedInverse`
holds one for the thread that made it (a planner serves one thread: the
loop's, or a plan's beside it), with each configuration's bits looked up once;
it gives the same answers as the closed form's ``solve``.
"""

from __future__ import annotations

import threading
from typing import Any

import numpy as np
import numpy.typing as npt

Matrix = npt.NDArray[np.float64]
Vector = npt.NDArray[np.float64]


class PreparedInverse:
    """The prepared inverse of ``closed`` (see the module doc) for the calling thread."""

    def __init__(self, closed: Any) -> None:
        self.closed = closed
        self.solver = closed.solver()
        self.owner = threading.get_ident()
        self.bits: dict[str, int] = {}

    @classmethod
    def of(cls, closed: Any) -> PreparedInverse | None:
        """One for ``closed`` if it offers a prepared inverse, else None."""
        return cls(closed) if hasattr(closed, "solver") else None

    def here(self) -> bool:
        """Whether the calling thread is the one it serves."""
        return threading.get_ident() == self.owner

    def __call__(self, t6: Matrix, seed: Vector | None, config: str) -> Vector | None:
        """The joints of ``t6`` in ``config`` nearest ``seed``, or None."""
        if seed is None:  # no seed: the closed form's own choice of turns
            q = self.closed.solve(t6, config)
            return None if q is None else np.asarray(q, dtype=float)
        bits = self.bits.get(config)
        if bits is None:
            bits = self.bits[config] = self.closed.bits(config)
        sv = self.solver
        sv.pose[...] = t6
        sv.seed[...] = seed
        return sv.q.copy() if sv(bits) == sv.REACHED else None
