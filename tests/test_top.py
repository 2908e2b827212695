"""pyrt top: a refreshing status view of a served robot, on a terminal and piped."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time

import pytest
from _server_rig import served

from pyrt.cli import main
from pyrt.cli.top import render
from pyrt.db import copy_station

pytestmark = pytest.mark.wallclock


def _top(*args: str, timeout: float = 60) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "PYRT_TOKEN"}
    return subprocess.run([sys.executable, "-m", "pyrt", "top", *args], capture_output=True,
                          text=True, timeout=timeout, env=env, stdin=subprocess.DEVNULL)


def test_render_keeps_the_servers_values_and_puts_each_field_on_a_line():
    """A snapshot: title, loop time, one aligned line per field with the value as sent (hex stays hex); no empty line unless spaced."""
    lines = render("pyrt top: gripper at h:1",
                   "t=2.640121 position=-7046 sensors=0xFBFF fault=0", ["tick 1000 µs: 3 ticks"])
    assert lines == ["pyrt top: gripper at h:1", "t = 2.640 s (loop time)",
                     "  position  -7046", "  sensors   0xFBFF", "  fault     0",
                     "tick 1000 µs: 3 ticks"]
    spaced = render("T", "t=1 a=1", ["s"], spaced=True)
    assert spaced == ["T", "t = 1.000 s (loop time)", "", "  a  1", "", "s"]


def test_once_prints_one_snapshot_of_a_served_gripper():
    """--once against a served gripper: its status line (hex, mm), its status fields with their units and the loop's timing, exit 0, no escape codes."""
    with served(wall=True) as sv:
        done = _top(f"{sv.host}:{sv.port}", "--once")
    assert done.returncode == 0, done.stderr
    out = done.stdout
    assert out.startswith(f"pyrt top: gripper at {sv.host}:{sv.port}\nt = ")
    assert re.search(r"^  position +-?\d+ counts$", out, re.M)
    assert re.search(r"^  sensors +0x[0-9A-F]{4} word$", out, re.M)
    # the console's own line, in the gripper's radix: hex counts with mm beside them
    assert re.search(r"^position [0-9A-F]{4} \(\d+\.\d mm\), target [0-9A-F]{4} ", out, re.M)
    assert re.search(r"^tick 1000 µs: \d+ ticks, \d+ overruns", out, re.M)
    assert "\x1b" not in out and out.count("pyrt top:") == 1


def test_piped_top_prints_one_block_per_interval_and_time_moves():
    """Piped with --count 3: three blocks separated by empty lines, the loop time increasing."""
    with served(wall=True) as sv:
        done = _top(f"{sv.host}:{sv.port}", "--count", "3", "--hz", "5", "--no-stats")
    assert done.returncode == 0, done.stderr
    blocks = [b for b in done.stdout.split("\n\n") if b.strip()]
    assert len(blocks) == 3 and all(b.startswith("pyrt top: gripper") for b in blocks)
    times = [float(re.search(r"t = ([\d.]+) s", b).group(1)) for b in blocks]
    assert times == sorted(times) and times[-1] - times[0] >= 0.2
    assert "tick 1000" not in done.stdout  # --no-stats


def test_top_on_a_terminal_redraws_in_place_and_leaves_on_ctrl_c():
    """On a terminal the screen is cleared and redrawn; Ctrl-C leaves with status 0 and the cursor shown."""
    pexpect = pytest.importorskip("pexpect")
    with served(wall=True) as sv:
        child = pexpect.spawn(sys.executable, ["-m", "pyrt", "top", f"{sv.host}:{sv.port}",
                                               "--hz", "10"], encoding="utf-8", timeout=30,
                              dimensions=(40, 100),
                              # the size top reads (shutil honours these first): the screen
                              # holds the status, the whole stats table and the footer
                              env={**os.environ, "LINES": "40", "COLUMNS": "100"},
                              # SIGINT may be inherited ignored (a suite run in the background)
                              preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
        try:
            child.expect_exact("\x1b[H\x1b[2J")
            child.expect(r"position +-?\d+")
            child.expect_exact("\x1b[H\x1b[2J")  # redrawn
            child.expect("Ctrl-C leaves")
            child.sendintr()
            child.expect(pexpect.EOF)
        finally:
            child.close()
        assert child.exitstatus == 0
        assert "\x1b[?25h" in child.before  # the cursor is given back


def test_top_says_in_one_line_when_the_server_goes_away():
    """A server that closes mid-watch ends top with one line naming it and status 1."""
    with served(wall=True) as sv:
        proc = subprocess.Popen([sys.executable, "-m", "pyrt", "top", f"{sv.host}:{sv.port}",
                                 "--hz", "10", "--no-stats"], stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL)
        assert proc.stdout.readline().startswith("pyrt top: gripper")
        sv.server.close()
        _out, err = proc.communicate(timeout=30)
    assert proc.returncode == 1
    assert err.count("\n") == 1 and err.startswith(f"pyrt top: {sv.host}:{sv.port}: ")


@pytest.mark.parametrize(("args", "message"), [
    (["127.0.0.1:1"], "pyrt top: 127.0.0.1:1: "),
    (["nonsense:port"], "port must be"),
    (["127.0.0.1:5050", "--hz", "0"], "--hz must be 0.5..20"),
    (["127.0.0.1:5050", "--count", "0"], "--count must be >= 1"),
])
def test_bad_addresses_and_options_are_one_line(args, message, capsys):
    """No server, a bad address or a bad option: one line on stderr, non-zero status, nothing on stdout."""
    assert main(["top", *args]) != 0
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1 and message in err


def test_top_shows_a_served_manipulator(tmp_path):
    """Against pyrt manipulator --serve (a subprocess): position, tensions and fault fields."""
    db = copy_station("prototype", tmp_path / "db")
    proc = subprocess.Popen([sys.executable, "-m", "pyrt", "manipulator", "--serve",
                             "127.0.0.1:0", "--headless", "--db", str(db)],
                            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True,
                            env={k: v for k, v in os.environ.items() if k != "PYRT_TOKEN"})
    try:
        port = None
        deadline = time.monotonic() + 30
        while port is None and time.monotonic() < deadline:
            m = re.search(r"serving \S+ on 127\.0\.0\.1:(\d+)", proc.stderr.readline())
            port = m and m.group(1)
        assert port, "the manipulator did not say where it serves"
        done = _top(f"127.0.0.1:{port}", "--once")
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.communicate(timeout=20)
    assert done.returncode == 0, done.stderr
    out = done.stdout
    assert out.startswith(f"pyrt top: prototype at 127.0.0.1:{port}\n")
    for field, unit in (("x", "cm"), ("y", "cm"), ("z", "cm"), ("tension0", "N"),
                        ("fault", "bool")):
        assert re.search(rf"^  {field} +\S+ {unit}$", out, re.M), field
    assert "tick 5000 µs:" in out
