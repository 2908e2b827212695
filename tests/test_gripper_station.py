"""The gripper station: P moves through the motion queue, reflex clearing it, ack."""

from __future__ import annotations

import io

import pytest

from pyrt.commands import RobotShell
from pyrt.scheduler import Loop, SimClock
from pyrt.station.gripper import build_gripper


@pytest.fixture
def station():
    st = build_gripper(Loop(SimClock()))
    out = io.StringIO()
    shell = RobotShell(st, out)
    st.runner.start()

    def run(*lines: str) -> list[str]:
        out.seek(0)
        out.truncate()
        for line in lines:
            shell.onecmd(line)
        return out.getvalue().splitlines()

    st.run = run
    assert run("I")[-1].startswith("jaws wide open")
    yield st
    st.shutdown()


def counts(word: str) -> int:
    value = int(word, 16)
    return value - 0x10000 if value & 0x8000 else value


def test_p_during_a_move_replaces_its_target(station):
    """002: a P given while the jaws move changes the target of that move; wait says at target."""
    station.run("P -1000")
    station.runner.sleep(0.2)
    assert station.controller.moving
    station.run("P -0400")
    assert len(station.runner.motion) == 0  # nothing queued behind: the move took it
    lines = station.run("wait")
    assert lines[0].startswith("at target: position")
    assert abs(counts(station.run("W")[0]) + 0x0400) <= 16
    assert counts(station.run("T")[0]) == -0x0400
    assert station.executor.last.stop_reason == "stopped"


def test_queued_motion_records_run_in_order(station):
    """motion gripper_move records queue behind the running move; wait waits for all of them."""
    station.run("P -1000", "motion gripper_move target=-1024")
    assert len(station.runner.motion) + station.executor.busy >= 1
    lines = station.run("wait")
    assert lines[0].startswith("at target")
    assert abs(counts(station.run("W")[0]) + 0x0400) <= 16
    assert station.executor.last.target == -0x0400


def test_full_motion_queue_refuses(station):
    """More P moves than the motion queue holds: the extra one is refused with a clear error."""
    cap = station.runner.motion.capacity
    lines = station.run(*[f"motion gripper_move target=-{0x100 + k}" for k in range(cap + 2)])
    assert any("motion queue full" in line for line in lines)


def test_jammed_motor_ends_each_queued_move_without_current(station):
    """Jammed motor: 002's stopped bit ends every queued move in turn; the drive is left null."""
    station.run("sim fault jam", "P -1000", "P -0800", "P -0400")
    lines = station.run("wait 5")
    assert lines[0].startswith("stopped") and station.plant.board.dac == 0x80
    assert counts(station.run("W")[0]) == 0 and not station.executor.busy


def test_fault_empties_the_motion_queue_and_needs_ack(station):
    """A fault mid-move: drive nulled and queued moves dropped in the same tick; P refused until ack."""
    ctl = station.controller
    station.run("P -1000", "motion gripper_move target=-2048",
                "motion gripper_move target=-1024")
    station.runner.sleep(0.2)
    assert ctl.moving and len(station.runner.motion) == 2

    def trip():
        station.trip("loadcell on fire", source="test")
        return station.plant.board.dac, len(station.runner.motion), station.executor.busy

    assert station.runner.call(trip) == (0x80, 0, False)
    assert station.executor.last.stop_reason == "fault: loadcell on fire"
    lines = station.run("W")
    assert lines[0].startswith("FAULT: loadcell on fire") and "ack" in lines[1]
    assert "ack" in station.run("P -0200")[0]
    station.runner.sleep(1.0)
    assert station.plant.board.dac == 0x80 and not ctl.moving
    assert station.run("ack")[-1].startswith("fault acknowledged")
    station.run("P -0200", "wait")
    assert abs(counts(station.run("W")[0]) + 0x0200) <= 16
