"""pyrt replay checks every option before it replays a tick, and says so as a command line does."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
GRIPPER = ROOT / "tests" / "journals" / "gripper.pj"


def _replay(cwd: Path, *argv: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "pyrt", "replay", *argv], cwd=cwd,
                          capture_output=True, text=True, timeout=120)


USAGE_ERRORS = [
    (["--scope", "gripper.nope", "--scope-save", "k.csv"],
     "--scope gripper.nope: no channel 'gripper.nope': gripper has no signal 'nope'"),
    (["--scope", "encoder", "--scope-save", "j.txt"],
     "--scope-save j.txt: use a file name ending .csv, .npz, .mcap, .png, .svg, .pdf"),
    (["--scope", "encoder", "--scope-save", "noext"], "--scope-save noext: use a file name"),
    (["--scope-save", "k.csv"], "--scope-save needs --scope CHANNELS"),
    (["--scope", "encoder", "--scope-save", "no/such/dir/k.csv"],
     "--scope-save no/such/dir/k.csv: there is no directory no/such/dir"),
    (["--scope", "encoder,nosignal"], "--scope nosignal: no channel 'nosignal'"),
    (["--scope", "gripper.where", "--scope-save", "k.csv"],  # a text signal: not sampled
     "--scope gripper.where: where is text (where the robot is): the scope samples numbers"),
]


@pytest.mark.parametrize(("argv", "message"), USAGE_ERRORS)
def test_a_bad_option_is_a_usage_error_before_any_tick(tmp_path, argv, message):
    """A bad option exits 2 with the usage line and 'pyrt replay: error: ...'; nothing is
    replayed and no file is written."""
    done = _replay(tmp_path, str(GRIPPER), *argv)
    assert done.returncode == 2, done.stdout + done.stderr
    assert done.stderr.startswith("usage: pyrt replay")
    assert f"pyrt replay: error: {message}" in done.stderr
    assert "replayed" not in done.stdout
    assert list(tmp_path.iterdir()) == []


def test_a_journal_that_cannot_be_read_exits_1(tmp_path):
    """A missing journal is a run that failed (exit 1, one line), not a usage error."""
    done = _replay(tmp_path, str(tmp_path / "none.pj"))
    assert done.returncode == 1
    assert done.stderr.startswith("pyrt replay: journal ")
    assert "Traceback" not in done.stderr


@pytest.mark.parametrize("name", ["run.npz", "run.mcap"])
def test_good_options_replay_and_write_the_file(tmp_path, name):
    """Channels that exist and a known extension replay (exit 0) and write the file."""
    done = _replay(tmp_path, str(GRIPPER), "--scope", "encoder,dac", "--scope-save", name)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "identical" in done.stdout
    assert f"saved 5053 samples of 2 channel(s) to {name}" in done.stdout
    assert (tmp_path / name).is_file()
