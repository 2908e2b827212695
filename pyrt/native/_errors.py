"""Status codes of the C kernels and the exceptions they become: the one place.

The codes are ``#define``\\ s in ``csrc/pyrt_native.h``; :class:`Status`
mirrors them with the values the compiler supplies.  Every wrapper in
:mod:`pyrt.native` hands the code an entry point returned to
:func:`raise_for_status` (or :func:`converged`, for a solver whose best
point so far is an answer too) and never looks at it itself: every non-OK
code becomes one of the :class:`~pyrt.errors.NativeError` subclasses below,
so nothing above :mod:`pyrt.native` ever sees a raw return code.  A wrapper
that knows more about a failure than the code says catches the subclass and
raises the same subclass with a better message.
"""

from __future__ import annotations

import enum
from collections.abc import Callable
from typing import NoReturn

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
    "converged",
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
    """A rope segment has (almost) zero length: the carriage is at a pulley, an
    attachment or the neck ring's rim."""

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
    Status.EDEGENERATE: "zero-length rope segment (the carriage at a pulley, an attachment "
                        "or the neck ring's rim)",
}


#: A wrapper's explanation of a failure: given the exception the status
#: becomes, the detail to name instead of the generic reason (or None).
Detail = Callable[[NativeError], "str | None"]


def raise_for_status(rc: int, what: str, detail: Detail | None = None) -> None:
    """Raise the exception for C status *rc* (nothing for PYRT_OK).

    *what* names the call and its context, e.g. ``"find_position (5 ropes)"``;
    *detail*, when given, may name what was wrong better than the code can
    (which array held the NaN), keeping the exception class.
    """
    if rc:
        _raise(rc, what, detail)


def converged(rc: int, what: str) -> bool:
    """True for PYRT_OK, False for PYRT_ENOCONVERGE (a solver that stopped at
    its iteration limit with its best point so far); any other status raises
    as :func:`raise_for_status` does."""
    if not rc:
        return True
    if rc == Status.ENOCONVERGE:
        return False
    _raise(rc, what, None)


def _raise(rc: int, what: str, detail: Detail | None) -> NoReturn:
    try:
        status = Status(rc)
    except ValueError:
        raise NativeError(f"{what}: unknown status {rc} from the C kernel") from None
    cls = _BY_STATUS[status]
    exc = cls(f"{what}: {_WHY[status]}")
    better = detail(exc) if detail is not None else None
    if better:
        exc = cls(f"{what}: {better}")
    raise exc
