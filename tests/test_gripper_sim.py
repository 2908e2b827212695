"""The simulated jaws and the cage's registers: what the controller's ports and interrupts see."""

from __future__ import annotations

import pytest

from pyrt.boards.gripper import (
    DAC,
    GRIPPER_CAGE,
    LED_HI,
    LED_LO,
    P8155_PA,
    P8155_PB,
    P8155_PC,
    GripperBoard,
)
from pyrt.boards.i8031 import I8031, VECTOR_EXT0, VECTOR_EXT1
from pyrt.boards.registers import RegisterBoard
from pyrt.sim.gripper import JawPlant

MS = 1_000_000


def rig(**kw):
    cpu = I8031()
    regs = RegisterBoard(GRIPPER_CAGE)  # the cage's register file: the jaws on one side,
    board = GripperBoard(regs, cpu)  # the 8031 on the other (interrupts raised at poll)
    counts = {"up": 0, "down": 0}
    cpu.set_vector(VECTOR_EXT0, lambda: counts.__setitem__("up", counts["up"] + 1))
    cpu.set_vector(VECTOR_EXT1, lambda: counts.__setitem__("down", counts["down"] + 1))
    plant = JawPlant(regs, **kw)
    t = [0]

    def run(ms: int, dac: int | None = None) -> None:
        if dac is not None:
            cpu.movx_write(DAC, dac)
        for _ in range(ms):
            plant.step(t[0])
            board.poll(t[0])
            t[0] += MS

    return cpu, board, plant, counts, run


def test_dac_is_latched_and_read_back():
    """The DAC keeps the last byte written through MOVX; unmapped addresses read FF."""
    cpu, board, *_ = rig()
    assert board.dac == 0x80
    cpu.movx_write(DAC, 0x12)
    assert board.dac == 0x12 and cpu.movx_read(DAC) == 0x12
    assert cpu.movx_read(0x4321) == 0xFF


def test_current_in_the_deadband_does_not_move_the_jaws():
    """A current of 8 or less (friction) leaves the jaws where they are."""
    _cpu, _board, plant, counts, run = rig(start=-0x800)
    run(500, dac=0x80 - 8)
    assert plant.x == -0x800 and counts == {"up": 0, "down": 0}


def test_negative_current_closes_and_counts_down():
    """Negative current closes the jaws; each count is one external interrupt 1."""
    _cpu, _board, plant, counts, run = rig(start=-0x800)
    run(500, dac=0x80 - 60)
    moved = -0x800 - int(plant.x // 1)
    assert moved > 100 and counts["down"] == moved and counts["up"] == 0


def test_open_stop_is_hard_and_fires_the_limit_sensor():
    """Full open current stalls at the wide-open stop (a few counts in) with the limit bit low."""
    cpu, _board, plant, _counts, run = rig(start=-0x100)
    run(2000, dac=0xFF)
    assert 0 <= plant.x <= plant.p.max_open_overtravel and plant.v == 0.0
    assert cpu.movx_read(P8155_PB) & 0x04 == 0
    run(10, dac=0x80)
    assert plant.v == 0.0


def test_stalled_motor_stalls_on_an_object():
    """Squeezing an object: the jaws stop where the object's spring balances the drive."""
    _cpu, _board, plant, _counts, run = rig(start=-0x1000, object_mm=40.0)
    touch = plant.p.counts_at_opening(40.0)
    run(6000, dac=0x80 - 0x40)
    depth = touch - plant.x
    assert plant.v == pytest.approx(0.0, abs=1.0)
    assert depth == pytest.approx((0x40 - plant.p.deadband) / plant.p.k_object, rel=0.05)
    x = plant.x
    run(100, dac=0x80)  # the worm holds the squeeze: no spring-back
    assert plant.x == pytest.approx(x, abs=1.0)


def test_object_sensors():
    """Crossfire with an object; inner proximity near it; overload when squeezed hard."""
    cpu, _board, plant, _counts, run = rig(start=-0x400, object_mm=40.0)
    run(1)
    assert cpu.movx_read(P8155_PB) & 0x01 == 0  # crossfire on
    assert cpu.movx_read(P8155_PA) == 0xFF  # far away: proximity off
    run(6000, dac=0x00)
    assert cpu.movx_read(P8155_PA) & 0x11 == 0
    assert cpu.movx_read(P8155_PB) & 0x02 == 0  # overload
    plant.set_object(None)
    run(1)
    assert cpu.movx_read(P8155_PB) & 0x03 == 0x03


def test_object_wider_than_the_opening_is_refused():
    """An object cannot be put between jaws that are closer than its width."""
    *_, plant, _counts, _run = rig(start=-0x2000)
    with pytest.raises(ValueError):
        plant.set_object(40.0)
    with pytest.raises(ValueError):
        plant.set_object(0.0)


def test_faults_jam_encoder_limit_port():
    """jam: no motion; encoder: motion without interrupts; limit: never low; port: stuck value."""
    cpu, _board, plant, counts, run = rig(start=-0x100)
    plant.inject("jam")
    run(300, dac=0xFF)
    assert plant.x == -0x100
    plant.clear_faults()
    plant.inject("encoder")
    run(300, dac=0x80 - 60)
    assert plant.x < -0x100 - 50 and counts == {"up": 0, "down": 0}
    plant.clear_faults()
    plant.inject("limit")
    run(3000, dac=0xFF)
    assert plant.x >= 0 and cpu.movx_read(P8155_PB) & 0x04
    plant.inject("port", 0x5A, port="2D")
    run(1)
    assert cpu.movx_read(P8155_PA) == 0x5A
    with pytest.raises(ValueError):
        plant.inject("gremlins")


def test_jog_switch_and_its_timer():
    """A timed jog holds PC0/PC1 low for its duration, then releases."""
    cpu, _board, plant, _counts, run = rig()
    run(1)
    plant.jog("close", 50 * MS)
    assert cpu.movx_read(P8155_PC) & 0x03 == 0x01
    run(60)
    assert cpu.movx_read(P8155_PC) & 0x03 == 0x03 and plant.jog_state == "off"
    plant.jog("open")
    assert cpu.movx_read(P8155_PC) & 0x03 == 0x02


def test_leds_latch_what_is_written():
    """The LED latches hold the bytes written; LED on iff its bit is 0."""
    cpu, board, *_ = rig()
    assert board.leds == 0xFFFF
    cpu.movx_write(LED_LO, 0xFE)
    cpu.movx_write(LED_HI, 0xFB)
    assert board.leds == 0xFBFE


def test_physics_advances_by_elapsed_time():
    """dt = now - last: one 10 ms step moves the jaws as far as ten 1 ms steps, roughly."""
    _c, _b, a, _n, _r = rig(start=-0x800)
    _c2, _b2, b, _n2, _r2 = rig(start=-0x800)
    a.board.write(DAC, 0x80 - 100)
    b.board.write(DAC, 0x80 - 100)
    for t in range(0, 200 * MS + 1, MS):
        a.step(t)
    for t in range(0, 200 * MS + 1, 10 * MS):
        b.step(t)
    assert a.x == pytest.approx(b.x, rel=0.05)
