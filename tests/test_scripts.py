"""Scripts fail loudly: a piped console, `pyrt send -f` and `pyrt connect` name the line that
failed, stop there (or run on with -k) and exit non-zero; overrun lines stay off the prompt line."""

from __future__ import annotations

import io
import os
import subprocess
import sys

from _server_rig import TOKEN, served

from pyrt.cli._loopopts import OverrunLines
from pyrt.console import Console


def _pyrt(*argv: str, stdin: str | None = None, cwd, stdin_file=None, env_extra=None):
    env = dict(os.environ, PYRT_HOME=str(cwd / "home"), **(env_extra or {}))
    return subprocess.run([sys.executable, "-m", "pyrt", *argv], input=stdin,
                          stdin=stdin_file, capture_output=True, text=True, timeout=120,
                          env=env, cwd=cwd)


def test_a_script_file_with_a_bad_line_exits_1_naming_it_and_stops_there(tmp_path):
    """`pyrt gripper < s.txt`: the unknown word on line 2 is named (file, number, text), line 3 never runs, exit 1."""
    script = tmp_path / "s.txt"
    script.write_text("W\nfoo\nW\n")
    with script.open() as f:
        done = _pyrt("gripper", "--speed", "max", stdin_file=f, cwd=tmp_path)
    assert done.returncode == 1, done.stderr
    assert "pyrt gripper: s.txt:2: 'foo' failed: error: unknown command 'foo'" in done.stderr
    assert "the script stops here (-k runs on)" in done.stderr
    assert done.stdout.count("CMD: W\n") == 1  # the third line did not run
    assert "stopped at line 2 (an error): every motor stopped" in done.stdout.splitlines()[-1]


def test_keep_going_runs_on_and_still_exits_1(tmp_path):
    """-k: every line runs; each failed line is named, then how many failed; exit 1."""
    done = _pyrt("gripper", "--speed", "max", "-k", stdin="W\nfoo\nW\nbar\n", cwd=tmp_path)
    assert done.returncode == 1, done.stderr
    assert done.stdout.count("CMD: W\n") == 2
    assert "stdin:2: 'foo' failed" in done.stderr and "stdin:4: 'bar' failed" in done.stderr
    assert "stdin: 2 lines failed: 2, 4" in done.stderr
    assert "end of input: every motor stopped" in done.stdout


def test_a_script_whose_lines_all_run_exits_0(tmp_path):
    """A script without a failure: exit 0, nothing on stderr."""
    done = _pyrt("gripper", "--speed", "max", stdin="W\nT\n", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stderr == ""


def test_an_out_of_range_move_fails_the_manipulator_script(tmp_path):
    """A move outside the vessel is refused: the script stops there, exit 1, the refusal quoted."""
    done = _pyrt("manipulator", "--speed", "max",
                 stdin="prototype to 0 0 500\nstatus\n", cwd=tmp_path)
    assert done.returncode == 1, done.stderr
    assert ("stdin:1: 'prototype to 0 0 500' failed: error: prototype to: refused"
            in done.stderr)
    assert "prototype> status" not in done.stdout


def test_a_fault_during_a_wait_fails_the_script_at_that_line(tmp_path):
    """A rope that breaks during a move: the FAULT fails the 'wait' line (3), exit 1."""
    done = _pyrt("manipulator", "--speed", "max",
                 stdin="sim fault axis0 break\nprototype to 0 0 60\nwait\nstatus\n",
                 cwd=tmp_path)
    assert done.returncode == 1, done.stderr
    assert "stdin:3: 'wait' failed: FAULT: LOW_TENSION_STOP" in done.stderr
    assert "stopped at line 3 (a fault)" in done.stdout


class _Shell:
    """An interpreter that fails on 'bad' and raises a fault message after 'late'."""

    prompt = "> "

    def __init__(self, out):
        self.stdout = out
        self.failures = 0
        self.pending: list[str] = []

    def onecmd(self, line: str) -> bool:
        if line == "bad":
            self.failures += 1
            self.stdout.write("error: bad is bad\n")
        elif line == "late":
            self.pending.append("FAULT something broke")
        else:
            self.stdout.write(f"ran {line}\n")
        return False

    def messages(self) -> list[str]:
        out, self.pending = self.pending, []
        self.failures += len(out)
        return out


def test_a_fault_after_the_last_line_is_that_lines_failure():
    """A fault reported after the script's last line (a move left running) fails that line."""
    out, err = io.StringIO(), io.StringIO()
    shell = _Shell(out)
    console = Console(shell, io.StringIO("ok\nlate\n"), out, messages=shell.messages,
                      keep_going=False, errors=err, what="pyrt x")
    assert console.run() == 1
    assert err.getvalue().startswith("pyrt x: stdin:2: 'late' failed: FAULT something broke")


def test_a_fault_seen_before_the_next_prompt_stops_the_script_there():
    """A fault that comes between two lines is the earlier line's; the next line never runs."""
    out, err = io.StringIO(), io.StringIO()
    shell = _Shell(out)
    console = Console(shell, io.StringIO("late\nnext\n"), out, messages=shell.messages,
                      keep_going=False, errors=err)
    assert console.run() == 1
    assert "ran next" not in out.getvalue()
    assert "stdin:1: 'late' failed: FAULT something broke; the script stops here" in err.getvalue()
    assert console.ended_by == "stopped at line 1 (a fault)"


def test_send_a_script_stops_at_the_first_refused_line(tmp_path):
    """`pyrt send PORT -f s.txt`: replies printed, the refused line named with its number, exit 1."""
    script = tmp_path / "s.txt"
    script.write_text("W\n# a comment\n\nnope\nW\n")
    with served() as sv:
        done = _pyrt("send", f"{sv.host}:{sv.port}", "-f", str(script), cwd=tmp_path,
                     env_extra={"PYRT_TOKEN": TOKEN})
        assert done.returncode == 1, done.stderr
        assert f"{script}:4: 'nope' failed: " in done.stderr
        assert done.stdout.splitlines() == ["0000"]  # line 5 was not sent
        kept = _pyrt("send", f"{sv.host}:{sv.port}", "-f", "-", "-k", stdin="nope\nW\nzap\n",
                     cwd=tmp_path, env_extra={"PYRT_TOKEN": TOKEN})
        assert kept.returncode == 1
        assert "0000" in kept.stdout.splitlines()
        assert "stdin: 2 lines failed: 1, 3" in kept.stderr
        bad_token = _pyrt("send", f"{sv.host}:{sv.port}", "-f", "-",
                          stdin="AUTH not-the-token-0123456789\nW\n", cwd=tmp_path)
        assert bad_token.returncode == 1 and "stdin:1: 'AUTH ...' failed" in bad_token.stderr
        assert "not-the-token" not in bad_token.stderr
        good = _pyrt("send", f"{sv.host}:{sv.port}", "-f", "-", stdin="W\nW\n", cwd=tmp_path,
                     env_extra={"PYRT_TOKEN": TOKEN})
        assert good.returncode == 0 and good.stdout.splitlines() == ["0000", "0000"]


def test_send_needs_a_command_or_a_file(tmp_path):
    """Neither a COMMAND nor -f, or -k without -f, or a missing file: usage errors, exit 2."""
    assert _pyrt("send", "5099", cwd=tmp_path).returncode == 2
    assert _pyrt("send", "5099", "W", "-k", cwd=tmp_path).returncode == 2
    gone = _pyrt("send", "5099", "-f", "nope.txt", cwd=tmp_path)
    assert gone.returncode == 2 and "nope.txt: there is no such file" in gone.stderr


def test_connect_with_a_script_stops_at_the_first_refused_line(tmp_path):
    """`pyrt connect PORT < s.txt`: the ERR reply fails the line, the rest is not sent, exit 1."""
    with served() as sv:
        done = _pyrt("connect", f"{sv.host}:{sv.port}", stdin="status\nnope\nstatus\n",
                     cwd=tmp_path, env_extra={"PYRT_TOKEN": TOKEN})
        assert done.returncode == 1, done.stderr
        assert "pyrt connect: stdin:2: 'nope' failed: error: command" in done.stderr
        assert done.stdout.count("gripper> status\n") == 1


# -- overrun lines ------------------------------------------------------------------------------


class _Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def _line(n: int) -> str:
    return f"overrun: {n} ticks, worst 1.50 ms over at tick 4031; see stats"


def test_overrun_lines_are_one_line_then_a_summary_per_window():
    """A burst: its first line as it comes; the rest counted and said once per window."""
    clock, got = _Clock(), []
    lines = OverrunLines(got.append, clock=clock, window_s=10.0)
    lines.put(_line(2))
    for k in range(1, 20):  # a line a second, as the loop gives them
        clock.t = float(k)
        lines.put(_line(3))
    assert got == [_line(2), "overrun: 27 more overruns in the last 10 s; see stats"]
    clock.t = 40.0  # the rest of the burst, said when the next line comes
    lines.put(_line(1))
    assert got[2:] == ["overrun: 30 more overruns in the last 30 s; see stats"]


def test_an_overrun_after_a_quiet_window_is_shown_as_it_comes():
    """One overrun, a window without any, then another: both lines as they come, no summary."""
    clock, got = _Clock(), []
    lines = OverrunLines(got.append, clock=clock, window_s=10.0)
    lines.put(_line(2))
    clock.t = 30.0
    lines.put(_line(5))
    assert got == [_line(2), _line(5)]


def test_quiet_overrun_lines_say_nothing():
    """--quiet-overruns: no line at all."""
    got: list[str] = []
    lines = OverrunLines(got.append, quiet=True, clock=_Clock())
    lines.put(_line(2))
    assert got == []


def test_overrun_lines_never_land_on_a_scripts_prompt_line():
    """Attached to a console, an overrun line comes on a line of its own before the next prompt."""
    clock, sunk = _Clock(), []
    lines = OverrunLines(sunk.append, clock=clock)
    lines.attach()
    out = io.StringIO()

    class Shell:
        prompt = "CMD: "
        stdout = out

        def onecmd(self, line: str) -> bool:
            lines.put(_line(2))  # the loop overran while the line ran
            self.stdout.write("done\n")
            return False

    Console(Shell(), io.StringIO("W\n"), out, messages=lines.messages).run()
    assert sunk == []
    assert out.getvalue() == f"CMD: W\ndone\n{_line(2)}\nCMD: \n"


def test_quiet_overruns_is_an_option_of_every_station(tmp_path):
    """`pyrt gripper --quiet-overruns` is accepted; --help says what it does."""
    done = _pyrt("gripper", "--help", cwd=tmp_path)
    assert "--quiet-overruns" in done.stdout and "summary" in done.stdout
    run = _pyrt("gripper", "--speed", "max", "--quiet-overruns", stdin="W\n", cwd=tmp_path)
    assert run.returncode == 0, run.stderr
