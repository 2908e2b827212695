"""The audit trail: remote commands that move or change the robot are shown on the console and logged."""

from __future__ import annotations

import io
import os
import re
import subprocess
import sys
import time

import pytest
from _server_rig import TOKEN, served

from pyrt.client import Client
from pyrt.commands import RobotShell


def test_remote_commands_that_act_are_posted_and_logged(tmp_path):
    """A DAQ client's stop and set are posted for the console and written to the audit log; its reads are not."""
    with served() as s:
        path = s.server.robot.open_audit_log(tmp_path / "audit.log")
        console = RobotShell(s.rig, io.StringIO())
        console.messages()  # what start-up said
        guest = s.client()
        guest.command("W")
        guest.command("get gripper.speed")
        guest.command("stop")
        op = s.client()
        op.auth(TOKEN)
        op.command("set gripper.speed 33")
        op.command("P E47A")
        assert len(op.command("wait")) == 1  # a remote wait does not take the console's lines
        said = [str(m) for m in console.messages()]
        s.server.robot.close_audit_log()
    audit = [m for m in said if m.startswith("remote: ")]
    assert len(audit) == 3, said
    assert re.fullmatch(r"remote: DAQ client \d+ 127\.0\.0\.1:\d+: stop", audit[0])
    assert audit[1].endswith(": set gripper.speed 33")
    logged = path.read_text().splitlines()
    assert len(logged) == 3 and logged[2].endswith(": P E47A")
    assert re.match(r"\d{4}-\d\d-\d\d \d\d:\d\d:\d\d,\d{3} DAQ client \d+ 127\.0\.0\.1:\d+: stop$",
                    logged[0])


def test_a_failed_auth_is_audited(tmp_path):
    """A wrong token is an audit line naming the client (console and log); nothing else changes."""
    with served() as s:
        path = s.server.robot.open_audit_log(tmp_path / "audit.log")
        console = RobotShell(s.rig, io.StringIO())
        console.messages()
        c = s.client()
        with pytest.raises(Exception, match="wrong token"):
            c.auth("not-the-token")
        said = [m for m in console.messages() if m.startswith("remote: ")]
        s.server.robot.close_audit_log()
    assert len(said) == 1 and re.fullmatch(
        r"remote: DAQ client \d+ 127\.0\.0\.1:\d+: failed AUTH \(1 of \d+\)", said[0]), said
    assert path.read_text().strip().endswith("failed AUTH (1 of 3)")


def test_the_audit_log_rotates_by_size(tmp_path):
    """Past audit_max_bytes the log is rotated; the newest line is in the live file."""
    with served() as s:
        s.server.robot.audit_max_bytes = 400
        path = s.server.robot.open_audit_log(tmp_path / "audit.log")
        for i in range(40):
            s.server.robot.audit("DAQ client 1 x", f"P {i:04X}")
        s.server.robot.close_audit_log()
    assert (tmp_path / "audit.log.1").exists()
    assert path.read_text().splitlines()[-1].endswith("P 0027")
    assert path.stat().st_size <= 400


@pytest.mark.wallclock
def test_the_audit_line_of_a_remote_stop_appears_on_the_console(tmp_path):
    """pyrt gripper --serve: a client's stop is shown on the operator's console naming the client, and logged in the working directory."""
    env = dict(os.environ, HOME=str(tmp_path), PYRT_HOME=str(tmp_path / "pyrt-home"),
               PYTHONUNBUFFERED="1")
    env.pop("PYRT_TOKEN", None)
    proc = subprocess.Popen([sys.executable, "-m", "pyrt", "gripper", "--serve", "127.0.0.1:0",
                             "--speed", "1"], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env, cwd=tmp_path)
    try:
        seen = ""
        deadline = time.monotonic() + 30
        # start-up (its 'I') ends with the jaws' state; a stop before that would abandon
        # the start-up's init, which fails a piped script by design
        while "serving gripper on " not in seen or "jaws wide open" not in seen:
            assert time.monotonic() < deadline, seen
            line = proc.stdout.readline()
            assert line, seen
            seen += line
        host, port = re.search(r"serving gripper on (\S+):(\d+)", seen).groups()
        client = Client(host, int(port))
        client.command("stop")
        client.close()
        proc.stdin.write("T\n")  # the console prints the loop's lines before each command
        proc.stdin.flush()
        out, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
    assert re.search(r"remote: DAQ client \d+ 127\.0\.0\.1:\d+: stop", out), (out, err)
    log = (tmp_path / "pyrt-gripper-audit.log").read_text()
    assert re.search(r"DAQ client \d+ 127\.0\.0\.1:\d+: stop", log)
