"""The gripper console an operator can trust: stop, Ctrl-C, faults once, truthful wait,
the operator's comforts, and input that is refused in one short line."""

from __future__ import annotations

import io
import os
import signal
import subprocess
import sys
import time

import pytest

from pyrt.boards.i8031 import DRVON, FLAGS
from pyrt.cli import main
from pyrt.commands import RobotShell
from pyrt.console import Console
from pyrt.scheduler import Loop, SimClock
from pyrt.station.gripper import build_gripper


class Session:
    """A gripper station on a SimClock with its shell; ``run`` returns the lines printed."""

    def __init__(self, init: bool = True):
        self.station = build_gripper(Loop(SimClock()))
        self.runner = self.station.start()
        self.out = io.StringIO()
        self.shell = RobotShell(self.station, self.out)
        self.ctl = self.station.controller
        self.plant = self.station.plant
        if init:
            assert self.run("I")[-1].startswith("jaws wide open")

    def run(self, *lines: str) -> list[str]:
        self.out.seek(0)
        self.out.truncate()
        for line in lines:
            self.shell.onecmd(line)
        return self.out.getvalue().splitlines()

    def messages(self) -> list[str]:
        return self.shell.messages()

    def close(self) -> None:
        self.station.close()


@pytest.fixture
def session():
    s = Session()
    yield s
    s.close()


def move_period_s(s: Session) -> float:
    return s.ctl.schedule().move_ns / 1e9


def stopped_within_one_period(s: Session) -> None:
    """Current zero now; the jaws coasting to rest within one MVJAWS period."""
    assert s.runner.call(lambda: s.station.plant.board.dac) == 0x80
    assert not s.ctl.ram[FLAGS] & (1 << DRVON)
    s.runner.sleep(move_period_s(s))
    full = s.ctl.calibration.speed(0x7F)
    assert abs(s.plant.v) < 0.05 * full  # the worm's lag: stopping, not yet still


@pytest.mark.parametrize("word", ["I", "C", "P-1B86"])
def test_stop_during_i_c_and_p_stops_the_jaws_within_one_jaw_move_period(word):
    """stop mid-I, mid-C and mid-P: current zero in that tick, the jaws at rest a period later."""
    s = Session(init=word != "I")
    try:
        if word == "P-1B86":
            s.run(word)
        else:  # the foreground job, started as the console would, without waiting for it
            s.runner.call(s.ctl.start_init if word == "I" else s.ctl.start_calibration)
            if word == "C":
                s.runner.sleep(1.5)  # past the first init: closing
        s.runner.sleep(0.5)
        assert s.runner.call(lambda: s.station.plant.board.dac) != 0x80
        said = s.run("stop")
        assert said[0].startswith("gripper: every motor stopped; position ")
        assert "mm), target " in said[0] and "error " in said[0]
        stopped_within_one_period(s)
        assert not s.runner.call(s.station.busy)
    finally:
        s.close()


def test_ctrl_c_during_wait_stops_the_move_through_the_console(monkeypatch):
    """Ctrl-C while 'wait' waits for a P move: the console's interrupt path stops the jaws."""
    s = Session()
    try:
        real = s.shell.onecmd

        def onecmd(line):
            if line == "wait":
                s.runner.sleep(0.3)  # the move is under way when the operator presses Ctrl-C
                raise KeyboardInterrupt
            return real(line)

        feed = iter(["P-1B86", "wait", "W"])

        def fake_input(prompt):
            try:
                return next(feed)
            except StopIteration:
                raise EOFError from None

        monkeypatch.setattr(s.shell, "onecmd", onecmd)
        monkeypatch.setattr("builtins.input", fake_input)
        Console(s.shell, io.StringIO(), s.out)._run_input()
        text = s.out.getvalue()
        assert "interrupted: gripper: every motor stopped; position " in text
        stopped_within_one_period(s)
        monkeypatch.undo()
        assert s.run("wait") == ["nothing to wait for: jaws idle"]
    finally:
        s.close()


def test_after_a_fault_reads_answer_and_the_fault_is_shown_once(session):
    """A supervision fault mid-move: shown once (as the loop's line), then S, W, T, stats and monitor D answer."""
    s = session
    s.run("M", "C 45 18", "Q", "P-1B86", "sleep 10")
    assert s.station.fault is not None
    shown = s.messages()  # what the console prints before the next prompt
    assert sum("P move oscillating" in line for line in shown) == 1
    lines = s.run("S", "W", "T", "stats", "M", "D 2C", "Q", "status")
    assert len(lines[0]) == 16 and set(lines[0]) <= {"0", "1"} and lines[1].startswith("on: ")
    assert lines[2] == f"{s.ctl.position():04X}" and lines[3] == "E47A"
    assert not any("FAULT" in line and "oscillating" in line for line in lines[:-1])
    assert any(line.startswith("2C ") for line in lines)
    assert lines[-1].startswith("position ") and ", fault, drive +0" in lines[-1]
    refused = s.run("P-100")
    assert refused[0].startswith("error: gripper P: refused: gripper is stopped by a fault")
    assert s.run("ack")[0].startswith("fault acknowledged")
    assert s.messages() == []


def test_a_fault_raised_at_a_command_is_shown_once_and_the_read_still_answers(session):
    """A fault the console has not shown yet comes with the next read, once, and the read answers."""
    s = session
    s.runner.call(s.station.trip, "test fault", "test", take_fault=False)
    lines = s.run("W", "W")
    assert lines.count("0000") == 2
    assert sum(line.startswith("FAULT: test fault") for line in lines) == 1
    assert s.messages() == []  # the loop's line is not shown again


def test_wait_says_at_target_stopped_short_or_fault(session):
    """wait: 'at target', 'stopped short of the target by N counts (why)', or 'fault: ...'."""
    s = session
    assert s.run("P-1000", "wait")[0].startswith("at target: position ")
    s.run("sim fault jam", "P-1800")
    said = s.run("wait")[0]
    assert said.startswith("stopped short of the target by ")
    err = int(said.split(" by ")[1].split()[0])
    assert abs(err - 0x800) <= 16 and "(the stopped bit ended the move" in said
    s.run("sim fault none", "P0", "wait", "M", "C 45 18", "Q", "P-1B86")
    said = s.run("wait")
    assert said[0].startswith("fault: P move oscillating about the target")
    assert sum("oscillating" in line for line in said + s.messages()) == 1


def test_p_in_millimetres_and_positions_beside_counts(session):
    """P 42.5mm moves to a 42.5 mm opening (the station's calibration); status shows mm beside counts."""
    s = session
    cal = s.ctl.calibration
    s.run("P 42.5mm", "wait")
    assert abs(cal.mm(s.ctl._sword(0x4A)) - 42.5) < 0.2
    assert abs(s.plant.opening_mm - 42.5) < 0.2  # the sim's truth
    line = s.run("status")[0]
    assert line.startswith(f"position {s.ctl.position():04X} (42.")
    assert ", idle, drive +0" in line
    assert s.run("P 80mm")[0] == "error: target 80mm is out of range (0..76 mm)"


def test_p_takes_any_length_unit_beside_hexadecimal(session):
    """P 4.25cm is P 42.5mm (the one number grammar); P E47A stays hexadecimal; P 1_0mm is refused."""
    s = session
    cal = s.ctl.calibration
    s.run("P 4.25cm", "wait")
    assert abs(cal.mm(s.ctl._sword(0x4A)) - 42.5) < 0.2
    assert s.run("P 1_0mm")[0].startswith("error: target '1_0mm' is not a hexadecimal number")
    s.run("P E47A", "wait")
    assert s.ctl.target() == 0xE47A


def test_s_decodes_the_sensor_byte_by_name(session):
    """S prints the 16 bits, then the sensors that are on by name."""
    s = session
    assert s.run("S") == ["1111101111111111", "on: limit"]
    s.run("sim object 30", "P 31mm", "wait")
    bits, names = s.run("S")
    assert bits[15 - 8] == "0"  # crossfire
    assert names == "on: crossfire, right -Ya, left +Ya"


def test_x_confirms_what_it_changed_and_names_its_range(session):
    """X 33 says what it stored; X 100 and X 0 name the range 01..7F and change nothing."""
    s = session
    assert s.run("X 33") == [
        "speed 7F -> 33: JSPEED 33, MXPJSPD B3, MXNJSPD 4D (up to 860 counts/s)"]
    assert s.run("X 100") == ["error: speed 100 is out of range (01..7F)"]
    assert s.run("X 0") == ["error: speed 0 is out of range (01..7F)"]
    assert s.ctl.ram[0x51] == 0x33


def test_exit_and_clear_are_console_words(session):
    """exit ends the session like quit; clear is not parsed as C with an argument."""
    s = session
    assert s.run("clear") == []
    assert s.shell.onecmd("exit") is True
    assert not s.runner.call(s.station.busy)


def test_errors_quote_at_most_40_characters(session):
    """100 KB of garbage in a command: a one-line error quoting at most 40 characters."""
    s = session
    for line in ("P" + "9" * 100_000, "X " + "A" * 100_000, "Q" * 100_000, "P 1" + "m" * 100_000):
        said = s.run(line)
        assert len(said) == 1 and said[0].startswith("error: ") and len(said[0]) < 200


def test_motion_gripper_move_is_checked_when_queued(session):
    """motion gripper_move with a bad target or parameter is refused at once; nothing queued."""
    s = session
    for bad, why in (("target=xyz", "not a hexadecimal number"), ("target=5", "out of range"),
                     ("target=ABC", "positive"),
                     ("target=-100 speed=3", "unknown parameter 'speed'"), ("", "missing"),
                     ("target=1.5", "not a whole number")):
        said = s.run(f"motion gripper_move {bad}")
        assert said[0].startswith("error: ") and why in said[0], said
        assert len(s.runner.motion) == 0
    assert s.run("motion gripper_move target=-1000")[0].startswith("motion gripper_move queued")


def test_the_manipulators_motion_type_is_not_offered(session):
    """motion lists only gripper_move; motion hare_path is refused with the gripper's types."""
    s = session
    listed = s.run("motion")
    assert any("gripper_move" in line for line in listed)
    assert not any("hare_path" in line for line in listed)
    said = s.run("motion hare_path target=1,2,3")[0]
    assert "not a motion type of gripper (it has gripper_move)" in said
    assert set(s.shell.completions()["motion"]) == {"gripper_move"}


def test_help_says_p_replaces_the_target_of_a_running_move(session):
    """help P tells that a P during a move replaces its target."""
    text = "\n".join(session.run("help P"))
    assert "replaces the target" in text and "mm" in text


def test_start_accepts_a_negative_hex_count(monkeypatch, capsys):
    """--start -0C00 is a value, not an option; the jaws start there."""
    monkeypatch.setattr(sys, "stdin", io.StringIO("sim\nquit\n"))
    assert main(["gripper", "--speed", "max", "--no-init", "--start", "-0C00"]) == 0
    assert "jaws -3072 counts" in capsys.readouterr().out


@pytest.mark.wallclock
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_sigterm_to_a_real_time_gripper_stops_the_jaws_and_exits_0(tmp_path, sig):
    """SIGTERM (or SIGINT) mid-move to `pyrt gripper` at real time: jaws stopped, drive current
    +0; exit 0 (SIGINT: 130, the status of an interrupted script)."""
    env = dict(os.environ, HOME=str(tmp_path), PYRT_HOME=str(tmp_path / "pyrt-home"),
               PYTHONUNBUFFERED="1")
    proc = subprocess.Popen([sys.executable, "-m", "pyrt", "gripper", "--speed", "1"],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env, cwd=tmp_path)
    try:
        seen = ""
        deadline = time.monotonic() + 30
        proc.stdin.write("P-1B86\nstatus\n")
        proc.stdin.flush()
        while ", moving, drive " not in seen:
            assert time.monotonic() < deadline, seen
            line = proc.stdout.readline()
            assert line, seen
            seen += line
        proc.send_signal(sig)
        # stdin stays open until the signal has ended the process: an EOF that a starved
        # process reads before its signal handler runs would end the script normally (0)
        proc.wait(timeout=60)
        out, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
    assert proc.returncode == (130 if sig == signal.SIGINT else 0), err
    last = out.strip().splitlines()[-1]
    assert f"pyrt gripper: {signal.Signals(sig).name}: every motor stopped; jaws at " in last
    assert last.endswith("drive current +0")
    assert "Traceback" not in err


def test_sim_fault_says_what_it_did():
    """sim fault jam|limit|encoder|port|none: one line each saying what was injected or cleared."""
    from pyrt.commands import RobotShell
    from pyrt.scheduler import Loop, SimClock
    from pyrt.station.gripper import build_gripper

    station = build_gripper(Loop(SimClock()))
    station.start()
    try:
        out = io.StringIO()
        shell = RobotShell(station, out)
        for line in ("sim fault jam", "sim fault limit", "sim fault encoder",
                     "sim fault port 2D 3F", "sim fault none"):
            shell.onecmd(line)
        assert out.getvalue().splitlines() == [
            "sim: motor jammed (the jaws do not move, whatever the drive); 'sim fault none' "
            "clears it",
            "sim: limit sensor dead (it never fires, even at the open stop); 'sim fault none' "
            "clears it",
            "sim: encoder dead (its count stays where it is); 'sim fault none' clears it",
            "sim: port 2D stuck at 3F",
            "sim: every injected fault cleared"]
        assert station.plant.faults == set()
    finally:
        station.shutdown()
