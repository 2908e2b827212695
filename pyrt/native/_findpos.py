"""The iterated-linear position finder and rope geometry (csrc/findpos.c).

000, section 5: the source position is the one that minimises the sum of
squared rope-length residuals (Eq. 1), found by iterating the linearised
normal equations (Eq. 2) with the rope directions held fixed per iteration,
until the step is below the tolerance (:data:`DEFAULT_TOL`, 000's 0.1 cm,
from ``csrc/findpos.h``).  A direction along which the side ropes' bottom
attachments sum to less than 1 cm (absolute values) is frozen at its start
value (the document's *freeze* vector).

Conventions (every function here):

* points are (N, 3) arrays in cm; a central rope's bottom row is all NaN;
  ``offsets`` (the carriage pulley offsets, Delta of Eq. 1) default to zero;
* residual = measured length - predicted length, in cm, and ``rms`` is
  ``sqrt(mean(residual**2))`` (the document's distErr);
* 1 <= N <= 16.

:func:`find_position` and :func:`rope_lengths` convert their arguments
explicitly (any real numeric array-like).  :class:`PositionFinder`, the form
for the control poll, binds geometry and output buffers once and refuses
anything but float64 C-contiguous arrays of the right shape on its per-call
path, so that path does no conversion.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar, NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from pyrt.errors import NativeError
from pyrt.native._arrays import F64, as_f64, require_f64
from pyrt.native._errors import NativeInputError, NonFiniteError, Status, raise_for_status
from pyrt.native._lib import ffi, lib

__all__ = [
    "PositionFinder",
    "PositionResult",
    "RopeSegments",
    "find_position",
    "freeze_mask",
    "rope_lengths",
    "rope_segments",
]

MAX_ROPES: int = lib.PYRT_FINDPOS_MAX_ROPES
#: The step tolerance (cm; 000's 0.1) and iteration limit by default.
DEFAULT_TOL: float = lib.PYRT_FINDPOS_DEFAULT_TOL
DEFAULT_MAX_ITER: int = lib.PYRT_FINDPOS_DEFAULT_MAX_ITER
_NROWS = (None, 3)
_NDARRAY = np.ndarray
_SHAPE3 = (3,)
_STRIDE = (8,)


@dataclass(frozen=True)
class PositionResult:
    """A converged position: ``position`` (3,) cm, ``rms`` cm, ``residuals``
    (N,) cm (measured - predicted), ``iterations`` and ``status`` (always
    :attr:`Status.OK`: failures raise instead)."""

    position: np.ndarray
    rms: float
    residuals: np.ndarray
    iterations: int
    status: Status = Status.OK


class RopeSegments(NamedTuple):
    """Forward geometry for one source position (all cm; N ropes).

    ``total`` = ``top_len`` + ``bottom_len``; ``top_dir`` and ``bottom_dir``
    (N, 3) are unit vectors from the carriage pulley toward the top pulley and
    toward the bottom attachment (zero rows for a central rope): the
    directions in which each rope pulls the source.
    """

    total: np.ndarray
    top_len: np.ndarray
    bottom_len: np.ndarray
    top_dir: np.ndarray
    bottom_dir: np.ndarray


def _ptr(arr: np.ndarray) -> Any:
    return ffi.cast("double *", ffi.from_buffer(arr))


def _geometry(tops: object, bottoms: object, offsets: object | None
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    t = as_f64("tops", tops, _NROWS)
    n = t.shape[0]
    if not 1 <= n <= MAX_ROPES:
        raise NativeInputError(f"tops: expected 1 to {MAX_ROPES} ropes, got {n}")
    b = as_f64("bottoms", bottoms, (n, 3))
    o = None if offsets is None else as_f64("offsets", offsets, (n, 3))
    return t, b, o


def _detail(arrays: Mapping[str, np.ndarray | None], exc: NativeError) -> str | None:
    """The array that holds NaN/infinity, or the bottom rows that are partly
    NaN, when that is why *exc* was raised."""
    if isinstance(exc, NonFiniteError):
        for name, arr in arrays.items():
            if arr is None:
                continue
            bad = ~np.isfinite(arr)
            if name == "bottoms":
                bad &= ~np.isnan(arr).all(axis=1, keepdims=True)
            if bad.any():
                return f"{name} holds NaN or infinity"
    elif isinstance(exc, NativeInputError):
        b = arrays.get("bottoms")
        if b is not None:
            partial = np.isnan(b).any(axis=1) & ~np.isnan(b).all(axis=1)
            if partial.any():
                rows = np.flatnonzero(partial).tolist()
                return f"bottoms rows {rows} are partly NaN (a central rope is all NaN)"
    return None


def _check(rc: int, what: str, arrays: Mapping[str, np.ndarray | None]) -> None:
    raise_for_status(rc, what, functools.partial(_detail, arrays))


def _freeze_flags(freeze: object, bottoms: np.ndarray) -> tuple[int, int, int]:
    if freeze is None:
        return freeze_mask(bottoms)
    f = np.asarray(freeze)
    if f.shape != (3,) or f.dtype.kind not in "biu":
        raise NativeInputError(
            f"freeze: expected three booleans (x, y, z), got {freeze!r}"
        )
    flags = tuple(int(bool(v)) for v in f)
    if all(flags):
        raise NativeInputError("freeze: every direction is frozen, nothing to solve")
    return flags  # type: ignore[return-value]


def _check_solver_options(tol: float, max_iter: int) -> tuple[float, int]:
    try:
        tol = float(tol)
    except (TypeError, ValueError):
        raise NativeInputError(f"tol: expected a number, got {tol!r}") from None
    if not (tol > 0.0 and np.isfinite(tol)):
        raise NativeInputError(f"tol: expected a finite tolerance > 0 cm, got {tol!r}")
    if not isinstance(max_iter, (int, np.integer)) or isinstance(max_iter, bool):
        raise NativeInputError(f"max_iter: expected an integer, got {max_iter!r}")
    if not 1 <= max_iter <= 2**31 - 1:
        raise NativeInputError(f"max_iter: expected >= 1, got {max_iter}")
    return tol, int(max_iter)


def freeze_mask(bottoms: ArrayLike) -> tuple[int, int, int]:
    """The document's freeze vector for these bottom attachments: 1 for a
    direction whose side-rope bottoms sum (absolute values) to under 1 cm."""
    b = as_f64("bottoms", bottoms, _NROWS)
    n = b.shape[0]
    if not 1 <= n <= MAX_ROPES:
        raise NativeInputError(f"bottoms: expected 1 to {MAX_ROPES} ropes, got {n}")
    out = ffi.new("int32_t[3]")
    _check(lib.pyrt_findpos_freeze_mask(n, _ptr(b), out), "freeze_mask", {"bottoms": b})
    return (int(out[0]), int(out[1]), int(out[2]))


def find_position(
    tops: ArrayLike,
    bottoms: ArrayLike,
    lengths: ArrayLike,
    start: ArrayLike,
    offsets: ArrayLike | None = None,
    freeze: ArrayLike | None = None,
    tol: float = DEFAULT_TOL,
    max_iter: int = DEFAULT_MAX_ITER,
) -> PositionResult:
    """Source position from measured rope lengths (000 ``findPositionL``).

    *freeze* is three booleans (x, y, z) to hold at *start*; ``None`` applies
    the document's rule to *bottoms*.  Raises :class:`NativeInputError` /
    :class:`NonFiniteError` for bad input, :class:`SingularError`,
    :class:`DegenerateGeometryError` or :class:`NoConvergenceError` when no
    position can be produced.
    """
    t, b, o = _geometry(tops, bottoms, offsets)
    n = t.shape[0]
    lens = as_f64("lengths", lengths, (n,))
    x = as_f64("start", start, (3,)).copy()
    flags = _freeze_flags(freeze, b)
    tol, max_iter = _check_solver_options(tol, max_iter)
    res = np.empty(n, dtype=F64)
    p = ffi.new("pyrt_findpos_problem *")
    p.n = n
    p.tops = _ptr(t)
    p.bottoms = _ptr(b)
    p.offsets = ffi.NULL if o is None else _ptr(o)
    p.lengths = _ptr(lens)
    p.freeze = flags
    p.tol = tol
    p.max_iter = max_iter
    p.position = _ptr(x)
    p.residuals = _ptr(res)
    _check(lib.pyrt_findpos_solve(p), f"find_position ({n} ropes)",
           {"tops": t, "bottoms": b, "offsets": o, "lengths": lens, "start": x})
    return PositionResult(x, float(p.rms), res, int(p.iterations))


def rope_segments(position: ArrayLike, tops: ArrayLike, bottoms: ArrayLike,
                  offsets: ArrayLike | None = None) -> RopeSegments:
    """Forward geometry: segment lengths and directions for a source position."""
    t, b, o = _geometry(tops, bottoms, offsets)
    n = t.shape[0]
    x = as_f64("position", position, (3,))
    out = RopeSegments(
        np.empty(n, F64), np.empty(n, F64), np.empty(n, F64),
        np.empty((n, 3), F64), np.empty((n, 3), F64),
    )
    rc = lib.pyrt_rope_lengths(
        n, _ptr(t), _ptr(b), ffi.NULL if o is None else _ptr(o), _ptr(x),
        *(_ptr(a) for a in out),
    )
    _check(rc, f"rope_lengths ({n} ropes)",
           {"tops": t, "bottoms": b, "offsets": o, "position": x})
    return out


def rope_lengths(position: ArrayLike, tops: ArrayLike, bottoms: ArrayLike,
                 offsets: ArrayLike | None = None) -> np.ndarray:
    """Predicted rope lengths (N,) in cm for a source at *position* (Eq. 1)."""
    t, b, o = _geometry(tops, bottoms, offsets)
    n = t.shape[0]
    x = as_f64("position", position, (3,))
    total = np.empty(n, F64)
    rc = lib.pyrt_rope_lengths(
        n, _ptr(t), _ptr(b), ffi.NULL if o is None else _ptr(o), _ptr(x),
        _ptr(total), ffi.NULL, ffi.NULL, ffi.NULL, ffi.NULL,
    )
    _check(rc, f"rope_lengths ({n} ropes)",
           {"tops": t, "bottoms": b, "offsets": o, "position": x})
    return total


class PositionFinder:
    """The position finder prepared for one rope set, for the control poll.

    Geometry and the input/output buffers are converted and bound to the C
    problem once, here.  Per poll::

        finder.solve(lengths)          # start from the last solution
        finder.solve(lengths, start)   # or from an explicit start
        finder.position, finder.rms, finder.residuals, finder.iterations

    ``lengths`` and ``start`` must be float64 C-contiguous arrays of shape
    (N,) and (3,) (refused otherwise: this path never converts); they are
    copied into the bound buffers.  Alternatively write the lengths into
    :attr:`lengths` in place and call ``solve()`` with no arguments.

    :attr:`tops` is the bound (N, 3) array itself: writing to it (or calling
    :meth:`set_top`) moves a top point for the next solve, e.g. where a rope
    bears on the neck ring.  :attr:`position` and :attr:`residuals` are
    read-only views of the bound outputs, overwritten by every successful
    solve; a failed solve raises and leaves them as they were (apart from
    :attr:`position` taking an explicitly given start).
    """

    #: Ropes per problem (csrc/findpos.h PYRT_FINDPOS_MAX_ROPES).
    MAX_ROPES: ClassVar[int] = MAX_ROPES

    def __init__(self, tops: ArrayLike, bottoms: ArrayLike, offsets: ArrayLike | None = None,
                 freeze: ArrayLike | None = None, tol: float = DEFAULT_TOL,
                 max_iter: int = DEFAULT_MAX_ITER):
        t, b, o = _geometry(tops, bottoms, offsets)
        n = t.shape[0]
        flags = _freeze_flags(freeze, b)
        tol, max_iter = _check_solver_options(tol, max_iter)
        self._tops = t.copy()
        self._bottoms = b.copy()
        self._offsets = np.zeros((n, 3), F64) if o is None else o.copy()
        self._lengths = np.zeros(n, F64)
        self._position = np.zeros(3, F64)
        self._residuals = np.zeros(n, F64)
        self._bufs = [ffi.from_buffer(a) for a in (
            self._tops, self._bottoms, self._offsets, self._lengths,
            self._position, self._residuals,
        )]
        p = ffi.new("pyrt_findpos_problem *")
        p.n = n
        p.tops, p.bottoms, p.offsets, p.lengths, p.position, p.residuals = (
            ffi.cast("double *", buf) for buf in self._bufs
        )
        p.freeze = flags
        p.tol = tol
        p.max_iter = max_iter
        self._p = p
        self._solve = lib.pyrt_findpos_solve
        self._what = f"PositionFinder.solve ({n} ropes)"
        self._detail = functools.partial(_detail, {
            "tops": self._tops, "bottoms": self._bottoms, "lengths": self._lengths,
            "start": self._position})
        self._len_shape = (n,)
        self._solved = False
        self.n = n
        self._freeze = flags
        self.position = self._position.view()
        self.position.flags.writeable = False
        self.residuals = self._residuals.view()
        self.residuals.flags.writeable = False
        self.bottoms = self._bottoms.view()
        self.bottoms.flags.writeable = False
        self.offsets = self._offsets.view()
        self.offsets.flags.writeable = False

    @property
    def tops(self) -> np.ndarray:
        """The bound (N, 3) top points, cm; writes take effect at the next solve."""
        return self._tops

    @property
    def lengths(self) -> np.ndarray:
        """The bound (N,) measured-length buffer that :meth:`solve` reads, cm."""
        return self._lengths

    @property
    def freeze(self) -> tuple[int, int, int]:
        """The freeze flags (x, y, z) bound at construction."""
        return self._freeze

    @property
    def tol(self) -> float:
        """Step tolerance, cm."""
        return self._p.tol

    @property
    def max_iter(self) -> int:
        """Iteration limit."""
        return self._p.max_iter

    @property
    def rms(self) -> float:
        """RMS residual of the last successful solve, cm (distErr)."""
        return self._p.rms

    @property
    def iterations(self) -> int:
        """Linear solves of the last successful solve."""
        return self._p.iterations

    def set_top(self, i: int, point: ArrayLike) -> None:
        """Move the top point of rope *i* (e.g. to its neck-ring contact point)."""
        if not -self.n <= i < self.n:
            raise NativeInputError(f"rope index {i} out of range for {self.n} ropes")
        pt = as_f64("point", point, (3,))
        if not np.isfinite(pt).all():
            raise NativeInputError(f"top point of rope {i} must be finite, got {pt}")
        self._tops[i] = pt

    def solve(self, lengths: np.ndarray | None = None, start: np.ndarray | None = None
              ) -> np.ndarray:
        """Solve for the source position; returns :attr:`position` (a view).

        Without *start* the previous solution is the start (the first solve
        needs one).  Raises like :func:`find_position`.
        """
        if lengths is not None:
            if (lengths.__class__ is not _NDARRAY or lengths.dtype is not F64
                    or lengths.shape != self._len_shape or lengths.strides != _STRIDE):
                require_f64("lengths", lengths, self._len_shape)
            self._lengths[...] = lengths
        if start is not None:
            if (start.__class__ is not _NDARRAY or start.dtype is not F64
                    or start.shape != _SHAPE3 or start.strides != _STRIDE):
                require_f64("start", start, _SHAPE3)
            self._position[...] = start
        elif not self._solved:
            raise NativeInputError("solve: the first solve needs a start position")
        raise_for_status(self._solve(self._p), self._what, self._detail)
        self._solved = True
        return self.position
