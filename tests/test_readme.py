"""The README's first move runs as written: two commands, the second fast on simulated time."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _first_block() -> list[str]:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    block = re.search(r"```sh\n(.*?)```", text, re.S)
    assert block is not None
    return [ln for ln in block.group(1).splitlines() if ln.strip()]


def test_the_first_move_is_two_commands_and_names_speed_max():
    """Install, then the move: two lines, the second piped into pyrt manipulator --speed max."""
    lines = _first_block()
    assert len(lines) == 2
    assert lines[0].endswith("pip install .")
    assert "pyrt manipulator --speed max" in lines[1] and "wait" in lines[1]


def test_the_first_move_runs_as_written(tmp_path):
    """The README's second line, run by the shell as written: the move ends at its endpoint, exit 0."""
    line = _first_block()[1]
    bindir = os.path.dirname(sys.executable)
    env = dict(os.environ, PYRT_HOME=str(tmp_path / "home"),
               PATH=bindir + os.pathsep + os.environ.get("PATH", ""))
    done = subprocess.run(["sh", "-c", line], capture_output=True, text=True, env=env,
                          cwd=tmp_path, timeout=120)
    assert done.returncode == 0, done.stderr
    assert "prototype stopped: ENDPOINT_STOP" in done.stdout
    assert "source at (0.03, 0.00, 50.06)" in done.stdout
