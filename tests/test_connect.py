"""pyrt connect: an interactive console on a served robot, its completion and its stop."""

from __future__ import annotations

import io
import os
import subprocess
import sys

from _server_rig import served

from pyrt.cli.connect import RemoteShell
from pyrt.client import Client
from pyrt.console.base import complete


def test_remote_shell_reads_refuses_and_stops():
    """Unprivileged: reads are answered, a move is refused with one error line, stop is served."""
    with served() as sv:
        out = io.StringIO()
        shell = RemoteShell(sv.client(), out, "gripper")
        assert shell.onecmd("W") is False
        assert shell.onecmd("P E47A") is False
        assert shell.onecmd("stop") is False
        lines = out.getvalue().splitlines()
        assert lines[0] == "0000"
        assert lines[1].startswith("error: denied")
        assert not any(ln.startswith("error") for ln in lines[2:])
        assert sv.still_and_null()
        assert shell.onecmd("exit") is True


def test_an_unprivileged_stop_halts_the_operators_move():
    """The operator starts a move; a second, unauthenticated client's stop halts it at once."""
    with served() as sv:
        op = sv.operator()
        op.command("I")
        op.command("P-1B86")
        assert sv.runner.call(lambda: sv.rig.busy())
        watcher = RemoteShell(sv.client(), io.StringIO(), "gripper")
        watcher.onecmd("stop")
        assert not sv.runner.call(lambda: sv.rig.busy())
        assert sv.still_and_null()


def test_completion_comes_from_the_servers_own_help():
    """The completion table is the server's words, objects and their commands."""
    with served() as sv:
        shell = RemoteShell(sv.client(), io.StringIO(), "gripper")
        table = shell.completions()
        assert {"help", "wait", "stop", "status", "scope", "auth", "exit"} <= set(table)
        assert complete(table, "sim ") == sorted(table["sim"])
        assert "fault" in table["sim"] and "gripper" in complete(table, "help g")


def test_pyrt_connect_runs_a_piped_script_against_a_served_robot(tmp_path):
    """pyrt connect in a subprocess, piped: status and stop are answered; exit leaves, code 0."""
    with served(wall=True) as sv:
        env = {k: v for k, v in os.environ.items() if k != "PYRT_TOKEN"}
        done = subprocess.run(
            [sys.executable, "-m", "pyrt", "connect", f"{sv.host}:{sv.port}"],
            input="status\nstop\nexit\n", capture_output=True, text=True, timeout=60,
            env=env, cwd=tmp_path)
        assert done.returncode == 0, done.stderr
        out = done.stdout
        assert out.startswith(f"connected to {sv.host}:{sv.port}: ")
        assert "gripper> status\n" in out and " position=" in out and "error:" not in out
        assert "gripper> stop\ngripper: every motor stopped" in out
        assert Client(sv.host, sv.port).status().fields["fault"] == 0
