"""The rope world's step at rest: what it skips while no channel counts changes nothing it gives."""

from __future__ import annotations

import pytest

from pyrt.boards.dataconcentrator import DataConcentrator
from pyrt.boards.tio10 import AWO_BITS, DIR_BITS, TIO10
from pyrt.db import load_station, station_directory
from pyrt.sim.manipulator import ManipulatorPlant, rig_from_station
from pyrt.sim.sensors import Imperfections

MS = 1_000_000


@pytest.fixture(scope="module")
def rig():
    return rig_from_station(load_station(station_directory("prototype")))


def _plant(rig, imp=None):
    tio, dc = TIO10(), DataConcentrator()
    plant = ManipulatorPlant(rig, tio.registers, dc.registers,
                             imperfections=imp or Imperfections.ideal())
    return plant, tio, dc


def _arm(tio, channel, period, payout=True):
    tio.select_source(channel, 3)
    tio.load_period(channel, period)
    tio.set_bit(*DIR_BITS[channel], payout)
    tio.set_bit(*AWO_BITS[channel], False)
    tio.arm(channel)


@pytest.mark.parametrize("period", [333, 500, 1250])
def test_a_world_left_at_rest_moves_as_one_that_never_moved(rig, period):
    """A motor stopped part-way through a period, the world left at rest, then armed again,
    counts exactly as in a world armed for the first time at that moment (its phase was 0)."""
    ch = rig.ropes[1].channel
    moved, tio_a, _ = _plant(rig)
    _arm(tio_a, ch, period)
    for t in range(0, 37):  # a few pulses and part of one more: the phase is not 0
        moved.step(t * MS)
    assert moved.ropes[1].phase != 0.0
    tio_a.disarm(ch)
    tio_a.set_bit(*AWO_BITS[ch], True)
    fresh, tio_b, _ = _plant(rig)
    fresh.step(0)
    for t in range(37, 300):  # at rest: every step after the first has nothing to move
        moved.step(t * MS)
        fresh.step(t * MS)
    assert moved.ropes[1].phase == 0.0
    before = tio_a.pulses(ch)
    _arm(tio_a, ch, period)
    _arm(tio_b, ch, period)
    for t in range(300, 1300):
        moved.step(t * MS)
        fresh.step(t * MS)
    assert tio_a.pulses(ch) - before == tio_b.pulses(ch) > 0
    assert moved.ropes[1].phase == fresh.ropes[1].phase


def test_at_rest_the_clock_and_the_loadcells_still_move_every_step(rig):
    """At rest (nothing armed) every step still sets the real-time clock and converts the
    loadcells, their noise included, and moves no rope."""
    plant, tio, dc = _plant(rig, Imperfections(seed=7))
    payouts = [st.payout for st in plant.ropes]
    codes = set()
    for t in range(0, 100):
        plant.step(t * MS)
        assert tio.rtc_ticks() == t * 5_000
        codes.add(tuple(dc.registers.values("adc")))
    assert len(codes) > 10
    assert [st.payout for st in plant.ropes] == payouts
    assert all(st.phase == 0.0 for st in plant.ropes)
