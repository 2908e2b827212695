"""pyrt urdf on 004's hardware (a), a motion-control board that takes setpoints at the
trajectory rate and servos on the board, against hardware (b), the passive servo board."""

from __future__ import annotations

import contextlib
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pyrt.boards.armdrive import ENABLED, FAULT, arm_drive_kind
from pyrt.errors import ConfigError, FaultError
from pyrt.journal import Tick, read_journal
from pyrt.scheduler import Loop, SimClock
from pyrt.station.urdf import URDF, build_urdf

ROOT = Path(__file__).resolve().parents[1]
#: The same targets on both kinds of hardware: every joint within this (deg) in truth.
SAME_DEG = 0.05
_LO = np.array([-150.0, -30.0, -210.0, -100.0, -90.0, -250.0])
_HI = np.array([150.0, 210.0, 30.0, 160.0, 90.0, 250.0])


def _pyrt(*argv: str, stdin: str = "", timeout: float = 300) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-m", "pyrt", *argv], input=stdin, cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=timeout)


def _start(hardware: str, tick_ns: int):
    station = build_urdf(Loop(SimClock(), period_ns=tick_ns), hardware=hardware)
    runner = station.start()
    assert runner.wait_until(lambda: station.arm.powered and not station.busy(), 5.0)
    return station, runner


@pytest.fixture(scope="module")
def both():
    """The PUMA on hardware (a) with the host ticking at the trajectory rate (10 ms), and on
    hardware (b) at 1 ms."""
    pair = [_start("a", 10_000_000), _start("b", 1_000_000)]
    yield pair
    for station, _runner in pair:
        station.close()


def _move(station, runner, q_deg) -> np.ndarray:
    runner.call(station.arm.move_joints, *q_deg)
    assert runner.wait_until(lambda: not station.busy(), 60.0), "the move never ended"
    assert station.fault is None, station.fault
    assert station.arm.last_stop == "at target", station.arm.last_stop
    return np.degrees(runner.call(lambda: station.plant.truth().q))


@settings(max_examples=5, deadline=None, database=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(u=st.lists(st.floats(0.05, 0.95), min_size=6, max_size=6))
def test_the_same_arm_reaches_the_same_targets_on_hardware_a_and_b(both, u):
    """Random joint targets within the limits: the arm on the motion-control board (setpoints at 100 Hz, the board's servo at 1 kHz) and on the passive board (the host's servo at 1 kHz) both end at the target in truth, every joint within 0.05 deg of it and of each other."""
    target = (_LO + np.array(u) * (_HI - _LO)).round(3)
    (sa, ra), (sb, rb) = both
    got_a = _move(sa, ra, target.tolist())
    got_b = _move(sb, rb, target.tolist())
    assert np.abs(got_a - target).max() <= SAME_DEG, got_a - target
    assert np.abs(got_b - target).max() <= SAME_DEG, got_b - target
    assert np.abs(got_a - got_b).max() <= SAME_DEG


def test_on_hardware_a_the_host_has_no_servo_task_and_the_board_servos():
    """On hardware (a) the station's only task is the trajectory (every 10 ticks at 1 ms, every tick at 10 ms); the board is enabled with no fault and its amplifiers drive the arm."""
    for tick_ns, every in ((1_000_000, 10), (10_000_000, 1)):
        station, runner = _start("a", tick_ns)
        try:
            assert [t.name for t in station.arm.tasks()] == ["trajectory"]
            assert station.arm.every == every
            status = runner.call(lambda s=station: s.board.read("status"))
            assert status & ENABLED and not status & FAULT
            assert station.board.kind == arm_drive_kind(6)
            assert runner.call(lambda s=station: np.abs(s.plant.truth().current).max()) > 0.0
            sig = station.arm.signal("status")
            assert sig is not None and runner.call(sig.read) & ENABLED
        finally:
            station.close()


def test_hardware_b_refuses_a_tick_longer_than_its_servo_and_a_refuses_one_not_dividing_10_ms():
    """--hardware b on a 10 ms tick, --hardware a on a 3 ms tick: refused at build time with the reason."""
    with pytest.raises(ConfigError, match="hardware b"):
        build_urdf(Loop(SimClock(), period_ns=10_000_000), hardware="b")
    with pytest.raises(ConfigError, match="does not divide"):
        build_urdf(Loop(SimClock(), period_ns=3_000_000), hardware="a")
    with pytest.raises(ConfigError, match="a or b"):
        build_urdf(Loop(SimClock()), hardware="c")


def _on_tick(station, seen: list) -> bool:
    """Loop thread, after each tick: the board's enable and the arm's amplifiers at the fault."""
    if station.fault is not None:
        seen.append((station.board.read("enable"), station.plant._k.enable.tolist(),
                     station.board.read("status")))
        return True
    return False


@pytest.mark.parametrize("push_deg", [6.0, 1.6])
def test_a_fault_disables_the_hardware_a_board_in_the_same_tick(push_deg):
    """A following error (joint 2 pushed 6 deg: the board trips on its own, every amplifier off in its tick, and says which joint) or a joint beyond its limit (joint 1 pushed 1.6 deg past it: the host's check): in the tick the station's fault comes in, the board's enable register is 0 and the arm's amplifiers are off; ack, then a move enables the board again and ends at target."""
    station, runner = _start("a", 1_000_000)
    try:
        arm = station.arm
        if push_deg < 2.0:
            runner.call(arm.move_joints, 159.5, 45, -180, 0, -45, 0)
            assert runner.wait_until(lambda: not station.busy(), 60.0)
        else:
            runner.call(arm.move_joints, 20, 60, -170, 10, -40, 10)
            runner.sleep(0.3)

        def push():
            q = station.plant.truth().q
            q[0 if push_deg < 2.0 else 1] += math.radians(push_deg)
            station.plant.set_state(q)

        runner.call(push)
        seen: list = []
        with contextlib.suppress(FaultError):
            runner.wait_until(lambda: _on_tick(station, seen), 1.0)
        assert station.fault is not None
        cause = station.fault.cause
        if push_deg > 2.0:
            assert "following error: the board tripped on joint joint2" in cause or \
                "following error: the board tripped on joint" in cause, cause
        else:
            assert "beyond its limits" in cause, cause
        enable, amps, _status = seen[0]
        assert enable == 0
        if push_deg > 2.0:  # the board had switched its amplifiers off itself
            assert amps == [0] * 6
        runner.sleep(0.01)
        assert runner.call(lambda: station.plant._k.enable.tolist()) == [0] * 6
        runner.call(station.acknowledge, take_fault=False)
        runner.call(arm.move_joints, 0, 45, -180, 0, -45, 0)
        assert runner.wait_until(lambda: not station.busy(), 60.0)
        assert station.fault is None and arm.last_stop == "at target"
        assert runner.call(lambda: station.board.read("status")) & ENABLED
    finally:
        station.close()


def test_on_hardware_a_the_journal_shows_output_writes_only_on_trajectory_ticks(tmp_path):
    """pyrt urdf --hardware a --journal at a 1 ms tick, a script with a move: every output write of the journal but the shutdown's reflex (enable 0 at quit) is the trajectory task's, on ticks one trajectory period (10 ticks) apart; on hardware (b) the servo task writes between them."""
    script = "puma560 movej 10 30 -150 20 -30 40\nwait\nquit\n"
    writes = {}
    for hw in ("a", "b"):
        journal = tmp_path / f"{hw}.pj"
        done = _pyrt("urdf", "--hardware", hw, "--speed", "max", "--journal", str(journal),
                     stdin=script)
        assert done.returncode == 0, done.stderr
        assert "at target" in done.stdout, done.stdout
        header, records = read_journal(str(journal))
        writes[hw] = [(r.tick, header.outputs[i], v, header.writers[w]) for r in records
                      if isinstance(r, Tick) for i, v, w in r.outputs]
    moving = [(t, w) for t, name, v, w in writes["a"] if not (name.endswith("enable") and v == 0)]
    assert len(moving) > 100
    assert {w for _t, w in moving} == {"trajectory"}
    assert len({t % 10 for t, _w in moving}) == 1
    assert any(name.endswith("enable") and v == 0 for _t, name, v, _w in writes["a"][-6:])
    assert len({t % 10 for t, _n, _v, _w in writes["b"]}) == 10


def test_board_kinds_follow_the_hardware_named_on_the_command_line():
    """pyrt urdf's (and board-sim's) board is 'drive' (the motion-control board) with --hardware a, 'servo' (the passive board) without, as the parsed options say; parsing them leaves the factory as it was (an in-process replay of a hardware (a) journal changes no later answer)."""
    import argparse

    p = argparse.ArgumentParser()
    URDF.add_world_arguments(p)
    assert URDF.board_kinds_of(p.parse_args(["--hardware", "a"])) == {"drive": arm_drive_kind(6)}
    assert list(URDF.board_kinds()) == ["servo"]  # nothing kept from the parse
    assert list(URDF.board_kinds_of(p.parse_args([]))) == ["servo"]
    with pytest.raises(SystemExit):
        p.parse_args(["--hardware", "c"])


def test_after_a_fault_the_brakes_hold_the_arm_where_it_was():
    """On hardware (a) the board engages each joint's brake while its amplifier is off, on hardware (b) the reflex writes each brake's release 0: after a fault the arm stays within 0.05 deg of where it was for 2 s (it does not sink onto its stops); ack and a move release them again."""
    moved = {}
    for hw, tick in (("a", 10_000_000), ("b", 1_000_000)):
        station, runner = _start(hw, tick)
        try:
            runner.call(station.arm.move_joints, 0, 60, -150, 0, -45, 0)
            assert runner.wait_until(lambda s=station: not s.busy(), 60.0)
            with contextlib.suppress(FaultError):
                runner.call(station.arm.fail, "test: a fault", station.arm.name)
            q0 = runner.call(lambda s=station: s.plant.truth().q, take_fault=False)
            runner.sleep(2.0)
            q1 = runner.call(lambda s=station: s.plant.truth().q, take_fault=False)
            moved[hw] = float(np.degrees(np.abs(q1 - q0)).max())
            with contextlib.suppress(FaultError):  # the fault, told once
                runner.call(lambda: None)
            runner.call(station.acknowledge, take_fault=False)
            runner.call(station.arm.move_joints, 0, 45, -180, 0, -45, 0)
            assert runner.wait_until(lambda s=station: not s.busy(), 60.0)
            assert station.fault is None and station.arm.last_stop == "at target"
        finally:
            station.close()
    assert moved["a"] < 0.05 and moved["b"] < 0.05, moved


@pytest.mark.parametrize("hardware", ["a", "b"])
def test_an_arm_lying_beyond_a_limit_at_power_on_is_brought_back_inside(hardware):
    """The simulated arm starts 1.5 deg beyond joint 1's upper limit (inside its end stop): at power-on the servo (b) or the board's setpoints (a) bring it back inside its limits, with no fault, and a move then ends at target."""
    station = build_urdf(Loop(SimClock(), period_ns=1_000_000), hardware=hardware)
    try:
        q = station.plant.truth().q
        q[0] = station.chain.upper[0] + math.radians(1.5)
        station.plant.set_state(q)
        runner = station.start()
        assert runner.wait_until(lambda: station.arm.powered and not station.busy(), 10.0)
        assert station.fault is None
        q1 = runner.call(lambda: station.plant.truth().q)
        assert q1[0] <= station.chain.upper[0] + 1e-4
        runner.call(station.arm.move_joints, 100, 45, -180, 0, -45, 0)
        assert runner.wait_until(lambda: not station.busy(), 60.0)
        assert station.fault is None and station.arm.last_stop == "at target"
    finally:
        station.close()
