"""The ready-queue check in C against its pure-Python reference."""

from __future__ import annotations

import pytest
from _ref_readyq import check as ref_check
from hypothesis import given, settings
from hypothesis import strategies as st

from pyrt.native import QueueChecker


@settings(max_examples=300, deadline=None)
@given(
    image=st.binary(min_size=40, max_size=128),
    capacity=st.integers(min_value=1, max_value=6),
    t_addr=st.integers(min_value=0, max_value=20),
    checks=st.integers(min_value=1, max_value=5),
)
def test_c_check_equals_the_reference(image, capacity, t_addr, checks):
    """Any byte image, any layout: C and the reference free the same slots and leave the same bytes."""
    q_addr = t_addr + capacity
    a, b = bytearray(image), bytearray(image)
    checker = QueueChecker(a, t_addr, q_addr, capacity)
    for _ in range(checks):
        assert checker.check() == ref_check(b, t_addr, q_addr, capacity)
        assert a == b


def test_gripper_layout_example():
    """T at 2F, Q at 35: the slot whose byte reaches zero is freed and its address returned."""
    mem = bytearray(128)
    mem[0x2F:0x32] = bytes([1, 2, 0x0C])
    mem[0x35:0x3B] = bytes([0x41, 0x05, 0x73, 0x04, 0xC2, 0x04])
    checker = QueueChecker(mem, 0x2F, 0x35, 6)
    assert checker.check() == [0x0541]
    assert mem[0x2F:0x32] == bytes([0, 1, 0x0B]) and mem[0x35:0x37] == b"\0\0"
    assert checker.check() == [0x0473]


def test_bad_layout_is_refused():
    """A queue that does not fit in the image, a bad capacity or a non-bytearray image is refused."""
    with pytest.raises(ValueError):
        QueueChecker(bytearray(10), 0, 6, 6)
    with pytest.raises(ValueError):
        QueueChecker(bytearray(100), 0, 10, 0)
    with pytest.raises(TypeError):
        QueueChecker(bytes(100), 0, 10, 6)  # type: ignore[arg-type]
