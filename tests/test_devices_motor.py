"""Motor: limits, the STEP_MODE ramp, VELOCITY_MODE, windings off when idle."""

from __future__ import annotations

import pytest

from pyrt.boards.tio10 import AWO_BITS, DIR_BITS, TIO10
from pyrt.devices.motor import OFF, ON, STANDBY, VELOCITY_MODE, Motor
from pyrt.errors import CommandError, ConfigError
from pyrt.sim.cards import add_pulses

CH = 7


def _motor(tio=None, **kw):
    tio = tio or TIO10()
    args = {"start_speed": 0.5, "cruise_speed": 7.0}
    args.update(kw)
    return Motor("axis0Motor", tio, CH, **args), tio


def _pulse(tio, n):
    add_pulses(tio.registers, CH, n)


def _windings_on(tio, ch=CH):
    return not tio.bit(*AWO_BITS[ch])


@pytest.mark.parametrize("channel", [4, 5])
def test_rtc_channels_refused(channel):
    """A motor on channel 4 or 5 is a ConfigError naming the real-time clock."""
    tio = TIO10()
    with pytest.raises(ConfigError, match="real-time clock"):
        Motor("m", tio, channel, 0.5, 7.0)
    assert tio.writes == 0


@pytest.mark.parametrize("start,cruise,match", [
    (0.05, 7.0, "below the minimum 0.07"),
    (0.5, 7.5, "above the limit 7.0"),
    (2.0, 1.0, "below the start speed"),
    (float("nan"), 7.0, "finite"),
])
def test_speed_limits_enforced(start, cruise, match):
    """Start speed >= 0.07 and cruise <= 7.0 cm/s are enforced with clear errors."""
    tio = TIO10()
    with pytest.raises(ConfigError, match=match):
        Motor("m", tio, CH, start, cruise)
    assert tio.writes == 0


def test_power_up_state_is_windings_off():
    """A new motor is stopped with its windings off."""
    m, tio = _motor()
    assert not tio.armed(CH)
    assert not _windings_on(tio)
    assert m.state == OFF


@pytest.mark.parametrize("bad", ["8", 7.01, "fast", "", "nan", -1, 0.3, True])
def test_bad_maxspeed_changes_nothing(bad):
    """maxspeed above 7.0, below the start speed or malformed is refused; nothing changes."""
    m, tio = _motor()
    m.move(400)
    writes = tio.writes
    with pytest.raises(CommandError):
        m.maxspeed(bad)
    assert m.cruise_speed == 7.0
    assert tio.writes == writes


def test_maxspeed_sets_the_cruise_period():
    """maxspeed 2 caps the STEP_MODE cruise period at 2 cm/s."""
    m, tio = _motor()
    assert m.maxspeed("2") == 2.0
    m.move(4000)
    for _ in range(200):
        _pulse(tio, 10)
        m.poll()
    assert tio.period(CH) == m.cruise_period == 625  # 50 kHz / (2 cm/s * 40 /cm)


def test_step_mode_ramp_decrements_per_step_and_mirrors():
    """The period shrinks by 10 counts a step from the start speed's, cruises, and grows back
    by 10 a step over the same number of steps before the end; the motor stops itself."""
    m, tio = _motor()
    total = 1000
    m.move(total)
    assert tio.armed(CH) and _windings_on(tio)
    assert tio.bit(*DIR_BITS[CH])  # positive: pay out
    start = m.start_period
    assert tio.period(CH) == start == 2500
    periods = []
    taken = 0
    while tio.armed(CH):
        _pulse(tio, 1)
        taken += 1
        m.poll()
        if tio.armed(CH):
            periods.append(tio.period(CH))
    assert taken == total
    assert periods[0] == start - 10
    assert periods[9] == start - 100
    assert min(periods) == m.cruise_period
    assert periods[-1] == start - 10
    assert periods[:50] == periods[::-1][:50]  # the ramp down mirrors the ramp up
    assert not _windings_on(tio)
    assert m.state == OFF


def test_short_move_is_a_triangle():
    """A move too short to reach cruise accelerates for half and decelerates for half."""
    m, tio = _motor()
    m.move(-60)
    assert not tio.bit(*DIR_BITS[CH])  # negative: pay in
    periods = []
    while tio.armed(CH):
        _pulse(tio, 1)
        m.poll()
        periods.append(tio.period(CH) if tio.armed(CH) else None)
    assert min(p for p in periods if p) == m.start_period - 10 * 30
    assert m.position_steps == -60


def test_desired_steps_can_change_while_moving():
    """Raising the move's total while it runs makes the motor take the new total."""
    m, tio = _motor()
    m.move(100)
    for _ in range(50):
        _pulse(tio, 1)
        m.poll()
    m.set_desired_steps(300)
    n = 50
    while tio.armed(CH):
        _pulse(tio, 1)
        n += 1
        m.poll()
    assert n == 300


def test_stop_switches_windings_off():
    """stop disarms the channel and switches the windings off."""
    m, tio = _motor()
    m.move(1000)
    _pulse(tio, 5)
    m.poll()
    m.stop()
    assert not tio.armed(CH)
    assert not _windings_on(tio)
    assert m.state == OFF


def test_velocity_mode_dv_limit_and_reversal_through_standby():
    """Velocity changes by at most DV_LIMIT a poll and reverses only through standby, where
    the windings are off."""
    m, tio = _motor()
    m.velocity_mode()
    assert m.mode == VELOCITY_MODE and m.state == STANDBY
    assert not tio.armed(CH)
    m.set_desired_velocity(2.0)
    seen = []
    for _ in range(5):
        m.poll()
        seen.append(m.velocity)
    assert seen == [0.5, 1.0, 1.5, 2.0, 2.0]
    assert m.state == ON and tio.armed(CH) and _windings_on(tio)
    assert tio.period(CH) == m.period_for(2.0)
    m.set_desired_velocity(-1.0)
    seen = []
    for _ in range(7):
        m.poll()
        seen.append((m.velocity, m.state))
    assert [v for v, _ in seen] == [1.5, 1.0, 0.5, 0.0, -0.5, -1.0, -1.0]
    assert seen[3][1] == STANDBY
    assert not tio.bit(*DIR_BITS[CH])
    m.set_desired_velocity(0.0)
    for _ in range(3):
        m.poll()
    assert m.state == STANDBY and not tio.armed(CH) and not _windings_on(tio)


def test_velocity_is_clamped_to_cruise():
    """A desired velocity beyond the cruise speed is held at the cruise speed."""
    m, _ = _motor(cruise_speed=3.0)
    m.velocity_mode()
    m.set_desired_velocity(10.0)
    assert m.desired_velocity == 3.0
    with pytest.raises(CommandError):
        m.set_desired_velocity(float("inf"))


def test_bad_step_count_refused():
    """A move must be a whole number of steps; a refused move touches no register."""
    m, tio = _motor()
    writes = tio.writes
    with pytest.raises(CommandError):
        m.move(2.5)
    assert tio.writes == writes and not tio.armed(CH)


def test_from_record_uses_database_values():
    """Motor.from_record takes channel, speeds and constants from a MotorRecord."""
    from pyrt.db import load_station, station_directory

    rec = load_station(station_directory("prototype")).motor("motor1")
    m = Motor.from_record(rec, TIO10(), name="axis1Motor")
    assert (m.name, m.channel, m.start_speed, m.cruise_speed) == ("axis1Motor", 8, 0.5, 7.0)
    assert m.ramp_decrement == rec.ramp_decrement and m.dv_limit == rec.dv_limit
