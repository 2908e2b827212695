"""The gripper's CMD: and monitor interpreters, through the runner, on a SimClock."""

from __future__ import annotations

import io
import re

import pytest
from _gripper_rig import make_rig

from pyrt.commands import RobotShell
from pyrt.commands.gripper import parse_hex, parse_target
from pyrt.errors import CommandError

TARGETS = [
    ("-1B86", -0x1B86), ("E47A", -0x1B86), ("e47a", -0x1B86), (" -1b86 ", -0x1B86),
    ("0", 0), ("0000", 0), ("-0", 0), ("D600", -0x2A00), ("8000", -0x8000), ("-8000", -0x8000),
    ("FFFF", -1), ("- 10", -0x10),
]
BAD_TARGETS = ["", "1234", "+1", "7FFF", "-8001", "10000", "XYZ", "-", "E4 7A", "0x10", "--1"]


@pytest.mark.parametrize(("text", "value"), TARGETS)
def test_parse_target(text, value):
    """P targets: two's complement or negative hex, both spellings the same count."""
    assert parse_target(text) == value


@pytest.mark.parametrize("text", BAD_TARGETS)
def test_parse_target_refuses(text):
    """Positive, oversized or malformed targets raise CommandError."""
    with pytest.raises(CommandError):
        parse_target(text)


def test_parse_hex_ranges():
    """Hex numbers are checked against their range and spelled back in the error."""
    assert parse_hex("7f", "address", 0x7F) == 0x7F
    for bad in ("80", "", "g1", "-1", "1 2"):
        with pytest.raises(CommandError):
            parse_hex(bad, "address", 0x7F)


@pytest.fixture
def session():
    rig = make_rig()
    runner = rig.runner
    out = io.StringIO()
    shell = RobotShell(rig.station, out)
    runner.start()
    shell.onecmd("I")

    def run(*lines: str) -> list[str]:
        out.seek(0)
        out.truncate()
        for line in lines:
            assert not shell.onecmd(line)
        return out.getvalue().splitlines()

    run.rig = rig
    run.shell = shell
    run.runner = runner
    yield run
    runner.stop()


def test_p_with_and_without_space_is_the_same_move(session):
    """P-1B86, PE47A and P E47A all set target E47A."""
    for cmd in ("P-1B86", "PE47A", "p e47a", "P -1B86"):
        session("P0000", "wait")
        assert session(cmd, "T") == ["E47A"]


def test_positive_target_refused_nothing_moves(session):
    """P 1234 prints one error line; the target stays and no drive current is applied."""
    lines = session("P 1234", "sleep 0.5", "T", "W")
    assert lines[0].startswith("error: target 1234 refused")
    assert lines[1:] == ["0000", "0000"]
    assert session.rig.board.dac == 0x80


def test_letters_with_stray_arguments_are_refused(session):
    """W 12 and S X are errors, not the W or S command."""
    assert session("W 12")[0].startswith("error: W takes no argument")
    assert session("sx")[0].startswith("error: S takes no argument")


def test_unknown_letter_is_one_error_line(session):
    """An unknown command prints one error line and changes nothing."""
    ram = bytes(session.rig.cpu.ram)
    assert len(session("Z")) == 1
    assert session("Z")[0].startswith("error: unknown command")
    assert bytes(session.rig.cpu.ram)[0x48:0x54] == ram[0x48:0x54]


def test_monitor_c_and_d_show_addr_value(session):
    """Monitor C 43 20 prints '43 20' and the task period really changes; D prints '43 20'."""
    assert session("M") == []
    assert session.shell.prompt == "* "
    assert session("C 43 20")[0] == "43 20"  # and a warning: 128 ms may oscillate
    assert session("D 43") == ["43 20"]
    assert session("N") == ["44 0A"]
    assert session.runner.call(lambda: session.rig.ctl.queue.routine("MVJAWS").period()) == 0x20


def test_monitor_bad_address_writes_nothing(session):
    """C 80 01, D 80 and C 43 G1 print one error line each; RAM unchanged."""
    session("M")
    ram = bytes(session.rig.cpu.ram[0x42:0x54])
    for cmd in ("C 80 01", "D 80", "C 43 G1", "C 43", "C 43 100", "D", "C 4301"):
        lines = session(cmd)
        assert len(lines) == 1 and lines[0].startswith("error:"), (cmd, lines)
    assert bytes(session.rig.cpu.ram[0x42:0x54]) == ram


def test_monitor_l_i_n_s_q(session):
    """The report's L example: I, L FBFE shows 2D FE, N shows 2E FB; S shows SP; Q back."""
    session("M")
    assert session("S") == ["SP 57"]
    assert session("I") == ["clock interrupt OFF (ready queue frozen)"]
    assert session("L FBFE") == ["2D FE"]
    assert session("N") == ["2E FB"]
    assert session.rig.board.leds == 0xFBFE
    lines = session("Q")
    assert "still OFF" in lines[0]
    assert session.shell.prompt == "CMD: "
    session("M", "I", "Q")
    assert session.rig.ctl.clock_enabled


def test_monitor_entered_at_sp(session):
    """Entering the monitor sets the address to SP: N shows the byte after it."""
    session("M")
    assert session("N") == ["58 00"]


def test_words_do_not_collide_with_letters(session):
    """stats, sim, sleep and wait are words; s alone is the S command."""
    assert session("s")[0] == "1111101111111111"
    assert session("stats")[0].startswith("tick 1000")
    assert session("sim")[0].startswith("jaws ")
    assert session("sleep 0.1") == []
    assert session("wait") == ["nothing to wait for: jaws idle"]


def test_sim_object_and_faults(session):
    """sim object 30 turns crossfire on (S bit 10 = 0); sim fault none clears faults."""
    assert session("sim object 30", "sleep 0.1", "S") == ["1111101011111111",
                                                          "on: limit, crossfire"]
    assert session("sim object 99")[0].startswith("error:")
    assert session("sim fault jam", "sim fault none") == [  # each says what it did
        "sim: motor jammed (the jaws do not move, whatever the drive); 'sim fault none' clears it",
        "sim: every injected fault cleared"]
    assert session("sim fault port 2D G1")[0].startswith("error:")
    assert session("sim jog sideways")[0].startswith("error:")


def test_dead_limit_i_enters_the_monitor(session):
    """With a dead limit sensor, I prints the failure and the prompt becomes '* '."""
    session("sim fault limit")
    lines = session("P -1000", "wait", "I")
    assert lines[-1].startswith("INIT FAILED")
    assert session.shell.prompt == "* "
    assert session.rig.board.dac == 0x80


def test_fault_is_reported_once_and_motion_refused_until_ack(session):
    """A fault comes back once at the next command; moves are refused until ack, then work again."""
    session.runner.call(lambda: session.rig.station.trip("test trip", source="test"))
    lines = session("W")
    assert lines[0].startswith("FAULT: test trip")
    assert "type ack" in lines[1]
    assert session("W") == ["0000"]  # reported once; reading still works
    lines = session("P -0100")
    assert lines[0].startswith("error:") and "ack" in lines[0]
    assert session.rig.board.dac == 0x80 and session("T") == ["0000"]
    assert session("ack")[0].startswith("fault acknowledged (test trip)")
    assert session("ack") == ["no fault to acknowledge"]
    session("P -0100", "wait")
    assert abs(int(session("W")[0], 16) - 0xFF00) <= 16


def test_help_lists_each_level(session):
    """help lists the CMD: letters and the words; in the monitor, the monitor letters."""
    text = "\n".join(session("help"))
    for letter in "CEIMPSTWX":
        assert f"\n  {letter}" in text
    assert "sleep SECONDS" in text
    session("M")
    text = "\n".join(session("help"))
    assert "C addr value" in text and "L pattern" in text
    assert session("help P")[0].startswith("error:")  # P is not a monitor letter
    session("Q")
    assert session("help P")[0].startswith("P target")


def test_wait_with_the_clock_off_says_so(session):
    """P with the clock interrupt off: wait explains instead of waiting in vain."""
    session("M", "I", "Q")
    lines = session("P -100", "wait")
    assert lines[-1].startswith("the clock interrupt is OFF")
    session("M", "I", "Q")
    assert session("wait")[0].startswith("at target")


def test_scope_records_the_gripper_variables(session):
    """scope add encoder dac, run roll, P: the frame shows the encoder going down."""
    assert session("scope add encoder dac sim.x ram:2C")[0].endswith("encoder, dac, sim.x, ram:2C")
    session("scope run roll", "P -400", "wait")
    lines = session("scope show 2000")
    assert lines[0] == "t_s encoder dac sim.x ram:2C"
    # the encoder as the console shows counts (hex, mm beside it), then dac as a number
    words = [line.split() for line in lines[1:]]
    assert all(re.fullmatch(r"\(\d+\.\d", w[2]) and w[3] == "mm)" for w in words)
    enc = [int(w[1], 16) - (0x10000 if int(w[1], 16) >= 0x8000 else 0) for w in words]
    dac = [float(w[4]) for w in words]
    assert enc[0] > enc[-1] and -0x400 - 16 <= enc[-1] <= -0x400 + 16
    assert min(dac) < 0x80 and dac[-1] == 0x80
    assert session("scope add nothing")[0].startswith("error: no channel")


def test_i_with_the_clock_off_is_refused_not_a_fault(session):
    """I while the clock interrupt is off: one error line, no fault, nothing moves."""
    session("M", "I", "Q")
    lines = session("I")
    assert lines == ["error: init needs the clock interrupt, which is off (monitor I): "
                     "M, I turns it on"]
    assert session.rig.loop.take_fault() is None and session.rig.board.dac == 0x80


def test_c_with_a_jammed_motor_enters_the_monitor(session):
    """C: the first init fails on a jammed motor, the message is printed, prompt '* '."""
    session("P -800", "wait", "sim fault jam")
    lines = session("C")
    assert lines[-1].startswith("INIT FAILED")
    assert session.shell.prompt == "* " and session.rig.board.dac == 0x80


def test_jog_through_sim_keeps_target_with_position(session):
    """sim jog close 0.5: the jaws close, T follows W, the current ends null."""
    lines = session("sim jog close 0.5", "sleep 1", "W", "T")
    w, t = (int(x, 16) - 0x10000 for x in lines)
    assert w < -200 and abs(w - t) < 60
    assert session.rig.board.dac == 0x80
