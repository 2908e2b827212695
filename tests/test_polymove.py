"""The PolyAxis's parts: built from its record and services, the move controller
(one plan per ``to``, one caller of ``fail``), and its own params."""

from __future__ import annotations

import ast
import dataclasses
from pathlib import Path

import pytest
from _manipulator_rig import make_station

import pyrt
from pyrt.errors import CommandError, ConfigError
from pyrt.native import FuzzyInput
from pyrt.robots.polyaxis import PolyAxis, PolyAxisServices
from pyrt.robots.polymove import MoveController

ROBOTS = Path(pyrt.__file__).parent / "robots"


@pytest.fixture
def proto(tmp_path):
    station, runner = make_station(tmp_path)
    yield station, runner
    station.close()


def _count(obj, name: str, calls: list[str]) -> None:
    """Count the calls of ``obj.name`` in ``calls`` (the method still runs)."""
    real = getattr(obj, name)

    def counted(*args, **kw):
        calls.append(name)
        return real(*args, **kw)

    setattr(obj, name, counted)


def test_to_is_checked_and_planned_once(proto):
    """'to x y z' plans its path once and checks the target and the estimate once."""
    station, runner = proto
    pa = station.polyaxis
    calls: list[str] = []
    for name in ("plan_path", "check_target", "refuse_if_lost"):
        _count(pa.mover, name, calls)
    text = runner.call(pa.run_command, "to", "0", "0", "90")
    assert "segment" in text and pa.active
    assert sorted(calls) == ["check_target", "plan_path", "refuse_if_lost"]
    runner.call(pa.stop)
    assert not pa.active


def test_a_refused_to_moves_nothing_and_plans_once(proto):
    """A target outside the vessel is refused by the one path check; nothing moves."""
    station, runner = proto
    pa = station.polyaxis
    calls: list[str] = []
    _count(pa.mover, "plan_path", calls)
    with pytest.raises(CommandError, match="outside the vessel; nothing moved"):
        runner.call(pa.run_command, "to", "0", "0", "5000")
    assert calls == ["plan_path"] and not pa.active and pa.moves == 0
    assert not station.motors_running()


def test_halt_is_the_only_caller_of_fail():
    """In the PolyAxis and its parts, only MoveController.halt calls fail."""
    callers = []
    for module in ("polyaxis.py", "polymove.py", "polystatus.py"):
        tree = ast.parse((ROBOTS / module).read_text())
        for cls in (n for n in tree.body if isinstance(n, ast.ClassDef)):
            for fn in (n for n in cls.body if isinstance(n, ast.FunctionDef)):
                for node in ast.walk(fn):
                    if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                            and node.func.attr == "fail"):
                        callers.append(f"{cls.name}.{fn.name}")
    assert callers and set(callers) == {"MoveController.halt"}


def test_max_tension_and_end_error_are_the_polyaxis_own_params(proto):
    """MAX_TENSION and END_ERROR are the PolyAxis's params, listed once; setting them
    changes the rope model and the fuzzy rules, and a refused value changes nothing."""
    station, runner = proto
    pa = station.polyaxis
    assert [p.name for p in pa.params()] == ["MAX_TENSION", "END_ERROR"]
    names = [p.name for p in station.params_of(pa)]
    assert names.count("MAX_TENSION") == 1 and names.count("END_ERROR") == 1
    max_t, end = pa.params()
    runner.call(end.write, 0.7)
    assert pa.end_error == pa.model.end_error == 0.7
    before = pa.max_tension
    with pytest.raises(CommandError, match="nothing changed"):
        runner.call(max_t.write, pa.low_tension)
    assert pa.max_tension == before
    runner.call(max_t.write, before - 10.0)
    assert pa.model.max_tension == before - 10.0
    assert (pa.batch.inputs[:, FuzzyInput.TENSION_HIGH] == before - 10.0).all()


def test_a_polyaxis_is_built_from_its_record_and_services(tmp_path):
    """The record is where the limits come from; the services bundle is what it works with."""
    station, _runner = make_station(tmp_path)
    record = dataclasses.replace(station.station.polyaxis(), max_tension=150.0, end_error=0.4)
    motion = station.motion
    seen: list[object] = []
    station.close()
    services = PolyAxisServices(motion=motion, pattern_writer="sync", on_stop=(seen.append,))
    pa = PolyAxis(record, station.axes, station.av, services, name="again")
    assert (pa.name, pa.max_tension, pa.end_error) == ("again", 150.0, 0.4)
    assert pa.model.max_tension == 150.0
    assert (pa.batch.inputs[:, FuzzyInput.TENSION_HIGH] == 150.0).all()
    assert pa.motion is motion and pa.pattern_writer == "sync" and pa.on_stop == [seen.append]
    assert isinstance(pa.mover, MoveController) and pa.executor is pa.mover.executor
    with pytest.raises(ConfigError, match="pattern writer"):
        PolyAxisServices(pattern_writer="later")
    with pytest.raises(AttributeError, match="estimator"):
        pa.position = (0.0, 0.0, 0.0)
