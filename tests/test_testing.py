"""pyrt.testing: a station of one's own runs the conformance suite in its own tests, and the suite fails a station that breaks the contract."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

#: A third party's package: a one-motor station and its conformance test, nothing of
#: pyrt's tests on the path.  ``{go}`` and ``{peek}`` are the decorators of two records.
STATION = '''
from pyrt import Arg, Component, Loop, SimClock, Signal, Station, command


class Motor(Component):
    """One motor whose drive the world reads."""

    name = "motor"

    def __init__(self) -> None:
        self.drive = 0

    def signals(self) -> list[Signal]:
        return [Signal.attr("drive", "counts", self, "drive", "the drive register")]

    {go}
    def go(self, n: int) -> str:
        """motor go N: drive at N counts."""
        self.drive = n
        return f"driving at {{n}}"

    {peek}
    def peek(self) -> str:
        """motor peek: the drive register."""
        {peek_body}
        return str(self.drive)

    def reflex(self) -> None:
        self.drive = 0


def build_station() -> Station:
    station = Station(Loop(SimClock()))
    station.name = "onemotor"
    station.adopt(Motor())
    return station
'''

TEST = '''
from onemotor import build_station

from pyrt.testing import StationConformance


class TestOneMotorConformance(StationConformance):
    samples = {"Motor.go": [["5"]]}

    def build(self, tmp_path):
        return build_station()

    def driven(self, station):
        drive = station.root.drive
        return [f"drive {drive}"] if drive else []

    def settings(self, station):
        return station.root.drive, len(station.motion)

    def start_move(self, station, runner):
        runner.call(station.root.go, 7)
'''

GOOD = {"go": '@command(Arg("N", int, lo=1, hi=100, units="counts"), name="go", moves=True)',
        "peek": '@command(name="peek", reads_only=True)', "peek_body": "pass"}


def _run_suite(tmp_path: Path, *only: str, **change: str) -> subprocess.CompletedProcess[str]:
    """The third party's tests (``only``: those checks), run by pytest in a directory of
    their own."""
    parts = {**GOOD, **change}
    (tmp_path / "onemotor.py").write_text(textwrap.dedent(STATION).format(**parts))
    (tmp_path / "test_onemotor.py").write_text(textwrap.dedent(TEST))
    return subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                           "--rootdir", str(tmp_path), "-o", "addopts=", str(tmp_path),
                           *(("-k", " or ".join(only)) if only else ())],
                          cwd=tmp_path, capture_output=True, text=True, timeout=300)


def test_a_third_party_station_passes_the_suite_in_its_own_tests(tmp_path):
    """A station outside pyrt subclasses StationConformance: pytest runs every check of the suite on it, and a conforming station passes them all."""
    done = _run_suite(tmp_path)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "9 passed" in done.stdout, done.stdout


BROKEN = [
    ({"go": '@command(Arg("N", int, lo=1, hi=100, units="counts"), name="go")'},
     "test_a_record_not_marked_moves_never_starts_an_actuator"),
    ({"peek_body": "self.drive = 1"},
     "test_a_reading_record_changes_nothing"),
    ({"go": '@command(Arg("N", float, units="counts"), name="go", moves=True)'},
     "test_every_nasty_word_in_every_argument_gives_a_command_error"),
]


@pytest.mark.parametrize(("change", "check"), BROKEN, ids=["unmarked-move", "peek-writes",
                                                          "nan-accepted"])
def test_the_suite_fails_a_station_that_breaks_the_contract(tmp_path, change, check):
    """A move not marked 'moves', a reading record that writes, an argument that takes nan: the check that covers it fails (pytest exits 1 naming it)."""
    done = _run_suite(tmp_path, check, **change)
    assert done.returncode == 1, done.stdout + done.stderr
    assert f"FAILED test_onemotor.py::TestOneMotorConformance::{check}" in done.stdout, \
        done.stdout
