"""pyrt urdf's console words for moving frames and buffer modes: the conveyor and PLCopen's
aborting, checked against the simulated arm's truth."""

from __future__ import annotations

import math

import numpy as np
import pytest
from _urdf_rig import puma_station
from _urdf_rig import settle as _settle
from _urdf_rig import target as _target

from pyrt.errors import CommandError
from pyrt.kinematics.puma import puma560

CHAIN = puma560()
#: How far the true tool may be from its point on a moving conveyor while tracking (mm).
TRACK_MM = 2.0


@pytest.fixture(scope="module")
def puma():
    """One PUMA station on simulated time for this module."""
    yield from puma_station()


def _go(station, runner, pose) -> None:
    """The tool to ``pose`` (mm, deg) by a joint move, righty-above-noflip, and at rest."""
    q = CHAIN.closed_form.inverse(_target(*pose), "righty-above-noflip")
    runner.call(station.arm.move_joints, *np.degrees(q).tolist())
    _settle(station, runner)


# -- the conveyor -----------------------------------------------------------------------------


@pytest.mark.parametrize("velocity", [(0.0, 50.0, 0.0), (-40.0, 0.0, 30.0)])
def test_the_tool_tracks_its_point_on_the_conveyor_in_truth(puma, velocity):
    """NAME conveyor at 50 mm/s, then movel to a point on the belt: once the tool has reached it (state tracking, wait returns), the simulated true tool stays within 2 mm of the point as the belt carries it for 2 s; stop brakes it to rest and holds; conveyor 0 0 0 leaves COORD where the belt took it."""
    station, runner = puma
    arm = station.arm
    _go(station, runner, (500, 100, 400, 180, 20, 90))
    said = runner.call(arm.set_conveyor, *velocity)
    assert "conveyor at" in said
    point = (450, -100, 350, 180, 20, 90)
    assert "on the moving conveyor" in runner.call(arm.move_line, *point)
    belt = arm.conveyor
    assert belt is not None
    # wait returns when the tool has reached its point and tracks it
    _settle(station, runner)
    assert arm.state == "tracking" and station.fault is None
    assert station.last_stop().startswith("tracking"), station.last_stop()
    want_local = _target(*point)
    worst = [0.0]
    t0 = runner.call(lambda: station.plant.truth().time)

    def watch() -> bool:
        tr = station.plant.truth()
        want = (belt.pose_at(tr.time) @ want_local)[:3, 3]
        worst[0] = max(worst[0], float(np.linalg.norm(tr.tool[:3, 3] - want)))
        return tr.time - t0 >= 2.0

    assert runner.wait_until(watch, 10.0)
    assert worst[0] * 1e3 <= TRACK_MM, f"{worst[0] * 1e3:.3f} mm from the point on the belt"
    moved = runner.call(lambda: station.plant.truth().tool[:3, 3].copy())
    with pytest.raises(CommandError, match="tracks the conveyor"):
        runner.call(arm.set_conveyor, 0, 0, 0)
    assert "braking" in runner.call(station.stop)
    _settle(station, runner)
    assert station.fault is None and arm.powered and arm.state == "idle"
    assert "stopped" in station.last_stop()
    qd = runner.call(lambda: station.plant.truth().qd)
    assert float(np.max(np.abs(qd))) < math.radians(0.5)
    # the belt carried the tool along its velocity
    assert np.dot(moved - (belt.pose_at(t0) @ want_local)[:3, 3], velocity) > 0
    said = runner.call(arm.set_conveyor, 0, 0, 0)
    assert "conveyor stopped" in said and arm.conveyor is None
    at = runner.call(lambda: arm.coord_frame.copy())
    assert np.linalg.norm(at[:3, 3]) > 0.05  # COORD kept where the belt took it
    runner.call(arm.set_coord, 0, 0, 0, 0, 0, 0)


def test_a_new_move_leaves_the_conveyor_and_ends_at_its_target_in_truth(puma):
    """While the tool tracks the conveyor, a movej leaves it (continuously: no fault, no following-error trip) and ends at its target at rest in truth, 'at target'."""
    station, runner = puma
    arm = station.arm
    _go(station, runner, (500, 100, 400, 180, 20, 90))
    runner.call(arm.set_conveyor, 0, 50, 0)
    runner.call(arm.move_line, 450, -100, 350, 180, 20, 90)
    _settle(station, runner)
    assert arm.state == "tracking"
    runner.sleep(0.5)
    assert "leaving the moving frame" in runner.call(arm.move_joints, 0, 45, -180, 0, -45, 0)
    _settle(station, runner)
    assert station.fault is None and station.last_stop() == "at target"
    q = runner.call(lambda: station.plant.truth().q)
    assert np.degrees(np.abs(q - np.radians([0, 45, -180, 0, -45, 0]))).max() < 0.05
    runner.call(arm.set_conveyor, 0, 0, 0)
    runner.call(arm.set_coord, 0, 0, 0, 0, 0, 0)


def test_the_conveyor_word_is_refused_while_a_move_runs_and_for_bad_speeds(puma):
    """conveyor while a move runs is refused (nothing changes); a speed beyond 500 mm/s is out of its range; help gives the grammar and the range."""
    station, runner = puma
    arm = station.arm
    _settle(station, runner)
    runner.call(arm.move_joints, 20, 60, -160, 10, -30, 10)
    with pytest.raises(CommandError, match="refused while a move runs"):
        runner.call(arm.set_conveyor, 0, 50, 0)
    assert arm.conveyor is None
    _settle(station, runner)
    rec = arm.find_command("conveyor")
    with pytest.raises(CommandError):
        rec.parse(["0", "600", "0"], "0 600 0")
    assert "conveyor VX VY VZ" in rec.help and "-500..500 mm/s" in rec.help
    runner.call(arm.move_joints, 0, 45, -180, 0, -45, 0)
    _settle(station, runner)


# -- PLCopen's buffer modes on the console ----------------------------------------------------


def _peak_deviation(station, runner, first, second, option):
    """Queue movej ``first``, then after 0.4 s movej ``second`` with ``option``: (how near the
    truth came to ``first`` (deg), the reply to the second, the last stop)."""
    arm = station.arm
    runner.call(arm.move_joints, 0, 45, -180, 0, -45, 0)
    _settle(station, runner)
    runner.call(arm.move_joints, *first)
    runner.sleep(0.4)
    said = runner.call(arm.move_joints, *second, option)
    nearest = [math.inf]

    def watch() -> bool:
        q = np.degrees(station.plant.truth().q)
        nearest[0] = min(nearest[0], float(np.max(np.abs(q - first))))
        return not station.busy()

    assert runner.wait_until(watch, 30.0)
    assert station.fault is None
    q = np.degrees(runner.call(lambda: station.plant.truth().q))
    assert float(np.max(np.abs(q - second))) < 0.05  # on the second target in truth
    return nearest[0], said, station.last_stop()


def test_aborting_replaces_the_running_move_at_once_and_buffered_waits_for_it(puma):
    """movej buffer=aborting given while a long move runs replaces it at once (the truth turns away and never comes near the first target; 'aborting' is said, and the move ends 'at target' on the new one); buffer=buffered passes through the first target exactly, then goes on."""
    station, runner = puma
    first = (90, 100, -100, 60, -60, 90)
    second = (-20, 40, -170, -20, -30, -20)
    near, said, last = _peak_deviation(station, runner, first, second, "buffer=aborting")
    assert "aborting the running move" in said
    assert near > 20.0, near
    assert last == "at target"
    near, said, last = _peak_deviation(station, runner, first, second, "buffer=buffered")
    assert "at rest on its target" in said
    assert near < 0.05, near
    assert last == "at target"


def test_a_bad_buffer_mode_is_refused_and_the_options_say_the_modes(puma):
    """buffer=fast is refused naming the options (nothing moves); movej's help gives buffer=MODE with aborting, buffered and blending."""
    station, runner = puma
    arm = station.arm
    _settle(station, runner)
    with pytest.raises(CommandError, match="not an option") as info:
        runner.call(arm.move_joints, 10, 50, -170, 0, -40, 0, "buffer=fast")
    assert "nothing moved" in str(info.value)
    assert not runner.call(station.busy)
    text = arm.find_command("movej").help
    assert all(w in text for w in ("buffer=MODE", "aborting", "buffered", "blending"))


def test_a_conveyor_that_carries_the_point_where_the_arm_cannot_follow_brakes_it(puma):
    """A conveyor at 100 mm/s carries the tracked point toward the edge of the reach: before a joint would need more than its velocity limit (or the point leaves the reach) the arm is braked to rest and holds, without a fault; the move ends saying why; the truth is at rest."""
    station, runner = puma
    arm = station.arm
    _go(station, runner, (500, 100, 400, 180, 20, 90))
    runner.call(arm.set_conveyor, 0, 100, 0)
    runner.call(arm.move_line, 450, -100, 350, 180, 20, 90)
    _settle(station, runner)
    assert arm.state == "tracking"
    assert runner.wait_until(lambda: arm.state != "tracking", 20.0)
    _settle(station, runner)
    assert station.fault is None and arm.powered
    said = station.last_stop()
    assert said.startswith("stopped: the moving frame carried the tool's point where the arm "
                           "cannot follow"), said
    runner.sleep(0.2)
    qd = runner.call(lambda: station.plant.truth().qd)
    assert float(np.max(np.abs(qd))) < math.radians(0.5)
    runner.call(arm.set_conveyor, 0, 0, 0)
    runner.call(arm.set_coord, 0, 0, 0, 0, 0, 0)


# -- planning outside the loop ------------------------------------------------------------------


@pytest.fixture
def planned_where(puma, monkeypatch):
    """Every plan and every inverse of a move, with whether the loop was ticking then."""
    from pyrt.motion.planner import Planner
    from pyrt.station._urdf_moves import ArmMoves

    station, _ = puma
    loop = station.runner.loop
    seen: list[tuple[str, bool]] = []
    plan, solve = Planner.plan, ArmMoves.solve

    def watched_plan(self, *a, **k):
        seen.append(("plan", loop.running))
        return plan(self, *a, **k)

    def watched_solve(self, *a, **k):
        seen.append(("solve", loop.running))
        return solve(self, *a, **k)

    monkeypatch.setattr(Planner, "plan", watched_plan)
    monkeypatch.setattr(ArmMoves, "solve", watched_solve)
    return seen


def _shell(station, runner):
    import io

    from pyrt.commands.robot import RobotShell

    out = io.StringIO()
    shell = RobotShell(station, out, runner=runner)

    def say(line: str) -> str:
        out.seek(0)
        out.truncate()
        shell.onecmd(line)
        return out.getvalue()

    return say


def test_console_moves_are_planned_outside_the_loop_and_queued_plans_blend(puma, planned_where):
    """movej, moveto and movel from the console: every plan and inverse runs in the console's thread with the loop not ticking (none in a tick); a move given while one is queued plans from the queued end and blends into it; the tool ends at the last target in truth."""
    station, runner = puma
    _go(station, runner, (500, 100, 400, 180, 20, 90))
    planned_where.clear()
    say = _shell(station, runner)
    assert "moving to" in say("puma560 movej 10 50 -170 10 -40 10")
    assert "blends into the running move" in say("puma560 moveto 500 -100 400 180 0 90")
    # planned from the queued end of movej: a blend at its corner
    assert runner.call(lambda: station.arm._latest.buffer) == "blending"
    # the line from the joint move's end: no room for a blend, and the reply says so
    said = say("puma560 movel 450 -100 350 180 0 90")
    assert "at rest on its target: no blend (no room to blend" in said, said
    kinds = {k for k, _ in planned_where}
    assert kinds == {"plan", "solve"}
    assert [k for k, ticking in planned_where if ticking] == []
    _settle(station, runner)
    assert runner.call(lambda: station.arm.last_stop) == "at target"
    truth = runner.call(lambda: station.plant.truth().tool[:3, 3].copy())
    assert np.linalg.norm(truth * 1e3 - [450, -100, 350]) < 0.5


def test_a_tick_that_takes_a_console_move_plans_nothing(puma, planned_where):
    """The hand-over of a console move is bounded: in the tick that takes it, and every tick while it runs, no plan and no inverse of a move is made (counted, not timed)."""
    station, runner = puma
    _go(station, runner, (500, 100, 400, 180, 20, 90))
    planned_where.clear()
    say = _shell(station, runner)
    for line in ("puma560 movej 0 45 -180 0 -45 0", "puma560 moveto 500 0 450 180 0 90",
                 "puma560 movel 480 0 400 180 0 90"):
        assert "refused" not in say(line)
    _settle(station, runner)
    assert len(planned_where) >= 3
    assert sum(1 for _, ticking in planned_where if ticking) == 0


def _prepared_call(station, runner, rec, between):
    """The console's hand-over of ``rec``, with ``between()`` run in the loop after its
    snapshot and before its hand-over (once)."""
    from pyrt.component import Prepared

    done = []

    def call(arg):
        if isinstance(arg, Prepared) and not done:
            done.append(runner.call(between))
        return runner.call(station.execute, station.arm, rec, [arg])

    return call


def test_a_stop_between_planning_and_hand_over_refuses_the_move_nothing_moves(puma):
    """A stop taken after a move's snapshot and before its hand-over: the plan is stale, planning again is refused while the arm brakes, with a clear error; the arm comes to rest short of that move's target and nothing stays queued."""
    from pyrt.component import run_prepared

    station, runner = puma
    arm = station.arm
    _go(station, runner, (500, 100, 400, 180, 20, 90))
    runner.call(arm.move_joints, 10, 50, -170, 10, -40, 10)
    runner.sleep(0.2)
    rec = arm.find_command("movej")
    target = [-20.0, 30.0, -150.0, -10.0, -30.0, -10.0]
    with pytest.raises(CommandError, match=r"refused: the arm is stopping.*nothing moved"):
        run_prepared(rec, rec.parse([f"{v:g}" for v in target]),
                     _prepared_call(station, runner, rec, station.stop))
    _settle(station, runner)
    q = np.degrees(runner.call(lambda: arm.q.copy()))
    assert np.max(np.abs(q - target)) > 5.0, "the refused move ran"
    assert runner.call(lambda: arm.last_stop).startswith("stopped")


def test_a_move_queued_between_planning_and_hand_over_is_planned_again_from_it(puma):
    """Another move queued after a move's snapshot and before its hand-over: the hand-over is stale, the move is planned again from the new queued end, and the arm ends at the move given last, in truth."""
    from pyrt.component import run_prepared

    station, runner = puma
    arm = station.arm
    _go(station, runner, (500, 100, 400, 180, 20, 90))
    rec = arm.find_command("movej")
    last = [0.0, 45.0, -180.0, 0.0, -45.0, 0.0]
    said = run_prepared(rec, rec.parse([f"{v:g}" for v in last]),
                        _prepared_call(station, runner, rec,
                                       lambda: arm.move_joints(10, 50, -170, 10, -40, 10)))
    assert "queued" in said
    _settle(station, runner)
    q = np.degrees(runner.call(lambda: arm.q.copy()))
    assert np.max(np.abs(q - last)) < 0.05
    assert runner.call(lambda: arm.last_stop) == "at target"
