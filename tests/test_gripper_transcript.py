"""The whole command set piped through `pyrt gripper --speed max`, as a script."""

from __future__ import annotations

import io
import os
import re
import sys

import pytest

from pyrt.cli import main

SCRIPT = """\
W
T
E
P-1B86
wait
W
T
E
P 0800
PE47A
wait
T
p -0800
wait
W
P D800
wait
W
P0
wait
sim object 30
sleep 0.2
S
P D600
wait
S
X 33
T
M
D 43
C 43 20
N
S
I
L FBFE
N
D 2E
I
C 80 00
Q
sim object none
C
W
quit
"""


def run_cli(argv: list[str], script: str, monkeypatch, capsys, status: int = 0) -> str:
    monkeypatch.setattr(sys, "stdin", io.StringIO(script))
    assert main(argv) == status
    return capsys.readouterr().out


def answers(out: str) -> dict[str, list[str]]:
    """Map each echoed command line to the lines printed after it."""
    result: list[tuple[str, list[str]]] = []
    for line in out.splitlines():
        m = re.match(r"^(CMD: |\* )(.*)$", line)
        if m:
            result.append((m.group(2), []))
        elif result:
            result[-1][1].append(line)
    return result


def hexword(s: str) -> int:
    v = int(s, 16)
    return v - 0x10000 if v & 0x8000 else v


def test_whole_command_set_transcript(monkeypatch, capsys):
    """Every CMD: and monitor command in one piped script, with the report's formats."""
    # the script refuses some lines on purpose: -k runs it to its end, status 1
    out = run_cli(["gripper", "--speed", "max", "-k"], SCRIPT, monkeypatch, capsys, status=1)
    assert out.splitlines()[1] == "jaws wide open (limit sensor on), encoder 0000"
    steps = answers(out)
    got = iter(steps)

    def nxt(cmd: str) -> list[str]:
        c, lines = next(got)
        assert c == cmd, (c, cmd)
        return lines

    assert nxt("W") == ["0000"]
    assert nxt("T") == ["0000"]
    assert nxt("E") == ["0080"]
    assert nxt("P-1B86") == []
    assert nxt("wait")[0].startswith("at target: position")
    assert abs(hexword(nxt("W")[0]) + 0x1B86) <= 16
    assert nxt("T") == ["E47A"]
    e = nxt("E")[0]
    assert len(e) == 4 and abs(int(e, 16) - 0x80) <= 16
    assert nxt("P 0800")[0].startswith("error: target 0800 refused")
    assert nxt("PE47A") == []
    nxt("wait")
    assert nxt("T") == ["E47A"]
    assert nxt("p -0800") == []
    nxt("wait")
    assert abs(hexword(nxt("W")[0]) + 0x0800) <= 16
    nxt("P D800")
    nxt("wait")
    assert abs(hexword(nxt("W")[0]) - hexword("D800")) <= 16
    nxt("P0")
    nxt("wait")
    assert nxt("sim object 30") == []
    nxt("sleep 0.2")
    s = nxt("S")[0]
    # Appendix A: 2E.0 crossfire (bit 8), 2E.1 overload (bit 9), 2E.2 limit (bit 10)
    assert len(s) == 16 and s[15 - 8] == "0" and s[15 - 9] == "1"  # crossfire on, no overload
    nxt("P D600")
    nxt("wait")
    s = nxt("S")[0]
    assert s[15 - 8] == "0" and s[15 - 9] == "0"  # squeezed: overload on
    assert s[15 - 10] == "1"  # limit off: the jaws are nearly closed
    assert s[15 - 0] == "0" and s[15 - 4] == "0"  # inner proximity sensors on
    assert nxt("X 33") == [
        "speed 7F -> 33: JSPEED 33, MXPJSPD B3, MXNJSPD 4D (up to 860 counts/s)"]
    assert nxt("T") == ["D600"]
    assert nxt("M") == []
    assert nxt("D 43") == ["43 0C"]
    assert nxt("C 43 20")[0] == "43 20"  # with a warning: MVJAWS 128 ms may oscillate
    assert nxt("N") == ["44 0A"]
    assert nxt("S") == ["SP 57"]
    assert nxt("I") == ["clock interrupt OFF (ready queue frozen)"]
    assert nxt("L FBFE") == ["2D FE"]
    assert nxt("N") == ["2E FB"]
    assert nxt("D 2E") == ["2E FB"]  # frozen: SENSORS does not overwrite it
    assert nxt("I") == ["clock interrupt ON"]
    assert nxt("C 80 00")[0].startswith("error: address 80")
    assert nxt("Q") == []
    nxt("sim object none")
    c = nxt("C")
    assert len(c) == 1 and re.fullmatch(r"[0-9A-F]{4}", c[0])
    assert -0x2A00 - 300 < hexword(c[0]) < -0x2A00 + 50  # about D600, a little more
    assert nxt("W") == ["0000"]
    assert nxt("quit") == ["pyrt gripper: quit: every motor stopped; jaws at 0000 (76.0 mm), "
                           "drive current +0"]


def mvjaws_calls(lines: list[str]) -> int:
    for line in lines:
        if line.startswith("MVJAWS"):
            return int(line.split()[1])
    raise AssertionError(f"no MVJAWS line in {lines}")


def test_c_43_changes_the_jaw_move_rate(monkeypatch, capsys):
    """Monitor C 43 30 makes MVJAWS run a quarter as often (stats over 4.8 s)."""
    script = "stats\nsleep 4.8\nstats\nM\nC 43 30\nQ\nsleep 1\nstats\nsleep 4.8\nstats\nquit\n"
    out = run_cli(["gripper", "--speed", "max", "--no-init"], script, monkeypatch, capsys)
    stats = [lines for cmd, lines in answers(out) if cmd == "stats"]
    fast = mvjaws_calls(stats[1]) - mvjaws_calls(stats[0])
    slow = mvjaws_calls(stats[3]) - mvjaws_calls(stats[2])
    assert fast == pytest.approx(4800 / (4 * 0x0C), abs=1)
    assert slow == pytest.approx(4800 / (4 * 0x30), abs=1)


def test_script_output_is_deterministic(monkeypatch, capsys):
    """At --speed max the same script prints the same transcript twice."""
    script = "P-1000\nwait\nW\nE\nS\nquit\n"
    a = run_cli(["gripper", "--speed", "max"], script, monkeypatch, capsys)
    b = run_cli(["gripper", "--speed", "max"], script, monkeypatch, capsys)
    assert a == b


def test_dead_limit_at_power_up_lands_in_the_monitor(monkeypatch, capsys):
    """--fault limit: the power-up I fails, prints why, and the first prompt is '* '."""
    out = run_cli(["gripper", "--speed", "max", "--fault", "limit"], "D 2C\nQ\nquit\n",
                  monkeypatch, capsys)
    lines = out.splitlines()
    assert lines[1].startswith("INIT FAILED: jaws stopped before the limit sensor fired")
    assert lines[2].startswith("* D 2C")
    assert int(lines[3].split()[1], 16) & 0x08 == 0  # drive bit clear


def test_end_of_input_ends_the_program(monkeypatch, capsys):
    """A script without quit ends at end of input with status 0, saying the motors stopped."""
    out = run_cli(["gripper", "--speed", "max", "--no-init"], "W\n", monkeypatch, capsys)
    assert out.rstrip().endswith("CMD: \npyrt gripper: end of input: every motor stopped; "
                                 "jaws at 0000 (76.0 mm), drive current +0")


def test_bad_options_are_one_line_errors(monkeypatch, capsys):
    """--object wider than the jaws is a one-line error, exit status 1."""
    monkeypatch.setattr(sys, "stdin", io.StringIO(""))
    assert main(["gripper", "--speed", "max", "--object", "200"]) == 1
    assert "object width" in capsys.readouterr().err


def test_terminal_session_with_pexpect():
    """The real `pyrt gripper` on a terminal: prompt, command, answer, quit."""
    pexpect = pytest.importorskip("pexpect")
    env = dict(os.environ, PROMPT_TOOLKIT_NO_CPR="1", TERM="xterm")
    child = pexpect.spawn(
        sys.executable, ["-m", "pyrt", "gripper", "--speed", "max"], encoding="utf-8",
        timeout=20, dimensions=(24, 120), env=env,
    )
    try:
        child.expect("CMD:")
        child.sendline("W")
        child.expect("0000")
        child.expect("CMD:")
        child.sendline("M")
        child.expect(r"\*")
        child.sendline("D 43")
        child.expect("43 0C")
        child.sendline("Q")
        child.expect("CMD:")
        child.sendline("quit")
        child.expect(pexpect.EOF)
    finally:
        child.close()
    assert child.exitstatus == 0
