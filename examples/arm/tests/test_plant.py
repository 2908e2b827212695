"""The simulated arm: dynamics with friction, the torque limit, encoders and injected faults."""

from __future__ import annotations

import dataclasses
import itertools
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pyrt_arm.kinematics import fk
from pyrt_arm.plant import (
    ELBOW_DRIVE,
    MAX_STEP_S,
    SHOULDER_DRIVE,
    Plant,
    PlantParams,
    wrap_int32,
)

MS = 1e-3


def frictionless() -> PlantParams:
    motors = tuple(dataclasses.replace(m, viscous_nm_s_per_rad=0.0, coulomb_nm=0.0)
                   for m in (SHOULDER_DRIVE, ELBOW_DRIVE))
    # end stops out of the way: the arm may spin freely
    return PlantParams(motors=motors, hard_stops_deg=((-1e6, 1e6), (-1e6, 1e6)))  # type: ignore[arg-type]


def snapshot(plant: Plant) -> tuple[object, ...]:
    return (plant.q_deg, plant.qd_deg_s, plant.counts(), plant.time_s, plant.current_a)


def test_energy_decays_with_friction_and_no_drive_until_the_arm_sticks():
    """Coasting from 200 and -150 deg/s with zero drive, the kinetic energy never rises and the arm comes to rest and stays."""
    plant = Plant(q_deg=(10.0, 40.0), qd_deg_s=(200.0, -150.0))
    energies = [plant.kinetic_energy_j()]
    for _ in range(3000):
        plant.step(MS)
        energies.append(plant.kinetic_energy_j())
    assert energies[0] > 0.5
    assert all(b <= a + 1e-12 for a, b in itertools.pairwise(energies))
    assert energies[-1] == 0.0
    rest = plant.q_deg
    for _ in range(200):
        plant.step(MS)
    assert plant.q_deg == rest


def test_without_friction_energy_and_the_shoulder_momentum_are_kept():
    """With friction removed and no drive, kinetic energy and the momentum conjugate to q0 stay within 0.5 % over 2 s."""
    params = frictionless()
    plant = Plant(params, q_deg=(0.0, 30.0), qd_deg_s=(120.0, -200.0))

    def momentum() -> float:
        (m00, m01), _ = params.mass_matrix(plant.q_deg[1])
        v0, v1 = (math.radians(v) for v in plant.qd_deg_s)
        return m00 * v0 + m01 * v1

    e0, p0 = plant.kinetic_energy_j(), momentum()
    for _ in range(2000):
        plant.step(MS)
        assert plant.kinetic_energy_j() == pytest.approx(e0, rel=5e-3)
        assert momentum() == pytest.approx(p0, rel=5e-3)
    assert plant.q_deg[1] != pytest.approx(30.0, abs=10.0)  # the elbow did swing


@pytest.mark.parametrize("drive", [1.0, 2.5, 37.0])
def test_torque_limited_step_reaches_the_limit_torque_and_no_more(drive):
    """Any drive at or beyond the current limit gives exactly the limit torque, and the shoulder (elbow braked) speeds up as J w' = tau_max - b w - f_c predicts."""
    plant = Plant()
    plant.jam(1)
    plant.drive[0] = drive
    limit = SHOULDER_DRIVE.torque_limit_nm
    assert limit == pytest.approx(12.0)
    (m00, _), _ = plant.params.mass_matrix(0.0)
    b, fc = SHOULDER_DRIVE.viscous_nm_s_per_rad, SHOULDER_DRIVE.coulomb_nm
    w_final = (limit - fc) / b
    for k in range(1, 301):
        plant.step(MS)
        assert plant.torque_nm[0] == limit
        assert plant.current_a[0] == SHOULDER_DRIVE.current_limit_a
        t = k * MS
        expected = w_final * (1.0 - math.exp(-b * t / m00))
        assert math.radians(plant.qd_deg_s[0]) == pytest.approx(expected, rel=2e-3)
    assert plant.qd_deg_s[1] == 0.0


def test_negative_drive_saturates_at_minus_the_limit_and_small_drive_is_proportional():
    """Drive -1 gives minus the limit torque; drive 0.1 gives Kt * 0.1 * amp_gain * gear, below the limit."""
    plant = Plant()
    plant.drive[:] = [-1.0, 0.1]
    plant.step(MS)
    assert plant.torque_nm[0] == -SHOULDER_DRIVE.torque_limit_nm
    assert plant.torque_nm[1] == pytest.approx(0.1 * ELBOW_DRIVE.torque_per_drive_nm)
    assert abs(plant.torque_nm[1]) < ELBOW_DRIVE.torque_limit_nm


def test_a_drive_within_coulomb_friction_leaves_the_arm_at_rest():
    """A torque below the Coulomb friction does not move a joint at rest (it sticks, no creep)."""
    plant = Plant(q_deg=(20.0, 20.0))
    plant.jam(1)
    plant.drive[0] = 0.9 * SHOULDER_DRIVE.coulomb_nm / SHOULDER_DRIVE.torque_per_drive_nm
    for _ in range(500):
        plant.step(MS)
    assert plant.q_deg[0] == pytest.approx(20.0, abs=1e-12)
    plant.drive[0] *= 1.5 / 0.9
    plant.step(0.05)
    assert plant.q_deg[0] > 20.0


@settings(max_examples=20, deadline=None)
@given(a0=st.floats(-1.0, 1.0), a1=st.floats(-1.0, 1.0), f0=st.floats(0.5, 5.0),
       f1=st.floats(0.5, 5.0))
def test_encoder_counts_track_q_within_one_count(a0, a1, f0, f1):
    """Under any sinusoidal drive the counter stays within one count of q times counts per degree."""
    plant = Plant()
    for k in range(400):
        t = k * MS
        plant.drive[:] = [a0 * math.sin(2 * math.pi * f0 * t), a1 * math.sin(2 * math.pi * f1 * t)]
        plant.step(MS)
        for j in (0, 1):
            exact = plant.q_deg[j] * plant.counts_per_deg(j)
            assert abs(plant.count(j) - exact) <= 1.0


def test_encoder_resolution_is_4096_per_motor_turn_times_the_gear():
    """One joint turn is 4096 x 50 = 204800 counts: 568.9 counts per degree."""
    plant = Plant(q_deg=(90.0, -45.0))
    assert plant.counts_per_deg(0) == pytest.approx(204800 / 360)
    assert plant.counts() == (51200, -25600)


def test_encoder_wraps_as_a_32_bit_signed_counter():
    """Preset near 2**31 - 1, the counter wraps to -2**31 and on as the joint turns on."""
    plant = Plant()
    plant.preset_encoder(0, 2**31 - 100)
    assert plant.count(0) == 2**31 - 100
    plant.drive[0] = 0.3
    while plant.q_deg[0] < 1.0:
        plant.step(MS)
    travelled = math.floor(plant.q_deg[0] * plant.counts_per_deg(0))
    assert plant.count(0) < 0
    assert plant.count(0) == wrap_int32(2**31 - 100 + travelled)
    assert wrap_int32(plant.count(0) - (2**31 - 100)) == travelled


def test_wrap_int32_keeps_the_signed_range():
    """wrap_int32 maps 2**31 to -2**31 and -2**31 - 1 to 2**31 - 1, and leaves the range alone."""
    assert wrap_int32(2**31) == -(2**31)
    assert wrap_int32(-(2**31) - 1) == 2**31 - 1
    assert wrap_int32(12345) == 12345


def test_a_jammed_joint_stays_put_under_full_drive_while_the_other_moves():
    """A braked shoulder holds its angle exactly under full drive; the elbow still moves; released, the shoulder moves."""
    plant = Plant(q_deg=(30.0, 10.0), qd_deg_s=(50.0, 0.0))
    plant.jam(0)
    assert plant.qd_deg_s[0] == 0.0
    held = plant.q_deg[0]
    count = plant.count(0)
    plant.drive[:] = [1.0, 0.5]
    for _ in range(500):
        plant.step(MS)
        assert plant.q_deg[0] == held
        assert plant.qd_deg_s[0] == 0.0
    assert plant.count(0) == count
    assert plant.q_deg[1] > 20.0
    assert plant.active_faults() == ["q0 jammed"]
    plant.jam(0, False)
    plant.step(0.02)
    assert plant.q_deg[0] > held


def test_a_disconnected_encoder_freezes_and_counts_on_from_there_when_reconnected():
    """With the elbow's encoder off its counter holds while the joint moves; reconnected it counts on from the frozen value."""
    plant = Plant()
    plant.drive[1] = 0.4
    plant.step(0.05)
    plant.disconnect_encoder(1)
    frozen = plant.count(1)
    q_off = plant.q_deg[1]
    plant.step(0.05)
    assert plant.count(1) == frozen
    assert plant.q_deg[1] > q_off + 1.0
    assert plant.active_faults() == ["q1 encoder disconnected"]
    plant.disconnect_encoder(1, False)
    q_on = plant.q_deg[1]
    plant.step(0.05)
    moved = (plant.q_deg[1] - q_on) * plant.counts_per_deg(1)
    assert abs(plant.count(1) - frozen - moved) <= 1.0


def test_motor_off_and_a_disabled_amplifier_give_no_torque():
    """A motor cut off (its status shows it), or an amplifier disabled, passes no current whatever the drive: the joint does not move."""
    plant = Plant()
    plant.motor_off(0)
    plant.amp_enable[1] = False
    plant.drive[:] = [1.0, -1.0]
    plant.step(0.1)
    assert plant.current_a == (0.0, 0.0)
    assert plant.q_deg == (0.0, 0.0)
    assert plant.active_faults() == ["q0 motor off"]
    assert (plant.motor_powered(0), plant.motor_powered(1)) == (False, True)
    plant.clear_faults()
    assert plant.motor_powered(0)
    plant.amp_enable[1] = True
    plant.step(0.01)
    assert plant.current_a[0] > 0.0 > plant.current_a[1]
    assert plant.active_faults() == []


def test_a_long_step_is_cut_into_internal_steps_of_at_most_0_2_ms():
    """step(10 ms) once lands where ten step(1 ms) do (both use 0.2 ms internal steps)."""
    a, b = Plant(), Plant()
    for plant in (a, b):
        plant.drive[:] = [0.5, -0.3]
    a.step(0.01)
    for _ in range(10):
        b.step(MS)
    assert MAX_STEP_S == 0.2e-3
    assert a.q_deg == pytest.approx(b.q_deg, abs=1e-12)
    assert a.qd_deg_s == pytest.approx(b.qd_deg_s, abs=1e-9)
    assert a.time_s == pytest.approx(0.01)


def test_uneven_steps_converge_on_the_same_motion():
    """Jittered loop periods (0.7 .. 1.3 ms) give the same motion to within 1e-3 deg after 0.3 s."""
    a, b = Plant(), Plant()
    for plant in (a, b):
        plant.drive[:] = [0.4, -0.2]
    for _ in range(300):
        a.step(MS)
    t = 0.0
    k = 0
    while t < 0.3 - 1e-12:
        dt = min((0.7e-3, 1.3e-3, 1.0e-3)[k % 3], 0.3 - t)
        b.step(dt)
        t += dt
        k += 1
    assert a.q_deg == pytest.approx(b.q_deg, abs=1e-3)


def test_a_joint_driven_into_its_end_stop_stops_there():
    """Driven without a servo, the elbow stops at its end stop (160 deg), with zero velocity, and stays."""
    plant = Plant(q_deg=(0.0, 100.0))
    plant.drive[1] = 1.0
    for _ in range(1000):
        plant.step(MS)
        assert plant.q_deg[1] <= 160.0
    assert plant.q_deg[1] == pytest.approx(160.0)
    assert plant.qd_deg_s[1] == 0.0


def test_the_true_tip_is_fk_of_the_true_angles():
    """tip_mm is the forward kinematics of the true joint angles."""
    plant = Plant(q_deg=(25.0, -60.0))
    plant.drive[:] = [0.2, 0.2]
    plant.step(0.05)
    assert plant.tip_mm == fk(*plant.q_deg)


@pytest.mark.parametrize("dt", [-1e-3, math.nan, math.inf, "1"])
def test_a_bad_step_is_refused_and_changes_nothing(dt):
    """step of a negative, non-finite or non-number dt is a ValueError and leaves the plant as it was."""
    plant = Plant(qd_deg_s=(10.0, 0.0))
    before = snapshot(plant)
    with pytest.raises(ValueError, match="dt_s"):
        plant.step(dt)
    assert snapshot(plant) == before


def test_a_non_finite_drive_is_refused_and_changes_nothing():
    """A NaN drive is a ValueError naming the joint, and the plant does not move."""
    plant = Plant(qd_deg_s=(10.0, 0.0))
    plant.drive[1] = math.nan
    before = snapshot(plant)
    with pytest.raises(ValueError, match=r"drive\[1\]"):
        plant.step(MS)
    assert snapshot(plant) == before


@pytest.mark.parametrize("joint", [2, -1, True, "q0"])
def test_an_unknown_joint_is_refused(joint):
    """Fault injection and encoder reads take joint 0 or 1 only."""
    plant = Plant()
    for call in (plant.jam, plant.disconnect_encoder, plant.motor_off, plant.count,
                 plant.motor_powered, plant.counts_per_deg):
        with pytest.raises(ValueError, match="joint must be 0"):
            call(joint)
    assert plant.active_faults() == []


def test_a_start_beyond_the_end_stops_or_a_bad_preset_is_refused():
    """The plant refuses a starting angle beyond the end stops, and a preset outside 32 bits."""
    with pytest.raises(ValueError, match="end stops"):
        Plant(q_deg=(179.0, 0.0))
    plant = Plant()
    with pytest.raises(ValueError, match="32-bit"):
        plant.preset_encoder(0, 2**31)
    assert plant.count(0) == 0
