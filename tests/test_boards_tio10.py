"""The TIO10 and dataConcentrator views over their register files: checks from the declarations."""

from __future__ import annotations

import pytest

from pyrt.boards.dataconcentrator import (
    DATACONCENTRATOR,
    AnalogChannel,
    DataConcentrator,
    DigitalChannel,
)
from pyrt.boards.registers import RegisterBoard
from pyrt.boards.tio10 import AWO_BITS, DIR_BITS, RTC_CHANNELS, TIO10, TIO10_KIND, source_hz
from pyrt.sim.cards import add_counts, add_pulses, channel_period, set_adc, set_rtc


@pytest.mark.parametrize("channel", RTC_CHANNELS)
def test_rtc_channels_refused_for_output(channel):
    """Channels 4 and 5 (the real-time clock) refuse a period, a source and arming."""
    tio = TIO10()
    for op in (lambda: tio.load_period(channel, 100), lambda: tio.arm(channel),
               lambda: tio.select_source(channel, 3), lambda: tio.disarm(channel)):
        with pytest.raises(ValueError, match="real-time clock"):
            op()
    assert tio.writes == 0


@pytest.mark.parametrize("bad", [-1, 10, 3.0, True, "7"])
def test_bad_channel_numbers_refused(bad):
    """Only integers 0..9 name a clock channel."""
    with pytest.raises(ValueError, match=r"0\.\.9"):
        TIO10().load_period(bad, 100)


@pytest.mark.parametrize("period", [0, 1, 0x10000, -5])
def test_period_must_fit_the_16_bit_load_register(period):
    """Periods outside 2..65535 are refused and the register keeps its value."""
    tio = TIO10()
    tio.load_period(7, 500)
    with pytest.raises(ValueError, match="16-bit"):
        tio.load_period(7, period)
    assert tio.period(7) == 500


def test_arm_needs_a_period():
    """A channel with no period loaded cannot be armed."""
    tio = TIO10()
    with pytest.raises(ValueError, match="no period"):
        tio.arm(7)
    assert not tio.armed(7)


def test_sources_and_plant_period_in_clock_ticks():
    """F1..F5 divide the 5 MHz clock by powers of ten; the plant sees periods in 5 MHz ticks."""
    assert [source_hz(s) for s in range(1, 6)] == [5_000_000, 500_000, 50_000, 5_000, 500]
    tio = TIO10()
    tio.select_source(7, 3)
    tio.load_period(7, 250)
    tio.arm(7)
    assert channel_period(tio.registers, 7) == (25_000, True)
    with pytest.raises(ValueError, match=r"F1\.\.F5"):
        tio.select_source(7, 6)


def test_pia_bits_read_modify_write():
    """Setting one PIA bit leaves the others alone."""
    tio = TIO10()
    tio.write_port(0, 0b1010_0000)
    tio.set_bit(0, 1, True)
    assert tio.read_port(0) == 0b1010_0010
    tio.set_bit(0, 7, False)
    assert tio.read_port(0) == 0b0010_0010
    assert tio.bit(0, 5) and not tio.bit(0, 7)
    with pytest.raises(ValueError):
        tio.write_port(0, 256)
    with pytest.raises(ValueError):
        tio.set_bit(4, 0, True)


def test_motor_wiring_covers_the_eight_motor_channels():
    """Direction and windings-off bits exist for every channel but 4 and 5, all distinct."""
    assert sorted(DIR_BITS) == [0, 1, 2, 3, 6, 7, 8, 9]
    assert sorted(AWO_BITS) == sorted(DIR_BITS)
    bits = list(DIR_BITS.values()) + list(AWO_BITS.values())
    assert len(set(bits)) == len(bits)


def test_pulse_counter_and_rtc_wrap():
    """The pulse counter wraps at 16 bits; the RTC counts 5 MHz ticks modulo 2**32."""
    tio = TIO10()
    add_pulses(tio.registers, 8, 65_530)
    add_pulses(tio.registers, 8, 10)
    assert tio.pulses(8) == 4
    set_rtc(tio.registers, 1_000_000_000)
    assert tio.rtc_ticks() == 5_000_000
    set_rtc(tio.registers, 900_000_000_000)
    assert tio.rtc_ticks() == (900 * 5_000_000) % (1 << 32)


def test_a_view_over_any_register_file_writes_through_and_powers_up_at_f1():
    """A TIO10 over a register file of the kind writes its registers there; a channel counts F1
    at power-up; the writes counted are those made, a refused one is none."""
    regs = RegisterBoard(TIO10_KIND)
    tio = TIO10(regs)
    assert [tio.source(c) for c in range(10)] == [1] * 10 and tio.registers is regs
    tio.load_period(7, 300)
    tio.arm(7)
    with pytest.raises(ValueError, match=r"src: value must be an integer 0\.\.7"):
        tio.select_source(7, 8)
    assert regs.output("per", 7) == 300 and regs.output("armed", 7) == 1 and tio.writes == 2


def test_counter_channel_is_signed_24_bit():
    """A counter that counted below zero reads negative through DigitalChannel."""
    dc = DataConcentrator()
    ch = DigitalChannel(dc, 168)
    add_counts(dc.registers, 168, -3)
    assert dc.read_counter(168) == (1 << 24) - 3
    assert ch.count() == -3
    ch.reset()
    assert ch.count() == 0


def test_adc_clamps_to_12_bits():
    """The ADC latches 0..4095 whatever the plant asks for."""
    dc = DataConcentrator()
    a = AnalogChannel(dc, 3)
    set_adc(dc.registers, 3, 5000)
    assert a.code() == 4095
    set_adc(dc.registers, 3, -7)
    assert a.code() == 0


@pytest.mark.parametrize("bad", [-1, 256, 1.5])
def test_bad_counter_address_refused(bad):
    """Counter addresses are 0..255."""
    with pytest.raises(ValueError, match=r"0\.\.255"):
        DigitalChannel(DataConcentrator(), bad)


def test_bad_adc_channel_refused():
    """ADC channels are 0..15."""
    with pytest.raises(ValueError, match=r"0\.\.15"):
        AnalogChannel(DataConcentrator(), 16)


def test_clearing_a_counter_is_the_declared_strobe():
    """clear_counter writes clr[a] = 1, which the declaration says clears cnt[a] in the register
    file; the other counters keep their counts."""
    regs = RegisterBoard(DATACONCENTRATOR)
    dc = DataConcentrator(regs)
    add_counts(regs, 168, 9)
    add_counts(regs, 169, 4)
    dc.clear_counter(168)
    assert (dc.read_counter(168), dc.read_counter(169)) == (0, 4) and regs.writes == 1
