"""Pluggable motion types: registry, entry points, and the executor stepping queued records."""

from __future__ import annotations

import sys
import textwrap

import pytest

from pyrt.errors import CommandError
from pyrt.scheduler import Loop, SimClock
from pyrt.scheduler import motion as motion_mod
from pyrt.scheduler.motion import (
    MotionExecutor,
    MotionRecord,
    MotionType,
    get_motion_type,
    motion_type_names,
    register_motion_type,
)
from pyrt.scheduler.runner import Runner


class Ramp(MotionType):
    """Moves a 1-D robot's position toward a target by a fixed step per poll."""

    name = "ramp"

    def start(self, robot, record, now_ns):
        self.robot = robot
        self.target = float(record.params["target"])
        if not -100 <= self.target <= 100:
            raise CommandError(f"target {self.target} outside -100..100")

    def step(self, now_ns):
        pos = self.robot["pos"]
        d = self.target - pos
        if abs(d) <= 1.0:
            self.robot["pos"] = self.target
            self.stop("endpoint")
        else:
            self.robot["pos"] = pos + (1.0 if d > 0 else -1.0)


def test_registered_motion_runs_queued_records_in_order():
    """Queued motion records run one after another through the executor, each to its stop reason."""
    register_motion_type("ramp", Ramp, replace=True)
    loop = Loop(SimClock())
    robot = {"pos": 0.0}
    runner = Runner(loop)
    finished = []
    executor = MotionExecutor(robot, runner.motion.get, lambda m: finished.append(m.stop_reason))
    loop.attach(executor.poll)
    runner.start()
    runner.submit_motion(MotionRecord("ramp", {"target": 10}))
    runner.submit_motion(MotionRecord("RAMP", {"target": -5}))
    assert runner.wait_until(lambda: len(finished) == 2, 1.0)
    assert robot["pos"] == -5.0 and finished == ["endpoint", "endpoint"]


def test_unknown_type_and_bad_parameters_are_refused():
    """An unknown motion type or a start() refusal ends the record as refused; the robot does not move."""
    register_motion_type("ramp", Ramp, replace=True)
    robot = {"pos": 0.0}
    records = [MotionRecord("warp", {}), MotionRecord("ramp", {"target": 500})]
    done = []
    executor = MotionExecutor(robot, lambda: records.pop(0) if records else None, done.append)
    executor.poll(0)
    executor.poll(1)
    assert [m.stop_reason for m in done] == [
        "refused: unknown motion type 'warp'; known: " + ", ".join(motion_type_names()),
        "refused: target 500.0 outside -100..100",
    ]
    assert robot["pos"] == 0.0 and not executor.busy


def test_an_error_while_stepping_trips_the_robot_not_the_loop():
    """An exception in step() ends the motion and goes to on_error (the robot's fault), never to the loop."""

    class Broken(Ramp):
        def step(self, now_ns):
            raise ZeroDivisionError("encoder lost")

    register_motion_type("broken", Broken, replace=True)
    records = [MotionRecord("broken", {"target": 5})]
    errors, done = [], []
    executor = MotionExecutor(
        {"pos": 0.0}, lambda: records.pop(0) if records else None, done.append,
        lambda cause, m: errors.append(cause),
    )
    executor.poll(0)
    assert errors == ["ZeroDivisionError: encoder lost"]
    assert done[0].stop_reason == "failed: ZeroDivisionError: encoder lost" and not executor.busy


def test_abort_stops_the_current_motion():
    """A reflex action aborts the running motion with its reason."""
    register_motion_type("ramp", Ramp, replace=True)
    robot = {"pos": 0.0}
    records = [MotionRecord("ramp", {"target": 50})]
    done = []
    executor = MotionExecutor(robot, lambda: records.pop(0) if records else None, done.append)
    executor.poll(0)
    executor.poll(1)
    executor.abort("LOW_TENSION_STOP")
    assert done[0].stop_reason == "LOW_TENSION_STOP" and robot["pos"] == 2.0
    executor.poll(2)
    assert robot["pos"] == 2.0


def test_registry_refuses_bad_registrations():
    """Only MotionType subclasses under identifier names; no silent replacement."""
    with pytest.raises(TypeError):
        register_motion_type("thing", dict)  # type: ignore[arg-type]
    with pytest.raises(ValueError):
        register_motion_type("not a name", Ramp)

    class Other(MotionType):
        pass

    register_motion_type("ramp", Ramp, replace=True)
    with pytest.raises(ValueError, match="already registered"):
        register_motion_type("ramp", Other)


def test_entry_point_motion_type_is_found_and_runs(tmp_path, monkeypatch):
    """A motion type published by an installed distribution's entry point is found by name and runs."""
    pkg = tmp_path / "labmotions"
    pkg.mkdir()
    (pkg / "__init__.py").write_text(textwrap.dedent('''
        from pyrt.scheduler.motion import MotionType

        class Spiral(MotionType):
            name = "spiral"
            drives = (dict,)

            def start(self, robot, record, now_ns):
                self.robot = robot
                self.turns = int(record.params["turns"])

            def step(self, now_ns):
                self.robot["turns"] += 1
                if self.robot["turns"] >= self.turns:
                    self.stop("turns done")
    '''))
    dist = tmp_path / "labmotions-1.0.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: labmotions\nVersion: 1.0\n")
    (dist / "entry_points.txt").write_text("[pyrt.motion_types]\nspiral = labmotions:Spiral\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(motion_mod, "_loaded_entry_points", False)
    monkeypatch.delitem(motion_mod._registry, "spiral", raising=False)
    try:
        assert "spiral" in motion_type_names()
        cls = get_motion_type("Spiral")
        assert cls.__module__ == "labmotions"
        robot = {"turns": 0}
        records = [MotionRecord("spiral", {"turns": 3})]
        done = []
        executor = MotionExecutor(robot, lambda: records.pop(0) if records else None, done.append)
        for t in range(5):
            executor.poll(t)
        assert robot["turns"] == 3 and done[0].stop_reason == "turns done"
    finally:
        motion_mod._registry.pop("spiral", None)
        sys.modules.pop("labmotions", None)
