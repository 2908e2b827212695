"""Excess-128 DAC conversions of the gripper (csrc/convert.c through pyrt.native)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pyrt.native import excess128, excess128_many, from_excess128

VECTORS = [
    (0, 0x80),        # null current (002)
    (127, 0xFF),      # full positive
    (-128, 0x00),     # full negative
    (1, 0x81),
    (-1, 0x7F),
    (128, 0xFF),      # saturates, never wraps
    (-129, 0x00),
    (10**6, 0xFF),
    (-(10**6), 0x00),
    (2**31 - 1, 0xFF),
    (-(2**31), 0x00),
    (2**40, 0xFF),    # beyond int32: clamped before C sees it
    (-(2**40), 0x00),
]


@pytest.mark.parametrize(("value", "byte"), VECTORS)
def test_excess128_vectors(value, byte):
    """Drive values map to DAC bytes with null at 0x80, saturating at 00 and FF."""
    assert excess128(value) == byte
    assert excess128(np.int64(value) if abs(value) < 2**63 else value) == byte


@given(st.integers(-128, 127))
def test_round_trip(value):
    """Every representable drive value survives byte and back."""
    assert from_excess128(excess128(value)) == value


@given(st.integers(-(2**40), 2**40))
def test_saturation_is_clamping(value):
    """Any integer gives the byte of the value clamped to -128..127."""
    assert excess128(value) == max(-128, min(127, value)) + 128


@settings(max_examples=50, deadline=None)
@given(st.lists(st.integers(-(2**31), 2**31 - 1), max_size=64))
def test_vector_form_equals_scalar(values):
    """excess128_many equals the scalar conversion element by element."""
    out = excess128_many(values)
    assert out.dtype == np.uint8 and out.shape == (len(values),)
    assert out.tolist() == [excess128(v) for v in values]


def test_from_excess128_every_byte():
    """from_excess128 is the inverse over all 256 bytes."""
    assert [from_excess128(b) for b in range(256)] == list(range(-128, 128))


@pytest.mark.parametrize("bad", [1.5, "7", None, [1]])
def test_excess128_refuses_non_integers(bad):
    """A non-integer drive value is refused."""
    with pytest.raises(TypeError):
        excess128(bad)


@pytest.mark.parametrize("bad", [-1, 256, 0x1FF])
def test_from_excess128_refuses_out_of_range(bad):
    """A byte outside 00..FF is refused."""
    with pytest.raises(ValueError):
        from_excess128(bad)


def test_vector_form_refuses_2d():
    """The vector form takes a 1-D array only."""
    with pytest.raises(ValueError):
        excess128_many([[1, 2], [3, 4]])


def test_vector_form_saturates_beyond_32_bits():
    """Drive values beyond the int32 range saturate at 00/FF instead of wrapping."""
    out = excess128_many(np.array([2**40, -(2**40), 2**31, -(2**31) - 1], dtype=np.int64))
    assert out.tolist() == [0xFF, 0x00, 0xFF, 0x00]


def test_vector_form_refuses_floats():
    """A float array is refused rather than truncated."""
    with pytest.raises(TypeError):
        excess128_many(np.array([1.5]))
