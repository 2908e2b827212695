"""The pyrt program as a shell sees it: a closed pipe, a refused connection, a taken port, a misspelt command, usage errors exit 2."""

from __future__ import annotations

import os
import socket
import subprocess
import sys

import pytest
from _server_rig import served

ENV = {k: v for k, v in os.environ.items() if k != "PYRT_TOKEN"}


def _pyrt(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "pyrt", *args], capture_output=True,
                          text=True, timeout=timeout, env=ENV, stdin=subprocess.DEVNULL)


def _piped_into_head(command: str) -> subprocess.CompletedProcess:
    """``command | head -1`` in bash; stdout is head's, the last line the command's status."""
    return subprocess.run(["bash", "-c", f"{command} | head -1; echo \"status ${{PIPESTATUS[0]}}\""],
                          capture_output=True, text=True, timeout=120, env=ENV,
                          stdin=subprocess.DEVNULL)


def test_top_into_a_reader_that_leaves_ends_quietly():
    """pyrt top PORT --count N | head -1: once head has gone, top ends with status 0 and
    nothing on stderr (it said '[Errno 32] Broken pipe', status 1)."""
    with served(wall=True) as sv:
        done = _piped_into_head(f"{sys.executable} -m pyrt top {sv.port} --count 40 --hz 20 "
                                "--no-stats")
    assert done.stdout == f"pyrt top: gripper at 127.0.0.1:{sv.port}\nstatus 0\n"
    assert done.stderr == ""


@pytest.mark.parametrize("argv", [
    ["overruns", "--help"],
    ["reference", "gripper"],
])
def test_other_commands_into_a_reader_that_leaves_end_quietly(argv):
    """Any command whose reader leaves early ends with status 0 and nothing on stderr."""
    done = _piped_into_head(" ".join([sys.executable, "-m", "pyrt", *argv]))
    assert done.stdout.endswith("status 0\n") and done.stderr == ""


def test_a_served_station_on_a_taken_port_fails_before_its_banner():
    """--serve on a port another process holds: one line saying so on stderr, exit 1,
    and nothing on stdout (no banner, no 'type help' first)."""
    holder = socket.socket()
    holder.bind(("127.0.0.1", 0))
    holder.listen()
    port = holder.getsockname()[1]
    try:
        done = subprocess.run([sys.executable, "-m", "pyrt", "gripper", "--serve", str(port),
                               "--speed", "max"], input="quit\n", capture_output=True,
                              text=True, timeout=120, env=ENV)
    finally:
        holder.close()
    assert done.returncode == 1
    assert done.stdout == ""
    assert done.stderr == (f"pyrt gripper: cannot serve on 127.0.0.1:{port}: Address already "
                           "in use\n")


def test_a_misspelt_command_gets_did_you_mean():
    """pyrt manipulatr: argparse's usage error, exit 2, and the nearest command named."""
    done = _pyrt("manipulatr")
    assert done.returncode == 2
    assert "did you mean 'manipulator'?" in done.stderr


@pytest.mark.parametrize(("argv", "message"), [
    (["demo", "--seconds", "-1"], "pyrt demo: error: --seconds must be > 0"),
    (["gripper", "--headless"], "pyrt gripper: error: --headless needs --serve"),
    (["gripper", "--max-overruns", "0", "--speed", "max"],
     "pyrt gripper: error: --max-overruns must be >= 1"),
    (["gripper", "--scope-dir", "/nonexistent/dir", "--speed", "max"],
     "pyrt gripper: error: --scope-dir /nonexistent/dir: there is no such directory"),
    (["overruns", "x.jsonl", "--worst", "-1"], "pyrt overruns: error: --worst must be >= 0"),
    (["board-sim"], "pyrt board-sim: error: name the station whose world to serve"),
])
def test_usage_errors_found_by_a_commands_own_checks_exit_2_as_argparses_do(argv, message):
    """An option a command's own checks refuse ends as an argparse usage error does:
    'pyrt CMD: error: ...' on stderr, exit 2, no traceback (it was exit 1)."""
    done = _pyrt(*argv)
    assert done.returncode == 2, done.stderr
    assert message in done.stderr and "Traceback" not in done.stderr
    assert _pyrt("demo", "--no-such-option").returncode == 2  # argparse's own, the same


@pytest.mark.parametrize(("argv", "message"), [
    (["manipulator", "--db", "a", "--init-db", "b"],
     "pyrt manipulator: error: give --db DIR (an existing database) or --init-db DIR"),
    (["manipulator", "--db", "/nonexistent/db"],
     "pyrt manipulator: error: --db /nonexistent/db: no such directory; seed it with"),
    (["top", "5050", "--hz", "0"], "pyrt top: error: --hz must be 0.5..20, got 0"),
    (["top", "5050", "--count", "0"], "pyrt top: error: --count must be >= 1, got 0"),
    (["connect", "5050", "--hz", "99"], "pyrt connect: error: --hz must be 0..50, got 99"),
    (["send", "no:port:x", "W"], "pyrt send: error: "),
    (["top", "no:port:x"], "pyrt top: error: "),
])
def test_every_commands_option_checks_read_and_exit_as_argparses(argv, message):
    """The semantic checks of manipulator, top, connect and send: 'pyrt CMD: error: ...',
    exit 2, as argparse's own usage errors (some were exit 1 or without 'error:')."""
    done = _pyrt(*argv)
    assert done.returncode == 2, done.stderr
    assert done.stderr.startswith(message), done.stderr
