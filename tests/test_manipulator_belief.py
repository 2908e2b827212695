"""The manipulator's start-up belief check: against a board-sim whose world was built from
another database (another POSITION), the tensions say so and every move is refused, naming both
positions and what to do; board-sim says which database it read."""

from __future__ import annotations

import os
import queue
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest

from pyrt.db import load_station
from pyrt.station.manipulator import BELIEF_CM, belief_doubt

pytestmark = pytest.mark.wallclock

#: Only a hang takes this long: a bound that catches one, never a measure of speed.
HANG_S = 60.0


def _pyrt(*argv: str, stdin: str, cwd: Path) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYRT_HOME=str(cwd / "home"))
    return subprocess.run([sys.executable, "-m", "pyrt", *argv], input=stdin,
                          capture_output=True, text=True, timeout=180, env=env, cwd=cwd)


class _BoardSim:
    """``pyrt board-sim prototype`` in a process of its own; its first lines."""

    def __init__(self, *extra: str):
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "pyrt", "board-sim", "prototype", "--listen", "127.0.0.1:0",
             "--watchdog", "2", *extra],
            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        self._lines: queue.Queue[str | None] = queue.Queue()
        threading.Thread(target=self._pump, daemon=True).start()
        self.first = [self._line(), self._line()]
        self.url = self.first[0].split(" on ")[1].split()[0]

    def _pump(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self._lines.put(line.rstrip("\n"))
        self._lines.put(None)

    def _line(self) -> str:
        try:
            line = self._lines.get(timeout=HANG_S)  # a bound for a hang only
        except queue.Empty:
            line = None
        if line is None:
            self.close()
            raise AssertionError(f"board-sim said nothing more; stderr {self.proc.stderr!r}")
        return line

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
        try:
            self.proc.wait(HANG_S)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(HANG_S)
            assert self.proc.stderr is not None
            err = self.proc.stderr.read()
            raise AssertionError(f"board-sim did not stop on SIGTERM within {HANG_S:g} s; "
                                 f"its stderr: {err[-2000:]!r}") from None


@pytest.fixture(scope="module")
def moved_db(tmp_path_factory) -> Path:
    """A working copy whose POSITION an earlier run moved to (0, 0, 50)."""
    cwd = tmp_path_factory.mktemp("moved")
    db = cwd / "db"
    done = _pyrt("manipulator", "--speed", "max", "--init-db", str(db),
                 stdin="prototype to 0 0 50\nwait\n", cwd=cwd)
    assert done.returncode == 0, done.stderr
    assert load_station(db).polyaxis().position[2] == pytest.approx(50.0, abs=0.5)
    return db


@pytest.fixture
def packaged_sim() -> Iterator[_BoardSim]:
    sim = _BoardSim()
    yield sim
    sim.close()


def test_board_sim_says_which_database_it_read(packaged_sim, moved_db):
    """board-sim's second line names the database and the POSITION its world holds."""
    line = packaged_sim.first[1]
    assert line.startswith("pyrt board-sim: world from the packaged prototype database (")
    assert "the source at its POSITION (" in line and ", 0.00, 95.57) cm" in line
    assert "same --db DIR" in line
    sim = _BoardSim("--db", str(moved_db))
    try:
        assert sim.first[1].startswith(f"pyrt board-sim: world from the database {moved_db}")
        assert "POSITION (0.03, 0.00, 50.06) cm" in sim.first[1]
    finally:
        sim.close()


def test_a_world_that_disagrees_refuses_every_move_naming_both_positions(packaged_sim,
                                                                          moved_db, tmp_path):
    """Station POSITION z=50, board-sim's world z=95.6: a start-up line says so, the move is
    refused (nothing moved, no fault), the script exits 1, and POSITION is not rewritten."""
    done = _pyrt("manipulator", "--db", str(moved_db), "--boards", packaged_sim.url,
                 stdin="prototype to 0 0 60\n", cwd=tmp_path)
    assert done.returncode == 1, done.stderr
    note = next(ln for ln in done.stdout.splitlines() if ln.startswith("start-up: moves refused"))
    assert "the world disagrees with the database at start-up" in note
    assert "not at POSITION (0.03, 0.00, 50.06) cm" in note
    assert "the rope tensions put the source near (" in note
    assert f"this station's --db {moved_db}" in note and "prototype setpos X Y Z" in note
    assert "error: prototype to: refused: the position estimate is not trusted" in done.stdout
    assert "FAULT" not in done.stdout
    assert load_station(moved_db).polyaxis().position[2] == pytest.approx(50.06, abs=0.01)


def test_setpos_where_the_source_is_allows_moves_again(packaged_sim, moved_db, tmp_path):
    """After 'setpos' at the world's position (board-sim's line gave it) a move is accepted."""
    done = _pyrt("manipulator", "--db", str(moved_db), "--boards", packaged_sim.url,
                 stdin="prototype setpos -0.2 0 95.57\nprototype to -0.2 0 93\nstop\n",
                 cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "moves allowed" in done.stdout and "prototype: to (-0.2, 0, 93)" in done.stdout


def test_the_documented_workflow_agrees(moved_db, tmp_path):
    """board-sim and the station given the same --db: no start-up refusal, the move is taken."""
    sim = _BoardSim("--db", str(moved_db))
    try:
        done = _pyrt("manipulator", "--db", str(moved_db), "--boards", sim.url,
                     stdin="prototype to 0 0 52\nstop\n", cwd=tmp_path)
    finally:
        sim.close()
    assert done.returncode == 0, done.stderr
    assert "moves refused" not in done.stdout
    assert "prototype: to (0, 0, 52)" in done.stdout


def test_belief_doubt_is_the_tension_position_beyond_the_bound():
    """Within BELIEF_CM of POSITION: no doubt; beyond: both positions and the worst rope said."""
    here = (0.0, 0.0, 50.0)
    assert belief_doubt(here, [31.9, 8.8, 9.5], [30.3, 9.7, 10.0], (-3.2, 0.0, 51.0)) is None
    near = (0.0, 0.0, 50.0 + BELIEF_CM - 1)
    assert belief_doubt(here, [31.9, 8.8, 9.5], [30.3, 9.7, 10.0], near) is None
    said = belief_doubt(here, [34.6, 8.8, 10.2], [30.3, 9.7, 10.0], (-6.5, 0.0, 107.6))
    assert said is not None
    assert "near (-6.50, 0.00, 107.60) cm, 58 cm away" in said
    assert "rope 0 holds 34.6 N where POSITION needs 30.3 N" in said
