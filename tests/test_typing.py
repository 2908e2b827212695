"""Types that are checked: mypy (pyproject.toml's [tool.mypy]) over pyrt and the example arm.

pyrt ships ``py.typed``, so editors and type checkers trust its annotations;
these tests hold them to it.  The whole package is checked at mypy's default
strictness and the public station API (``pyrt``, ``pyrt.component``,
``pyrt.station.base``, ``pyrt.station.factory``, ``pyrt.scheduler.task``,
``pyrt.scheduler.motion``, ``pyrt.boards.registers``, ``pyrt.errors``,
``pyrt.units``) strictly.

The package-wide test asserts that mypy finds no error anywhere in pyrt.

mypy runs cold (a fresh cache in a temporary directory each time): about
5 s for the package, 3 s for a user's strict script, 2 s for the arm, 12 s
in all on a 2-core machine.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "pyproject.toml"
ARM = ROOT / "examples" / "arm"

_ERROR = re.compile(r"^(?P<path>[^:\n]+\.pyi?):(?P<line>\d+): error: (?P<text>.*)$", re.M)


def _mypy(*args: str, cwd: Path, cache: Path, pyrt_path: bool = False
          ) -> subprocess.CompletedProcess[str]:
    """``python -m mypy ARGS`` in ``cwd``; a crash or a missing mypy fails the test.

    ``pyrt_path``: find pyrt in this tree (an editable install's import hook
    is invisible to mypy) and follow it silently, as a user's checker does
    with an installed package: its types count, its own errors are not the
    user's.
    """
    env = dict(os.environ)
    extra: tuple[str, ...] = ()
    if pyrt_path:
        env["MYPYPATH"] = str(ROOT)
        extra = ("--follow-imports", "silent")
    proc = subprocess.run(
        [sys.executable, "-m", "mypy", "--cache-dir", str(cache), "--no-color-output",
         "--show-error-codes", *extra, *args],
        cwd=cwd, env=env, capture_output=True, text=True, timeout=600,
    )
    if "No module named mypy" in proc.stderr:
        pytest.fail("mypy is not installed: pip install -e '.[test]'")
    # 0: clean, 1: errors found; anything else is mypy failing to run.
    assert proc.returncode in (0, 1), proc.stdout + proc.stderr
    return proc


def _errors(output: str) -> list[tuple[str, str]]:
    return [(m["path"].replace("\\", "/"), m.group(0)) for m in _ERROR.finditer(output)]


def test_pyrt_has_no_type_errors(tmp_path):
    """mypy over pyrt, with the project's configuration, reports no error in any file."""
    proc = _mypy("--config-file", str(CONFIG), "pyrt", cwd=ROOT, cache=tmp_path / "cache")
    found = _errors(proc.stdout)
    assert "source file" in proc.stdout, proc.stdout + proc.stderr  # it did run
    assert found == [], "\n".join(line for _path, line in found)


def test_public_modules_are_checked_strictly_and_the_rest_at_default(tmp_path):
    """The configuration flags an unannotated function in a public module (pyrt.units) but not in an internal one (pyrt.fileio)."""
    pkg = tmp_path / "src" / "pyrt"
    pkg.mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    body = "def scale(x, k):\n    return x * k\n"
    (pkg / "units.py").write_text(body)
    (pkg / "fileio.py").write_text(body)
    proc = _mypy("--config-file", str(CONFIG), "pyrt/units.py", "pyrt/fileio.py", "pyrt/__init__.py",
                 cwd=tmp_path / "src", cache=tmp_path / "cache")
    found = _errors(proc.stdout)
    assert [p for p, line in found if "[no-untyped-def]" in line] == ["pyrt/units.py"], proc.stdout
    assert not any(p == "pyrt/fileio.py" for p, _ in found), proc.stdout


@pytest.mark.skipif(not (ARM / "pyrt_arm").is_dir(), reason="no examples/arm in this tree")
def test_example_arm_passes_mypy_strict(tmp_path):
    """mypy --strict (the arm's own configuration) over examples/arm's pyrt_arm reports no error."""
    proc = _mypy("--config-file", str(ARM / "pyproject.toml"), "--strict", "-p", "pyrt_arm",
                 cwd=ARM, cache=tmp_path / "cache", pyrt_path=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "no issues found" in proc.stdout, proc.stdout


USER_SCRIPT = """\
from pyrt import Arg, Component, Signal, Station, StationFactory, Task, command, run_station
from pyrt.errors import Fault

reveal_type(Station)
reveal_type(Component)
reveal_type(Task)
reveal_type(run_station)
reveal_type(Fault)


def exit_code(argv: list[str]) -> int:
    return run_station(object(), argv)
"""


def test_a_strict_user_script_sees_the_public_api_typed(tmp_path):
    """A user's module checked with mypy --strict imports the public API without error, and its names have real types, not Any."""
    script = tmp_path / "mine.py"
    script.write_text(USER_SCRIPT)
    proc = _mypy("--strict", str(script), cwd=tmp_path, cache=tmp_path / "cache",
                 pyrt_path=True)
    assert _errors(proc.stdout) == [], proc.stdout
    revealed = re.findall(r'Revealed type is "(.*)"', proc.stdout)
    assert len(revealed) == 5, proc.stdout
    assert "Any" not in revealed, proc.stdout
    assert "pyrt.station.base.Station" in revealed[0]
    assert revealed[4].endswith("-> pyrt.errors.Fault"), revealed[4]
    assert "details: dict[str, Any]" in revealed[4], revealed[4]  # not a bare dict
