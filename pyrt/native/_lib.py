"""The compiled cffi module; imported here and nowhere else in pyrt."""

from pyrt._native import ffi, lib

__all__ = ["ffi", "lib"]
