"""The in-process register file: its inputs in one int64 buffer in declared order."""

from __future__ import annotations

import random

from hypothesis import given
from hypothesis import strategies as st

from pyrt.boards.image import input_buffer
from pyrt.boards.registers import OUTPUT, BoardKind, Register, RegisterBoard, iter_inputs

KIND = BoardKind("mixed", (
    Register("drive", count=2, width=16, signed=True, direction=OUTPUT, off=0),
    Register("count", count=3, width=32, signed=True),
    Register("clear", count=3, direction=OUTPUT, clears="count"),
    Register("port", width=8, power_up=0xF8),
    Register("wide", count=2, width=32),
))


def test_input_buffer_is_the_inputs_in_declared_order():
    """input_buffer() holds every input in iter_inputs order, power-up values included."""
    board = RegisterBoard(KIND)
    buf = input_buffer(board)
    assert buf is not None and buf.format == "q" and len(buf) == KIND.input_count
    assert buf.tolist() == board.snapshot() == [0, 0, 0, 0xF8, 0, 0]
    rnd = random.Random(3)
    for reg, i in iter_inputs(KIND):
        board.set_input(reg.name, rnd.randrange(reg.low, reg.high + 1), i)
    assert buf.tolist() == [board.read(reg.name, i) for reg, i in iter_inputs(KIND)]


@given(st.data())
def test_cells_write_the_buffer_in_place(data):
    """A world's item write through cells() is what read(), snapshot() and the buffer see."""
    board = RegisterBoard(KIND)
    cells = {r.name: board.cells(r.name) for r in KIND.inputs()}
    want = {r.name: [0] * r.count for r in KIND.inputs()}
    want["port"][0] = 0xF8
    for reg, i in data.draw(st.lists(st.sampled_from(list(iter_inputs(KIND))), max_size=20)):
        v = data.draw(st.integers(reg.low, reg.high))
        cells[reg.name][i] = v
        want[reg.name][i] = v
        assert cells[reg.name][i] == v
    flat = [v for r in KIND.inputs() for v in want[r.name]]
    assert board.snapshot() == flat == board.input_buffer().tolist()
    assert all(type(v) is int for v in board.snapshot())
    for r in KIND.inputs():
        assert board.values(r.name) == want[r.name]
        assert [board.read(r.name, i) for i in range(r.count)] == want[r.name]


def test_outputs_stay_lists_and_a_strobe_clears_its_input():
    """An output's cells are a list; a clear strobe zeroes its input in the buffer."""
    board = RegisterBoard(KIND)
    assert type(board.cells("drive")) is list
    board.cells("count")[1] = -7
    board.write("clear", 1, 1)
    assert board.read("count", 1) == 0 and board.input_buffer()[1] == 0
    board.cells("count")[2] = 5
    board.setter("clear", 2)(1)
    assert board.snapshot()[:3] == [0, 0, 0]
