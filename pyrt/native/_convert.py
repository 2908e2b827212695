"""Excess-128 conversions of the gripper DAC (csrc/convert.c)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from pyrt.native._errors import raise_for_status
from pyrt.native._lib import ffi, lib

__all__ = ["excess128", "excess128_many", "from_excess128"]


def excess128(value: int) -> int:
    """Signed drive value to an excess-128 DAC byte, saturating at 00 and FF."""
    if not isinstance(value, (int, np.integer)):
        raise TypeError(f"drive value must be an integer, got {type(value).__name__}")
    v = int(value)
    v = max(-(2**31), min(2**31 - 1, v))
    out = ffi.new("uint8_t *")
    raise_for_status(lib.pyrt_excess128(v, out), "excess128")
    return out[0]


def from_excess128(byte: int) -> int:
    """Excess-128 DAC byte (00..FF) to the signed drive value (-128..127)."""
    if not 0 <= byte <= 0xFF:
        raise ValueError(f"DAC byte must be 00..FF, got {byte!r}")
    out = ffi.new("int32_t *")
    raise_for_status(lib.pyrt_from_excess128(byte, out), "from_excess128")
    return out[0]


def excess128_many(values: npt.ArrayLike) -> np.ndarray:
    """Vectorised :func:`excess128`: integer drive values to a uint8 array of DAC bytes."""
    arr = np.asarray(values)
    if arr.ndim != 1:
        raise ValueError(f"expected a 1-D array of drive values, got shape {arr.shape}")
    if arr.size and not np.issubdtype(arr.dtype, np.integer):
        raise TypeError(f"drive values must be integers, got dtype {arr.dtype}")
    # Clip to the int32 range before narrowing, so huge values saturate
    # instead of wrapping; the C function saturates the rest.
    arr = np.ascontiguousarray(np.clip(arr, -(2**31), 2**31 - 1), dtype=np.int32)
    out = np.empty(arr.shape[0], dtype=np.uint8)
    rc = lib.pyrt_excess128_many(
        ffi.from_buffer("int32_t[]", arr), ffi.from_buffer("uint8_t[]", out), arr.shape[0]
    )
    raise_for_status(rc, f"excess128_many ({arr.shape[0]} values)")
    return out
