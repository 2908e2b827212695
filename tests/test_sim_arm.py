"""The simulated arm (pyrt.sim.arm) against physics, and the servo (pyrt.native.Servo)
closing the loop on it through the board's registers, on the simulated clock."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pyrt.boards import RegisterBoard
from pyrt.boards.armservo import arm_servo_kind
from pyrt.errors import ConfigError
from pyrt.kinematics import Chain, Inertial, Joint
from pyrt.kinematics.puma import puma560
from pyrt.native import Servo, ServoTrip, gain_ranges, tuned_gains
from pyrt.sim.arm import (
    DAC_FULL_SCALE,
    PUMA560_MOTORS,
    ArmPlant,
    ArmWorld,
    FTCalibration,
    Motor,
    default_motors,
)

PERIOD = 1e-3
CHAIN = puma560(closed_form=False)
ARMATURE = np.array([m.reflected_inertia for m in PUMA560_MOTORS])
EFFORT = np.array([j.effort for j in CHAIN.joints])
Q0 = np.radians([10.0, 45.0, -120.0, 20.0, 40.0, 30.0])


def puma(**kw) -> ArmWorld:
    kw.setdefault("q0", Q0)
    return ArmWorld(CHAIN, motors=PUMA560_MOTORS, **kw)


def kinetic(world: ArmWorld) -> float:
    t = world.truth()
    return 0.5 * float(t.qd @ ((CHAIN.mass_matrix(t.q) + np.diag(ARMATURE)) @ t.qd))


# ------------------------------------------------------------------ the world alone


def test_free_arm_with_damping_settles():
    """Motors off, the PUMA falls under gravity and comes to rest (on its end stops) with the
    URDF's damping and friction: after 4 s no joint moves faster than 0.01 rad/s."""
    w = puma()
    moved = 0.0
    for _ in range(4000):
        w.step(PERIOD)
        moved = max(moved, float(np.abs(w.truth().qd).max()))
    t = w.truth()
    assert moved > 0.5                     # it did fall
    assert np.abs(t.qd).max() < 0.01
    assert kinetic(w) < 1e-3
    assert ((t.q >= w.stop_lower - 0.05) & (t.q <= w.stop_upper + 0.05)).all()


@pytest.mark.parametrize("q0_deg", [(0, 0, 0, 0, 45, 0), (30, 20, -40, 30, 60, 10)])
def test_energy_is_conserved_without_damping_or_friction(q0_deg):
    """With no damping, friction or stops, 1 s of free swinging (peak kinetic energy above 50 J)
    keeps the total energy within 0.5 % of the peak kinetic energy at the 1 ms step, and the
    error halves with the step (the symplectic step's first order)."""
    errors = []
    for h in (1e-3, 0.5e-3):
        w = puma(q0=np.radians(q0_deg), damping=0.0, friction=0.0, max_step=h,
                 stop_margin=100.0)
        e0 = w.energy()
        worst = peak = 0.0
        for _ in range(1000):
            w.step(PERIOD)
            worst = max(worst, abs(w.energy() - e0))
            peak = max(peak, kinetic(w))
        assert peak > 50.0
        assert worst < 0.005 * peak
        errors.append(worst)
    assert errors[1] < 0.6 * errors[0]


def test_a_joint_driven_into_its_end_stop_stops_there():
    """Full current on the waist toward its upper limit: the joint runs into the stop (2 deg
    beyond the limit) and rests in it, pressed in by effort / stiffness (0.5 deg)."""
    w = puma()
    w.board.write("enable", 1, 0)
    w.board.write("dac", DAC_FULL_SCALE, 0)
    for _ in range(3000):
        w.step(PERIOD)
    t = w.truth()
    stop = CHAIN.upper[0] + math.radians(2.0)
    press = EFFORT[0] / w.stop_stiffness[0]
    assert abs(t.qd[0]) < 1e-3
    assert t.q[0] == pytest.approx(stop + press, abs=0.1 * press)
    assert math.degrees(press) == pytest.approx(0.5)


def test_the_table_pushes_back_with_its_stiffness():
    """At rest with the tip 1 mm and 3 mm into the table, the normal force is k d (k the
    stated 5e4 N/m); above the table it is zero; the arm falling onto it with its motors off
    lies on it (the tip a few tenths of a millimetre in, by its force over k) and never
    passes through."""
    w = puma(tip=(0.0, 0.0, 0.1))
    top = float(w.truth().tip[2])
    w.set_table(top + 0.001)
    w.set_state(Q0)
    assert w.truth().contact.tolist() == pytest.approx([0.0, 0.0, 50.0])
    w.set_table(top + 0.003)
    w.set_state(Q0)
    assert w.truth().contact[2] == pytest.approx(150.0)
    w.set_table(top - 0.001)
    w.set_state(Q0)
    assert w.truth().contact.tolist() == [0.0, 0.0, 0.0]
    # falling onto it: the table's force carries part of the arm's weight
    z = top - 0.02
    w.set_table(z)
    lowest = top
    for _ in range(3000):
        w.step(PERIOD)
        lowest = min(lowest, float(w.truth().tip[2]))
    t = w.truth()
    assert t.contact[2] > 10.0
    assert lowest > z - 0.002
    assert t.tip[2] == pytest.approx(z - t.contact[2] / w.table_stiffness, abs=2e-5)


def test_the_table_resists_sliding_with_its_friction():
    """The tip sliding along the table at 0.1 m/s meets a tangential force of mu times the normal
    force, against its velocity."""
    w = puma(tip=(0.0, 0.0, 0.1))
    w.set_table(float(w.truth().tip[2]) + 0.002)
    jac = CHAIN.jacobian(Q0)
    r = CHAIN.fk(Q0)[:3, :3] @ np.array([0.0, 0.0, 0.1])
    jt = jac[:3] - np.cross(r, jac[3:].T).T           # the tip's linear Jacobian
    w.set_state(Q0, np.linalg.pinv(jt) @ np.array([0.1, 0.0, 0.0]))
    f = w.truth().contact
    assert f[2] == pytest.approx(100.0, rel=1e-6)
    assert f[0] == pytest.approx(-w.table_friction * f[2], rel=1e-6)
    assert abs(f[1]) < 1e-6 * f[2]


def test_ft_sensor_reads_the_contact_in_its_frame():
    """The wrist sensor's registers, through its calibration, read the table's force turned
    into the tool frame and its moment about the sensor (tip x f), within the noise."""
    cal = FTCalibration(counts_per_n=2000.0, counts_per_nm=5000.0, offsets=(5, -3, 0, 7, 0, 1))
    w = puma(tip=(0.02, 0.0, 0.1), ft=cal, seed=3)
    w.set_table(float(w.truth().tip[2]) + 0.002)
    w.set_state(Q0)
    t = w.truth()
    f_world = t.contact
    assert f_world[2] == pytest.approx(100.0)
    r = t.tool[:3, :3]
    f_s = r.T @ f_world
    m_s = np.cross([0.02, 0.0, 0.1], f_s)
    read = cal.wrench(w.board.values("ft"))
    assert read[:3] == pytest.approx(f_s, abs=4 * 0.05 + 1e-3)
    assert read[3:] == pytest.approx(m_s, abs=4 * 0.002 + 1e-3)
    assert np.abs(f_s).max() > 20.0   # a rotated tool: the force is not along the sensor's z alone


def test_payload_weighs_on_the_joints_and_the_sensor():
    """A 2 kg payload at the tip adds its weight to the gravity the motors must hold and is
    read by the wrist sensor as 2 g along the world's -z."""
    w = puma(ft_noise=(0.0, 0.0))
    w.set_payload(2.0)
    w.set_state(Q0)
    t = w.truth()
    read = w.ft.wrench(w.board.values("ft"))
    assert (t.tool[:3, :3] @ read[:3]) == pytest.approx([0.0, 0.0, -2.0 * 9.81], abs=2e-3)
    heavier = w._dyn.gravity_torque(Q0)  # the world's own chain, with the payload
    assert np.abs(heavier - CHAIN.gravity_torque(Q0)).max() > 1.0


def test_dac_gives_current_and_torque_in_real_units():
    """DAC counts become amps (full scale: the motor's max current) and joint torque Kt G i;
    a disabled amplifier gives none."""
    w = puma()
    w.board.write("dac", 16384, 1)
    w.board.write("dac", -8000, 2)
    w.board.write("enable", 1, 1)
    w.step(PERIOD)
    t = w.truth()
    m = PUMA560_MOTORS[1]
    assert t.current[1] == pytest.approx(16384 / 32767 * m.max_current)
    assert t.torque[1] == pytest.approx(m.kt * m.gear * t.current[1])
    assert t.torque[1] == pytest.approx(EFFORT[1] * 16384 / 32767)
    assert t.current[2] == 0.0 and t.torque[2] == 0.0


def test_a_motor_stronger_than_the_effort_is_clamped_at_it():
    """Full scale of a motor twice the joint's effort gives the URDF's effort, no more."""
    strong = [Motor(kt=m.kt, gear=m.gear, rotor_inertia=m.rotor_inertia,
                    max_current=2 * m.max_current) for m in PUMA560_MOTORS]
    w = ArmWorld(CHAIN, motors=strong, q0=Q0)
    w.board.write("enable", 1, 0)
    w.board.write("dac", -DAC_FULL_SCALE, 0)
    w.step(PERIOD)
    assert w.truth().torque[0] == -EFFORT[0]


def test_the_arm_plays_a_world_behind_sim_boards():
    """On boards opened with sim: from arm_servo_kind, ArmPlant steps the arm by the time that
    passed, and the world's watchdog turns every DAC and enable off."""
    from pyrt.boards import open_boards
    from pyrt.sim.world import World

    boards = open_boards("sim:", "puma560", {"arm": arm_servo_kind(6)}).simulated
    arm = puma(board=boards["arm"])
    world = World("puma560", boards, ArmPlant(arm))
    world.step(0)
    world.step(5_000_000)
    assert arm.time == pytest.approx(0.005)
    assert "q2" in world.info() and "z" in world.info()
    board = boards["arm"]
    board.write("dac", 1000, 3)
    board.write("enable", 1, 3)
    world.outputs_off()
    assert board.values("dac") == [0] * 6 and board.values("enable") == [0] * 6


def test_encoder_counter_wraps_as_a_32_bit_counter():
    """The count register follows the joint in counts per joint turn and wraps past 2**31."""
    joint = Joint("spin", "revolute", np.eye(4), (0, 0, 1), effort=10.0,
                  inertial=Inertial(1.0, (0.1, 0, 0), np.eye(3) * 0.01))
    chain = Chain("spinner", [joint])
    motor = Motor(kt=0.1, gear=1.0, rotor_inertia=0.0, max_current=100.0,
                  counts_per_rev=1 << 30)
    w = ArmWorld(chain, motors=[motor], gravity=(0, 0, 0))
    w.set_state([2 * math.pi * 0.5])
    assert w.board.read("count") == 1 << 29
    w.set_state([2 * math.pi * 2.25])           # 2.25 turns: 2**31 + 2**28 counts
    assert w.board.read("count") == -(1 << 31) + (1 << 28)
    w.set_state([-2 * math.pi * 2.25])
    assert w.board.read("count") == (1 << 31) - (1 << 28)


def test_bad_configuration_is_refused():
    """A start beyond the stops, a joint without an effort limit, a board without the
    registers: ConfigError naming the problem."""
    with pytest.raises(ConfigError, match="end stops"):
        puma(q0=np.radians([0, 0, 0, 0, 150, 0]))
    free = Chain("free", [Joint("j", "revolute", np.eye(4), (0, 0, 1),
                                inertial=Inertial(1.0, (0.1, 0, 0), np.eye(3)))])
    with pytest.raises(ConfigError, match="no effort limit"):
        default_motors(free)
    with pytest.raises(ConfigError, match="lacks register"):
        ArmWorld(CHAIN, board=RegisterBoard(arm_servo_kind(2)))


# ------------------------------------------------------------------ the servo on the world


class Rig:
    """The servo closing the loop through the board: counts in, DAC counts out, 1 kHz."""

    def __init__(self, world: ArmWorld, bandwidth_hz: float = 10.0, felim: float = 0.2):
        self.w = world
        self.b = world.board
        self.cpr = np.array([m.counts_per_joint_rev for m in world.motors]) / (2 * math.pi)
        self.npc = np.array([m.nm_per_count for m in world.motors])
        q = self.measure()
        inertia = np.diag(CHAIN.mass_matrix(q)) + ARMATURE
        gains = tuned_gains(inertia, EFFORT, PERIOD, bandwidth_hz, felim=felim)
        self.s = Servo(6, PERIOD, names=CHAIN.joint_names, gains=gains,
                       ranges=gain_ranges(2 * inertia, EFFORT, PERIOD))
        for j in range(6):
            self.b.write("enable", 1, j)
        self.s.reset(q, ff=CHAIN.gravity_torque(q))
        self.ticks = 0

    def measure(self) -> np.ndarray:
        return np.array(self.b.values("count"), dtype=float) / self.cpr

    def tick(self) -> ServoTrip | None:
        self.s.q[:] = self.measure()
        trip = self.s.tick()
        dac = np.clip(np.rint(self.s.tau / self.npc), -DAC_FULL_SCALE, DAC_FULL_SCALE)
        for j, d in enumerate(dac.astype(int).tolist()):
            self.b.write("dac", d, j)
        self.w.step(PERIOD)
        self.ticks += 1
        return trip

    def step_to(self, target: np.ndarray, ff: bool = True) -> None:
        g = CHAIN.gravity_torque(target) if ff else np.zeros(6)
        self.s.segment(PERIOD, self.measure(), np.zeros(6), target, np.zeros(6), ffa=g, ffb=g)


@pytest.mark.parametrize("joint", range(6))
def test_a_step_of_each_joint_settles_with_gravity_feed_forward(joint):
    """A 2 deg step of one PUMA joint (10 Hz triple-pole PID, gravity feed-forward): the true
    joint overshoots by less than 15 % and stays within 0.05 deg of the target from 0.2 s on;
    the other joints (disturbed through the coupling) stay within 0.2 deg, and within
    0.05 deg from 0.2 s on."""
    rig = Rig(puma())
    for _ in range(100):
        rig.tick()
    start = rig.measure()
    target = start.copy()
    target[joint] += math.radians(2.0)
    rig.step_to(target)
    hist = []
    for _ in range(1000):
        assert rig.tick() is None
        hist.append(rig.w.truth().q.copy())
    h = np.degrees(np.array(hist) - target)
    assert h[:, joint].max() < 0.15 * 2.0
    assert np.abs(h[200:, joint]).max() < 0.05
    others = [k for k in range(6) if k != joint]
    assert np.abs(h[:, others]).max() < 0.2
    assert np.abs(h[200:, others]).max() < 0.05


def test_without_feed_forward_the_integrator_removes_the_steady_state_error():
    """Holding against gravity without feed-forward or integrator leaves the shoulder low by
    g / kp (give or take its Coulomb friction over kp); the integrator switched on removes the
    error to below 0.005 deg within 1 s."""
    rig = Rig(puma())
    rig.s.set_gains({"kff": np.zeros(6), "ki": np.zeros(6)})
    rig.step_to(Q0, ff=False)
    for _ in range(1000):
        rig.tick()
    err = rig.w.truth().q - Q0
    g = CHAIN.gravity_torque(Q0)
    fc = CHAIN.joints[1].friction
    assert -(g[1] + fc) / rig.s.kp[1] < err[1] < -(g[1] - fc) / rig.s.kp[1]
    assert abs(err[1]) > math.radians(0.02)
    tuned = tuned_gains(np.ones(6), EFFORT, PERIOD, 10.0)
    inertia = np.diag(CHAIN.mass_matrix(Q0)) + ARMATURE
    rig.s.set_gains({"ki": tuned["ki"] * inertia})
    for _ in range(1000):
        rig.tick()
    assert np.degrees(np.abs(rig.w.truth().q - Q0)).max() < 0.005


def test_a_following_error_zeroes_every_output_in_the_same_tick_and_names_the_joint():
    """The shoulder's amplifier fails (enable off) while holding: the arm sags, and the tick
    whose following error passes the shoulder's limit zeroes every DAC and names joint2."""
    rig = Rig(puma(), felim=math.radians(1.0))
    for _ in range(50):
        rig.tick()
    rig.b.write("enable", 0, 1)
    trip = None
    for _ in range(2000):
        trip = rig.tick()
        if trip is not None:
            break
    assert trip is not None and trip.name == "joint2" and trip.joint == 1
    assert abs(trip.error) > math.radians(1.0)
    assert rig.s.tau.tolist() == [0.0] * 6
    assert rig.b.values("dac") == [0] * 6
    assert rig.ticks < 1000


def test_closed_loop_runs_are_deterministic():
    """Two runs of the same moves on the simulated clock give bit-identical truth and F/T
    registers."""
    def run():
        rig = Rig(puma(tip=(0, 0, 0.1), seed=7))
        target = Q0 + np.radians([3, -2, 2, 5, -4, 6])
        rig.step_to(target)
        for _ in range(300):
            rig.tick()
        return rig.w.truth().q.tolist(), rig.b.values("ft"), rig.b.values("count")

    assert run() == run()


def _quintic(q0: np.ndarray, q1: np.ndarray, duration: float, t: float):
    """Position, velocity and acceleration of a rest-to-rest quintic at t."""
    s = min(max(t / duration, 0.0), 1.0)
    d = q1 - q0
    return (q0 + d * (10 * s**3 - 15 * s**4 + 6 * s**5),
            d * (30 * s**2 - 60 * s**3 + 30 * s**4) / duration,
            d * (60 * s - 180 * s**2 + 120 * s**3) / duration**2)


def test_dynamics_feed_forward_at_the_trajectory_rate_tracks_a_fast_move():
    """A 0.6 s move of every joint by 50 deg (peaks 156 deg/s, 830 deg/s^2), handed to the servo
    as 10 ms quintic segments with the inverse dynamics computed at the knots only (the
    trajectory rate): the true joints follow the reference within 0.04 deg (what is left is the
    velocity estimate's lag and the friction); without that feed-forward the largest error is
    more than twice as large."""
    def run(kff: float) -> float:
        rig = Rig(puma())
        damping = np.array([j.damping for j in CHAIN.joints])
        rig.s.set_gains({"kff": np.full(6, kff), "ka": ARMATURE * kff, "kv": damping * kff})
        q0 = rig.measure()
        q1 = q0 + math.radians(50.0)
        worst = 0.0
        for seg in range(70):
            a = _quintic(q0, q1, 0.6, seg * 0.01)
            b = _quintic(q0, q1, 0.6, (seg + 1) * 0.01)
            rig.s.segment(0.01, a[0], a[1], b[0], b[1], a[2], b[2],
                          ffa=CHAIN.rnea(*a), ffb=CHAIN.rnea(*b))
            for _ in range(10):
                now = rig.w.truth().q        # the instant the tick measures and refers to
                assert rig.tick() is None
                worst = max(worst, float(np.abs(now - rig.s.q_ref).max()))
        return math.degrees(worst)

    with_ff, without = run(1.0), run(0.0)
    assert with_ff < 0.04
    assert without > 2 * with_ff
