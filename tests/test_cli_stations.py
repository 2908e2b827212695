"""Any station runs the same way: installed ones as sub-commands, others through ``pyrt run``."""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

import pytest

import pyrt
from pyrt.cli import build_parser
from pyrt.errors import ConfigError
from pyrt.station.factory import StationFactory, as_factory, installed_stations, load_factory

ROOT = Path(__file__).resolve().parents[1]
CLI = Path(pyrt.__file__).parent / "cli"
#: The manipulator's own tools, which name it by design.
ROBOT_TOOLS = {"forcemap.py", "logsort.py"}
ROBOT_WORDS = ("gripper", "manipulator", "prototype", "polyaxis")


def _pyrt(*argv: str, stdin: str = "", timeout: float = 120) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": f"{ROOT}{os.pathsep}{ROOT / 'tests'}"}
    return subprocess.run([sys.executable, "-m", "pyrt", *argv], input=stdin, cwd=ROOT,
                          env=env, capture_output=True, text=True, timeout=timeout)


def _docstrings(tree: ast.AST) -> set[int]:
    """ids of the docstring nodes of a module and its classes and functions."""
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
                out.add(id(body[0].value))
    return out


def test_cli_names_no_robot():
    """No code of pyrt.cli names a robot: no import, no string (the manipulator's forcemap
    and logsort aside; docstrings may give examples)."""
    offenders = []
    for path in sorted(CLI.glob("*.py")):
        if path.name in ROBOT_TOOLS:
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        docs = _docstrings(tree)
        for node in ast.walk(tree):
            if id(node) in docs:
                continue
            texts = []
            if isinstance(node, ast.Constant) and isinstance(node.value, str):
                texts.append(node.value)
            elif isinstance(node, (ast.Import, ast.ImportFrom)):
                texts += [a.name for a in node.names] + [getattr(node, "module", "") or ""]
            for text in texts:
                low = text.lower()
                offenders += [f"{path.name}: {w!r} in {text[:60]!r}"
                              for w in ROBOT_WORDS if w in low]
    assert not offenders, offenders


def test_builtin_stations_are_installed_through_the_entry_point_group():
    """The gripper and the manipulator are found through pyrt.stations, as any station is."""
    stations = installed_stations()
    assert {"gripper", "manipulator"} <= set(stations)
    assert stations["gripper"].value == "pyrt.station.gripper:GRIPPER"


def test_installed_stations_are_sub_commands():
    """Every installed station is a sub-command of pyrt, with the shared options."""
    parser = build_parser()
    args = parser.parse_args(["gripper", "--speed", "max", "--serve", "0", "--no-init"])
    assert args.speed is None and args.serve == "0" and args.no_init
    text = parser.format_help()
    assert "gripper" in text and "manipulator" in text and "run" in text


def test_as_factory_takes_instances_classes_and_functions():
    """A factory may be an instance, a subclass or a build(loop, args) function; nothing else."""
    from _tiny_station import CounterFactory, build

    assert as_factory(CounterFactory()).name == "counter"
    assert isinstance(as_factory(CounterFactory), CounterFactory)
    fn = as_factory(build, "tiny")
    assert isinstance(fn, StationFactory) and fn.name == "tiny"
    assert fn.summary.startswith("A counter station")
    with pytest.raises(ConfigError, match="not a station factory"):
        as_factory(42)


@pytest.mark.parametrize("spec, why", [
    ("nocolon", "expected MODULE:FACTORY"),
    ("no_such_module_xyz:build", "cannot import"),
    ("_tiny_station:nothing", "has no 'nothing'"),
])
def test_load_factory_refuses_a_bad_spec(spec, why):
    """A malformed or missing MODULE:FACTORY is refused, saying what is wrong."""
    sys.path.insert(0, str(ROOT / "tests"))
    try:
        with pytest.raises(ConfigError, match=why):
            load_factory(spec)
    finally:
        sys.path.remove(str(ROOT / "tests"))


def test_pyrt_run_a_function_factory_from_any_module():
    """pyrt run MODULE:FUNCTION runs a piped script on the station it builds."""
    run = _pyrt("run", "_tiny_station:build", "--speed", "max",
                stdin="counter step 5\nsleep 0.01\nstatus counter\ncounter step 500\nquit\n")
    assert run.returncode == 1, run.stderr  # the refused last line fails the script
    assert "stdin:4: 'counter step 500' failed" in run.stderr
    out = run.stdout
    assert "counter.count = " in out
    count = int(out.split("counter.count = ")[1].split()[0])
    assert 45 <= count <= 60  # 10 ticks of 1 ms at step 5 (a tick or two either side)
    assert "N 500 is out of range: N 1..100 ticks" in out
    assert "every motor stopped" in out.splitlines()[-1]


def test_pyrt_run_a_factory_class_with_options_of_its_own():
    """pyrt run MODULE:CLASS takes the factory's own options and its defaults (speed max)."""
    run = _pyrt("run", "_tiny_station:CounterFactory", "--first-step", "7",
                stdin="sleep 0.002\nstatus counter\n")
    assert run.returncode == 0, run.stderr
    assert "pyrt counter: counter" in run.stdout
    count = int(run.stdout.split("counter.count = ")[1].split()[0])
    assert count % 7 == 0 and count > 0


def test_pyrt_run_help_lists_every_station_option():
    """pyrt run MODULE:FACTORY --help shows the shared options and the factory's own."""
    run = _pyrt("run", "_tiny_station:CounterFactory", "--help")
    assert run.returncode == 0, run.stderr
    for option in ("--first-step", "--boards", "--serve", "--epics", "--headless",
                   "--timing-log", "--tick-us", "--speed", "--history"):
        assert option in run.stdout


def test_pyrt_run_refuses_a_missing_factory_in_one_line():
    """An unknown module is one error line and status 1, not a traceback."""
    run = _pyrt("run", "no_such_module_xyz:build")
    assert run.returncode == 1
    assert run.stderr.strip().count("\n") == 0 and "cannot import" in run.stderr


def test_run_station_from_a_script_of_ones_own():
    """pyrt.run_station(factory, argv) runs a station from a user's script."""
    code = ("import sys, pyrt; from _tiny_station import build; "
            "sys.exit(pyrt.run_station(build, ['--speed', 'max']))")
    env = {**os.environ, "PYTHONPATH": f"{ROOT}{os.pathsep}{ROOT / 'tests'}"}
    run = subprocess.run([sys.executable, "-c", code], input="status counter\nquit\n",
                         cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert "counter.count = " in run.stdout


def test_a_tick_longer_than_the_station_runs_on_is_refused():
    """--tick-us above what the manipulator's polls allow says why, not 'an earlier pyrt'
    (a usage error: exit 2)."""
    run = _pyrt("manipulator", "--tick-us", "100000")
    assert run.returncode == 2
    assert "at most 10000 µs" in run.stderr and "earlier pyrt" not in run.stderr
