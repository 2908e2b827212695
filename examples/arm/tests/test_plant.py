"""The simulated arm: its URDF's numbers, friction, the torque limit, encoders and injected
faults, behind the example's servo board."""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pyrt import RegisterBoard

from pyrt_arm.boards import SERVO, drive_counts
from pyrt_arm.kinematics import GEOMETRY, fk
from pyrt_arm.plant import CHAIN, MOTORS, PAYLOAD_KG, Plant, wrap_int32

MS = 1e-3


def plant_at(q_deg: Sequence[float] = (0.0, 0.0), qd_deg_s: Sequence[float] = (0.0, 0.0),
             **kw: float) -> Plant:
    """A plant behind a servo board of its own."""
    return Plant(RegisterBoard(SERVO), q_deg=q_deg, qd_deg_s=qd_deg_s, **kw)


def drive(plant: Plant, drives: Sequence[float], enable: int = 1) -> None:
    """The controller's side: each joint's drive (-1 .. 1 of full scale) and enable."""
    for j, d in enumerate(drives):
        plant.board.write("drive", drive_counts(d), j)
        plant.board.write("enable", enable, j)


def snapshot(plant: Plant) -> tuple[object, ...]:
    return (plant.q_deg, plant.qd_deg_s, plant.counts(), plant.time_s, plant.current_a)


def test_the_urdf_is_the_arms_geometry_and_limits():
    """The URDF's chain puts the tip where the arm's kinematics does, and its joint limits are the arm's."""
    for q in itertools.product((-150.0, -30.0, 0.0, 45.0, 140.0), repeat=2):
        tip = CHAIN.fk(np.radians(q))[:3, 3] * 1e3
        assert tip[:2] == pytest.approx(fk(*q), abs=1e-9)
        assert tip[2] == 0.0
    assert np.degrees(CHAIN.lower) == pytest.approx([lo for lo, _ in GEOMETRY.limits_deg])
    assert np.degrees(CHAIN.upper) == pytest.approx([hi for _, hi in GEOMETRY.limits_deg])


@given(q1=st.floats(-150.0, 150.0), v0=st.floats(-200.0, 200.0), v1=st.floats(-200.0, 200.0))
@settings(max_examples=25, deadline=None)
def test_the_kinetic_energy_is_that_of_two_rods_a_payload_and_the_rotors(q1, v0, v1):
    """The arm's kinetic energy is qd' M qd / 2 with M of two uniform rods (2 kg, 300 mm; 1 kg, 250 mm), 0.5 kg at the tip and the rotors through 50:1 gears."""
    plant = plant_at((10.0, q1), (v0, v1))
    l1, l2, m1, m2, mp = 0.3, 0.25, 2.0, 1.0, PAYLOAD_KG
    j2 = m2 * l2 * l2 / 3.0 + mp * l2 * l2
    alpha = m1 * l1 * l1 / 3.0 + j2 + (m2 + mp) * l1 * l1 + MOTORS[0].reflected_inertia
    beta = l1 * (m2 * l2 / 2.0 + mp * l2)
    delta = j2
    c = math.cos(math.radians(q1))
    m00, m01, m11 = alpha + 2 * beta * c, delta + beta * c, delta + MOTORS[1].reflected_inertia
    w0, w1 = math.radians(v0), math.radians(v1)
    expected = 0.5 * (m00 * w0 * w0 + 2 * m01 * w0 * w1 + m11 * w1 * w1)
    assert plant.kinetic_energy_j() == pytest.approx(expected, rel=1e-9, abs=1e-12)


def test_energy_decays_with_friction_and_no_drive_until_the_arm_rests():
    """Coasting from 200 and -150 deg/s with the amplifiers off, the kinetic energy never rises; the arm comes to rest and stays."""
    plant = plant_at((10.0, 40.0), (200.0, -150.0))
    energies = [plant.kinetic_energy_j()]
    for _ in range(3000):
        plant.step(MS)
        energies.append(plant.kinetic_energy_j())
    assert energies[0] > 0.5
    assert all(b <= a + 1e-12 for a, b in itertools.pairwise(energies))
    assert energies[-1] < 1e-15
    rest = plant.q_deg
    for _ in range(200):
        plant.step(MS)
    assert plant.q_deg == pytest.approx(rest, abs=1e-9)


def test_a_constant_torque_runs_a_joint_at_the_speed_its_friction_allows():
    """The elbow jammed, a constant drive of 0.03 on the shoulder: it settles at (tau - Coulomb) / viscous, the URDF's friction (0.4 N m, 0.5 N m s/rad)."""
    plant = plant_at((-150.0, 0.0))
    plant.jam(1)
    drive(plant, (0.03, 0.0))
    for _ in range(5000):
        plant.step(MS)
    tau = drive_counts(0.03) / 32767 * MOTORS[0].torque_limit
    assert plant.torque_nm[0] == pytest.approx(tau)
    assert math.radians(plant.qd_deg_s[0]) == pytest.approx((tau - 0.4) / 0.5, rel=0.01)
    assert abs(plant.qd_deg_s[1]) < 1e-3


def test_the_drive_gives_torque_up_to_the_limit():
    """Full drive gives the joint's torque limit (Kt i_limit gear: 12 N m, 4 A); a tenth of the elbow's drive a tenth of Kt amp_gain gear."""
    plant = plant_at()
    drive(plant, (-1.0, 0.1))
    plant.step(MS)
    assert plant.torque_nm[0] == pytest.approx(-12.0)
    assert plant.current_a[0] == pytest.approx(-4.0)
    assert plant.torque_nm[1] == pytest.approx(drive_counts(0.1) / 32767 * 0.04 * 4.0 * 50.0)


def test_a_disabled_amplifier_or_a_motor_without_power_gives_no_torque():
    """Disabled: no current; the motor's power cut: no current whatever the enable, and amp_ok shows it; cleared, the joint is driven again."""
    plant = plant_at()
    drive(plant, (1.0, -1.0), enable=0)
    plant.step(0.1)
    assert plant.current_a == (0.0, 0.0) and plant.q_deg == (0.0, 0.0)
    assert plant.board.values("amp_ok") == [0, 0]
    drive(plant, (1.0, -1.0))
    plant.motor_off(0)
    plant.step(0.01)
    assert plant.current_a[0] == 0.0 > plant.current_a[1]
    assert plant.board.values("amp_ok") == [0, 1]
    assert plant.active_faults() == ["q0 motor off"]
    assert (plant.motor_powered(0), plant.motor_powered(1)) == (False, True)
    plant.clear_faults()
    plant.step(0.01)
    assert plant.current_a[0] > 0.0 and plant.board.values("amp_ok") == [1, 1]
    assert plant.active_faults() == []


@given(a0=st.floats(0.05, 0.6), a1=st.floats(0.05, 0.6), f0=st.floats(0.5, 3.0),
       f1=st.floats(0.5, 3.0))
@settings(max_examples=10, deadline=None)
def test_the_counters_are_the_floor_of_the_true_angle_in_counts(a0, a1, f0, f1):
    """Under arbitrary drives the board's counter is floor(q * counts per degree) of the true angle."""
    plant = plant_at()
    for k in range(300):
        t = k * MS
        drive(plant, (a0 * math.sin(2 * math.pi * f0 * t), a1 * math.sin(2 * math.pi * f1 * t)))
        plant.step(MS)
        if k % 25 == 0:
            for j in (0, 1):
                assert plant.count(j) == math.floor(plant.q_deg[j] * plant.counts_per_deg(j))


def test_the_counters_start_at_the_angle_in_counts():
    """At (90, -45) deg the counters read (51200, -25600): 204800 counts per joint turn."""
    plant = plant_at((90.0, -45.0))
    assert plant.counts_per_deg(0) == pytest.approx(204800 / 360)
    assert plant.counts() == (51200, -25600)
    assert plant.board.values("count") == [51200, -25600]


def test_a_preset_counter_counts_on_and_wraps_at_32_bits():
    """Preset near 2**31 - 1, the counter wraps to negative as the joint turns on."""
    plant = plant_at()
    plant.preset_encoder(0, 2**31 - 100)
    assert plant.count(0) == 2**31 - 100
    drive(plant, (0.3, 0.0))
    while plant.q_deg[0] < 1.0:
        plant.step(MS)
    travelled = math.floor(plant.q_deg[0] * plant.counts_per_deg(0))
    assert plant.count(0) < 0
    assert plant.count(0) == wrap_int32(2**31 - 100 + travelled)


def test_a_jammed_joint_stops_at_once_and_stays_while_the_other_moves():
    """Jammed moving at 50 deg/s, the shoulder stops and holds within one count under full drive; the elbow moves on; released, the shoulder moves."""
    plant = plant_at((30.0, 10.0), (50.0, 0.0))
    plant.jam(0)
    assert plant.qd_deg_s[0] == 0.0
    held, count = plant.q_deg[0], plant.count(0)
    drive(plant, (1.0, 0.5))
    for _ in range(100):
        plant.step(MS)
        assert abs(plant.q_deg[0] - held) < 1.0 / plant.counts_per_deg(0)
    assert abs(plant.count(0) - count) <= 1
    assert plant.q_deg[1] > 20.0
    assert plant.active_faults() == ["q0 jammed"]
    plant.jam(0, False)
    plant.step(0.02)
    assert plant.q_deg[0] > held + 0.01


def test_a_disconnected_encoder_freezes_and_counts_on_when_reconnected():
    """The elbow's counter freezes while its encoder is off although the joint moves; reconnected, it counts on from the frozen value."""
    plant = plant_at()
    drive(plant, (0.0, 0.4))
    plant.step(0.05)
    plant.disconnect_encoder(1)
    frozen, q_off = plant.count(1), plant.q_deg[1]
    plant.step(0.05)
    assert plant.count(1) == frozen
    assert plant.q_deg[1] > q_off + 1.0
    assert plant.active_faults() == ["q1 encoder disconnected"]
    plant.disconnect_encoder(1, False)
    q_on = plant.q_deg[1]
    plant.step(0.05)
    moved = (plant.q_deg[1] - q_on) * plant.counts_per_deg(1)
    assert abs(plant.count(1) - frozen - moved) <= 1.0


class _CheckedBoard(RegisterBoard):
    """A servo board whose registers the wiring cannot reach in place (any other view)."""


def test_the_wiring_in_place_and_through_the_checked_calls_gives_the_same_arm():
    """Behind the in-process board (the world's registers in place on it while no fault is applied) and behind a board reached only through values()/set_input(), the same drives give the same counters, amp_ok and true angles, through a motor cut and restored, a jam and its release, a disconnected encoder, a preset and a motor cut."""
    fast = plant_at((10.0, 40.0))
    slow = Plant(_CheckedBoard(SERVO), q_deg=(10.0, 40.0))
    assert fast._wiring._count is not None and slow._wiring._count is None  # the two paths
    assert fast.world._direct is not None and slow.world._direct is None
    direct = []
    for k in range(450):
        t = k * MS
        for p in (fast, slow):
            if k == 60:
                p.motor_off(0)
            elif k == 90:
                p.motor_off(0, False)
            elif k == 120:
                p.jam(1)
            elif k == 150:
                p.jam(1, False)
            elif k == 200:
                p.disconnect_encoder(1)
            elif k == 260:
                p.disconnect_encoder(1, False)
            elif k == 300:
                p.preset_encoder(0, 2**31 - 50)
            elif k == 350:
                p.motor_off(1)
            drive(p, (0.4 * math.sin(2 * math.pi * 2.0 * t), 0.3 * math.cos(2 * math.pi * t)),
                  enable=0 if 20 <= k < 30 else 1)
            p.step(MS)
        direct.append(fast.world._direct is not None)
        assert fast.board.values("count") == slow.board.values("count")
        assert fast.board.values("amp_ok") == slow.board.values("amp_ok")
        assert fast.q_deg == slow.q_deg
    # in place but while a motor is cut or an encoder frozen or shifted (for good, once
    # reconnected: its counts stay shifted)
    assert direct == [not (60 <= k < 90 or k >= 200) for k in range(450)]
    assert fast.active_faults() == slow.active_faults() == ["q1 motor off"]


def test_a_joint_driven_into_its_end_stop_stops_there():
    """Driven at full torque without a servo, the elbow stops at its end stop (158 deg, 8 beyond its limit): hitting it at full speed, three degrees into it at most; at rest, under one."""
    plant = plant_at((0.0, 100.0))
    drive(plant, (0.0, 1.0))
    for _ in range(1500):
        plant.step(MS)
        assert plant.q_deg[1] <= 161.0
    assert plant.q_deg[1] == pytest.approx(158.0, abs=1.0)
    assert abs(plant.qd_deg_s[1]) < 0.1


def test_one_long_step_is_ten_of_a_millisecond():
    """step(10 ms) lands where ten step(1 ms) do: the world integrates in 1 ms internal steps."""
    a, b = plant_at(), plant_at()
    for plant in (a, b):
        drive(plant, (0.5, -0.3))
    a.step(0.01)
    for _ in range(10):
        b.step(MS)
    assert a.q_deg == pytest.approx(b.q_deg, abs=1e-12)
    assert a.qd_deg_s == pytest.approx(b.qd_deg_s, abs=1e-9)
    assert a.time_s == pytest.approx(0.01)


def test_uneven_steps_stay_as_close_to_the_fine_motion_as_even_ones():
    """Driven open loop for 0.3 s (50 deg of travel), jittered loop periods (0.7 .. 1.3 ms) end no further from the motion of 0.1 ms steps than even 1 ms periods do, both within 0.2 deg."""
    even, jittered, fine = plant_at(), plant_at(), plant_at(max_step_s=0.1e-3)
    for plant in (even, jittered, fine):
        drive(plant, (0.4, -0.2))
    for _ in range(300):
        even.step(MS)
        fine.step(MS)
    t = 0.0
    k = 0
    while t < 0.3 - 1e-12:
        dt = min((0.7e-3, 1.3e-3, 1.0e-3)[k % 3], 0.3 - t)
        jittered.step(dt)
        t += dt
        k += 1

    def off(plant: Plant) -> float:
        return max(abs(a - b) for a, b in zip(plant.q_deg, fine.q_deg, strict=True))

    assert fine.q_deg[0] > 45.0
    assert off(jittered) <= off(even) < 0.2


def test_the_true_tip_is_fk_of_the_true_angles():
    """tip_mm is the forward kinematics of the true joint angles."""
    plant = plant_at((25.0, -60.0))
    drive(plant, (0.2, 0.2))
    plant.step(0.05)
    assert plant.tip_mm == pytest.approx(fk(*plant.q_deg), abs=1e-9)


@pytest.mark.parametrize("dt", [-1e-3, math.nan, math.inf, "1"])
def test_a_bad_step_is_refused_and_changes_nothing(dt):
    """step of a negative, non-finite or non-number dt is a ValueError and leaves the plant as it was."""
    plant = plant_at(qd_deg_s=(10.0, 0.0))
    before = snapshot(plant)
    with pytest.raises(ValueError, match="dt"):
        plant.step(dt)
    assert snapshot(plant) == before


@pytest.mark.parametrize("joint", [2, -1, True, "q0"])
def test_an_unknown_joint_is_refused(joint):
    """Fault injection and encoder reads take joint 0 or 1 only."""
    plant = plant_at()
    for call in (plant.jam, plant.disconnect_encoder, plant.motor_off, plant.count,
                 plant.motor_powered, plant.counts_per_deg):
        with pytest.raises(ValueError, match="joint must be 0"):
            call(joint)
    assert plant.active_faults() == []


def test_a_start_beyond_the_end_stops_a_bad_step_size_or_a_bad_preset_is_refused():
    """The plant refuses a starting angle beyond the end stops, an internal step beyond 10 ms, and a preset outside 32 bits."""
    with pytest.raises(ValueError, match="end stops"):
        plant_at((179.0, 0.0))
    with pytest.raises(ValueError, match="max_step_s"):
        plant_at(max_step_s=0.02)
    plant = plant_at()
    with pytest.raises(ValueError, match="32-bit"):
        plant.preset_encoder(0, 2**31)
    assert plant.count(0) == 0
