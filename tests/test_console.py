"""The line console: piped scripts, echo and prompts, end of input, loop messages."""

from __future__ import annotations

import importlib
import io

import pytest

from pyrt.console import Console


class Echo:
    """A tiny interpreter: prints the line upper-cased; 'mode' switches the prompt."""

    def __init__(self, stdout):
        self.stdout = stdout
        self.prompt = "A> "
        self.seen: list[str] = []

    def onecmd(self, line: str) -> bool:
        self.seen.append(line)
        if line == "quit":
            return True
        if line == "mode":
            self.prompt = "B> "
        self.stdout.write(line.upper() + "\n")
        return False


def test_piped_script_prints_prompts_and_echoes_lines():
    """Each prompt is printed with the line echoed after it, then the output."""
    out = io.StringIO()
    shell = Echo(out)
    assert Console(shell, io.StringIO("one\nmode\ntwo\n"), out).run() == 0
    assert out.getvalue() == "A> one\nONE\nA> mode\nMODE\nB> two\nTWO\nB> \n"


def test_end_of_input_without_newline():
    """The last line runs even without a newline; the console ends at end of input."""
    out = io.StringIO()
    shell = Echo(out)
    Console(shell, io.StringIO("last"), out).run()
    assert shell.seen == ["last"]


def test_quit_stops_reading():
    """Lines after quit are not run."""
    out = io.StringIO()
    shell = Echo(out)
    Console(shell, io.StringIO("a\nquit\nb\n"), out).run()
    assert shell.seen == ["a", "quit"]


def test_loop_messages_are_printed_before_the_next_prompt():
    """Messages drained from the loop appear on their own lines before the prompt."""
    out = io.StringIO()
    shell = Echo(out)
    pending = [["FAULT gripper: test"], [], []]
    Console(shell, io.StringIO("x\n"), out, messages=lambda: pending.pop(0) if pending else []).run()
    assert out.getvalue().splitlines()[0] == "FAULT gripper: test"
    assert out.getvalue().splitlines()[1] == "A> x"


def test_not_interactive_on_stringio():
    """StringIO is not a terminal: plain line mode."""
    assert not Console(Echo(io.StringIO()), io.StringIO(), io.StringIO()).interactive()


def test_input_fallback_without_prompt_toolkit(monkeypatch):
    """The input() fallback runs lines until EOF and prints messages before each prompt."""
    out = io.StringIO()
    shell = Echo(out)
    feed = iter(["a", "b"])
    prompts: list[str] = []

    def fake_input(prompt: str) -> str:
        prompts.append(prompt)
        try:
            return next(feed)
        except StopIteration:
            raise EOFError from None

    monkeypatch.setattr("builtins.input", fake_input)
    console = Console(shell, io.StringIO(), out, messages=lambda: [])
    assert console._run_input() == 0
    assert shell.seen == ["a", "b"] and prompts == ["A> "] * 3


def test_ctrl_c_on_a_terminal_abandons_the_command_only(monkeypatch):
    """KeyboardInterrupt inside a command prints 'interrupted' and the session goes on."""
    out = io.StringIO()

    class Slow(Echo):
        def onecmd(self, line):
            if line == "wait":
                raise KeyboardInterrupt
            return super().onecmd(line)

    shell = Slow(out)
    feed = iter(["wait", "after"])

    def fake_input(prompt):
        try:
            return next(feed)
        except StopIteration:
            raise EOFError from None

    monkeypatch.setattr("builtins.input", fake_input)
    Console(shell, io.StringIO(), out)._run_input()
    assert "interrupted" in out.getvalue() and shell.seen == ["after"]


@pytest.mark.parametrize("name", ["pyrt.console", "pyrt.commands"])
def test_exports_sorted_and_present(name):
    """The console and commands packages export a sorted __all__ of names they have."""
    module = importlib.import_module(name)
    assert list(module.__all__) == sorted(module.__all__)
    for attr in module.__all__:
        assert hasattr(module, attr)


def test_complete_walks_a_nested_table_case_insensitively():
    """complete() offers the words after the typed ones, by prefix, any case."""
    from pyrt.console.base import complete

    loop: dict = {}
    loop.update(a=loop, b=loop)
    table = {"prototype": {"to": None, "tensions": None}, "scope": {"add": loop},
             "quit": None}
    assert complete(table, "") == ["prototype", "quit", "scope"]
    assert complete(table, "PRO") == ["prototype"]
    assert complete(table, "prototype t") == ["tensions", "to"]
    assert complete(table, "prototype to ") == []
    assert complete(table, "scope add a b ") == ["a", "b"]
    assert complete(table, "nosuch x") == [] and complete(None, "") == []


def test_prompt_toolkit_completer_replaces_the_partial_word():
    """The terminal's completer completes from the shell's table and replaces the partial word."""
    from prompt_toolkit.document import Document

    class Shell(Echo):
        def completions(self):
            return {"prototype": {"tensionFind": None, "to": None}}

    console = Console(Shell(io.StringIO()), io.StringIO(), io.StringIO())
    found = list(console._completer().get_completions(Document("prototype te"), None))
    assert [(c.text, c.start_position) for c in found] == [("tensionFind", -2)]
    assert Console(Echo(io.StringIO()))._completer() is None


@pytest.mark.parametrize(("robot", "read"), [("gripper", "W"), ("manipulator", "status")])
def test_a_byte_that_is_not_utf8_is_a_bad_command_not_a_crash(robot, read, tmp_path):
    """'\\xff' on a strictly decoded stdin: one error line, the next command runs (-k), exit 1."""
    import os
    import subprocess
    import sys

    env = dict(os.environ, PYTHONIOENCODING="utf-8:strict", HOME=str(tmp_path),
               PYRT_HOME=str(tmp_path / "pyrt-home"))
    done = subprocess.run([sys.executable, "-m", "pyrt", robot, "--speed", "max", "-k"],
                          input=b"\xff\xfe bad\n" + read.encode() + b"\n", env=env,
                          capture_output=True, timeout=120, cwd=tmp_path)
    out = done.stdout.decode()
    assert done.returncode == 1, done.stderr.decode()[-2000:]  # the bad line fails the script
    assert "UnicodeDecodeError" not in done.stderr.decode()
    assert "error: unknown command or object '\ufffd\ufffd'" in out
    assert out.count("error:") == 1 and f" {read}\n" in out


def test_status_line_is_never_written_to_a_pipe():
    """Piped: the live status line is neither read nor written; the script runs as before."""
    calls = []

    def status():
        calls.append(1)
        return "STATUS-LINE"

    out = io.StringIO()
    Console(Echo(out), io.StringIO("a\nquit\n"), out, status=status).run()
    assert "STATUS-LINE" not in out.getvalue() and calls == []
    assert "A\n" in out.getvalue()


def test_status_line_on_a_terminal_is_the_toolbar_and_survives_a_failing_read():
    """On a terminal the status is prompt_toolkit's bottom toolbar; a read that raises says so in one line."""
    from prompt_toolkit.application import create_app_session
    from prompt_toolkit.input import create_pipe_input
    from prompt_toolkit.output import DummyOutput

    seen = []

    def status():
        seen.append(1)
        if len(seen) > 1:
            raise RuntimeError("loop gone")
        return "pos 0000\ntarget F000"

    out = io.StringIO()
    shell = Echo(out)
    console = Console(shell, stdout=out, status=status)
    assert console._status_line() == " pos 0000  target F000"
    assert console._status_line() == " status unavailable: RuntimeError: loop gone"
    with create_pipe_input() as pipe, create_app_session(input=pipe, output=DummyOutput()):
        pipe.send_text("hello\rquit\r")
        assert console._run_prompt_toolkit() == 0
    assert shell.seen == ["hello", "quit"]
    assert len(seen) > 2  # the toolbar was drawn, and a failing read did not end the session


def test_live_status_is_the_stations_status_at_real_time_only():
    """The consoles' status line reads the station's status (at real time); none on simulated time."""
    import argparse

    from pyrt.cli._loopopts import live_status
    from pyrt.errors import FaultError
    from pyrt.scheduler import Loop, WallClock
    from pyrt.station.gripper import build_gripper

    assert live_status(None, None, argparse.Namespace(speed=None)) is None
    station = build_gripper(Loop(WallClock()))
    runner = station.start()
    try:
        line = live_status(runner, station, argparse.Namespace(speed=1.0))
        assert line().startswith("position 0000 (76.0 mm), target 0000 (76.0 mm)")
        runner.call(station.trip, "test fault", "test", take_fault=False)
        assert "FAULT" in line().upper()
        with pytest.raises(FaultError):  # the line took nothing: the operator still gets it
            runner.call(lambda: None)
    finally:
        station.close()


def test_ctrl_c_stops_a_gripper_move_and_only_hints_when_idle(monkeypatch):
    """Ctrl-C during 'wait' or at the prompt mid-move stops the jaws; idle at the prompt it only hints."""
    from pyrt.commands import RobotShell
    from pyrt.scheduler import Loop, SimClock
    from pyrt.station.gripper import build_gripper

    station = build_gripper(Loop(SimClock()))
    runner = station.start()
    out = io.StringIO()
    shell = RobotShell(station, out)
    try:
        shell.onecmd("I")
        feed = iter([KeyboardInterrupt, "P-1B86", KeyboardInterrupt, "P-1B86", "wait", "W"])
        real = shell.onecmd

        def onecmd(line):
            if line == "wait":  # Ctrl-C while waiting for the move
                runner.sleep(0.2)
                raise KeyboardInterrupt
            return real(line)

        def fake_input(prompt):
            try:
                item = next(feed)
            except StopIteration:
                raise EOFError from None
            if item is KeyboardInterrupt:
                raise KeyboardInterrupt
            return item

        monkeypatch.setattr(shell, "onecmd", onecmd)
        monkeypatch.setattr("builtins.input", fake_input)
        Console(shell, io.StringIO(), out)._run_input()
        text = out.getvalue()
        assert "(Ctrl-C stops a move; nothing is moving" in text  # the first, idle
        assert text.count("interrupted: ") == 2  # at the prompt mid-move, and in 'wait'
        assert not runner.call(station.busy) and runner.call(lambda: station.board.dac) == 0x80
    finally:
        station.close()


def test_gripper_console_completes_words_objects_verbs_and_scope_channels():
    """The gripper console's Tab candidates for a few prefixes: words, the letters of the
    prompt's level, object verbs (the report's letters), scope channels."""
    from pyrt.commands.robot import RobotShell
    from pyrt.console.base import complete
    from pyrt.scheduler import Loop, SimClock
    from pyrt.station.gripper import build_gripper

    station = build_gripper(Loop(SimClock(), period_ns=1_000_000))
    try:
        table = RobotShell(station, io.StringIO()).completions()
        assert complete(table, "st") == ["stats", "status", "statusline", "stop"]
        assert complete(table, "gripper ") == ["C", "E", "I", "M", "P", "S", "T", "W", "X"]
        assert complete(table, "P") == ["P"]  # the level's letters, typed bare at CMD:
        assert complete(table, "w") == ["W", "wait"]
        assert complete(table, "monitor ") == ["C", "D", "I", "L", "N", "Q", "S"]
        assert complete(table, "scope a") == ["add"]
        channels = complete(table, "scope add gripper.")
        assert "gripper.encoder" in channels and "gripper.dac" in channels
        assert complete(table, "sim f") == ["fault"]
    finally:
        station.close()


def test_a_huge_piped_line_is_refused_whole_and_echoed_short():
    """100 KB on one line: refused with one error naming its length, echoed in at most ~200
    characters, never given to the shell; the next line runs as usual."""
    out = io.StringIO()
    shell = Echo(out)
    Console(shell, io.StringIO("P" + "x" * 100_000 + "\nnext\n"), out).run()
    text = out.getvalue()
    assert len(text) < 600
    assert "error: a line of 100001 characters is refused (at most 4096); nothing done" in text
    assert shell.seen == ["next"]


def test_a_long_line_within_the_bound_runs_and_its_echo_is_clipped():
    """A 1000-character line runs whole; its echo shows 200 characters and the length."""
    out = io.StringIO()
    shell = Echo(out)
    Console(shell, io.StringIO("y" * 1000 + "\n"), out).run()
    assert shell.seen == ["y" * 1000]
    assert f"A> {'y' * 200}... (1000 characters)\n" in out.getvalue()


class _GoneAfter(io.StringIO):
    """An output whose reader goes away after ``n`` writes (EPIPE from then on)."""

    def __init__(self, n: int):
        super().__init__()
        self.n = n

    def write(self, text: str) -> int:
        self.n -= 1
        if self.n < 0:
            raise BrokenPipeError(32, "Broken pipe")
        return super().write(text)


def test_a_reader_that_goes_away_ends_the_console_quietly_even_inside_a_command():
    """EPIPE while a command writes is not the command's error: the console ends there, status 0, reader_gone set, no further line run."""

    class Careful(Echo):
        def onecmd(self, line: str) -> bool:
            try:  # a shell that turns every Exception into a line of output
                return super().onecmd(line)
            except Exception as exc:  # pragma: no cover - the guard must not reach here
                self.seen.append(f"caught {type(exc).__name__}")
                return False

    out = _GoneAfter(3)
    shell = Careful(out)
    console = Console(shell, io.StringIO("one\ntwo\nthree\n"), out)
    assert console.run() == 0
    assert console.reader_gone and console.ended_by == "output closed"
    assert shell.seen == ["one"]  # 'A> ', 'one', 'ONE' written; the next prompt found it gone


def _closed_reader_run(args: list[str], tmp_path, stdin: bytes = b""):
    """Run ``python -m pyrt ARGS`` with stdout a pipe whose reader has already gone."""
    import os
    import subprocess
    import sys

    r, w = os.pipe()
    os.close(r)
    env = dict(os.environ, HOME=str(tmp_path), PYRT_HOME=str(tmp_path / "pyrt-home"))
    env.pop("PYRT_TOKEN", None)
    try:
        done = subprocess.run([sys.executable, "-m", "pyrt", *args], input=stdin, stdout=w,
                              stderr=subprocess.PIPE, env=env, timeout=120, cwd=tmp_path)
    finally:
        os.close(w)
    return done.returncode, done.stderr.decode()


@pytest.mark.parametrize("robot", ["gripper", "manipulator"])
def test_a_robot_whose_reader_has_gone_before_it_starts_ends_quietly(robot, tmp_path):
    """'pyrt ROBOT | head' with head already gone: no traceback, status 0."""
    rc, err = _closed_reader_run([robot, "--speed", "max"], tmp_path, b"help\nquit\n")
    assert "Traceback" not in err and "Exception ignored" not in err, err
    assert rc == 0, err


@pytest.mark.parametrize(("robot", "ready"), [("gripper", "jaws wide open"),
                                              ("manipulator", "pyrt manipulator: prototype")])
def test_a_robot_whose_reader_goes_away_mid_script_stops_the_robot_and_ends_quietly(
        robot, ready, tmp_path):
    """'printf 'help\\nstats\\nquit' | pyrt ROBOT --speed max | head -2': the console ends at the first write after head left, every motor stopped (said on stderr), status 0, no traceback."""
    import os
    import subprocess
    import sys

    env = dict(os.environ, HOME=str(tmp_path), PYRT_HOME=str(tmp_path / "pyrt-home"),
               PYTHONUNBUFFERED="1")
    env.pop("PYRT_TOKEN", None)
    proc = subprocess.Popen([sys.executable, "-m", "pyrt", robot, "--speed", "max"],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, env=env, cwd=tmp_path)
    try:
        seen = b""
        while ready.encode() not in seen:  # the robot runs: then the reader goes
            line = proc.stdout.readline()
            assert line, seen
            seen += line
        proc.stdout.close()
        _, err = proc.communicate(b"help\nstats\nstatus\nquit\n", timeout=120)
    finally:
        proc.kill()
    err = err.decode()
    assert "Traceback" not in err and "Exception ignored" not in err, err
    assert proc.returncode == 0, err
    assert f"pyrt {robot}: output closed: every motor stopped" in err


def test_a_failure_before_the_first_line_fails_the_script():
    """A start-up command that failed (or a fault shown before line 1) is a failure of the script: it stops there and the exit status is 1, naming it as start-up."""
    out, err = io.StringIO(), io.StringIO()
    shell = Echo(out)
    shell.failures = 1  # what start-up said: one failure before the console read a line
    status = Console(shell, io.StringIO("a\nb\n"), out, errors=err, keep_going=False).run()
    assert status == 1 and shell.seen == []
    assert "(start-up, before the first line)" in err.getvalue()
    assert "the script stops here" in err.getvalue()


def test_a_script_that_starts_clean_is_judged_by_its_lines_only():
    """No failure before line 1 and none after: exit status 0, every line run."""
    out, err = io.StringIO(), io.StringIO()
    shell = Echo(out)
    shell.failures = 0
    assert Console(shell, io.StringIO("a\nb\n"), out, errors=err, keep_going=False).run() == 0
    assert shell.seen == ["a", "b"] and err.getvalue() == ""
