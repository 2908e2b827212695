"""Argument checks shared by the kernels' wrappers.

The one-shot functions convert explicitly (:func:`as_f64`: any real numeric
array-like becomes a C-contiguous float64 copy or view); the prepared forms
refuse instead (:func:`require_f64`), so their per-call path never converts
behind the caller's back.
"""

from __future__ import annotations

import numpy as np

from pyrt.native._errors import NativeInputError

__all__ = ["F64", "as_f64", "require_f64"]

F64 = np.dtype(np.float64)


def as_f64(name: str, value: object, shape: tuple[int | None, ...]) -> np.ndarray:
    """*value* as a C-contiguous float64 array of *shape* (``None`` = any size).

    Integers and floats of any width are converted; booleans, complex,
    strings and objects are refused with :class:`NativeInputError`.
    """
    if (value.__class__ is np.ndarray and value.dtype is F64  # type: ignore[attr-defined]
            and value.shape == shape and value.flags.c_contiguous):  # type: ignore[attr-defined]
        return value  # type: ignore[return-value]  # already what it would be made into
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError) as exc:
        raise NativeInputError(f"{name}: not an array of numbers ({exc})") from None
    if arr.dtype.kind not in "fiu":
        raise NativeInputError(f"{name}: expected real numbers, got dtype {arr.dtype}")
    _check_shape(name, arr, shape)
    return np.ascontiguousarray(arr, dtype=F64)


def require_f64(name: str, value: object, shape: tuple[int, ...]) -> np.ndarray:
    """Refuse anything but a C-contiguous float64 ndarray of exactly *shape*."""
    if not isinstance(value, np.ndarray):
        raise NativeInputError(
            f"{name}: expected a numpy float64 array of shape {shape}, got {type(value).__name__}"
        )
    if value.dtype != F64:
        raise NativeInputError(f"{name}: expected dtype float64, got {value.dtype}")
    if not value.flags.c_contiguous:
        raise NativeInputError(f"{name}: array must be C-contiguous")
    if value.shape != shape:
        raise NativeInputError(f"{name}: expected shape {shape}, got {value.shape}")
    return value


def _check_shape(name: str, arr: np.ndarray, shape: tuple[int | None, ...]) -> None:
    ok = arr.ndim == len(shape) and all(
        want is None or got == want for got, want in zip(arr.shape, shape, strict=True)
    )
    if not ok:
        want = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
        raise NativeInputError(f"{name}: expected shape {want}, got {arr.shape}")
