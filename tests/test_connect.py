"""pyrt connect: an interactive console on a served robot, its completion and its stop."""

from __future__ import annotations

import io
import os
import subprocess
import sys
import time

import pytest
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


def test_ctrl_c_at_the_remote_prompt_stops_a_running_move_and_only_hints_when_idle():
    """Ctrl-C at the prompt of pyrt connect: a hint while nothing moves; a running move is stopped (over a second connection), as at a local console."""
    with served() as sv:
        shell = RemoteShell(sv.client(), io.StringIO(), "gripper")
        assert shell.interrupt(True).startswith("(Ctrl-C stops a move; nothing is moving")
        op = sv.operator()
        op.command("I")
        op.command("P-1B86")
        assert sv.runner.call(lambda: sv.rig.busy())
        said = shell.interrupt(True)
        assert said.startswith("interrupted: gripper: every motor stopped; position")
        assert not sv.runner.call(lambda: sv.rig.busy())
        assert sv.still_and_null()


def test_a_line_after_an_interrupted_sleep_says_it_waits_for_it_and_answers_itself():
    """After Ctrl-C abandons a remote 'sleep', the next line says the server first finishes it, then shows its own reply only."""
    with served(wall=True) as sv:  # the sleep takes 2 s of wall time
        out = io.StringIO()
        client = sv.operator()
        shell = RemoteShell(client, out, "gripper")
        client.send_line("sleep 2")  # what request() had sent when Ctrl-C came
        client.owed.append("sleep 2")
        assert "is dropped when it comes" in shell.interrupt(False)
        assert shell.onecmd("W") is False
        lines = out.getvalue().splitlines()
        assert lines[0] == ("(the server first finishes the interrupted 'sleep 2'; its reply "
                            "will be dropped)")
        assert lines[1:] == [f"{sv.runner.call(sv.ctl.position) & 0xFFFF:04X}"]
        assert not client.owed and client.late[-1][0] == "sleep 2"


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


def test_a_piped_auth_is_refused_and_never_takes_the_next_line_as_the_token(tmp_path):
    """Piped: 'auth' alone is refused with one error line (no GetPassWarning) and the next script line runs as a command; 'auth TOKEN' is refused too and sends nothing."""
    from _server_rig import TOKEN

    with served(wall=True) as sv:
        env = {k: v for k, v in os.environ.items() if k != "PYRT_TOKEN"}
        done = subprocess.run(
            [sys.executable, "-m", "pyrt", "connect", f"{sv.host}:{sv.port}", "-k"],
            input=f"auth\nstatus\nauth {TOKEN}\nP-1B86\nexit\n", capture_output=True,
            text=True, timeout=60, env=env, cwd=tmp_path)
        # the refused lines fail the script (-k: it runs on), named on stderr
        assert done.returncode == 1, done.stderr
        assert "GetPassWarning" not in done.stderr
        assert done.stderr.splitlines() == [
            ln for ln in done.stderr.splitlines() if ln.startswith("pyrt connect: stdin:")]
        assert "stdin:1: 'auth' failed" in done.stderr
        assert "stdin:3: 'auth ...' failed" in done.stderr and TOKEN not in done.stderr
        assert "stdin:4: 'P-1B86' failed" in done.stderr
        out = done.stdout
        assert ("gripper> auth\nerror: auth asks for the token on a terminal, and this input "
                "is not one") in out
        assert "gripper> status\nt=" in out and " position=" in out  # the next line ran
        assert "error: a token typed on a line is shown" in out
        assert "privileged" not in out.replace("unprivileged", "")
        assert "error: denied" in out  # the move was refused: no AUTH was sent
        assert sv.still_and_null()


#: Only a hang takes this long: a bound that catches one, never a measure of speed.
HANG_S = 60.0


def _read_until(child, pexpect, *texts: str, done=None, seconds: float = HANG_S) -> str:
    """Read a terminal session, answering prompt_toolkit's cursor-position requests as a
    terminal does, until every one of ``texts`` has come (and ``done()`` holds, if given);
    what was read.  The bound catches a hang only."""
    import time

    seen: list[str] = []
    end = time.monotonic() + seconds
    while not (all(t in "".join(seen) for t in texts) and (done is None or done())):
        if time.monotonic() > end:
            raise AssertionError(f"no {texts!r} in {''.join(seen)[-2000:]!r}")
        i = child.expect(["\x1b\\[6n", pexpect.TIMEOUT, pexpect.EOF], timeout=0.05)
        seen.append(child.before)
        if i == 0:
            child.send("\x1b[1;1R")
        elif i == 2:
            raise AssertionError(f"the session ended: {''.join(seen)[-2000:]!r}")
    return "".join(seen)


def test_pyrt_connect_on_a_terminal_asks_for_the_token_without_echo_and_shows_live_status(tmp_path):
    """On a terminal: 'auth' prompts for the token without echoing it, privilege is said once, a move runs, the status line shows it live."""
    pexpect = pytest.importorskip("pexpect")
    from _server_rig import TOKEN

    with served(wall=True) as sv:
        env = {k: v for k, v in os.environ.items() if k != "PYRT_TOKEN"}
        env.update(TERM="xterm", HOME=str(tmp_path))
        child = pexpect.spawn(sys.executable, ["-m", "pyrt", "connect", f"{sv.host}:{sv.port}",
                                               "--hz", "10"], encoding="utf-8", timeout=30,
                              dimensions=(24, 120), env=env, cwd=str(tmp_path))
        try:
            seen = _read_until(child, pexpect, "gripper>")
            child.sendline("auth")
            child.expect_exact("token: ")
            seen += child.before + "token: "
            child.sendline(TOKEN)
            seen += _read_until(child, pexpect, "privileged: every")
            child.sendline("P-1B86")
            moving = lambda: sv.runner.call(lambda: sv.ctl.moving, take_fault=False)  # noqa: E731
            seen += _read_until(child, pexpect, done=moving)
            # The status line is redrawn whole when a reply is printed: T until it shows the
            # move (the move lasts seconds; the bound catches a hang only).
            deadline = time.monotonic() + HANG_S
            while not ("target E47A (26.2 mm)" in seen and ", moving, drive" in seen):
                assert time.monotonic() < deadline, seen[-2000:]
                child.sendline("T")
                seen += _read_until(child, pexpect, "E47A")
            child.sendline("stop")
            seen += _read_until(child, pexpect, "gripper: every motor stopped")
            child.sendeof()
            child.expect(pexpect.EOF)
            seen += child.before
        finally:
            child.close()
        assert child.exitstatus == 0
        assert TOKEN not in seen  # never echoed
        # said once: by the server, not again by the console (the raw terminal stream may
        # carry a line twice when prompt_toolkit redraws on a late cursor report)
        assert "privileged: every console command is accepted" in seen
        assert "privileged: every command is accepted" not in seen
        # the live status line, unasked: the console's own line, counts in hex with mm
        assert "target E47A (26.2 mm)" in seen and ", moving, drive" in seen
        assert "gripper: every motor stopped" in seen
        assert sv.still_and_null()


@pytest.mark.wallclock
def test_ctrl_c_to_a_piped_connect_during_a_wait_stops_the_robot_and_ends_130(tmp_path):
    """SIGINT to a piped 'pyrt connect' during a remote wait: the jaws are stopped, said in one line, status 130."""
    import signal
    import time

    from _server_rig import TOKEN

    # the loop at a quarter of wall speed: the 3.5 s move lasts 14 s, so the interrupt comes
    # mid-move even when a loaded machine is slow to start and to deliver it
    with served(wall=True, speed=0.25) as sv:
        (tmp_path / "token").write_text(TOKEN + "\n")
        (tmp_path / "token").chmod(0o600)
        env = {k: v for k, v in os.environ.items() if k != "PYRT_TOKEN"}
        env.update(HOME=str(tmp_path), PYTHONUNBUFFERED="1")
        proc = subprocess.Popen(
            [sys.executable, "-m", "pyrt", "connect", f"{sv.host}:{sv.port}",
             "--token-file", "token"], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
            stderr=subprocess.PIPE, text=True, env=env, cwd=tmp_path,
            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
        busy = lambda: sv.runner.call(lambda: sv.rig.busy(), take_fault=False)  # noqa: E731
        waiting = lambda: sv.runner.call(lambda: sv.rig.waits_pending(), take_fault=False)  # noqa: E731
        try:
            proc.stdin.write("P D800\nwait\n")
            proc.stdin.flush()
            # the wait is at the server (the station counts it); the bound catches a hang only
            deadline = time.monotonic() + 60
            while not waiting():
                assert time.monotonic() < deadline, "the wait never reached the server"
                time.sleep(0.01)
            assert busy()  # a wait is counted only while something runs (3.5 s of loop time)
            proc.send_signal(signal.SIGINT)
            out, err = proc.communicate(timeout=30)
        finally:
            proc.kill()
        assert proc.returncode == 130, (out, err)
        assert "pyrt connect: interrupted: gripper: every motor stopped; position" in out
        assert "Traceback" not in err
        assert sv.still_and_null()


def test_ctrl_c_during_a_remote_wait_stops_the_move_and_every_later_reply_is_its_own(tmp_path):
    """On a terminal: Ctrl-C during a remote 'wait' stops the jaws (saying so), and W, T and S then answer themselves, not the line before."""
    pexpect = pytest.importorskip("pexpect")
    from _server_rig import TOKEN

    # the loop at a quarter of wall speed: the 3.5 s move lasts 14 s, so Ctrl-C comes mid-move
    # even when a loaded machine is slow to start the client and to deliver it
    with served(wall=True, speed=0.25) as sv:
        (tmp_path / "token").write_text(TOKEN + "\n")
        (tmp_path / "token").chmod(0o600)
        env = {k: v for k, v in os.environ.items() if k != "PYRT_TOKEN"}
        env.update(TERM="xterm", HOME=str(tmp_path))
        child = pexpect.spawn(sys.executable, ["-m", "pyrt", "connect", f"{sv.host}:{sv.port}",
                                               "--token-file", "token", "--hz", "0"],
                              encoding="utf-8", timeout=30, dimensions=(24, 120), env=env,
                              cwd=str(tmp_path))
        busy = lambda: sv.runner.call(lambda: sv.rig.busy(), take_fault=False)  # noqa: E731
        waiting = lambda: sv.runner.call(lambda: sv.rig.waits_pending(), take_fault=False)  # noqa: E731
        try:
            seen = _read_until(child, pexpect, "gripper>")
            child.sendline("P D800")  # 7000 counts: 3.5 s of loop time
            seen += _read_until(child, pexpect, done=busy)
            child.sendline("wait")
            seen += _read_until(child, pexpect, done=waiting)  # the wait is at the server
            assert busy()  # a wait is counted only while something runs
            child.sendintr()
            seen += _read_until(child, pexpect, "interrupted: gripper: every motor stopped; "
                                "position", "is dropped when it comes", done=lambda: not busy())
            # the jaws coast to rest after the stop (the motor lag): W then says where
            still = lambda: sv.runner.call(lambda: sv.rig.plant.v == 0.0,  # noqa: E731
                                           take_fault=False)
            seen += _read_until(child, pexpect, done=still)
            position = sv.runner.call(sv.ctl.position, take_fault=False)
            replies = {}
            for line, want in (("W", f"{position & 0xFFFF:04X}"), ("T", "D800"), ("S", "1111")):
                child.sendline(line)
                replies[line] = _read_until(child, pexpect, want)
            child.sendeof()
            child.expect(pexpect.EOF)
        finally:
            child.close()
        assert child.exitstatus == 0
        assert "interrupted: gripper: every motor stopped; position" in seen
        assert "is dropped when it comes" in seen
        assert sv.still_and_null()
        assert f"{position & 0xFFFF:04X}" in replies["W"]  # where the jaws stopped
        assert "at target" not in "".join(replies.values())  # the wait's reply is not shown
        assert "E47A" not in replies["W"] and "D800" in replies["T"]
        assert "D800" not in replies["S"] and "1111" in replies["S"]
