"""pyrt urdf: the PUMA 560 from its URDF, moved by joints and by poses and checked against the
simulated arm's truth; refusals; faults; the board, the journal and the command line."""

from __future__ import annotations

import contextlib
import importlib.util
import math
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from _urdf_rig import puma_station
from _urdf_rig import settle as _settle
from _urdf_rig import target as _target
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pyrt.boards.armservo import arm_servo_kind
from pyrt.errors import CommandError, FaultError
from pyrt.kinematics import rpy_of
from pyrt.kinematics.puma import puma560
from pyrt.scheduler import Loop, SimClock
from pyrt.station.urdf import URDF, build_urdf

ROOT = Path(__file__).resolve().parents[1]
#: What the truth must meet after a move: the tool within this of the target (mm, deg).
POS_MM, ROT_DEG = 0.5, 0.1

CHAIN = puma560()


def _pyrt(*argv: str, stdin: str = "", timeout: float = 300) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-m", "pyrt", *argv], input=stdin, cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=timeout)


def _rot_deg(a: np.ndarray, b: np.ndarray) -> float:
    """The angle (deg) of the rotation between the rotations of two poses."""
    r = a[:3, :3].T @ b[:3, :3]
    c = max(-1.0, min(1.0, (float(np.trace(r)) - 1.0) / 2.0))
    return math.degrees(math.acos(c))


def _outputs(station) -> list[int]:
    """Every DAC and enable register as the board holds it now."""
    b, n = station.board, station.chain.n
    return [b.read("dac", j) for j in range(n)] + [b.read("enable", j) for j in range(n)]


@pytest.fixture(scope="module")
def puma():
    """One PUMA station on simulated time for the in-process tests of this module."""
    yield from puma_station()


# -- the piped script -------------------------------------------------------------------


def test_a_piped_script_of_joint_and_pose_moves_ends_at_the_target_in_truth():
    """pyrt urdf --speed max with a piped script of joint moves and pose moves (blended, with and without a configuration): sim show's true tool pose ends within 0.5 mm and 0.1 deg of the last target."""
    script = "\n".join([
        "puma560 movej 10 30 -150 20 -30 40",
        "puma560 movej -20 60 -170 -30 -50 -40",
        "wait",
        "puma560 moveto 500 100 400 180 0 90",
        "wait",
        "puma560 moveto 450 -150 500 170 10 45 righty-above-noflip",
        "wait",
        "puma560 where",
        "sim show",
        "quit",
    ]) + "\n"
    done = _pyrt("urdf", "--speed", "max", stdin=script)
    assert done.returncode == 0, done.stderr
    assert "error" not in done.stdout + done.stderr, done.stdout + done.stderr
    m = re.search(r"tool \(([-\d.]+), ([-\d.]+), ([-\d.]+)\) mm, rpy \(([-\d.]+), ([-\d.]+), "
                  r"([-\d.]+)\) deg; table", done.stdout)
    assert m, done.stdout
    got = _target(*(float(v) for v in m.groups()))
    want = _target(450, -150, 500, 170, 10, 45)
    assert np.linalg.norm(got[:3, 3] - want[:3, 3]) * 1e3 <= POS_MM
    assert _rot_deg(got, want) <= ROT_DEG
    assert "last move: at target" in done.stdout


# -- the property: random reachable targets against the truth ---------------------------

_LO = np.radians([-150.0, -30.0, -210.0, -100.0, -90.0, -250.0])
_HI = np.radians([150.0, 210.0, 30.0, 160.0, 90.0, 250.0])


@st.composite
def _reachable(draw):
    """A joint vector inside the limits, the wrist away from its singularity."""
    u = [draw(st.floats(0.0, 1.0)) for _ in range(6)]
    q = _LO + np.array(u) * (_HI - _LO)
    if abs(q[4]) < math.radians(10.0):
        q[4] = math.copysign(math.radians(10.0), q[4] if q[4] else 1.0)
    return q


@settings(max_examples=8, deadline=None, database=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(q=_reachable(), named=st.booleans())
def test_pose_moves_to_random_reachable_targets_end_there_in_truth(puma, q, named):
    """Over random reachable tool poses (the pose of a random joint vector within the limits), moveto with the pose's configuration, or the numerical inverse toward a nearby pose, ends with the simulated true tool within 0.5 mm and 0.1 deg of the target."""
    station, runner = puma
    if not named:  # the numerical inverse from where the arm is: a pose nearby
        here = runner.call(lambda: station.arm.q.copy())
        q = np.clip(here + (q - (_LO + _HI) / 2) * 0.15, _LO, _HI)
    t = CHAIN.fk(q)
    x, y, z = (t[:3, 3] * 1e3).tolist()
    rx, ry, rz = (math.degrees(a) for a in rpy_of(t))
    words = [f"{v:.6f}" for v in (x, y, z, rx, ry, rz)]
    if named:
        words.append(CHAIN.closed_form.config_of(q))
    rec = station.arm.find_command("moveto")
    runner.call(station.execute, station.arm, rec, rec.parse(words, " ".join(words)))
    _settle(station, runner)
    assert station.fault is None
    assert station.arm.last_stop == "at target"
    truth = runner.call(lambda: station.plant.truth().tool)
    want = _target(*(float(w) for w in words[:6]))
    assert np.linalg.norm(truth[:3, 3] - want[:3, 3]) * 1e3 <= POS_MM
    assert _rot_deg(truth, want) <= ROT_DEG


# -- refusals change nothing ------------------------------------------------------------


REFUSED = [
    ("moveto", ["5000", "0", "0", "0", "0", "0"], "beyond the arm's reach"),
    ("moveto", ["500", "100", "400", "180", "0", "90", "righty-below-flip"], "beyond its limits"),
    ("moveto", ["500", "100", "400", "180", "0", "90", "sideways"], "configuration"),
    ("movej", ["10", "300", "-150", "0", "0", "0"], "out of range"),
    ("movej", ["10", "30"], "usage"),
]


@pytest.mark.parametrize(("verb", "words", "why"), REFUSED)
def test_an_unreachable_pose_or_a_target_beyond_a_limit_is_refused_and_nothing_moves(
        puma, verb, words, why):
    """An unreachable pose, a configuration that puts a joint beyond its limit, an unknown configuration, a joint target out of range, a short joint list: refused with the reason; nothing is queued, the servo's reference and the registers stay as they were."""
    station, runner = puma
    _settle(station, runner)
    rec = station.arm.find_command(verb)

    def act():
        before = (station.arm.servo.knots.tolist(), _outputs(station), station.arm.state)
        try:
            station.execute(station.arm, rec, rec.parse(words, " ".join(words)))
        except CommandError as exc:
            return str(exc), before, (station.arm.servo.knots.tolist(), _outputs(station),
                                     station.arm.state)
        return None, before, None

    said, before, after = runner.call(act)
    assert said is not None and why in said, said
    assert "nothing" in said or "usage" in said
    assert before[0] == after[0] and before[2] == after[2] == "idle"
    assert not runner.call(station.busy)


# -- faults ---------------------------------------------------------------------------------


def _watch(station, seen: list) -> bool:
    """Loop thread, after each tick: the outputs of the tick the fault came in."""
    if station.fault is not None:
        seen.append(_outputs(station))
        return True
    return False


@pytest.mark.parametrize("push_deg", [6.0, 1.6])
def test_a_fault_stops_every_joint_in_the_same_tick(push_deg):
    """A following error (joint 2 pushed 6 deg in the world) or a joint beyond its limit (joint 1 pushed past its limit by 1.6 deg, within the following-error limit) trips the station: in that tick every DAC and every enable register is 0; nothing moves until ack, then a move closes the loop again."""
    station = build_urdf(Loop(SimClock()))
    runner = station.start()
    try:
        arm = station.arm
        if push_deg < 2.0:  # to a joint limit first
            runner.call(arm.move_joints, 159.5, 45, -180, 0, -45, 0)
        else:
            runner.call(arm.move_joints, 20, 60, -170, 10, -40, 10)
        runner.sleep(0.3 if push_deg > 2.0 else 0.0)
        if push_deg < 2.0:
            _settle(station, runner)
        assert any(_outputs(station)[: station.chain.n])  # the servo drives

        def push():
            q = station.plant.truth().q
            j = 0 if push_deg < 2.0 else 1
            q[j] += math.radians(push_deg)
            station.plant.set_state(q)

        runner.call(push)
        seen: list = []
        with contextlib.suppress(FaultError):
            runner.wait_until(lambda: _watch(station, seen), 1.0)
        assert station.fault is not None
        cause = station.fault.cause
        assert ("following error" in cause) if push_deg > 2.0 else ("beyond its limits" in cause)
        assert seen and seen[0] == [0] * (2 * station.chain.n)
        rec = arm.find_command("movej")
        for call in (station.execute, lambda _c, _r, a: arm.move_joints(*a)):
            with pytest.raises(CommandError, match="ack"):
                runner.call(call, arm, rec, [0, 45, -180, 0, -45, 0], take_fault=False)
        runner.call(station.acknowledge, take_fault=False)
        assert _outputs(station) == [0] * 12
        runner.call(arm.move_joints, 0, 45, -180, 0, -45, 0)
        _settle(station, runner)
        assert station.fault is None and arm.last_stop == "at target"
    finally:
        station.close()


def test_stop_brakes_along_the_path_and_holds():
    """stop during a joint move brakes to rest and the servo holds the arm there (it carries its weight): no fault, amplifiers still on, the truth at rest."""
    station = build_urdf(Loop(SimClock()))
    runner = station.start()
    try:
        runner.call(station.arm.move_joints, 90, 100, -100, 60, -60, 90)
        runner.sleep(0.3)
        said = runner.call(station.stop)
        assert "braking" in said
        _settle(station, runner)
        runner.sleep(0.2)
        assert station.fault is None and station.arm.powered
        assert "stopped" in station.last_stop()
        qd = runner.call(lambda: station.plant.truth().qd)
        assert float(np.max(np.abs(qd))) < math.radians(0.5)
    finally:
        station.close()


# -- the board, the signals, the command line --------------------------------------------


def test_the_board_declares_a_dac_enable_and_counter_per_joint_and_six_wrench_channels():
    """The arm's passive servo board: per joint a 16-bit DAC, an enable and a brake release (off 0: no current, brake engaged) and a 32-bit counter; six F/T channels; the joint count is part of the kind's fingerprint."""
    k6, k7 = arm_servo_kind(6), arm_servo_kind(7)
    assert [(r.name, r.count) for r in k6.registers] == [("dac", 6), ("enable", 6),
                                                         ("release", 6), ("count", 6),
                                                         ("ft", 6)]
    assert all(r.off == 0 for r in k6.outputs())
    assert k6.fingerprint != k7.fingerprint
    with pytest.raises(ValueError):
        arm_servo_kind(0)


def test_the_signals_are_the_joints_and_the_tool_from_the_encoders_and_the_truth(puma):
    """NAME.q1 .. q6 (deg, the joint limits as display limits), x y z (mm), rx ry rz (deg) from the encoders agree with sim.x/.y/.z and the truth at rest."""
    station, runner = puma
    _settle(station, runner)
    values = runner.call(lambda: {n: s.read() for n, s in station.signals()})
    q2 = station.arm.signal("q2")
    assert q2.units == "deg" and (q2.limits.lopr, q2.limits.hopr) == pytest.approx((-45, 225))
    for axis in "xyz":
        assert abs(values[f"puma560.{axis}"] - values[f"sim.{axis}"]) < 0.1
    for axis in ("rx", "ry", "rz"):
        d = (values[f"puma560.{axis}"] - values[f"sim.{axis}"] + 180) % 360 - 180
        assert abs(d) < 0.05


def test_board_kinds_follow_the_urdf_named_on_the_command_line(tmp_path):
    """board-sim's board kinds are those of the URDF the parsed options name (the PUMA's
    without one); parsing them leaves the factory as it was."""
    import argparse

    assert URDF.board_kinds()["servo"].register("dac").count == 6
    text = (Path(__file__).parent / "data" / "two_link.urdf").read_text()
    path = tmp_path / "two.urdf"
    path.write_text(text)
    p = argparse.ArgumentParser()
    URDF.add_world_arguments(p)
    assert URDF.board_kinds_of(p.parse_args([str(path)]))["servo"].register("dac").count == 2
    assert URDF.board_kinds()["servo"].register("dac").count == 6
    assert URDF.board_kinds_of(p.parse_args([]))["servo"].register("dac").count == 6


def test_a_journal_of_the_urdf_station_replays_identically(tmp_path):
    """pyrt urdf --journal records a run of moves; pyrt replay re-runs it bit for bit from the URDF the journal keeps."""
    journal = tmp_path / "run.journal"
    script = "puma560 movej 10 50 -170 10 -40 10\nwait\npuma560 moveto 500 100 400 180 0 90\nwait\nquit\n"
    done = _pyrt("urdf", "--speed", "max", "--journal", str(journal), stdin=script)
    assert done.returncode == 0, done.stderr
    replay = _pyrt("replay", str(journal))
    assert replay.returncode == 0, replay.stdout + replay.stderr
    assert "identical" in replay.stdout


def test_any_urdf_runs_without_code(tmp_path):
    """A two-link arm given as a URDF file runs: its robot's name is the root, movej moves it (no closed form: moveto uses the numerical inverse) and the truth ends at the target."""
    path = Path(__file__).parent / "data" / "two_link.urdf"
    script = "twolink movej 30 -40\nwait\ntwolink where\nsim show\nquit\n"
    done = _pyrt("urdf", str(path), "--speed", "max", stdin=script)
    assert done.returncode == 0, done.stderr
    m = re.search(r"true joints ([-\d.]+) ([-\d.]+);", done.stdout)
    assert m, done.stdout
    assert abs(float(m.group(1)) - 30) < 0.05 and abs(float(m.group(2)) + 40) < 0.05


# -- movel, tool and coord (the motion layer's Cartesian segments) -----------------------


def _dist_to_line(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    ab = b - a
    s = min(max(float((p - a) @ ab) / float(ab @ ab), 0.0), 1.0)
    return float(np.linalg.norm(p - (a + s * ab)))


@pytest.mark.parametrize("line", [((500, 100, 400, 180, 0, 90), (500, -150, 450, 180, 0, 90)),
                                  ((450, -150, 500, 170, 10, 45), (600, 50, 350, 180, -10, 90))])
def test_movel_keeps_the_true_tool_on_the_line_and_ends_at_the_target(puma, line):
    """movel: at every servo tick the simulated true tool lies within 1 mm of the straight line, and it ends within 0.5 mm and 0.1 deg of the target."""
    station, runner = puma
    start, end = line
    # from the start pose's righty-above-noflip joints nearest zero (the wrist's turn known)
    q0 = CHAIN.closed_form.inverse(_target(*start), "righty-above-noflip")
    runner.call(station.arm.move_joints, *np.degrees(q0).tolist())
    _settle(station, runner)
    a = runner.call(lambda: station.plant.truth().tool[:3, 3].copy())
    b = _target(*end)[:3, 3]
    worst = [0.0]

    def watch() -> bool:
        p = station.plant.truth().tool[:3, 3]
        worst[0] = max(worst[0], _dist_to_line(p, a, b))
        return not station.busy()

    runner.call(station.arm.move_line, *map(float, end))
    assert runner.wait_until(watch, 30.0)
    assert worst[0] * 1e3 <= 1.0, f"{worst[0] * 1e3:.3f} mm off the line"
    truth = runner.call(lambda: station.plant.truth().tool)
    want = _target(*end)
    assert np.linalg.norm(truth[:3, 3] - want[:3, 3]) * 1e3 <= POS_MM
    assert _rot_deg(truth, want) <= ROT_DEG


def test_tool_and_coord_frames_carry_into_the_signals_and_the_targets(puma):
    """NAME tool puts a tool frame on the flange (the signals follow it), NAME coord the frame targets are given in: a moveto in a shifted COORD with a 100 mm tool ends with the true flange where the frames say; both refused while a move runs."""
    station, runner = puma
    arm = station.arm
    _settle(station, runner)
    try:
        runner.call(arm.set_tool, 0, 0, 100, 0, 0, 0)
        runner.call(arm.set_coord, 100, 0, 0, 0, 0, 0)
        runner.call(arm.move_to, 400, 100, 300, 180, 0, 90)
        with pytest.raises(CommandError, match="refused while a move runs"):
            runner.call(arm.set_tool, 0, 0, 0, 0, 0, 0)
        _settle(station, runner)
        flange = runner.call(lambda: station.plant.truth().tool)
        want = _target(500, 100, 300, 180, 0, 90) @ np.linalg.inv(_target(0, 0, 100, 0, 0, 0))
        assert np.linalg.norm(flange[:3, 3] - want[:3, 3]) * 1e3 <= POS_MM
        z = runner.call(lambda: station.arm.signal("z").read())
        assert abs(z - 300.0) <= POS_MM
    finally:
        runner.call(arm.set_tool, 0, 0, 0, 0, 0, 0)
        runner.call(arm.set_coord, 0, 0, 0, 0, 0, 0)


def test_options_set_the_speed_and_the_blend_and_bad_ones_are_refused(puma):
    """movej speed=0.25 keeps every true joint speed within a quarter of its limit (the same move at full speed goes beyond it); blend=0 on the second of two queued moves makes the first end exactly on its target (an exact stop, PLCopen's buffered) where without it the blend cuts the corner; an unknown option is refused naming the options, nothing moves."""
    station, runner = puma
    arm = station.arm
    _settle(station, runner)
    home = (0, 45, -180, 0, -45, 0)
    runner.call(arm.move_joints, *home)
    _settle(station, runner)
    vmax = np.array(arm.limits.vmax)
    peaks = []
    for speed in ("speed=1", "speed=0.25"):
        peak = [0.0]

        def fastest(peak=peak) -> bool:
            peak[0] = max(peak[0], float(np.max(np.abs(station.plant.truth().qd) / vmax)))
            return not station.busy()

        runner.call(arm.move_joints, 60, 80, -120, 40, -20, 60, speed)
        assert runner.wait_until(fastest, 30.0)
        peaks.append(peak[0])
        runner.call(arm.move_joints, *home)
        _settle(station, runner)
    assert peaks[0] > 0.3 and peaks[1] <= 0.25 * 1.03, peaks
    with pytest.raises(CommandError, match="not an option"):
        runner.call(arm.move_joints, 60, 80, -120, 40, -20, 60, "fast=1")
    assert not runner.call(station.busy)
    nearest = []
    for option in ([], ["blend=0"]):
        runner.call(arm.move_joints, *home)
        _settle(station, runner)
        runner.call(arm.move_joints, 30, 60, -150, 20, -30, 30)
        runner.call(arm.move_joints, 60, 80, -120, 40, -20, 60, *option)
        seen = []

        def watch(seen=seen) -> bool:
            q = np.degrees(station.plant.truth().q)
            seen.append(float(np.max(np.abs(q - [30, 60, -150, 20, -30, 30]))))
            return not station.busy()

        assert runner.wait_until(watch, 30.0)
        nearest.append(min(seen))
    # blended, the corner is cut; blend=0 on the second passes through the first target
    assert nearest[0] > 0.01 and nearest[1] < 0.005, nearest


def test_a_guarded_move_onto_the_table_stops_on_the_wrist_force(puma):
    """movel down onto sim table with force=20: the wrist sensor (the board's F/T registers) stops it within a few millimetres of the table, and last_stop says the force felt; without the table the same move reaches its target."""
    station, runner = puma
    arm = station.arm
    _settle(station, runner)
    q0 = CHAIN.closed_form.inverse(_target(500, 100, 450, 180, 0, 90), "righty-above-noflip")
    runner.call(arm.move_joints, *np.degrees(q0).tolist())
    _settle(station, runner)
    sim = station.find("sim")
    try:
        runner.call(sim.table, "350")
        runner.call(arm.move_line, 500, 100, 250, 180, 0, 90, "speed=0.1 force=20")
        _settle(station, runner)
        assert station.fault is None
        assert station.last_stop().startswith("force limit"), station.last_stop()
        z = runner.call(lambda: station.plant.truth().tool[2, 3]) * 1e3
        assert 345.0 <= z <= 351.0, z
    finally:
        runner.call(sim.table, "off")
    runner.call(arm.move_line, 500, 100, 300, 180, 0, 90, "speed=0.1 force=20")
    _settle(station, runner)
    assert station.last_stop() == "at target"


@pytest.mark.skipif(importlib.util.find_spec("caproto") is None, reason="caproto not installed")
def test_epics_serves_the_joints_with_their_limits_as_display_limits(puma):
    """--epics: the PV of each joint (NAME:Q1 ..) has the joint's limits as its display limits, in degrees."""
    from pyrt.server import ServedStation, Server
    from pyrt.server.epics import EpicsService

    station, runner = puma
    served = ServedStation(station)
    server = Server(runner, served, "127.0.0.1", 0)
    epics = EpicsService(runner, served, server, "PUMA:")
    try:
        for j, (lo, hi) in enumerate(zip(CHAIN.lower, CHAIN.upper, strict=True)):
            pv = epics.pvdb[f"PUMA:Q{j + 1}"]
            assert (pv.lower_disp_limit, pv.upper_disp_limit) == pytest.approx(
                (math.degrees(lo), math.degrees(hi)))
            assert pv.units == "deg"
    finally:
        epics.close()
        server.close()
