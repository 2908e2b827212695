"""The 8031 RAM image: Appendix A layout, word byte order, power-up state, the queue in RAM."""

from __future__ import annotations

import pytest
from _gripper_rig import make_rig

from pyrt.boards import i8031
from pyrt.boards.i8031 import I8031
from pyrt.robots.gripper import ADDR_MVJAWS, ADDR_SENSORS, ADDR_WATCHJAW

APPENDIX_A = [
    ("OINPTR", 0x08), ("OOUTPTR", 0x09), ("OBYTCNT", 0x0A), ("IINPTR", 0x15),
    ("IOUTPTR", 0x16), ("IBYTCNT", 0x17), ("FLAGS", 0x2C), ("PROX", 0x2D), ("OTHER", 0x2E),
    ("T", 0x2F), ("Q", 0x35), ("SYSCLKCNT", 0x41), ("SYSCLKPD", 0x42), ("MVJAWSPD", 0x43),
    ("SENSORPD", 0x44), ("WTCHJWSPD", 0x45), ("ERROR_CNT", 0x46), ("RATE", 0x48),
    ("ENCODER_CNT", 0x4A), ("COMMAND_CNT", 0x4C), ("OLD_ENC", 0x4E), ("STOPCNT", 0x50),
    ("JSPEED", 0x51), ("MXPJSPD", 0x52), ("MXNJSPD", 0x53), ("STACK_BOTTOM", 0x54),
    ("STACK_TOP", 0x7F),
]
BITS = [("TBFULL", 0), ("SEMA", 1), ("STOPPED", 2), ("DRVON", 3), ("DOJOG", 4),
        ("CROSSFIRE", 0), ("OVERLOAD", 1), ("LIMIT", 2)]


@pytest.mark.parametrize(("name", "addr"), APPENDIX_A + BITS)
def test_appendix_a_names(name, addr):
    """Every named RAM address and bit is where Appendix A puts it."""
    assert getattr(i8031, name) == addr


def test_words_are_little_endian():
    """A word is stored low byte at the lower address, as the L command text says."""
    cpu = I8031()
    cpu.set_word(i8031.ENCODER_CNT, -0x1B86)
    assert cpu.ram[0x4A] == 0x7A and cpu.ram[0x4B] == 0xE4
    assert cpu.word(0x4A) == 0xE47A and cpu.sword(0x4A) == -0x1B86


def test_ram_is_128_bytes_and_refuses_other_addresses():
    """The RAM is 128 bytes; addresses outside 00-7F and non-bytes are refused."""
    cpu = I8031()
    assert len(cpu.ram) == 128
    with pytest.raises(ValueError):
        cpu.write_byte(0x80, 1)
    with pytest.raises(ValueError):
        cpu.write_byte(0x10, 0x100)
    assert cpu.ram == bytearray(128)


def test_power_up_loads_appendix_b_values():
    """Power-up: SYSCLKPD 04, MVJAWSPD 0C, SENSORPD 0A, WTCHJWSPD 01, speed 7F, null DAC."""
    rig = make_rig()
    ram = rig.cpu.ram
    assert (ram[0x42], ram[0x43], ram[0x44], ram[0x45]) == (0x04, 0x0C, 0x0A, 0x01)
    assert (ram[0x51], ram[0x52], ram[0x53]) == (0x7F, 0xFF, 0x01)
    assert rig.board.dac == 0x80
    assert rig.cpu.word(0x46) == 0x0080


def test_queue_lives_in_ram_with_appendix_b_addresses():
    """Q (35-40) holds the routines' EPROM addresses 04C2, 0473, 0541; T (2F-34) their counts."""
    rig = make_rig()
    ram = rig.cpu.ram
    q = [ram[0x35 + 2 * i] | ram[0x36 + 2 * i] << 8 for i in range(6)]
    assert q[:3] == [ADDR_MVJAWS, ADDR_SENSORS, ADDR_WATCHJAW]
    assert q[3:] == [0, 0, 0]
    assert [ram[0x2F + i] for i in range(3)] == [0x0C, 0x0A, 0x01]
    rig.loop.run(4)  # one queue check (SYSCLKPD 04): WATCHJAW ran and rescheduled itself
    q = [ram[0x35 + 2 * i] | ram[0x36 + 2 * i] << 8 for i in range(6)]
    assert sorted(a for a in q if a) == sorted([ADDR_MVJAWS, ADDR_SENSORS, ADDR_WATCHJAW])
    assert rig.ctl.queue.pending() == ["MVJAWS", "SENSORS", "WATCHJAW"]


def test_sysclkpd_in_ram_sets_the_check_rate():
    """C 42 01 (SYSCLKPD) makes the clock handler check the queue every tick."""
    rig = make_rig()
    rig.loop.run(400)
    before = rig.ctl.queue.accumulators()
    calls_pd4 = {a.name: a.calls for a in before}["WATCHJAW"]
    rig.cpu.ram[0x42] = 0x01
    rig.loop.run(400)
    calls_pd1 = {a.name: a.calls for a in rig.ctl.queue.accumulators()}["WATCHJAW"] - calls_pd4
    assert 95 <= calls_pd4 <= 101
    assert 390 <= calls_pd1 <= 401


def test_ports_reset_high_and_are_checked():
    """P0-P3 latch FF after reset; P4 and non-bytes are refused."""
    cpu = I8031()
    assert [cpu.port_read(n) for n in range(4)] == [0xFF] * 4
    cpu.port_write(1, 0x5A)
    assert cpu.port_read(1) == 0x5A
    with pytest.raises(ValueError):
        cpu.port_write(4, 0)
    with pytest.raises(ValueError):
        cpu.port_write(1, 0x100)


def test_interrupt_vectors():
    """Handlers run from their vectors; a non-vector address is refused."""
    cpu = I8031()
    hits = []
    cpu.set_vector(i8031.VECTOR_EXT0, lambda: hits.append("up"))
    cpu.interrupt(i8031.VECTOR_EXT0)
    cpu.interrupt(i8031.VECTOR_EXT1)  # nothing installed: ignored
    assert hits == ["up"]
    with pytest.raises(ValueError):
        cpu.set_vector(0x0005, lambda: None)
