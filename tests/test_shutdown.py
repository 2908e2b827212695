"""The consoles' one way out, through a subprocess on real time: SIGTERM, SIGHUP, end of input."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time

import pytest


def _start(robot: str, tmp_path) -> subprocess.Popen:
    env = dict(os.environ, HOME=str(tmp_path), PYRT_HOME=str(tmp_path / "pyrt-home"),
               PYTHONUNBUFFERED="1")
    env.pop("PYRT_TOKEN", None)
    return subprocess.Popen([sys.executable, "-m", "pyrt", robot, "--speed", "1"],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env, cwd=tmp_path,
                            preexec_fn=_sigint_default)


def _sigint_default() -> None:
    """In the child: SIGINT back to its default action.  A suite started in the
    background by a non-interactive shell runs with SIGINT ignored, which the
    child would inherit (Python then installs no KeyboardInterrupt handler)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _read_until(proc: subprocess.Popen, text: str, timeout_s: float = 30.0) -> str:
    seen = ""
    deadline = time.monotonic() + timeout_s
    while text not in seen:
        assert time.monotonic() < deadline, f"no {text!r} in {seen!r}"
        line = proc.stdout.readline()
        assert line, f"ended before {text!r}: {seen!r}"
        seen += line
    return seen


@pytest.mark.wallclock
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_a_signal_mid_move_stops_every_motor_says_so_and_exits_0(tmp_path, sig):
    """SIGTERM or SIGHUP to an interactive gripper mid-move: one line saying the motors stopped, exit 0."""
    proc = _start("gripper", tmp_path)
    try:
        _read_until(proc, "jaws wide open")  # I has run
        proc.stdin.write("P-1B86\nT\n")
        proc.stdin.flush()
        _read_until(proc, "E47A")  # the target is set: the jaws are moving
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
    assert proc.returncode == 0, err
    assert f"pyrt gripper: {signal.Signals(sig).name}: every motor stopped" in out
    assert "Traceback" not in err


@pytest.mark.wallclock
def test_end_of_input_mid_move_on_the_manipulator_writes_back_and_says_so(tmp_path):
    """Ctrl-D (end of input) mid-move: every motor stopped, databases written back, in one line, exit 0."""
    proc = _start("manipulator", tmp_path)
    try:
        _read_until(proc, "type help")
        proc.stdin.write("prototype to 10 0 60\n")
        proc.stdin.flush()
        _read_until(proc, "prototype: to (10, 0, 60)")
        out, err = proc.communicate(timeout=30)  # closes stdin: end of input
    finally:
        proc.kill()
    assert proc.returncode == 0, err
    assert re.search(r"pyrt manipulator: end of input: every motor stopped; source at "
                     r"\(\S+, \S+, \S+\) cm; databases written back in ", out)


def _start_served(args: list[str], tmp_path) -> tuple[subprocess.Popen, str]:
    """Start ``pyrt ARGS`` with stdin a pipe; read stderr until the server says where it is."""
    env = dict(os.environ, HOME=str(tmp_path), PYRT_HOME=str(tmp_path / "pyrt-home"),
               PYTHONUNBUFFERED="1")
    env.pop("PYRT_TOKEN", None)
    proc = subprocess.Popen([sys.executable, "-m", "pyrt", *args, "--speed", "1"],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env, cwd=tmp_path)
    seen = ""
    deadline = time.monotonic() + 30
    while "serving" not in seen:
        assert time.monotonic() < deadline, seen
        line = proc.stderr.readline() if "--headless" in args else proc.stdout.readline()
        assert line, f"ended before serving: {seen!r}"
        seen += line
    return proc, seen


@pytest.mark.wallclock
@pytest.mark.parametrize("how", ["gripper console", "gripper --headless", "manipulator --serve"])
def test_a_second_sigterm_at_once_still_exits_0_with_every_motor_stopped(tmp_path, how):
    """Two SIGTERMs 10 ms apart mid-move (console, --headless, console with --serve): exit 0, never killed by the second, motors said stopped."""
    if how == "gripper console":
        proc = _start("gripper", tmp_path)
        _read_until(proc, "jaws wide open")
        proc.stdin.write("P-1B86\nT\n")
        proc.stdin.flush()
        _read_until(proc, "E47A")
    elif how == "gripper --headless":
        proc, _ = _start_served(["gripper", "--serve", "127.0.0.1:0", "--headless"], tmp_path)
    else:
        proc, _ = _start_served(["manipulator", "--serve", "127.0.0.1:0"], tmp_path)
        proc.stdin.write("prototype to 10 0 60\n")
        proc.stdin.flush()
        _read_until(proc, "prototype: to (10, 0, 60)")
    try:
        proc.send_signal(signal.SIGTERM)
        time.sleep(0.01)
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
    assert proc.returncode == 0, (out, err)
    assert "every motor stopped" in out, (out, err)
    assert "Traceback" not in err


@pytest.mark.wallclock
def test_headless_ends_on_sighup_like_sigterm(tmp_path):
    """--headless: SIGHUP (terminal closed) stops every motor, says so naming the signal, exits 0."""
    sig = signal.SIGHUP
    proc, _ = _start_served(["gripper", "--serve", "127.0.0.1:0", "--headless"], tmp_path)
    try:
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
    assert proc.returncode == 0, (out, err)
    assert f"pyrt gripper: {signal.Signals(sig).name}: every motor stopped" in out
    assert "Traceback" not in err


@pytest.mark.wallclock
def test_sigterm_to_the_manipulator_console_writes_back_and_says_so(tmp_path):
    """SIGTERM to an interactive manipulator mid-move: motors stopped and databases written back, in one line, exit 0."""
    proc = _start("manipulator", tmp_path)
    try:
        _read_until(proc, "type help")
        proc.stdin.write("prototype to 10 0 60\n")
        proc.stdin.flush()
        _read_until(proc, "prototype: to (10, 0, 60)")
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
    assert proc.returncode == 0, err
    assert re.search(r"pyrt manipulator: SIGTERM: every motor stopped; source at "
                     r"\(\S+, \S+, \S+\) cm; databases written back in ", out)


@pytest.mark.wallclock
def test_ctrl_c_to_a_piped_script_stops_every_motor_and_says_so(tmp_path):
    """SIGINT to a gripper running a piped script mid-move: the run ends with every motor stopped, said in one line, status 130."""
    proc = _start("gripper", tmp_path)
    try:
        _read_until(proc, "jaws wide open")
        proc.stdin.write("P-1B86\nT\n")
        proc.stdin.flush()
        _read_until(proc, "E47A")
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
    assert proc.returncode == 130, (out, err)
    assert "pyrt gripper: SIGINT: every motor stopped" in out
    assert "Traceback" not in err


@pytest.mark.wallclock
def test_sigint_to_a_piped_manipulator_says_where_the_source_stopped(tmp_path):
    """SIGINT to a piped manipulator mid-move: the closing line says where the source stopped, status 130."""
    proc = _start("manipulator", tmp_path)
    try:
        _read_until(proc, "type help")
        proc.stdin.write("prototype to 10 0 60\n")
        proc.stdin.flush()
        _read_until(proc, "prototype: to (10, 0, 60)")
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
    assert proc.returncode == 130, err
    assert re.search(r"pyrt manipulator: SIGINT: every motor stopped; source at "
                     r"\(\S+, \S+, \S+\) cm; databases written back in ", out), out[-400:]


@pytest.mark.wallclock
def test_a_headless_sigterm_says_its_closing_line_once_where_stderr_is_stdout(tmp_path):
    """--headless with stderr on stdout (a terminal, 2>&1): the closing line once, not twice
    (said on stdout and logged on stderr); with them apart both keep it (test above)."""
    env = dict(os.environ, HOME=str(tmp_path), PYRT_HOME=str(tmp_path / "pyrt-home"),
               PYTHONUNBUFFERED="1")
    proc = subprocess.Popen([sys.executable, "-m", "pyrt", "gripper", "--serve", "127.0.0.1:0",
                             "--headless", "--speed", "1"], stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env=env, cwd=tmp_path)
    try:
        seen = ""
        deadline = time.monotonic() + 30  # a bound for a hang only
        while "serving" not in seen:
            assert time.monotonic() < deadline, seen
            line = proc.stdout.readline()
            assert line, f"ended before serving: {seen!r}"
            seen += line
        proc.send_signal(signal.SIGTERM)
        out, _ = proc.communicate(timeout=30)
    finally:
        proc.kill()
    assert proc.returncode == 0, seen + out
    assert (seen + out).count("SIGTERM: every motor stopped") == 1, seen + out


class _ClosingStation:
    """A station whose close is hit by Ctrl-C (SIGINT to this process) half-way through."""

    def __init__(self) -> None:
        self.steps: list[str] = []
        self.reflexes = 0

    def close(self) -> None:
        self.steps.append("stop sent")
        os.kill(os.getpid(), signal.SIGINT)
        for _ in range(1000):  # the handler runs in this thread at the next bytecodes
            pass
        self.steps.append("loop stopped")

    def reflex(self, why: str) -> None:
        self.reflexes += 1

    def closing_note(self) -> str:
        return ""


class _EndedConsole:
    ended_by = "end of input"

    def run(self) -> int:
        return 0


def test_a_ctrl_c_while_the_station_closes_does_not_cut_the_close_short():
    """Ctrl-C during the close: the close runs to its end (stop sent, loop stopped), the status is the console's, and SIGINT is Python's own again after."""
    from pyrt.cli._shutdown import run_until_shutdown

    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        station, said = _ClosingStation(), []
        try:
            status = run_until_shutdown(station, _EndedConsole(), None, headless=False,
                                        say=said.append, what="pyrt test")
        except KeyboardInterrupt:
            pytest.fail(f"the Ctrl-C cut the close short after {station.steps}")
        assert station.steps == ["stop sent", "loop stopped"]
        assert status == 0 and station.reflexes == 0
        assert said == ["pyrt test: end of input: every motor stopped"]
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    finally:
        signal.signal(signal.SIGINT, before)
