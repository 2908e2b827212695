"""The arm station on simulated time: moves, wait, stop, blends, the faults' reflex in the
tick of the fault, the truth of status, the registers it drives."""

from __future__ import annotations

import io
import itertools
import math
import re

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pyrt import CommandError, ConfigError, FaultError, Loop, MotionType, SimClock
from pyrt.commands.robot import RobotShell
from pyrt.scheduler.motion import register_motion_type

from pyrt_arm.boards import DRIVE_FULL_SCALE, SERVO
from pyrt_arm.controller import AT_TARGET_DEG, TIP_TOLERANCE_MM, ArmController
from pyrt_arm.kinematics import GEOMETRY, JointLimitError, ik
from pyrt_arm.station import ArmStation, build_arm

_TIP = re.compile(r"tip \((-?[\d.]+), (-?[\d.]+)\) mm")


@pytest.fixture
def arm():
    """The arm on a simulated clock, started, with a shell on it."""
    station = build_arm(Loop(SimClock()))
    runner = station.start()
    out = io.StringIO()
    shell = RobotShell(station, out, runner=runner)
    yield station, runner, shell, out
    station.close()


def _say(shell: RobotShell, out: io.StringIO, line: str) -> str:
    out.seek(0)
    out.truncate()
    shell.onecmd(line)
    return out.getvalue()


def _registers(station: ArmStation) -> dict[str, list[int]]:
    board = station.board
    return {name: [board.read(name, j) for j in (0, 1)] for name in ("drive", "enable")}


def _tip_of(text: str) -> tuple[float, float]:
    m = _TIP.search(text)
    assert m, text
    return float(m.group(1)), float(m.group(2))


# -- the board ------------------------------------------------------------------------------


def test_the_servo_board_declares_counters_drives_and_enables_with_their_off_values():
    """Per joint: a 32-bit signed counter and an amplifier status (inputs), a 16-bit signed drive and an enable (outputs, off 0)."""
    count, amp, drive, enable = (SERVO.register(n) for n in ("count", "amp_ok", "drive", "enable"))
    assert (count.count, count.width, count.signed, count.is_input) == (2, 32, True, True)
    assert amp.is_input and amp.width == 1
    assert (drive.width, drive.signed, drive.is_input, drive.off) == (16, True, False, 0)
    assert drive.high == DRIVE_FULL_SCALE
    assert (enable.is_input, enable.off) == (False, 0)


def test_at_rest_the_amplifiers_are_off_and_the_arm_lies_still(arm):
    """Built and idle: every drive and enable register is 0, the arm does not move, wait has nothing to wait for."""
    station, runner, shell, out = arm
    runner.sleep(0.5)
    assert runner.call(lambda: _registers(station)) == {"drive": [0, 0], "enable": [0, 0]}
    assert station.plant.qd_deg_s == (0.0, 0.0)
    assert "nothing to wait for" in _say(shell, out, "wait")


# -- moves, wait, truth -----------------------------------------------------------------------


def test_a_move_ends_at_target_and_switches_the_amplifiers_off(arm):
    """arm to 45 30, wait: 'at target', the encoders' angles within AT_TARGET_DEG of the target, every output off afterwards."""
    station, runner, shell, out = arm
    assert "moving to q0 45.000 deg" in _say(shell, out, "arm to 45 30")
    said = _say(shell, out, "wait")
    assert said.startswith("at target"), said
    q0, q1 = runner.call(station.controller.angles)
    assert abs(q0 - 45) <= AT_TARGET_DEG and abs(q1 - 30) <= AT_TARGET_DEG
    assert runner.call(lambda: _registers(station)) == {"drive": [0, 0], "enable": [0, 0]}
    assert runner.call(station.last_stop) == "at target"


@settings(max_examples=8, derandomize=True, deadline=None)
@given(r=st.floats(GEOMETRY.r_min_mm + 30, GEOMETRY.r_max_mm - 30),
       phi=st.floats(-170.0, 170.0), elbow=st.sampled_from(["up", "down"]))
def test_after_wait_the_true_tip_is_where_status_says(r, phi, elbow):
    """Over random reachable targets in both elbow configurations: after arm xy and wait, the simulated arm's true tip lies within the stated TIP_TOLERANCE_MM of the tip status gives, and status's tip within 0.3 mm of the target."""
    x, y = r * math.cos(math.radians(phi)), r * math.sin(math.radians(phi))
    try:
        ik(x, y, elbow)  # type: ignore[arg-type]
    except JointLimitError:
        return  # that elbow cannot reach it within the joint limits
    station = build_arm(Loop(SimClock()))
    runner = station.start()
    out = io.StringIO()
    shell = RobotShell(station, out, runner=runner)
    try:
        _say(shell, out, f"arm xy {x:.3f} {y:.3f} {elbow}")
        said = _say(shell, out, "wait")
        assert said.startswith("at target"), said
        status = _say(shell, out, "status")
        assert f"±{TIP_TOLERANCE_MM:g} mm" in status
        sx, sy = _tip_of(status)
        tx, ty = runner.call(lambda: station.plant.tip_mm)
        # status prints 0.01 mm: allow its rounding beside the stated tolerance
        assert math.hypot(sx - tx, sy - ty) <= TIP_TOLERANCE_MM + 0.01
        assert math.hypot(sx - x, sy - y) <= 0.3
    finally:
        station.close()


def test_queued_moves_blend_without_stopping_at_the_corner(arm):
    """Two arm to queued back to back: the true joint speed never falls near zero between them (Paul's transition), and the arm ends at the second target."""
    station, runner, shell, out = arm
    speeds: list[float] = []
    _say(shell, out, "arm to 60 90")
    assert "blends into the running move" in _say(shell, out, "arm to 60 20")

    def sample() -> bool:
        speeds.append(math.hypot(*station.plant.qd_deg_s))
        return not station.busy()

    assert runner.wait_until(sample, 20.0)
    moving = [i for i, v in enumerate(speeds) if v > 20.0]
    between = speeds[moving[0]:moving[-1] + 1]
    assert min(between) > 20.0, min(between)
    assert max(speeds) > 60.0
    assert runner.call(station.last_stop) == "at target"
    q0, q1 = runner.call(station.controller.angles)
    assert abs(q0 - 60) <= AT_TARGET_DEG and abs(q1 - 20) <= AT_TARGET_DEG


def test_the_worlds_one_ms_integration_step_moves_the_arm_as_the_fine_step_does():
    """The same blended moves with the world integrating in 1 ms steps (the station's) and in the plant's fine 0.2 ms steps: the true joints agree within one encoder count (1/569 deg) all along."""
    traces = []
    for step in (1e-3, 0.2e-3):
        station = build_arm(Loop(SimClock()), world_step_s=step)
        runner = station.start()
        shell = RobotShell(station, io.StringIO(), runner=runner)
        try:
            for line in ("arm to 90 30", "arm xy 400 -100 down", "arm xy 200 300"):
                shell.onecmd(line)
            trace: list[tuple[float, float]] = []

            def sample(station=station, trace=trace) -> bool:
                trace.append(station.plant.q_deg)
                return not station.busy()

            assert runner.wait_until(sample, 30.0)
            traces.append(trace)
        finally:
            station.close()
    coarse, fine = traces
    assert abs(len(coarse) - len(fine)) <= 5
    diff = max(abs(c[j] - f[j]) for c, f in zip(coarse, fine, strict=False) for j in (0, 1))
    assert diff < 1.0 / 568.9


def test_moves_given_one_after_the_other_stop_between(arm):
    """The same two moves with a wait between: the arm comes to rest at the corner (the blend test's counterpart)."""
    station, _runner, shell, out = arm
    _say(shell, out, "arm to 60 90")
    assert _say(shell, out, "wait").startswith("at target")
    assert "moving to" in _say(shell, out, "arm to 60 20")
    # at rest on its friction (smoothed below 0.005 rad/s: the last of the speed it
    # settled with, under 2 deg/s, decays)
    assert max(abs(v) for v in station.plant.qd_deg_s) < 0.2
    assert _say(shell, out, "wait").startswith("at target")


def test_a_move_given_while_the_arm_settles_goes_on_from_its_target(arm):
    """A move given after the trajectory has ended but while the servo still settles starts from the last setpoint: the following error stays small and the arm ends at the new target."""
    station, runner, shell, out = arm
    _say(shell, out, "arm to 30 90")
    assert runner.wait_until(lambda: station.controller.state == "settling", 10.0)
    assert not runner.call(lambda: station.executor.busy)  # the trajectory has ended
    _say(shell, out, "arm to 60 60")
    errors: list[float] = []

    def sample() -> bool:
        errors.extend(abs(jt.error_deg) for jt in station.controller.joints if jt.engaged)
        return not station.busy()

    assert runner.wait_until(sample, 10.0)
    assert max(errors) < 0.1
    assert runner.call(station.last_stop) == "at target"


def test_stop_brakes_the_arm_to_rest_then_switches_it_off(arm):
    """stop during a move: the arm brakes at its acceleration limits (far less travel than coasting), wait says 'stopped (stop command)', every output 0 after."""
    station, runner, shell, out = arm
    _say(shell, out, "arm to -90 90")
    runner.sleep(0.6)
    before = runner.call(lambda: station.plant.q_deg[0])
    assert "braking to rest" in _say(shell, out, "stop")
    said = _say(shell, out, "wait")
    assert said.startswith("stopped (stop command)"), said
    after = runner.call(lambda: station.plant.q_deg[0])
    assert abs(after - before) < 15.0 and after > -80.0
    assert runner.call(lambda: _registers(station)) == {"drive": [0, 0], "enable": [0, 0]}
    assert _say(shell, out, "arm to 0 90").startswith("arm: moving to")  # moves again
    assert _say(shell, out, "wait").startswith("at target")


def test_moves_are_refused_with_a_clear_error_and_change_nothing(arm):
    """A joint target beyond its limit, a point out of reach, a point the chosen elbow cannot reach: error, nothing queued or moved."""
    station, runner, shell, out = arm
    assert "out of range: Q0 -170..170 deg (shoulder limits)" in _say(shell, out, "arm to 171 0")
    assert "out of reach" in _say(shell, out, "arm xy 10 10")
    assert "error:" in _say(shell, out, "arm xy 0 0 sideways")
    runner.sleep(0.1)
    assert not runner.call(station.busy)
    assert runner.call(lambda: _registers(station)) == {"drive": [0, 0], "enable": [0, 0]}


def test_arm_xy_keeps_the_present_elbow_unless_told(arm):
    """arm xy without an elbow keeps the elbow's side (q1 > 0 here: down); 'up' flips it."""
    station, runner, shell, out = arm
    _say(shell, out, "arm xy 400 100")
    _say(shell, out, "wait")
    assert runner.call(station.controller.angles)[1] > 0
    _say(shell, out, "arm xy 400 100 up")
    assert _say(shell, out, "wait").startswith("at target")
    assert runner.call(station.controller.angles)[1] < 0


# -- faults -----------------------------------------------------------------------------------


def _fault_tick(station: ArmStation, runner) -> dict[str, list[int]]:
    """The drive and enable registers read in the loop tick whose trip made the fault."""
    seen: dict[str, list[int]] = {}
    loop = station.loop

    def look() -> bool:
        f = station.fault
        if f is not None and not seen:
            assert f.time_ns == loop.now_ns, "not the tick of the fault"
            seen.update(_registers(station))
        return f is not None

    with pytest.raises(FaultError):
        runner.wait_until(look, 20.0)
    return seen


def test_a_following_error_trips_every_drive_and_enable_off_in_the_same_tick(arm):
    """sim fault jam q0 during a move: a q0 following-error fault; in the tick of the fault every drive register is 0 and every enable 0, wait says FAULT, moves are refused until ack."""
    station, runner, shell, out = arm
    _say(shell, out, "arm to 90 0")
    runner.sleep(0.3)
    assert runner.call(lambda: _registers(station)["enable"]) == [1, 1]
    _say(shell, out, "sim fault jam q0")
    assert _fault_tick(station, runner) == {"drive": [0, 0], "enable": [0, 0]}
    assert "q0 following error" in station.fault.cause
    assert "refused" in _say(shell, out, "arm to 0 90")
    assert "fault acknowledged" in _say(shell, out, "ack")
    _say(shell, out, "sim fault none")
    assert _say(shell, out, "arm to 0 90").startswith("arm: moving to")
    # the shell had not shown the fault yet (the test took it): it shows it once, first
    said = _say(shell, out, "wait").splitlines()
    assert said[0].startswith("FAULT arm: fault in shoulder") and said[-1].startswith("at target")


def test_a_joint_limit_fault_trips_every_drive_and_enable_off_in_the_same_tick(arm):
    """A servo limit tighter than the planner's (shoulder 60 deg): a move to 90 crosses it, a joint-limit fault (not a following error); every drive and enable 0 in that tick."""
    station, runner, shell, out = arm
    station.controller.joints[0].limits_deg = (-170.0, 60.0)
    _say(shell, out, "arm to 90 90")
    assert _fault_tick(station, runner) == {"drive": [0, 0], "enable": [0, 0]}
    assert "q0 at 60.0" in station.fault.cause and "outside its limits" in station.fault.cause
    assert runner.call(station.last_stop).startswith("fault: q0 at")


def test_a_disconnected_encoder_is_a_following_error_fault(arm):
    """sim fault encoder q0 during a move: q0's counter freezes, its following error grows past 1 deg and the station trips with every output off in that tick."""
    station, runner, shell, out = arm
    _say(shell, out, "arm to 60 90")
    runner.sleep(0.3)
    _say(shell, out, "sim fault encoder q0")
    assert _fault_tick(station, runner) == {"drive": [0, 0], "enable": [0, 0]}
    assert station.fault.cause.startswith("q0 following error")


def test_a_motor_without_power_is_a_fault(arm):
    """sim fault motor q1 during a move: the amplifier's status goes to 0 and the station trips (or the following error does first)."""
    station, runner, shell, out = arm
    _say(shell, out, "arm to 0 0")
    runner.sleep(0.2)
    _say(shell, out, "sim fault motor q1")
    assert _fault_tick(station, runner) == {"drive": [0, 0], "enable": [0, 0]}
    assert "q1" in station.fault.cause


def test_the_fault_is_shown_once(arm):
    """A following-error fault during a wait is shown once by the shell (its event id), not again by the commands after it."""
    _station, runner, shell, out = arm
    _say(shell, out, "arm to -90 0")
    runner.sleep(0.3)
    _say(shell, out, "sim fault jam q1")
    text = (_say(shell, out, "wait") + _say(shell, out, "sleep 0.2")
            + _say(shell, out, "sim show") + _say(shell, out, "arm to 0 0"))
    assert text.count("FAULT") == 1, text
    assert text.startswith("FAULT: q1 following error")


def test_sim_fault_needs_a_joint_and_none_takes_none(arm):
    """sim fault jam without a joint, or none with one: a CommandError; nothing injected."""
    station, runner, _shell, _out = arm
    sim = station.component("sim")
    with pytest.raises(CommandError, match="which joint"):
        runner.call(sim.run_command, "fault", "jam")
    with pytest.raises(CommandError, match="takes no joint"):
        runner.call(sim.run_command, "fault", "none", "q0")
    assert station.plant.active_faults() == []


def test_a_start_beyond_the_end_stops_is_refused():
    """build_arm with a start position beyond an end stop: ConfigError naming it."""
    with pytest.raises(ConfigError, match="end stops"):
        build_arm(Loop(SimClock()), start=(0.0, 170.0))


def test_the_controller_is_a_joint_robot_with_ranges():
    """The root drives joint_trajectory: joint_count 2, limits and the joints' range from the geometry."""
    from pyrt import RangedJointRobot

    station = build_arm(Loop(SimClock()))
    try:
        ctl = station.controller
        assert isinstance(ctl, ArmController) and isinstance(ctl, RangedJointRobot)
        assert "joint_trajectory" in station.motion_types()
        assert ctl.joint_range() == ((-170.0, -150.0), (170.0, 150.0))
    finally:
        station.close()


class _Drifting(MotionType):
    """A plug-in motion that drives the shoulder at 30 deg/s for 0.3 s and ends moving."""

    name = "arm_test_drift"
    drives = (ArmController,)

    def start(self, robot, record, now_ns):
        self.robot, self.t0 = robot, now_ns
        self.q = list(robot.joint_positions())

    def step(self, now_ns):
        t = (now_ns - self.t0) * 1e-9
        self.robot.command_joints((self.q[0] + 30.0 * t, self.q[1]), (30.0, 0.0))
        if t >= 0.3:
            self.stop("ended moving")


def test_a_plug_in_motion_that_ends_moving_is_braked_to_rest_not_extrapolated(arm):
    """A motion whose last knot has 30 deg/s: the shoulder is braked to rest near its acceleration limit (not held at once, not extrapolated: at most 1.25 deg past its last knot), no fault, every output off after."""
    from pyrt import MotionRecord

    from pyrt_arm.controller import AMAX_DEG_S2

    register_motion_type(_Drifting.name, _Drifting, replace=True)
    station, runner, _shell, _out = arm
    runner.call(station.submit_motion, MotionRecord(_Drifting.name, {}))
    assert runner.wait_until(lambda: station.controller.state == "moving", 5.0)
    assert runner.wait_until(lambda: station.controller.state != "moving", 5.0)
    speeds: list[float] = []

    def sample() -> bool:
        speeds.append(station.plant.qd_deg_s[0])
        return not station.busy()

    assert runner.wait_until(sample, 5.0)
    # the way to rest (until friction holds the last 2 deg/s): the true deceleration stays
    # near the limit (the servo's transient adds up to about 85 %); a hold at the last knot
    # would saturate the drive (about 2700 deg/s^2)
    decel = max(a - b for a, b in itertools.pairwise(speeds) if b > 2.0) / 1e-3
    assert decel <= 2.5 * AMAX_DEG_S2[0], decel
    assert runner.call(station.last_stop) == "at target"
    q0 = runner.call(lambda: station.plant.q_deg[0])
    last_knot = 30.0 * 0.3
    assert last_knot - 0.5 <= q0 <= last_knot + 30.0 ** 2 / (2 * AMAX_DEG_S2[0]) + 0.1, q0
    assert station.fault is None
    assert runner.call(lambda: _registers(station)) == {"drive": [0, 0], "enable": [0, 0]}


def test_arm_moves_are_planned_in_the_console_s_thread_never_in_a_tick(arm, monkeypatch):
    """arm to and arm xy, from rest and queued behind a running move: every plan is made with the loop not ticking (counted, not timed); the queued move blends from the running one's end and the arm ends at target."""
    from pyrt.motion import Evaluator

    _station, runner, shell, out = arm
    ticking: list[bool] = []
    plan = Evaluator.plan

    def watched(self, *a, **k):
        ticking.append(runner.loop.running)
        return plan(self, *a, **k)

    monkeypatch.setattr(Evaluator, "plan", watched)
    assert _say(shell, out, "arm to 60 30").startswith("arm: moving to")
    assert "blends into the running move" in _say(shell, out, "arm xy 300 200")
    assert _say(shell, out, "wait").startswith("at target")
    assert len(ticking) >= 2 and not any(ticking)
