"""The arm's servo on the time that really passed: a loop that stalls during a fast move."""

from __future__ import annotations

import io

import pytest
from pyrt import FaultError, Loop
from pyrt.commands.robot import RobotShell
from pyrt.testing import StallClock

from pyrt_arm.controller import AT_TARGET_DEG
from pyrt_arm.station import build_arm

MS = 1_000_000


def _say(shell: RobotShell, out: io.StringIO, line: str) -> str:
    out.seek(0)
    out.truncate()
    shell.onecmd(line)
    return out.getvalue().strip()


@pytest.mark.parametrize("stall_ms", [15, 30])
def test_a_stall_during_a_fast_move_does_not_trip_and_the_move_ends_at_target(stall_ms):
    """The loop stalls 15 or 30 ms, three times, during a fast move (the plant advancing by the time that passed): no following-error fault, and the encoders end at the target."""
    clock = StallClock()
    station = build_arm(Loop(clock))
    runner = station.start()
    try:
        out = io.StringIO()
        shell = RobotShell(station, out, runner=runner)
        assert _say(shell, out, "arm to 90 -60").startswith("arm: moving to")
        for t in (0.2, 0.1013, 0.0507):
            runner.sleep(t)
            clock.stall(stall_ms * MS)
        said = _say(shell, out, "wait")
        assert said.startswith("at target"), said
        assert station.fault is None
        q0, q1 = runner.call(station.controller.angles)
        assert abs(q0 - 90) <= AT_TARGET_DEG and abs(q1 + 60) <= AT_TARGET_DEG
    finally:
        station.close()


def test_a_jammed_joint_still_trips_through_a_stall():
    """The shoulder jammed during the same move with a 30 ms stall while it is jammed: the following error still trips it."""
    clock = StallClock()
    station = build_arm(Loop(clock))
    runner = station.start()
    try:
        out = io.StringIO()
        shell = RobotShell(station, out, runner=runner)
        _say(shell, out, "arm to 90 -60")
        runner.sleep(0.2)
        _say(shell, out, "sim fault jam q0")
        clock.stall(30 * MS)
        with pytest.raises(FaultError):
            runner.wait_until(lambda: station.fault is not None, 5.0)
        assert "q0 following error" in station.fault.cause
    finally:
        station.close()


def test_the_stall_clock_starts_every_later_tick_that_much_late():
    """pyrt.testing's StallClock: after stall(ns), now and every tick's start are ns after the deadline, and stalls add up."""
    clock = StallClock()
    assert clock.start_tick(5 * MS) == 5 * MS
    clock.stall(30 * MS)
    assert clock.now_ns() == 35 * MS
    assert clock.start_tick(6 * MS) == 36 * MS
    clock.stall(15 * MS)
    assert clock.start_tick(7 * MS) == 52 * MS and clock.now_ns() == 52 * MS
