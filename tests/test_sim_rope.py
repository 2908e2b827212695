"""The rope-and-source physics: statics kernel against its reference, and the plant."""

from __future__ import annotations

import dataclasses
import math

import _ref_statics as ref
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from pyrt.boards.dataconcentrator import DataConcentrator
from pyrt.boards.tio10 import AWO_BITS, DIR_BITS, TIO10
from pyrt.db import load_station, station_directory
from pyrt.errors import NativeError
from pyrt.native import StaticsSolver, rope_lengths
from pyrt.sim.manipulator import GRAVITY, ManipulatorPlant, rig_from_station
from pyrt.sim.sensors import Imperfections

MASS = 5.3357
WEIGHT = MASS * GRAVITY

# Five-rope geometry of the full-scale station (global = vessel co-ordinates).
TOPS5 = [(0, 0, 1299.0), (60, 0, 1299.0), (-60, 0, 1299.0), (0, 60, 1299.0), (0, -60, 1299.0)]
BOTS5 = [None, (545.44, 0, -250.0), (-545.44, 0, -250.0), (0, 545.44, -250.0),
         (0, -545.44, -250.0)]
OFFS5 = [(0, 0, 0), (5, 0, 0), (-5, 0, 0), (0, 5, 0), (0, -5, 0)]
RING5 = ((0.0, 0.0, 595.8), (0.0, 0.0, 1.0), 72.5)

TOPS3 = [(0, 5, 389.0), (50, 0, 391.0), (-50, 0, 391.0)]
BOTS3 = [None, (317.0, 0, 89.53), (-317.0, 0, 89.53)]
OFFS3 = [(0, 0, 0)] * 3


def _bottoms_nan(bottoms):
    return [(math.nan,) * 3 if b is None else b for b in bottoms]


def _solver(tops, bots, offs, payout, *, compliance=1e-9, dead=50.0, ring=None,
            weight=WEIGHT, position=(0, 0, 0), max_iter=50):
    n = len(tops)
    return StaticsSolver(tops, bots, offs, [dead] * n, [compliance] * n, payout, ring=ring,
                         weight=weight, position=position, floor_z=-600.0, max_iter=max_iter)


def _in_rim(p):
    """Inside the neck ring's rim: a place the carriage cannot be."""
    return abs(p[2] - RING5[0][2]) < 10.0 and math.hypot(p[0], p[1]) > 65.0


@pytest.mark.parametrize("geometry,x", [
    ((TOPS3, BOTS3, OFFS3), (-0.2, 0.0, 95.57)),
    ((TOPS3, BOTS3, OFFS3), (40.0, 0.0, 150.0)),
    ((TOPS5, BOTS5, OFFS5), (0.0, 0.0, 0.0)),
    ((TOPS5, BOTS5, OFFS5), (120.0, -80.0, -200.0)),
])
def test_stiff_ropes_at_rope_lengths_return_the_position(geometry, x):
    """With the lengths rope_lengths gives for a position and stiff ropes, the physics returns
    that position (to 0.005 cm: the ropes still stretch by micrometres under the weight, which
    the prototype's soft sideways direction amplifies)."""
    tops, bots, offs = geometry
    lengths = rope_lengths(x, tops, _bottoms_nan(bots), offs)
    payout = [50.0 + g for g in lengths]
    s = _solver(tops, bots, offs, payout, position=(x[0] + 3.0, x[1] - 2.0, x[2] + 4.0))
    assert s.solve()
    assert math.dist(s.position, x) < 5e-3


@pytest.mark.parametrize("tops,bots,offs,x,volume", [
    (TOPS3, BOTS3, OFFS3, (-0.2, 0.0, 95.57), 0.0),
    (TOPS5, BOTS5, OFFS5, (100.0, 50.0, -100.0), 0.0),
    (TOPS5, BOTS5, OFFS5, (100.0, 50.0, -100.0), 1000.0),
])
def test_tensions_balance_weight_and_buoyancy(tops, bots, offs, x, volume):
    """The rope forces balance the weight less the D2O buoyancy to 0.1 %."""
    weight = (MASS - 1.10e-3 * volume) * GRAVITY
    lengths = rope_lengths(x, tops, _bottoms_nan(bots), offs)
    payout = [50.0 + g - 0.5 for g in lengths]  # every rope in tension
    s = StaticsSolver(tops, bots, offs, [50.0] * len(tops), [2e-5] * len(tops), payout,
                      weight=weight, position=x, floor_z=-600.0)
    assert s.solve()
    t = s.tensions()
    t_ref, _, _, _ = ref.tensions_and_force(tops, bots, offs, [50.0] * len(tops),
                                            [2e-5] * len(tops), payout, s.position, weight)
    assert t == pytest.approx(t_ref, rel=1e-9, abs=1e-9)
    lift = [0.0, 0.0, 0.0]
    for i in range(len(tops)):
        _, pull, _ = ref.rope(tops[i], bots[i], offs[i], s.position, None)
        for k in range(3):
            lift[k] += t[i] * pull[k]
    assert abs(lift[2] - weight) <= 1e-3 * weight
    assert math.hypot(lift[0], lift[1]) <= 1e-3 * weight
    assert s.residual <= 1e-3 * weight


def test_lengthened_rope_goes_slack_rather_than_pushing():
    """Paying out 20 cm more on the central rope leaves it slack with zero tension; the side
    ropes hold the source where it was instead of the rope pushing it down."""
    x = (30.0, 0.0, 120.0)
    lengths = rope_lengths(x, TOPS3, _bottoms_nan(BOTS3), OFFS3)
    payout = [50.0 + g - 0.3 for g in lengths]
    s = _solver(TOPS3, BOTS3, OFFS3, payout, compliance=2e-5, position=x)
    assert s.solve()
    assert all(t > 0 for t in s.tensions())
    before = s.position
    payout[0] += 20.0
    s.set_payouts(payout)
    assert s.solve()
    t = s.tensions()
    assert t[0] == 0.0
    g, _, _ = s.evaluate(s.position)
    assert 50.0 + g[0] < payout[0] - 15.0  # the path is far shorter than the rope: slack
    assert abs(s.position[2] - before[2]) < 1.0 and abs(s.position[0] - before[0]) < 1.0
    assert t[1] > 0 and t[2] > 0


@settings(max_examples=30, deadline=None)
@given(extra=st.lists(st.floats(0.0, 50.0), min_size=5, max_size=5))
def test_tensions_are_never_negative(extra):
    """However much rope is payed out, no rope pushes: every tension is >= 0."""
    x = (50.0, -20.0, 0.0)
    lengths = rope_lengths(x, TOPS5, _bottoms_nan(BOTS5), OFFS5)
    payout = [50.0 + g + e for g, e in zip(lengths, extra, strict=True)]
    s = _solver(TOPS5, BOTS5, OFFS5, payout, compliance=2e-5, ring=RING5, position=x)
    s.solve()
    assert all(t >= 0.0 for t in s.tensions())


def test_rope_bears_on_the_neck_ring():
    """A top segment that would pass outside the neck ring wraps over it: longer than the
    straight line, and matching the reference's shortest path over the ring."""
    x = (350.0, 0.0, 100.0)
    s = _solver(TOPS5, BOTS5, OFFS5, [3000.0] * 5, ring=RING5)
    g, _, wrapped = s.evaluate(x)
    assert all(wrapped)
    straight = math.dist(TOPS5[0], x)
    assert g[0] > straight + 1.0
    for i in range(5):
        g_ref, _, w_ref = ref.rope(TOPS5[i], BOTS5[i], OFFS5[i], x, RING5)
        assert w_ref
        assert g[i] == pytest.approx(g_ref, abs=1e-6)
    _, _, near_axis = s.evaluate((10.0, 0.0, 100.0))
    assert not any(near_axis)


def test_side_ropes_bear_on_the_ring_from_below_with_the_source_in_the_neck():
    """With the source up in the neck the side ropes run down through the ring to their
    bottom attachments and bear on it from below; the equilibrium balances there too."""
    x = (0.0, 0.0, 800.0)
    s = _solver(TOPS5, BOTS5, OFFS5, [3000.0] * 5, ring=RING5, compliance=2e-5, position=x)
    g, _, wrapped = s.evaluate(x)
    assert wrapped == [False, True, True, True, True]
    for i in range(5):
        g_ref, _, w_ref = ref.rope(TOPS5[i], BOTS5[i], OFFS5[i], x, RING5)
        assert w_ref == wrapped[i]
        assert g[i] == pytest.approx(g_ref, abs=1e-6)
    payout = [50.0 + gi - 0.4 for gi in g]
    s.set_payouts(payout)
    assert s.solve()
    _, force, _, _ = ref.tensions_and_force(TOPS5, BOTS5, OFFS5, [50.0] * 5, [2e-5] * 5,
                                            payout, s.position, WEIGHT, RING5)
    assert math.sqrt(sum(f * f for f in force)) < 1e-4 * WEIGHT
    assert math.dist(s.position, x) < 1.0


def test_equilibrium_with_ropes_on_the_ring_balances():
    """Off to the side, with ropes bearing on the ring, the reference net force is ~0."""
    x = (380.0, 40.0, 150.0)
    s = _solver(TOPS5, BOTS5, OFFS5, [3000.0] * 5, ring=RING5, compliance=2e-5, position=x)
    g, _, _ = s.evaluate(x)
    payout = [50.0 + gi - 0.4 for gi in g]
    s.set_payouts(payout)
    assert s.solve()
    assert any(s.wrapped())
    ts, force, _, _ = ref.tensions_and_force(TOPS5, BOTS5, OFFS5, [50.0] * 5, [2e-5] * 5,
                                             payout, s.position, WEIGHT, RING5)
    assert math.sqrt(sum(f * f for f in force)) < 1e-4 * WEIGHT
    assert s.tensions() == pytest.approx(ts, rel=1e-6, abs=1e-6)


@settings(max_examples=40, deadline=None)
@given(
    x=st.tuples(st.floats(-300, 300), st.floats(-300, 300), st.floats(-250, 1100)),
    slack=st.lists(st.floats(-2.0, 1.0), min_size=5, max_size=5),
)
def test_c_equilibrium_matches_the_reference(x, slack):
    """For random positions and rope lengths the C equilibrium is a zero of the reference's
    net force, with the reference's tensions.  (Positions inside the ring's rim, where the
    carriage itself would cut through the ring, are not places a source can be.)"""
    assume(not _in_rim(x))
    # Some ropes may go slack and the source swing hundreds of centimetres: allow the
    # iterations for that (the plant's steps are small and warm-started).
    s = _solver(TOPS5, BOTS5, OFFS5, [3000.0] * 5, ring=RING5, compliance=2e-5, position=x,
                max_iter=400)
    g, _, _ = s.evaluate(x)
    payout = [50.0 + gi + d for gi, d in zip(g, slack, strict=True)]
    s.set_payouts(payout)
    converged = s.solve()
    assume(not _in_rim(s.position))  # the swing would have cut through the ring's rim
    assert converged
    ts, force, _, _ = ref.tensions_and_force(TOPS5, BOTS5, OFFS5, [50.0] * 5, [2e-5] * 5,
                                             payout, s.position, WEIGHT, RING5)
    if s.position[2] > -600.0 + 1e-9:  # not resting on the floor
        assert math.sqrt(sum(f * f for f in force)) < 1e-3 * WEIGHT
    assert s.tensions() == pytest.approx(ts, rel=1e-5, abs=1e-5)


def test_statics_refuses_bad_input():
    """Non-positive lengths or compliances and a carriage on a pulley are NativeErrors."""
    with pytest.raises(NativeError):
        s = _solver(TOPS3, BOTS3, OFFS3, [-1.0, 600.0, 600.0])
        s.solve()
    s = _solver(TOPS3, BOTS3, OFFS3, [400.0, 700.0, 700.0])
    with pytest.raises(NativeError):
        s.evaluate(TOPS3[1])


# -- the plant ------------------------------------------------------------------------


@pytest.fixture(scope="module")
def proto():
    return load_station(station_directory("prototype"))


def _plant(station, imp=None, **kw):
    rig = rig_from_station(station)
    tio, dc = TIO10(), DataConcentrator()
    plant = ManipulatorPlant(rig, tio.registers, dc.registers, imperfections=imp or Imperfections.ideal(), **kw)
    return plant, tio, dc


def _run(plant, t0_ms, ms):
    for i in range(t0_ms, t0_ms + ms):
        plant.step(i * 1_000_000)
    return t0_ms + ms


def _drive(tio, channel, period, payout):
    tio.select_source(channel, 3)
    tio.load_period(channel, period)
    tio.set_bit(*DIR_BITS[channel], payout)
    tio.set_bit(*AWO_BITS[channel], False)
    tio.arm(channel)


def test_plant_starts_in_equilibrium_at_the_database_position(proto):
    """The default payouts hold the prototype source at POLYAXIS POSITION."""
    plant, _, _ = _plant(proto)
    assert math.dist(plant.position, proto.polyaxis().position) < 0.05
    assert plant.converged


def test_plant_steps_by_elapsed_time(proto):
    """Pulses follow dt = now - last: 1 s at 500 counts of F3 is 100 pulses and 2.5 cm."""
    plant, tio, _ = _plant(proto)
    ch = plant.rig.ropes[0].channel
    before = plant.payout(0)
    _drive(tio, ch, 500, payout=True)
    plant.step(0)
    plant.step(1_000_000_000)  # one big step: an overrun is felt as elapsed time
    assert tio.pulses(ch) == 100
    assert plant.payout(0) - before == pytest.approx(100 / 40.0)


def test_encoder_counts_the_rope(proto):
    """The encoder register follows the payed-out rope in counts of SLOPE."""
    plant, tio, dc = _plant(proto)
    r = plant.rig.ropes[1]
    _drive(tio, r.channel, 500, payout=False)
    plant.step(0)
    plant.step(2_000_000_000)  # 200 pulses = 5 cm in
    raw = dc.read_counter(r.encoder_address)
    count = raw - (1 << 24) if raw >= 1 << 23 else raw
    assert count == round(-5.0 / r.encoder_cm_per_count)


def test_ideal_loadcells_read_the_tension(proto):
    """With imperfections off, SLOPE * adc + OFFSET is the rope tension to one ADC code."""
    plant, _, dc = _plant(proto)
    plant.step(0)
    for r, t in zip(plant.rig.ropes, plant.tensions(), strict=True):
        n = r.loadcell_slope * dc.read_adc(r.adc_channel) + r.loadcell_offset
        assert abs(n - t) <= abs(r.loadcell_slope)


def test_low_load_nonlinearity_without_bias_resistor():
    """Without the bias resistor a small load reads low; with it the error is within 0.7 %."""
    from pyrt.sim.sensors import loadcell_response

    off = Imperfections(bias_resistor=False, loadcell_nonlinearity=0.0)
    on = Imperfections(bias_resistor=True)
    assert loadcell_response(1.0, 222.4, off) < 0.5
    assert abs(loadcell_response(1.0, 222.4, on) - 1.0) <= 0.007 * 222.4
    assert loadcell_response(111.2, 222.4, on) == pytest.approx(111.2 + 0.007 * 222.4)


def test_loadcell_noise_and_offset_are_seeded_and_switchable(proto):
    """Noise changes readings from step to step; the same seed repeats them exactly."""
    imp = Imperfections(loadcell_noise=2.0, seed=7)
    a, _, dca = _plant(proto, imp)
    b, _, dcb = _plant(proto, imp)
    ch = a.rig.ropes[1].adc_channel
    seq_a, seq_b = [], []
    for i in range(20):
        a.step(i)
        b.step(i)
        seq_a.append(dca.read_adc(ch))
        seq_b.append(dcb.read_adc(ch))
    assert seq_a == seq_b
    assert len(set(seq_a)) > 1


def test_faults_show_at_the_sensors(proto):
    """Slip, stall, dead and stuck loadcells and a broken rope are visible in the registers."""
    plant, tio, dc = _plant(proto)
    r0, r1, r2 = plant.rig.ropes
    t = 0
    # slip: the motor pays out but the encoder does not count
    plant.inject_slip(0)
    _drive(tio, r0.channel, 500, payout=True)
    before = plant.payout(0)
    t = _run(plant, t, 500)
    assert plant.payout(0) > before + 1.0
    assert dc.read_counter(r0.encoder_address) == 0
    plant.clear_faults(0)
    # stall: pulses are issued, nothing moves
    plant.inject_stall(0)
    p0, pulses0 = plant.payout(0), tio.pulses(r0.channel)
    t = _run(plant, t, 500)
    assert tio.pulses(r0.channel) != pulses0
    assert plant.payout(0) == p0
    tio.disarm(r0.channel)
    # dead and stuck loadcells
    plant.inject_loadcell_dead(1)
    plant.inject_loadcell_stuck(2)
    stuck = dc.read_adc(r2.adc_channel)
    _drive(tio, r2.channel, 500, payout=False)  # tension on rope 2 changes
    t = _run(plant, t, 500)
    assert dc.read_adc(r1.adc_channel) == 0
    assert dc.read_adc(r2.adc_channel) == stuck
    tio.disarm(r2.channel)
    plant.clear_faults(1)
    plant.clear_faults(2)
    # rope break: the rope carries nothing, its loadcell reads no load
    plant.break_rope(1)
    t = _run(plant, t, 2)
    assert plant.tensions()[1] == 0.0
    n = r1.loadcell_slope * dc.read_adc(r1.adc_channel) + r1.loadcell_offset
    assert abs(n) <= abs(r1.loadcell_slope)


def test_windings_off_means_no_motion(proto):
    """With the all-windings-off bit set the clock pulses but the spindle does not turn."""
    plant, tio, _ = _plant(proto)
    ch = plant.rig.ropes[0].channel
    _drive(tio, ch, 500, payout=True)
    tio.set_bit(*AWO_BITS[ch], True)
    before = plant.payout(0)
    _run(plant, 0, 300)
    assert plant.payout(0) == before
    assert tio.pulses(ch) > 0


def test_buoyancy_only_when_submerged(proto):
    """A source with volume is lighter by 1.10 g/cm3 below the D2O surface, not above it."""
    rig = rig_from_station(proto)
    wet = dataclasses.replace(rig, volume=1000.0, liquid_level=200.0)
    dry = dataclasses.replace(rig, volume=1000.0, liquid_level=50.0)
    tio, dc = TIO10(), DataConcentrator()
    p_wet = ManipulatorPlant(wet, tio.registers, dc.registers, imperfections=Imperfections.ideal())
    p_dry = ManipulatorPlant(dry, TIO10().registers, DataConcentrator().registers,
                             imperfections=Imperfections.ideal())
    assert p_wet.weight == pytest.approx((MASS - 1.1) * GRAVITY)
    assert p_dry.weight == pytest.approx(MASS * GRAVITY)


def test_station_source_is_buoyant_below_the_neck():
    """By default the vessel is full to the neck ring: the SNO source (1000 cm3) is buoyed."""
    sno = load_station(station_directory("sno"))
    plant, _, _ = _plant(sno)
    assert plant.rig.liquid_level == pytest.approx(595.8)
    assert plant.weight == pytest.approx((sno.polyaxis().source_mass - 1.10) * GRAVITY)
    assert sum(plant.tensions()) > 0


def test_five_rope_station_settles(proto):
    """The full-scale station's source hangs at its database position with taut ropes."""
    sno = load_station(station_directory("sno"))
    plant, _, _ = _plant(sno)
    assert math.dist(plant.position, sno.polyaxis().position) < 0.05
    assert all(t > 0 for t in plant.tensions())


def test_with_every_rope_broken_the_source_rests_on_the_vessel_bottom(proto):
    """A source with no rope left falls to the vessel bottom and stays there."""
    plant, _, _ = _plant(proto)
    for i in range(3):
        plant.break_rope(i)
    _run(plant, 0, 200)  # the fall takes several steps: each solve's travel is limited
    assert plant.converged
    assert plant.position[2] == pytest.approx(plant.rig.floor_z)
    assert plant.tensions() == [0.0, 0.0, 0.0]


def test_partial_encoder_slip(proto):
    """An encoder slipping by 25 % counts three quarters of the rope."""
    plant, tio, dc = _plant(proto)
    r = plant.rig.ropes[2]
    plant.inject_slip(2, 0.25)
    _drive(tio, r.channel, 500, payout=True)
    plant.step(0)
    plant.step(4_000_000_000)  # 400 pulses = 10 cm out
    assert dc.read_counter(r.encoder_address) * r.encoder_cm_per_count == pytest.approx(
        7.5, abs=r.encoder_cm_per_count)
    with pytest.raises(ValueError):
        plant.inject_slip(2, 1.5)
