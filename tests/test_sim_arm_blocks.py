"""A few joints' servo board through sim:'s process image: the block writes that
pyrt.boards.armservo.ArmServoRegisters makes (a register of a few slots is written slot by
slot) give the register file exactly what a write of each gives."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pyrt.boards.armservo import DAC_FULL_SCALE, ArmServoRegisters, arm_servo_kind
from pyrt.boards.registry import open_boards


class Tap:
    """What a journal's tap sees: every output slot written, in order."""

    def __init__(self) -> None:
        self.seen: list[tuple[int, int]] = []

    def wrote(self, slot: int, value: int) -> None:
        self.seen.append((slot, value))


def _pair(n: int) -> tuple[ArmServoRegisters, object, object]:
    """An n-joint board opened twice: a block view of one, a plain view of the other."""
    made = []
    for _ in range(2):
        boards = open_boards("sim:", "arm", {"servo": arm_servo_kind(n)})
        boards.set_tick(0.001)
        made.append(boards)
    return ArmServoRegisters(made[0].registers("servo")), made[0], made[1]


@pytest.mark.parametrize("n", [1, 2, 3, 4, 5])
@settings(max_examples=25, deadline=None)
@given(data=st.data())
def test_a_few_slots_block_is_each_slots_write(n, data):
    """For 1 to 5 joints, a block of DACs under a mask gives the board (in the write phase, and at once outside a tick) and the image's change list and tap (if one listens) exactly what a write of each masked joint gives."""
    regs, blocks, plain = _pair(n)
    view = plain.registers("servo")
    taps = (Tap(), Tap())
    tapped = data.draw(st.booleans())  # untapped, a whole block of many slots is one store
    if tapped:
        blocks.image.tap, plain.image.tap = taps
    steps = data.draw(st.lists(st.tuples(
        st.lists(st.integers(-DAC_FULL_SCALE, DAC_FULL_SCALE), min_size=n, max_size=n),
        st.integers(0, 2**n - 1), st.booleans()), min_size=1, max_size=6))
    try:
        for k, (dac, mask, in_tick) in enumerate(steps):
            if in_tick:
                blocks.poll(k)
                plain.poll(k)
            regs.write_dacs(dac, mask)
            for j in range(n):
                if mask >> j & 1:
                    view.write("dac", dac[j], j)
            assert blocks.image._changed == plain.image._changed
            if in_tick:
                blocks.flush(k)
                plain.flush(k)
            assert blocks.simulated["servo"].values("dac") == plain.simulated["servo"].values("dac")
        assert taps[0].seen == taps[1].seen
    finally:
        blocks.close()
        plain.close()
