"""Status codes of the C kernels and the exceptions they become.

The codes are ``#define``\\ s in ``csrc/pyrt_native.h``; :class:`Status`
mirrors them with the values the compiler supplies.  Every non-OK code
becomes one of the :class:`~pyrt.errors.NativeError` subclasses below, so
nothing above :mod:`pyrt.native` ever sees a raw return code.
"""

from __future__ import annotations

import enum

from pyrt.errors import NativeError
from pyrt.native._lib import lib

__all__ = [
    "DegenerateGeometryError",
    "NativeInputError",
    "NoConvergenceError",
    "NonFiniteError",
    "SingularError",
    "SolverError",
    "Status",
    "raise_for_status",
]


class Status(enum.IntEnum):
    """The status codes every C kernel returns."""

    OK = lib.PYRT_OK
    EINVAL = lib.PYRT_EINVAL
    ENONFINITE = lib.PYRT_ENONFINITE
    ESINGULAR = lib.PYRT_ESINGULAR
    ENOCONVERGE = lib.PYRT_ENOCONVERGE
    EDEGENERATE = lib.PYRT_EDEGENERATE


class NativeInputError(NativeError):
    """An argument was refused before or by the C kernel: wrong shape, dtype,
    size or range.  Nothing was computed and no output was changed."""

    status = Status.EINVAL


class NonFiniteError(NativeInputError):
    """An input held NaN or infinity where a number was required."""

    status = Status.ENONFINITE


class SolverError(NativeError):
    """The position finder could not produce a position from valid input."""

    status = Status.ENOCONVERGE


class SingularError(SolverError):
    """The ropes do not fix the solved directions (singular normal equations)."""

    status = Status.ESINGULAR


class NoConvergenceError(SolverError):
    """The iteration limit was reached before the step fell below the tolerance."""

    status = Status.ENOCONVERGE


class DegenerateGeometryError(SolverError):
    """A rope segment has (almost) zero length: the source is at a pulley."""

    status = Status.EDEGENERATE


_BY_STATUS: dict[int, type[NativeError]] = {
    Status.EINVAL: NativeInputError,
    Status.ENONFINITE: NonFiniteError,
    Status.ESINGULAR: SingularError,
    Status.ENOCONVERGE: NoConvergenceError,
    Status.EDEGENERATE: DegenerateGeometryError,
}

_WHY = {
    Status.EINVAL: "invalid argument",
    Status.ENONFINITE: "NaN or infinity in the input",
    Status.ESINGULAR: "singular system: the ropes do not fix the solved directions",
    Status.ENOCONVERGE: "no convergence within the iteration limit",
    Status.EDEGENERATE: "zero-length rope segment (source at a pulley)",
}


def raise_for_status(rc: int, what: str) -> None:
    """Raise the exception for C status *rc* (nothing for PYRT_OK).

    *what* names the call and its context, e.g. ``"find_position (5 ropes)"``.
    """
    if rc == Status.OK:
        return
    try:
        status = Status(rc)
    except ValueError:
        raise NativeError(f"{what}: unknown status {rc} from the C kernel") from None
    raise _BY_STATUS[status](f"{what}: {_WHY[status]}")
