"""pyrt urdf on the time that really passed: a loop that stalls during a fast move."""

from __future__ import annotations

import numpy as np
import pytest
from _clocks import StallClock

from pyrt.errors import FaultError
from pyrt.scheduler import Loop
from pyrt.station.urdf import build_urdf

MS = 1_000_000
TARGET = (60.0, 20.0, -120.0, 60.0, -60.0, 90.0)


@pytest.mark.parametrize("stall_ms", [15, 22, 30])
def test_a_stall_during_a_fast_move_does_not_trip_and_the_move_ends_at_its_target(stall_ms):
    """The loop stalls 15 to 30 ms in the middle of a fast joint move (the world advancing by the time that passed): no following-error fault, and the arm ends at its target in truth."""
    clock = StallClock()
    station = build_urdf(Loop(clock))
    said: list[str] = []
    station.subscribe(lambda m: said.append(m.text))
    runner = station.start()
    try:
        arm = station.arm
        assert runner.wait_until(lambda: arm.powered and not station.busy(), 5.0)
        runner.call(arm.move_joints, *TARGET)
        for t in (0.25, 0.1013, 0.0507):  # mid-move, at various phases of the trajectory
            runner.sleep(t)
            clock.stall(stall_ms * MS)
        assert runner.wait_until(lambda: not station.busy(), 20.0)
        assert station.fault is None
        assert arm.last_stop == "at target"
        stalls = [m for m in said if "passed since its last tick" in m]
        assert len(stalls) == 3 and f"{stall_ms + 1:.1f} ms" in stalls[0], said
        q = runner.call(lambda: station.plant.truth().q)
        assert np.max(np.abs(np.degrees(q) - TARGET)) < 0.05
    finally:
        station.close()


def test_a_blocked_joint_still_trips_the_following_error_through_a_stall():
    """A joint held where it is (blocked) during the same fast move, with a 30 ms stall while it is held: the following error still trips the station, naming that joint, with every DAC 0."""
    clock = StallClock()
    station = build_urdf(Loop(clock))
    runner = station.start()
    try:
        arm = station.arm
        assert runner.wait_until(lambda: arm.powered and not station.busy(), 5.0)
        runner.call(arm.move_joints, *TARGET)
        runner.sleep(0.2)
        held = runner.call(lambda: station.plant.truth().q[0])

        def block() -> None:
            t = station.plant.truth()
            q, qd = t.q.copy(), t.qd.copy()
            q[0], qd[0] = held, 0.0
            station.plant.set_state(q, qd)

        with pytest.raises(FaultError):
            for i in range(500):
                runner.call(block)
                if i == 5:
                    clock.stall(30 * MS)
                runner.sleep(0.001)
        assert station.fault is not None
        assert "following error" in station.fault.cause and "joint1" in station.fault.cause
        assert [station.board.read("dac", j) for j in range(6)] == [0] * 6
    finally:
        station.close()


def test_without_a_stall_every_knot_is_made_on_the_trajectory_groups_tick():
    """A move on a loop that never stalls: the trajectory task makes every knot on its own tick (a motion's first segment starts at that tick), the servo never has to make one for it, and the move ends at its target."""
    from pyrt.scheduler import SimClock

    station = build_urdf(Loop(SimClock()))
    runner = station.start()
    try:
        arm = station.arm
        assert runner.wait_until(lambda: arm.powered and not station.busy(), 5.0)
        made: list[int] = []
        task_tick = arm.trajectory_tick  # the task keeps its own bound method

        def from_the_servo(now_ns: int) -> None:
            made.append(now_ns)
            task_tick(now_ns)

        arm.trajectory_tick = from_the_servo  # what the servo task calls on a stall
        starts: list[float] = []
        follow = arm.follow

        def recorded(period: float) -> None:
            starts.append(arm._start)
            follow(period)

        arm.follow = recorded
        runner.call(arm.move_joints, *TARGET)
        assert runner.wait_until(lambda: not station.busy(), 20.0)
        assert made == [] and arm.last_stop == "at target"
        assert len(starts) > 50
        # every segment starts on a trajectory tick (10 ms apart, from the first)
        steps = np.diff(starts) / 0.01
        assert np.allclose(steps, np.round(steps), atol=1e-6)
        assert round(starts[0] * 1000) % 10 == 0
    finally:
        station.close()
