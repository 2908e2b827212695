"""Encoder and Loadcell: conversions, Table 8 commands, loadcell calibration."""

from __future__ import annotations

import pytest

from pyrt.boards.dataconcentrator import AnalogChannel, DataConcentrator, DigitalChannel
from pyrt.devices.encoder import Encoder
from pyrt.devices.loadcell import Loadcell, parse_load
from pyrt.errors import CommandError, ConfigError
from pyrt.sim.cards import add_counts, set_adc


def _encoder(**kw):
    dc = DataConcentrator()
    add_counts(dc.registers, 168, 55)  # left over from before start-up
    enc = Encoder("axis0Encoder", DigitalChannel(dc, 168), 0.2392, 747.045410, **kw)
    return enc, dc


def test_encoder_resets_at_start_and_converts():
    """The counter is cleared at construction; length = ZEROLENGTH + SLOPE * count."""
    enc, dc = _encoder()
    assert enc.count() == 0
    assert enc.length() == pytest.approx(747.045410)
    add_counts(dc.registers, 168, -100)
    assert enc.length() == pytest.approx(747.045410 - 23.92)


def test_encoder_commands():
    """reset clears the counter; setZeroLength sets the zero length; read replies the value."""
    enc, dc = _encoder()
    add_counts(dc.registers, 168, 10)
    assert enc.read() == pytest.approx(747.045410 + 2.392)
    assert enc.find_command("read").lines(enc.read()) == ["749.437 cm"]
    enc.reset()
    assert enc.count() == 0
    assert enc.setZeroLength("500") == 500.0
    assert enc.length() == 500.0
    for bad in ("-1", "abc", float("inf")):
        with pytest.raises(CommandError):
            enc.setZeroLength(bad)
    assert enc.zero_length == 500.0


def test_encoder_readloop_says_every_poll():
    """readloop says the length (an info message from the encoder) at each poll until stoploop."""
    heard = []
    enc, _ = _encoder()
    enc.connect(tell=heard.append)
    enc.readloop()
    enc.poll(0.0)
    enc.poll(0.001)
    enc.stoploop()
    enc.poll(0.002)
    assert [(m.source, m.level) for m in heard] == [("axis0Encoder", "info")] * 2
    assert all(m.text.startswith("axis0Encoder: ") and m.text.endswith(" cm") for m in heard)


def test_encoder_holds_what_it_says_until_connected():
    """Said before anyone listens, the lines are held and handed over, in order, on connect."""
    enc, _ = _encoder()
    enc.readloop()
    enc.poll(0.0)
    enc.poll(0.001)
    held = enc.held_messages()
    assert len(held) == 2 and all(m.text.startswith("axis0Encoder: ") for m in held)
    heard = []
    enc.connect(tell=heard.append)
    assert heard == held
    assert enc.held_messages() == []


def test_zerolength_write_back_once_a_second_while_changing():
    """ZEROLENGTH is offered for write-back at most once a second, only when it changed."""
    written = []
    enc, dc = _encoder(write_back=written.append)
    for i in range(3000):  # 3 s at 1 ms, rope moving
        add_counts(dc.registers, 168, 1)
        enc.poll(i / 1000)
    assert len(written) == 3
    assert written[-1] == pytest.approx(enc.zero_length + 0.2392 * 2001, abs=1e-9)
    for i in range(3000, 6000):  # stationary: nothing more
        enc.poll(i / 1000)
    assert len(written) == 4  # the final value once, then silence


def test_encoder_config_errors():
    """A zero SLOPE is a ConfigError."""
    with pytest.raises(ConfigError):
        Encoder("e", DigitalChannel(DataConcentrator(), 1), 0.0, 10.0)


def _loadcell(**kw):
    dc = DataConcentrator()
    lc = Loadcell("axis0Loadcell", AnalogChannel(dc, 3), 0.6777730537, -482.535980,
                  maxload=222.4, **kw)
    return lc, dc


def test_loadcell_converts():
    """N = SLOPE * adc + OFFSET (Table 9)."""
    lc, dc = _loadcell()
    set_adc(dc.registers, 3, 800)
    assert lc.tension() == pytest.approx(0.6777730537 * 800 - 482.535980)


def test_loadcell_calibration_fits_by_least_squares():
    """Three points on a line give that line's slope and offset, handed to write-back."""
    saved = []
    lc, dc = _loadcell(write_back=lambda s, o: saved.append((s, o)))
    assert lc.calibrate() is None and lc.calibrating
    for code, load in ((700, "0"), (900, "100 N"), (1100, "200")):
        set_adc(dc.registers, 3, code)
        lc.point(load)
    slope, offset = lc.calibrate()
    assert slope == pytest.approx(0.5)
    assert offset == pytest.approx(-350.0)
    assert saved == [(slope, offset)]
    assert not lc.calibrating
    set_adc(dc.registers, 3, 1000)
    assert lc.tension() == pytest.approx(150.0)


def test_loadcell_calibration_with_hung_masses():
    """A point given as a hung mass is weighed with standard gravity; lb is pound-force."""
    assert parse_load("2 kg", "p") == pytest.approx(2 * 9.80665)
    assert parse_load("500g", "p") == pytest.approx(0.5 * 9.80665)
    assert parse_load("10 lb", "p") == pytest.approx(44.482216152605)
    for bad in ("-3", "2 furlongs", "heavy", "nan"):
        with pytest.raises(CommandError):
            parse_load(bad, "p")


def test_fewer_than_two_points_is_an_error():
    """Leaving calibration with fewer than two points is refused; the old fit stays."""
    saved = []
    lc, dc = _loadcell(write_back=lambda s, o: saved.append((s, o)))
    lc.calibrate()
    set_adc(dc.registers, 3, 800)
    lc.point(50)
    with pytest.raises(CommandError, match="at least two"):
        lc.calibrate()
    assert lc.calibrating
    assert (lc.slope, lc.offset) == (0.6777730537, -482.535980)
    assert saved == []


def test_points_at_one_code_are_an_error():
    """Two points at the same ADC code cannot fix a slope."""
    lc, dc = _loadcell()
    lc.calibrate()
    set_adc(dc.registers, 3, 800)
    lc.point(10)
    lc.point(20)
    with pytest.raises(CommandError, match="different loads"):
        lc.calibrate()


def test_point_outside_calibration_mode_is_an_error():
    """point without calibrate first is refused."""
    lc, _ = _loadcell()
    with pytest.raises(CommandError, match="calibration mode"):
        lc.point(10)


def test_keyboard_commands_by_name():
    """Encoder, Loadcell and Motor commands run by name; unknown names and wrong argument
    counts are CommandErrors."""
    from pyrt.boards.tio10 import TIO10
    from pyrt.devices.motor import Motor

    enc, dc = _encoder()
    add_counts(dc.registers, 168, 4)
    enc.run_command("reset")
    assert enc.count() == 0
    assert enc.run_command("SETZEROLENGTH", "12.5") == 12.5
    enc.run_command("readloop")
    assert enc.looping
    with pytest.raises(CommandError, match="unknown command"):
        enc.run_command("rewind")
    with pytest.raises(CommandError, match="takes 1 argument"):
        enc.run_command("setZeroLength")
    lc, dc = _loadcell()
    lc.run_command("calibrate")
    set_adc(dc.registers, 3, 700)
    lc.run_command("calibrationPoint", "0")
    set_adc(dc.registers, 3, 900)
    lc.run_command("point", "100")
    assert lc.run_command("calibrate") == pytest.approx((0.5, -350.0))
    m = Motor("axis0Motor", TIO10(), 7, 0.5, 7.0)
    assert m.run_command("maxspeed", "3") == 3.0
    with pytest.raises(CommandError):
        m.run_command("maxspeed", "3", "4")
