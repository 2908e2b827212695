"""pyrt urdf on rate groups: the servo group at 1 kHz and the trajectory group at 100 Hz
whatever the tick (--tick-us 500 leaves them so), hardware (a) with the trajectory group
alone, and an overrun charged to the task and group that caused it (stats, timing log)."""

from __future__ import annotations

import argparse
import json

import numpy as np
import pytest
from _clocks import MS, WorkClock

from pyrt.errors import ConfigError
from pyrt.scheduler import Loop, SimClock, TimingLog, read_timing_log
from pyrt.scheduler.report import format_statistics
from pyrt.station._urdf_arm import AT_TARGET_DEG, SERVO_PERIOD_NS, UrdfArm
from pyrt.station.urdf import URDF, build_urdf


def _groups(loop: Loop) -> dict[str, tuple[int, int]]:
    return {k: (g.period_ns, g.releases) for k, g in loop.statistics().groups.items()}


@pytest.mark.parametrize("tick_ns", [MS, MS // 2, MS // 4])
def test_the_servo_is_1_khz_and_the_trajectory_100_hz_whatever_the_tick(tick_ns):
    """One second of loop time on the SimClock at a 1 ms, 0.5 ms (--tick-us 500) or 0.25 ms tick: 1000 servo and 100 trajectory releases, each task once per release, the servo tuned for 1 ms; the physics follows the tick."""
    loop = Loop(SimClock(), period_ns=tick_ns)
    station = build_urdf(loop)
    try:
        loop.run(duration_ns=1_000 * MS)
        assert _groups(loop) == {"servo": (MS, 1_000), "trajectory": (10 * MS, 100)}
        tasks = loop.statistics().tasks
        assert (tasks["servo"].calls, tasks["servo"].group) == (1_000, "servo")
        assert (tasks["trajectory"].calls, tasks["trajectory"].group) == (100, "trajectory")
        assert tasks["io:read"].calls == 1_000 * MS // tick_ns  # the physics steps in it
        assert station.arm.servo.period == pytest.approx(SERVO_PERIOD_NS * 1e-9)
        assert station.arm.traj_period_s == pytest.approx(0.01)
        assert station.arm.powered and station.fault is None
    finally:
        station.close()


def test_tick_us_500_moves_the_arm_to_its_target():
    """At --tick-us 500 (the servo still at 1 kHz) a joint move ends at its target within the at-target tolerance, in the simulation's truth."""
    station = build_urdf(Loop(SimClock(), period_ns=MS // 2))
    runner = station.start()
    try:
        assert runner.wait_until(lambda: station.arm.powered and not station.busy(), 30.0)
        target = (10.0, 30.0, -150.0, 20.0, -30.0, 40.0)
        runner.call(station.arm.move_joints, *target)
        assert runner.wait_until(lambda: not station.busy(), 60.0)
        assert station.fault is None and station.arm.state == "idle"
        truth = runner.call(lambda: np.degrees(station.plant.truth().q))
        assert np.abs(truth - np.array(target)).max() < AT_TARGET_DEG
    finally:
        station.close()


def test_a_tick_that_does_not_divide_the_servos_period_is_refused():
    """Hardware (b) on a 0.3 ms or a 2 ms tick is refused with the reason, before any board opens."""
    for tick_ns in (300_000, 2 * MS):
        with pytest.raises(ConfigError, match="hardware b runs its servo group at 1 kHz"):
            build_urdf(Loop(SimClock(), period_ns=tick_ns))


@pytest.mark.parametrize("tick_ns", [MS, 10 * MS])
def test_hardware_a_has_the_trajectory_group_alone(tick_ns):
    """Hardware (a) at a 1 ms or a 10 ms tick: no servo group on the host, the trajectory group at 100 Hz."""
    loop = Loop(SimClock(), period_ns=tick_ns)
    station = URDF.build(loop, argparse.Namespace(boards=None, urdf=None, start=None,
                                                  hardware="a"))
    try:
        loop.run(duration_ns=1_000 * MS)
        assert _groups(loop) == {"trajectory": (10 * MS, 100)}
        assert loop.statistics().tasks["trajectory"].calls == 100
    finally:
        station.close()


def test_a_trajectory_that_overruns_is_charged_to_its_group(tmp_path, monkeypatch):
    """3 ms of work injected into the trajectory task (a clock that advances when it works): stats names the trajectory task under the trajectory group with every overrun, the timing log charges each overrun to that group, and the servo group shows the releases it missed."""
    clock = WorkClock()
    original = UrdfArm.trajectory_tick

    def slow(self, now_ns):
        original(self, now_ns)
        clock.work(3 * MS)

    monkeypatch.setattr(UrdfArm, "trajectory_tick", slow)
    path = tmp_path / "timing.jsonl"
    loop = Loop(clock, period_ns=MS, timing_log=TimingLog(str(path), version="test"))
    station = build_urdf(loop)
    try:
        loop.run(duration_ns=200 * MS)
        lines = format_statistics(loop.statistics()).splitlines()
    finally:
        station.close()
        loop.close()
    under = lines[lines.index("trajectory:") + 1:]
    row = next(ln for ln in under if ln.split()[0] == "trajectory")
    assert row.split()[1] == "20" and row.split()[-1] == "20"  # 20 calls, 20 overruns
    group = loop.statistics().groups
    assert group["trajectory"].overruns == 20 and group["servo"].overruns == 0
    # each time the two servo releases inside the 3 ms (the third is on time: the work ends on it)
    assert group["servo"].missed == 40

    records = [json.loads(ln) for ln in path.read_text().splitlines()]
    over = [r for r in records if r["type"] == "overrun"]
    assert len(over) == 20 and {r["group"] for r in over} == {"trajectory"}
    assert all(dict(zip([n for n, _ in r["tasks"]], r["task_groups"], strict=True))[
        "trajectory"] == "trajectory" for r in over)
    rep = read_timing_log(str(path))
    assert rep.tasks["trajectory"].group == "trajectory"
    assert rep.tasks["trajectory"].overruns == 20 and rep.groups["trajectory"].overruns == 20
