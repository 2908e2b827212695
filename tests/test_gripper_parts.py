"""The gripper controller's parts: the view of the 8031 RAM and the jaw supervision."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from pyrt.boards.i8031 import (
    COMMAND_CNT,
    ENCODER_CNT,
    ERROR_CNT,
    FLAGS,
    I8031,
    JSPEED,
    MVJAWSPD,
    MXNJSPD,
    MXPJSPD,
    OLD_ENC,
    RAM_SIZE,
    RATE,
    SENSORPD,
    SYSCLKPD,
    WTCHJWSPD,
)
from pyrt.errors import CommandError
from pyrt.robots.gripper import GripperController
from pyrt.robots.gripper_ram import DEFAULT_SCHEDULE, MASK_DOJOG, MASK_DRVON, GripperRam, Schedule
from pyrt.robots.jaw_supervision import JawSupervision
from pyrt.scheduler import Loop, SimClock


def _ram(tick_ns: int = 1_000_000) -> GripperRam:
    return GripperRam(bytearray(RAM_SIZE), lambda: tick_ns)


@given(addr=st.integers(0, RAM_SIZE - 2), value=st.integers(-(2**20), 2**20))
def test_a_word_reads_back_as_stored_unsigned_and_signed(addr, value):
    """set_word stores the low 16 bits little-endian; word and sword read them back."""
    mem = _ram()
    mem.set_word(addr, value)
    w = value & 0xFFFF
    assert mem.ram[addr] == w & 0xFF and mem.ram[addr + 1] == w >> 8
    assert mem.word(addr) == w
    assert mem.sword(addr) == (w - 0x10000 if w & 0x8000 else w)


def test_the_encoder_words_are_the_interrupt_handlers_words():
    """The ISR's word view and the RAM are one memory: ENCODER_CNT through either."""
    mem = _ram()
    mem.w16[ENCODER_CNT // 2] = 0xE47A
    assert mem.word(ENCODER_CNT) == 0xE47A and mem.sword(ENCODER_CNT) == -0x1B86


def test_zero_counts_and_speed_set_their_variables():
    """zero_counts clears the encoder variables with ERROR_CNT at 0080; set_speed sets the drive bytes."""
    mem = _ram()
    for addr in (ENCODER_CNT, COMMAND_CNT, OLD_ENC, RATE, ERROR_CNT):
        mem.set_word(addr, 0x1234)
    mem.zero_counts()
    assert [mem.word(a) for a in (ENCODER_CNT, COMMAND_CNT, OLD_ENC, RATE, ERROR_CNT)] == [
        0, 0, 0, 0, 0x80]
    mem.set_speed(0x33)
    assert (mem.ram[JSPEED], mem.ram[MXPJSPD], mem.ram[MXNJSPD]) == (0x33, 0xB3, 0x4D)


BAD_BYTES = [(-1, 0), (RAM_SIZE, 0), (0x45, 0x100), (0x45, -1)]


@pytest.mark.parametrize(("addr", "value"), BAD_BYTES)
def test_a_byte_outside_the_ram_or_not_a_byte_is_refused_and_changes_nothing(addr, value):
    """poke (monitor C) and peek (D) refuse what is not a RAM address or a byte; the RAM is unchanged."""
    mem = _ram()
    mem.ram[:] = bytes(range(RAM_SIZE))
    before = bytes(mem.ram)
    with pytest.raises(CommandError):
        mem.poke(addr, value)
    if not 0 <= addr < RAM_SIZE:
        with pytest.raises(CommandError, match="outside the on-chip RAM"):
            mem.peek(addr)
    assert bytes(mem.ram) == before
    assert mem.poke(0x45, 0x10) == 0x10 and mem.peek(0x45) == 0x10


def test_clear_drive_says_whether_a_move_or_jog_was_on():
    """clear_drive clears the drive and jog bits only and says whether either was set."""
    mem = _ram()
    mem.ram[FLAGS] = 0xFF
    assert mem.moving and mem.clear_drive() and mem.ram[FLAGS] == 0xFF & ~(MASK_DRVON | MASK_DOJOG)
    assert not mem.moving and not mem.clear_drive()


@pytest.mark.parametrize("tick_ns", [1_000_000, 250_000, 50_000, 2_000_000])
def test_power_up_keeps_002s_periods_at_any_tick(tick_ns):
    """Appendix B's values at 1 ms; at another tick the routines keep 002's periods within a byte's reach."""
    mem = _ram(tick_ns)
    values = mem.power_up_schedule()
    if tick_ns == 1_000_000:
        assert values == DEFAULT_SCHEDULE
    for addr, value in values.items():
        mem.ram[addr] = value
    sched = mem.schedule()
    default = Schedule(1_000_000, *(DEFAULT_SCHEDULE[a] for a in (SYSCLKPD, MVJAWSPD, SENSORPD,
                                                                  WTCHJWSPD)))
    for got, want in ((sched.move_ns, default.move_ns), (sched.sensor_ns, default.sensor_ns),
                      (sched.watch_ns, default.watch_ns)):
        assert abs(got - want) <= max(sched.check_ns, want // 10)


def test_a_schedule_with_one_value_changed():
    """with_value changes only the schedule variable named; another address leaves it as it was."""
    s = Schedule(1_000_000, 4, 0x0C, 0x0A, 1)
    assert s.with_value(WTCHJWSPD, 0x10) == Schedule(1_000_000, 4, 0x0C, 0x0A, 0x10)
    assert s.with_value(SYSCLKPD, 2).check_ns == 2_000_000
    assert s.with_value(0x50, 9) == s


def _controller(tick_ns: int = 1_000_000) -> GripperController:
    """A controller on a loop of ``tick_ns`` with the schedule power-up loads."""
    ctl = GripperController(I8031())
    ctl.attach(Loop(SimClock(), period_ns=tick_ns))
    for addr, value in ctl.power_up_schedule().items():
        ctl.ram[addr] = value
    return ctl


def test_the_supervision_refuses_an_unservable_schedule_without_changing_the_ram():
    """WTCHJWSPD 00 and a WATCHJAW faster than two counts at full speed are refused, nothing stored;
    the controller's monitor C check is the supervision's."""
    ctl = _controller(100_000)
    before = bytes(ctl.ram)
    assert isinstance(ctl.supervision, JawSupervision)
    with pytest.raises(CommandError, match="WTCHJWSPD 00 would stop the routine's clock"):
        ctl.schedule_warning(WTCHJWSPD, 0)
    with pytest.raises(CommandError, match="less than two encoder counts at full speed"):
        ctl.supervision.schedule_warning(SYSCLKPD, 1)
    assert bytes(ctl.ram) == before
    assert ctl.schedule_warning(SENSORPD, 0x0C) is None
    assert "moves may oscillate" in (ctl.schedule_warning(MVJAWSPD, 0xFF) or "")


def test_a_move_arms_the_settle_bound_and_its_end_disarms_it():
    """P arms the supervision with the settle bound of its distance; the move's end disarms it."""
    ctl = _controller()
    ctl.mem.set_speed(0x7F)
    ctl.move(-0x1000)
    sup = ctl.supervision
    assert sup.supervisor.active
    assert ctl.settle_bound_s == pytest.approx(sup.settle_bound_ns(-0x1000) / 1e9)
    assert sup.stall_bound_ns() <= ctl.stall_limit_ns
    ctl.move_ended("at target")
    assert not sup.supervisor.active and ctl.last_stop == "at target"
