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
