"""``pyrt gripper|manipulator --serve ... --headless``: the service, in a subprocess."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time

import pytest

from pyrt.client import Client
from pyrt.db import copy_station

pytestmark = pytest.mark.wallclock

TOKEN = "cli-token-0123456789"


def _start(args: list[str], env: dict | None = None, cwd=None) -> tuple[subprocess.Popen, int]:
    """Start ``pyrt ARGS`` (in ``cwd``) and read stderr until it says where it serves."""
    proc = subprocess.Popen([sys.executable, "-m", "pyrt", *args], stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, **(env or {})}, cwd=cwd)
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        line = proc.stderr.readline()
        if not line:
            break
        m = re.search(r"serving \S+ on 127\.0\.0\.1:(\d+)", line)
        if m:
            return proc, int(m.group(1))
    proc.kill()
    raise AssertionError(f"no 'serving' line: {proc.communicate()}")


def _stop(proc: subprocess.Popen, sig: int) -> tuple[int, str]:
    proc.send_signal(sig)
    _out, err = proc.communicate(timeout=20)
    return proc.returncode, err


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_headless_gripper_serves_and_stops_every_motor_on_a_signal(tmp_path, sig):
    """A headless gripper moves on a client's command; SIGTERM/SIGINT stop every motor and exit 0."""
    token = tmp_path / "token"
    token.write_text(TOKEN + "\n")
    token.chmod(0o600)
    proc, port = _start(["gripper", "--serve", "127.0.0.1:0", "--headless", "--token-file",
                         str(token), "--speed", "4"], cwd=tmp_path)
    try:
        with Client("127.0.0.1", port) as c:
            assert "AUTH to command" in c.greeting
            c.auth(TOKEN)
            c.command("wait")  # the power-up I
            c.command("P E47A")
            c.command("sleep 0.5")
            assert c.status().fields["moving"] == 1
    finally:
        code, err = _stop(proc, sig)
    assert code == 0, err
    assert "every motor stopped" in err
    # the audit trail of a headless service: its log in the working directory
    assert re.search(r"DAQ client \d+ 127\.0\.0\.1:\d+: P E47A",
                     (tmp_path / "pyrt-gripper-audit.log").read_text())


def test_headless_manipulator_serves_status(tmp_path):
    """pyrt manipulator --serve --headless answers STATUS and exits 0 on SIGTERM."""
    db = copy_station("prototype", tmp_path / "db")
    proc, port = _start(["manipulator", "--serve", "127.0.0.1:0", "--headless",
                         "--db", str(db)], env={"PYRT_TOKEN": TOKEN})
    try:
        with Client("127.0.0.1", port) as c:
            fields = c.status().fields
            assert {"x", "y", "z", "tension0", "fault"} <= fields.keys()
            assert c.request("prototype to 0 0 100").code == "denied"
            c.auth(TOKEN)
            assert c.command("prototype tensions")[0].startswith("prototype: desired tensions")
    finally:
        code, err = _stop(proc, signal.SIGTERM)
    assert code == 0, err
    assert "every motor stopped" in err


@pytest.mark.parametrize(("args", "message", "status"), [
    (["gripper", "--serve", "0.0.0.0:0", "--headless"], "without a token", 1),
    (["gripper", "--headless"], "--headless needs --serve", 2),
    (["gripper", "--serve", "127.0.0.1:99999"], "port", 2),
])
def test_refused_start_ups(args, message, status):
    """Serving beyond loopback without a token, --headless alone, a bad port: one line,
    exit 2 for a usage error, 1 for a start-up refused."""
    env = {k: v for k, v in os.environ.items() if k != "PYRT_TOKEN"}
    proc = subprocess.run([sys.executable, "-m", "pyrt", *args, "--speed", "max"],
                          stdin=subprocess.DEVNULL, capture_output=True, text=True, env=env,
                          timeout=60)
    assert proc.returncode == status
    assert message in proc.stderr
    assert "Traceback" not in proc.stderr


def test_send_subscribe_into_a_reader_that_leaves_ends_quietly(tmp_path):
    """pyrt send PORT SUBSCRIBE 50 | head -1: when the reader closes the pipe, send ends with status 0 and no error naming the server."""
    from _server_rig import served

    with served(wall=True) as sv:
        proc = subprocess.Popen(
            [sys.executable, "-m", "pyrt", "send", f"{sv.host}:{sv.port}", "SUBSCRIBE", "50"],
            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
            text=True, cwd=tmp_path)
        try:
            assert proc.stdout.readline().startswith("STATUS t=")
            proc.stdout.close()  # the reader leaves, as head does
            err = proc.stderr.read()
            proc.wait(timeout=30)
        finally:
            proc.kill()
    assert proc.returncode == 0, err
    assert err == ""
