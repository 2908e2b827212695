"""A piped ``wait`` says where the robot is every few seconds of the station's clock (one
line each, off with ``--wait-progress 0``); the shell of a terminal says nothing until the
move ends."""

from __future__ import annotations

import io
import os
import re
import subprocess
import sys

import pytest
from _manipulator_rig import make_station

from pyrt.commands import RobotShell

_PROGRESS = re.compile(r"^waiting, (\d+) s: source at \(([-\d.]+), ([-\d.]+), ([-\d.]+)\) cm$")
_END = re.compile(r"prototype stopped: ENDPOINT_STOP.* at t=([\d.]+) s$")


def _pyrt(*argv: str, stdin: str, cwd):
    env = dict(os.environ, PYRT_HOME=str(cwd / "home"))
    return subprocess.run([sys.executable, "-m", "pyrt", *argv], input=stdin,
                          capture_output=True, text=True, timeout=300, env=env, cwd=cwd)


def _progress(lines: list[str]) -> list[tuple[int, float]]:
    """(seconds, z) of each progress line."""
    return [(int(m[1]), float(m[4])) for line in lines if (m := _PROGRESS.match(line))]


def test_a_piped_wait_says_where_the_source_is_every_5_s_of_the_stations_clock(tmp_path):
    """printf 'prototype to 0 0 50\\nwait' | pyrt manipulator --speed max: a line every 5 s of loop time (5, 10, ...) until the move ends, the source going down; then the end as before; exit 0."""
    done = _pyrt("manipulator", "--speed", "max", stdin="prototype to 0 0 50\nwait\n",
                 cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    steps = _progress(lines)
    end = next(m for line in lines if (m := _END.search(line)))
    t_end = float(end[1])
    assert [t for t, _z in steps] == [5 * k for k in range(1, int(t_end // 5) + 1)]
    zs = [z for _t, z in steps]
    assert zs == sorted(zs, reverse=True) and zs[0] < 95.6 and zs[-1] > 50.0
    first = next(i for i, line in enumerate(lines) if _PROGRESS.match(line))
    ended = next(i for i, line in enumerate(lines) if _END.search(line))
    assert lines[first - 1].endswith("> wait") and ended == first + len(steps)


@pytest.mark.parametrize(("option", "every"), [("0", None), ("15", 15)])
def test_wait_progress_sets_the_interval_and_0_turns_it_off(tmp_path, option, every):
    """--wait-progress 0: the piped wait is silent until the end, as before; --wait-progress 15: a line every 15 s."""
    done = _pyrt("manipulator", "--speed", "max", "--wait-progress", option,
                 stdin="prototype to 0 0 50\nwait\n", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    t_end = float(next(m for line in lines if (m := _END.search(line)))[1])
    got = [t for t, _z in _progress(lines)]
    assert got == ([] if every is None else [every * k for k in range(1, int(t_end // every) + 1)])


@pytest.mark.parametrize("bad", ["-1", "nan", "inf", "soon"])
def test_a_bad_wait_progress_is_refused_before_anything_runs(tmp_path, bad):
    """--wait-progress takes seconds, 0 or more: anything else is a usage error (exit 2) naming it."""
    done = _pyrt("manipulator", "--speed", "max", f"--wait-progress={bad}", stdin="status\n",
                 cwd=tmp_path)
    assert done.returncode == 2
    assert "--wait-progress" in done.stderr and "seconds, 0 or more" in done.stderr
    assert "prototype>" not in done.stdout


def test_the_shells_wait_says_nothing_until_the_end_unless_told(tmp_path):
    """On SimClock: a RobotShell as a terminal's console has it (wait_progress_s 0) reports the end alone; with 10 s it says where the source is at 10, 20, 30 s of loop time, each where the station says it is then."""
    station, runner = make_station(tmp_path)
    try:
        out = io.StringIO()
        shell = RobotShell(station, out)
        assert shell.wait_progress_s == 0.0
        shell.onecmd("prototype to 0 0 80")
        shell.onecmd("wait")
        text = out.getvalue()
        assert "waiting," not in text and "ENDPOINT_STOP" in text
        out.seek(0)
        out.truncate()
        shell.wait_progress_s = 10.0
        t0 = runner.loop.now_ns
        seen: list[str] = []
        said = shell.say

        def say(line: str) -> None:  # where the station says it is, as each line is said
            if line.startswith("waiting,"):
                seen.append(f"{(runner.loop.now_ns - t0) / 1e9:.0f}: {station.where()}")
            said(line)

        shell.say = say  # type: ignore[method-assign]
        shell.onecmd("prototype to 0 0 50")
        shell.onecmd("wait")
        lines = out.getvalue().splitlines()
        progress = [line for line in lines if line.startswith("waiting,")]
        assert len(progress) >= 2
        assert [line.split(":", 1)[1].strip() for line in progress] == \
               [s.split(": ", 1)[1] for s in seen]
        assert [int(line.split()[1]) for line in progress] == \
               [10 * k for k in range(1, len(progress) + 1)]
        assert [int(s.split(":")[0]) for s in seen] == [10 * k for k in range(1, len(seen) + 1)]
        assert "ENDPOINT_STOP" in lines[-1]
    finally:
        station.close()
