"""The arm servo board's registers in blocks (pyrt.boards.armservo.ArmServoRegisters) and the
simulated arm's side of them: the in-process register file's storage in place, or any
register view's read/write (and write_many), with the same registers and values."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pyrt.boards.armservo import (
    DAC_FULL_SCALE,
    ArmServoRegisters,
    arm_servo_kind,
    register_cells,
)
from pyrt.boards.registers import BoardKind, Register, RegisterBoard
from pyrt.kinematics.puma import puma560
from pyrt.sim.arm import PUMA560_MOTORS, ArmWorld

N = 6


class View:
    """A register view that is not the register file: read/write only (as an image's)."""

    def __init__(self, board: RegisterBoard) -> None:
        self.board = board
        self.kind = board.kind
        self.calls: list[tuple[str, int, int]] = []

    def read(self, name: str, index: int = 0) -> int:
        return self.board.read(name, index)

    def write(self, name: str, value: int, index: int = 0) -> None:
        self.board.write(name, value, index)
        self.calls.append((name, index, value))

    def snapshot(self) -> list[int]:
        return self.board.snapshot()


class ManyView(View):
    """A view with write_many of (register, index, value), checked first."""

    def __init__(self, board: RegisterBoard) -> None:
        super().__init__(board)
        self.batches: list[list[tuple[str, int, int]]] = []

    def write_many(self, writes: list[tuple[str, int, int]]) -> None:
        for name, index, value in writes:
            self.kind.check_write(name, index, value)
        self.batches.append(list(writes))
        for name, index, value in writes:
            self.board.write(name, value, index)


class SubBoard(RegisterBoard):
    """An in-process board that is not the plain register file (no fast path)."""


def test_the_register_file_is_read_and_written_in_place():
    """On a RegisterBoard the fast path is taken and reads and writes its registers."""
    board = RegisterBoard(arm_servo_kind(N))
    regs = ArmServoRegisters(board)
    assert regs.direct
    for j in range(N):
        board.set_input("count", 1000 * j - 2**31 + 5, j)
    board.set_input("ft", -7, 2)
    assert regs.counts() == [board.read("count", j) for j in range(N)]
    assert regs.ft() == [0, 0, -7, 0, 0, 0]
    regs.write_dacs([1, -2, 3, -4, 5, DAC_FULL_SCALE])
    assert board.values("dac") == [1, -2, 3, -4, 5, DAC_FULL_SCALE]
    assert board.writes == N
    regs.write_all("enable", 1)
    regs.write_all("release", 1)
    assert board.values("enable") == [1] * N and board.values("release") == [1] * N


def test_register_cells_only_for_the_plain_register_file():
    """register_cells gives the live storage of a RegisterBoard, None for anything else."""
    board = RegisterBoard(arm_servo_kind(2))
    cells = register_cells(board, "dac")
    assert cells is not None
    cells[1] = -9
    assert board.output("dac", 1) == -9
    assert register_cells(board, "nonesuch") is None
    assert register_cells(View(board), "dac") is None
    assert register_cells(SubBoard(arm_servo_kind(2)), "dac") is None


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.lists(st.integers(-DAC_FULL_SCALE, DAC_FULL_SCALE), min_size=N,
                                   max_size=N),
                          st.integers(0, 2**N - 1)), min_size=1, max_size=8))
def test_every_path_writes_the_same_registers(steps):
    """Direct, read/write and write_many views: the same DAC values, only the joints asked."""
    boards = [RegisterBoard(arm_servo_kind(N)) for _ in range(3)]
    direct = ArmServoRegisters(boards[0])
    plain = View(boards[1])
    many = ManyView(boards[2])
    views = [direct, ArmServoRegisters(plain), ArmServoRegisters(many)]
    assert [v.direct for v in views] == [True, False, False]
    expect = [0] * N
    for dac, mask in steps:
        for v in views:
            v.write_dacs(dac, mask)
        expect = [d if mask >> j & 1 else e for j, (d, e) in enumerate(zip(dac, expect, strict=True))]
        for b in boards:
            assert b.values("dac") == expect
    asked = sum(bin(mask).count("1") for _, mask in steps)
    assert boards[0].writes == boards[1].writes == boards[2].writes == asked
    assert len(many.batches) == sum(1 for _, mask in steps if mask)  # one batch per block
    assert all(w[0] == "dac" for batch in many.batches for w in batch)


@pytest.mark.parametrize("make", [lambda b: b, View, ManyView], ids=["direct", "view", "many"])
@pytest.mark.parametrize("bad", [[0, 0, 0, DAC_FULL_SCALE + 2, 0, 0], [0, 0, 1.5, 0, 0, 0],
                                 [True, 0, 0, 0, 0, 0], [0] * (N - 1)])
def test_a_bad_block_is_refused_and_writes_nothing(make, bad):
    """A value the DAC does not hold (or a short block): ValueError, no register written."""
    board = RegisterBoard(arm_servo_kind(N))
    regs = ArmServoRegisters(make(board))
    with pytest.raises(ValueError, match="dac"):
        regs.write_dacs(bad)
    assert board.values("dac") == [0] * N and board.writes == 0
    with pytest.raises(ValueError):
        regs.write_all("enable", 2)
    with pytest.raises(ValueError, match="write_all"):
        regs.write_all("count", 0)
    assert board.writes == 0


def test_another_kind_is_refused():
    """The block view serves the arm servo board only."""
    other = BoardKind("other", (Register("dac", count=2, width=16, signed=True,
                                         direction="output"),))
    with pytest.raises(ValueError, match="arm servo board"):
        ArmServoRegisters(RegisterBoard(other))


def test_the_simulated_arm_is_the_same_through_either_path():
    """ArmWorld on the register file in place and on a board without the fast path: the
    same inputs after the same outputs, step by step."""
    chain = puma560(closed_form=False)
    q0 = [0.0, math.radians(60), math.radians(-120), 0.0, 0.3, 0.0]
    worlds = [ArmWorld(chain, motors=PUMA560_MOTORS, q0=q0, board=cls(arm_servo_kind(N)),
                       brake=[m.torque_limit for m in PUMA560_MOTORS])
              for cls in (RegisterBoard, SubBoard)]
    assert worlds[0]._direct is not None and worlds[1]._direct is None
    for step in range(60):
        for w in worlds:
            regs = ArmServoRegisters(w.board)
            if step == 5:
                regs.write_all("release", 1)
                regs.write_all("enable", 1)
            regs.write_dacs([(300 * (step % 7) - 900) * (-1) ** j for j in range(N)])
            w.step(1e-3)
        a, b = (w.board.snapshot() for w in worlds)
        assert a == b
    assert worlds[0].truth().q.tolist() == worlds[1].truth().q.tolist()


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.lists(st.integers(-DAC_FULL_SCALE, DAC_FULL_SCALE), min_size=N,
                                   max_size=N),
                          st.integers(0, 2**N - 1)), min_size=1, max_size=8))
def test_through_the_process_image_the_blocks_are_the_same(steps):
    """sim:'s image view: encoders and F/T in as slices of the image, the DACs asked out in the
    write phase (and at once outside the ticks), exactly what the register file gets directly."""
    from pyrt.boards.registry import open_boards

    boards = open_boards("sim:", "arm", {"servo": arm_servo_kind(N)})
    behind = boards.simulated["servo"]
    regs = ArmServoRegisters(boards.registers("servo"))
    assert not regs.direct and regs._out is not None
    regs.write_dacs([5] * N)  # outside the ticks: at once
    assert behind.values("dac") == [5] * N
    boards.set_tick(0.001)
    expect = [5] * N
    for k, (dac, mask) in enumerate(steps):
        for j in range(N):
            behind.set_input("count", k * 100 + j - 2**31, j)
        behind.set_input("ft", -k, 5)
        boards.poll(k)
        assert regs.counts() == [k * 100 + j - 2**31 for j in range(N)]
        assert regs.ft() == [0, 0, 0, 0, 0, -k]
        regs.write_dacs(dac, mask)
        assert behind.values("dac") == expect  # not before the write phase
        boards.flush(k)
        expect = [d if mask >> j & 1 else e for j, (d, e) in enumerate(zip(dac, expect, strict=True))]
        assert behind.values("dac") == expect
    regs.write_all("enable", 1)
    boards.flush(len(steps))
    assert behind.values("enable") == [1] * N
    image = boards.image
    regs.write_dacs([7] * N)  # a whole block: one change for the write phase
    assert behind.values("dac") == [7] * N  # outside a tick: at once
    boards.poll(len(steps) + 1)
    regs.write_dacs([7] * N)
    assert not image._changed  # the same block again is no change
    regs.write_dacs([8, 7, 7, 7, 7, 7])
    boards.flush(len(steps) + 1)
    assert behind.values("dac") == [8] + [7] * (N - 1)
    with pytest.raises(ValueError, match="dac"):
        regs.write_dacs([DAC_FULL_SCALE + 1] + [0] * (N - 1))
    boards.close()
