"""The gripper controller on simulated jaws: init, moves, the routines, jog, calibration."""

from __future__ import annotations

import pytest
from _gripper_rig import make_rig, signed

from pyrt.boards.gripper import P8155_PB
from pyrt.errors import CommandError

TARGETS = [-0x1B86, -0x0100, -0x2000, -0x0010, -0x2900, -0x0800, 0]


def test_init_opens_wide_and_zeroes_the_counts():
    """I drives the jaws to the limit sensor and leaves encoder, target and error at zero."""
    rig = make_rig(start=-0x1800)
    result = rig.init()
    assert result.ok
    assert rig.ctl.position() == 0 and rig.ctl.target() == 0 and rig.ctl.error() == 0x0080
    assert rig.plant.x > -rig.plant.p.limit_band  # physically at the wide-open stop
    assert rig.board.dac == 0x80


def test_p_reaches_several_targets_within_16_counts():
    """P moves end within 16 counts of the target, with the drive bit clear and current null."""
    rig = make_rig()
    rig.init()
    for target in TARGETS:
        pos = rig.move(target)
        assert abs(pos - target) <= 16, (hex(target), pos)
        assert not rig.cpu.ram[0x2C] & 0x08
        assert rig.board.dac == 0x80
        err = signed(rig.ctl.error())
        assert err - 0x80 == pos - target


def test_error_is_excess_128_of_actual_minus_target():
    """ERROR_CNT = actual - target + 80 (0080 no error, 008F fifteen counts past)."""
    rig = make_rig()
    rig.init()
    rig.cpu.set_word(0x4C, -15)  # target 15 counts closed of where the jaws are (0000)
    rig.loop.run(8)  # WATCHJAW runs at every queue check
    assert rig.ctl.error() == 0x008F
    rig.cpu.set_word(0x4C, 6)
    rig.loop.run(8)
    assert rig.ctl.error() == 0x007A


def test_positive_target_is_refused_and_nothing_moves():
    """A positive target raises CommandError; the target and drive bit are unchanged."""
    rig = make_rig()
    rig.init()
    with pytest.raises(CommandError):
        rig.ctl.move(0x1234)
    rig.loop.run(500)
    assert rig.ctl.target() == 0 and not rig.ctl.moving and rig.board.dac == 0x80


def test_mvjawspd_in_ram_changes_the_jaw_move_rate():
    """C 43 20 slows MVJAWS: it runs 0C/20 as often over the same loop time."""
    rig = make_rig()
    rig.loop.run(2000)
    calls = lambda: {a.name: a.calls for a in rig.ctl.queue.accumulators()}["MVJAWS"]  # noqa: E731
    base = calls()
    rig.loop.run(9600)
    fast = calls() - base
    rig.cpu.ram[0x43] = 0x20
    rig.loop.run(2000)  # let the old schedule value run out
    base = calls()
    rig.loop.run(9600)
    slow = calls() - base
    assert fast == pytest.approx(9600 / (4 * 0x0C), abs=1)
    assert slow == pytest.approx(9600 / (4 * 0x20), abs=1)


def test_x_changes_speed_limits_and_slows_the_jaws():
    """X 33 sets JSPEED 33, MXPJSPD B3, MXNJSPD 4D and the move takes longer."""
    rig = make_rig()
    rig.init()
    t0 = rig.loop.now_ns
    rig.move(-0x1000)
    fast = rig.loop.now_ns - t0
    rig.move(0)
    rig.ctl.set_speed(0x33)
    assert bytes(rig.cpu.ram[0x51:0x54]) == bytes([0x33, 0xB3, 0x4D])
    t0 = rig.loop.now_ns
    rig.move(-0x1000)
    assert rig.loop.now_ns - t0 > 1.5 * fast
    with pytest.raises(CommandError):
        rig.ctl.set_speed(0x80)


def test_sensors_with_an_object_between_the_jaws():
    """Crossfire while an object is there; inner proximity sensors near it; overload squeezed."""
    rig = make_rig(object_mm=30.0)
    rig.init()
    rig.loop.run(100)
    word = rig.ctl.sensor_word()
    assert word & 0x0400 == 0  # limit on (2E.2, bit 10, is 0)
    assert word & 0x0100 == 0  # crossfire on (2E.0, bit 8)
    assert word & 0x0011 == 0x0011  # proximity off far away
    touch = rig.plant.p.counts_at_opening(30.0)
    rig.move(int(touch) + 200)  # just short of the object
    rig.loop.run(100)
    word = rig.ctl.sensor_word()
    assert word & 0x0011 == 0 and word & 0x0200  # proximity on, no overload
    rig.move(-0x2900)  # squeeze hard
    rig.loop.run(100)
    word = rig.ctl.sensor_word()
    assert word & 0x0200 == 0  # overload on
    assert rig.board.leds == word  # SENSORS shows the same bits on the LEDs


def test_calibration_reports_the_closed_count():
    """C opens, closes until stopped, reads about D600 (slightly more: compliance), re-inits."""
    rig = make_rig()
    result = rig.run_job(rig.ctl.start_calibration(), max_s=120)
    assert result.ok
    closed = signed(result.value)
    assert -0x2A00 - 300 < closed < -0x2A00 + 50
    assert result.message == f"{result.value:04X}"
    assert rig.ctl.position() == 0 and rig.board.dac == 0x80


def test_jog_moves_and_keeps_target_equal_to_position():
    """The jog switch drives the jaws; the target follows them; release nulls the current."""
    rig = make_rig()
    rig.init()
    rig.move(-0x1000)
    rig.plant.jog("close", 500 * 1_000_000)
    rig.loop.run(600)
    assert signed(rig.ctl.position()) < -0x1000 - 200
    assert rig.board.dac == 0x80 and not rig.ctl.moving
    rig.loop.run(100)
    assert abs(signed(rig.ctl.target()) - signed(rig.ctl.position())) < 60


def test_jog_held_against_the_stop_is_cut_off():
    """A jog switch held against the wide-open stop nulls the current after STOPCNT bumps."""
    rig = make_rig()
    rig.init()
    rig.plant.jog("open")
    rig.loop.run(2000)
    assert rig.board.dac == 0x80
    assert rig.cpu.ram[0x2C] & 0x20  # JOGSTALL: ignored until released
    assert rig.stall.worst_ns < 400 * 1_000_000
    rig.plant.jog("off")
    rig.loop.run(100)
    assert not rig.cpu.ram[0x2C] & 0x20
    assert rig.loop.take_fault() is None


def test_monitor_clock_off_freezes_the_queue_and_sensors():
    """With the clock interrupt off the queue and 2D/2E are frozen; L's pattern stays."""
    rig = make_rig()
    rig.init()
    rig.ctl.toggle_clock()
    before = bytes(rig.cpu.ram[0x2F:0x41])
    assert rig.ctl.led_test(0xFBFE) == 0xFE
    rig.loop.run(500)
    assert bytes(rig.cpu.ram[0x2F:0x41]) == before
    assert rig.cpu.ram[0x2D] == 0xFE and rig.cpu.ram[0x2E] == 0xFB
    assert rig.board.leds == 0xFBFE
    rig.ctl.toggle_clock()
    rig.loop.run(100)
    assert rig.cpu.ram[0x2E] == rig.board.read(P8155_PB)


def test_p_during_init_is_refused():
    """A move while init is running is refused (busy); init goes on."""
    rig = make_rig()
    job = rig.ctl.start_init()
    rig.loop.run(10)
    with pytest.raises(CommandError, match="busy"):
        rig.ctl.move(-0x100)
    assert rig.run_job(job).ok


@pytest.mark.parametrize("speed", [0x7F, 0x33, 0x20])
def test_p_within_16_counts_at_slower_speeds(speed):
    """With X 33 (high-ratio worm) or slower, P still ends within 16 counts."""
    rig = make_rig()
    rig.init()
    rig.ctl.set_speed(speed)
    for target in (-0x0900, -0x0300, -0x1200):
        assert abs(rig.move(target, max_s=60) - target) <= 16
