"""Readers bound once: the typed boards' readers, checked when bound, read what the checked reads give."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from pyrt.boards.dataconcentrator import (
    ADC_CHANNELS,
    COUNTER_ADDRESSES,
    DATACONCENTRATOR,
    AnalogChannel,
    DataConcentrator,
    DigitalChannel,
)
from pyrt.boards.image import ImageRegisters, LocalImage
from pyrt.boards.registers import RegisterBoard, outputs_off
from pyrt.boards.tio10 import CHANNELS, PIA_PORTS, RTC_CHANNELS, TIO10, TIO10_KIND
from pyrt.devices.motor import Motor
from pyrt.sim.cards import add_counts, add_pulses, set_adc

#: The TIO10's readers by channel, and the checked read each stands for.
TIO_READERS = [("armed_reader", "armed"), ("pulses_reader", "pulses"),
               ("period_reader", "period"), ("source_reader", "source")]


def _image(kind, name="b"):
    """A typed board of ``kind`` over a process image of its register file (as ``sim:``
    gives it), the register file, and the image, its phases running."""
    board = RegisterBoard(kind)
    image = LocalImage("sim:", {name: kind}, {name: board})
    image.open()
    image.set_tick(0.005)
    return kind.remote(ImageRegisters(image, name)), board, image


def _tick(image):
    image.read_phase(0)
    image.write_phase(0)


@pytest.mark.parametrize("bound, checked", TIO_READERS)
@pytest.mark.parametrize("over", ["register file", "image"])
def test_tio10_readers_read_what_the_checked_reads_give(bound, checked, over):
    """Every clock channel's bound reader gives what the checked read of that channel gives."""
    if over == "image":
        tio, regs, image = _image(TIO10_KIND)
    else:
        tio, regs, image = TIO10(), None, None
    for ch in (0, 3, 7, 9):
        tio.select_source(ch, 3)
        tio.load_period(ch, 100 + ch)
    tio.arm(7)
    add_pulses(tio.registers if regs is None else regs, 7, 123)
    if image is not None:
        _tick(image)
    for ch in CHANNELS:
        read = getattr(tio, bound)(ch)
        want = getattr(tio, checked)(ch)
        assert read() == want  # bool(armed) == the register's 1 or 0
    tio.disarm(7)
    if image is not None:
        _tick(image)
    assert tio.armed_reader(7)() == 0


def test_tio10_port_reader_reads_the_port_back():
    """A PIA port's bound reader reads what the last write left there."""
    tio = TIO10()
    readers = [tio.port_reader(p) for p in PIA_PORTS]
    tio.write_port(2, 0x5A)
    tio.set_bit(0, 3, True)
    assert [r() for r in readers] == [tio.read_port(p) for p in PIA_PORTS]
    assert readers[2]() == 0x5A


@pytest.mark.parametrize("bad", [-1, 10, 3.0, True, "7", None])
@pytest.mark.parametrize("bound", [b for b, _ in TIO_READERS])
def test_tio10_reader_of_a_bad_channel_is_refused_when_bound(bound, bad):
    """A channel the period register does not have is a ValueError naming 0..9 at binding."""
    with pytest.raises(ValueError, match=r"0\.\.9"):
        getattr(TIO10(), bound)(bad)


@pytest.mark.parametrize("channel", RTC_CHANNELS)
def test_tio10_reads_the_rtc_channels_as_the_checked_reads_do(channel):
    """The real-time clock's channels may be read (as armed() and pulses() read them)."""
    tio = TIO10()
    assert tio.armed_reader(channel)() == int(tio.armed(channel))
    assert tio.pulses_reader(channel)() == tio.pulses(channel)


@pytest.mark.parametrize("bad", [-1, 4, 1.0])
def test_tio10_port_reader_of_a_bad_port_is_refused(bad):
    """Only ports 0..3 are PIA ports."""
    with pytest.raises(ValueError, match=r"0\.\.3"):
        TIO10().port_reader(bad)


@given(counts=st.lists(st.tuples(st.sampled_from([0, 1, 168, 255]),
                                 st.integers(-(1 << 24), 1 << 24)), max_size=20),
       code=st.integers(-10, 5000))
def test_dataconcentrator_readers_read_what_the_checked_reads_give(counts, code):
    """Counter and ADC readers give read_counter/read_adc; a channel's count and code agree."""
    dc = DataConcentrator()
    for address, n in counts:
        add_counts(dc.registers, address, n)
    set_adc(dc.registers, 3, code)
    for address in (0, 1, 168, 255):
        assert dc.counter_reader(address)() == dc.read_counter(address)
        channel = DigitalChannel(dc, address)
        assert channel.raw() == dc.read_counter(address)
        raw = dc.read_counter(address)
        assert channel.count() == (raw - (1 << 24) if raw >= 1 << 23 else raw)
    assert dc.adc_reader(3)() == dc.read_adc(3) == AnalogChannel(dc, 3).code()


@pytest.mark.parametrize("bad", [-1, 256, 1.5, True])
def test_counter_reader_of_a_bad_address_is_refused(bad):
    """A counter address outside 0..255 is refused when the reader is bound."""
    with pytest.raises(ValueError, match=r"0\.\.255"):
        DataConcentrator().counter_reader(bad)
    assert len(COUNTER_ADDRESSES) == 256


@pytest.mark.parametrize("bad", [-1, 16, "3"])
def test_adc_reader_of_a_bad_channel_is_refused(bad):
    """An ADC channel outside 0..15 is refused when the reader is bound."""
    with pytest.raises(ValueError, match=r"0\.\.15"):
        DataConcentrator().adc_reader(bad)
    assert len(ADC_CHANNELS) == 16


def test_a_cleared_counter_reads_zero_through_its_reader_in_the_same_tick():
    """Over an image, a counter cleared in a tick reads 0 through a reader bound before."""
    dc, regs, image = _image(DATACONCENTRATOR)
    add_counts(regs, 168, 42)
    _tick(image)
    ch = DigitalChannel(dc, 168)
    image.read_phase(0)
    assert ch.count() == 42
    ch.reset()
    assert ch.count() == 0 and ch.raw() == 0
    image.write_phase(0)


def test_a_motor_sees_its_channel_turned_off_from_outside():
    """A motor's bound armed reader follows the register: outputs turned off stop its running."""
    tio, _regs, image = _image(TIO10_KIND)
    m = Motor("axis0Motor", tio, 7, 0.5, 7.0)
    image.read_phase(0)
    m.move(400)
    assert m.running and m.armed() == 1 and m.speed() > 0
    image.write_phase(0)
    outputs_off(TIO10_KIND, tio.registers)  # the watchdog's outputs, not the motor's
    _tick(image)
    assert not m.running and m.armed() == 0 and m.speed() == 0.0
    assert m.running == tio.armed(7)
