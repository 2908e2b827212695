"""Properties of the gripper console: any input, no crash, no stray write, no stalled current."""

from __future__ import annotations

import io

from _gripper_rig import MS, make_rig
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pyrt.commands import RobotShell
from pyrt.commands.gripper import parse_target
from pyrt.console import Console
from pyrt.errors import CommandError

#: Current on a motor that does not move: never longer than the watchdog's limit.
STALL_BOUND_NS = 1000 * MS + 2 * MS

HEX = st.text("0123456789ABCDEFabcdef", max_size=5)
ARG = st.one_of(
    HEX,
    st.builds(lambda a, b: f"{a} {b}", HEX, HEX),
    st.builds(lambda a: f"-{a}", HEX),
    st.text(" -+0123456789ABCDEFGXZabcxyz.", max_size=8),
)
LETTER_LINE = st.builds(
    lambda letter, space, arg: f"{letter}{space}{arg}",
    st.sampled_from("CDEIJLMNPQSTWXcdeilmnpqstwx?1 "),
    st.sampled_from(["", " ", "  "]),
    ARG,
)
MONITOR_POKE = st.builds(
    lambda addr, value: f"C {addr:02X} {value:02X}",
    st.integers(0, 0x7F), st.integers(0, 0xFF),
)
WORD_LINE = st.sampled_from([
    "wait", "wait 2", "sleep 0.3", "sleep 2", "stats", "sim", "help", "help P", "sim jog open 0.3",
    "sim jog close 0.5", "sim jog close", "sim jog off", "sim fault jam", "sim fault limit",
    "sim fault encoder", "sim fault port 2E 00", "sim fault none", "sim object 20",
    "sim object none", "M", "Q", "I", "P D600", "P-0800", "X 10", "x 7f", "C 43 FF", "C 42 01",
])
LINES = st.lists(st.one_of(LETTER_LINE, MONITOR_POKE, WORD_LINE), max_size=10)


def session():
    rig = make_rig()
    runner = rig.runner
    out = io.StringIO()
    shell = RobotShell(rig.station, out)
    runner.start()
    shell.onecmd("I")
    return rig, runner, shell, out


def check(rig, runner, out) -> None:
    runner.sleep(6.0)  # whatever was started runs on, into a stop if it is headed there
    assert len(rig.cpu.ram) == 128
    assert rig.stall.worst_ns <= STALL_BOUND_NS, rig.stall.worst_ns
    assert "internal error" not in out.getvalue(), out.getvalue()


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(LINES)
def test_command_grammar_never_crashes_or_stalls(lines):
    """Any sequence of commands: no crash, RAM stays 128 bytes, no stalled current > 1 s."""
    rig, runner, shell, out = session()
    for line in lines:
        assert shell.onecmd(line) is False
    check(rig, runner, out)
    runner.stop()


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.binary(max_size=160))
def test_raw_bytes_never_crash_the_console(data):
    """Raw bytes piped into the console: it runs to end of input, nothing breaks; its status
    is 1 exactly when a line failed."""
    rig, runner, shell, out = session()
    text = data.decode("latin-1").replace("quit", "q")
    console = Console(shell, io.StringIO(text), out, messages=runner.messages)
    assert console.run() == (1 if console.failed else 0)
    check(rig, runner, out)
    runner.stop()


@settings(max_examples=200, deadline=None)
@given(st.integers(-0x8000, 0))
def test_both_target_spellings_agree(count):
    """Every non-positive count reads the same as 4-digit two's complement or as -hex."""
    assert parse_target(f"{count & 0xFFFF:04X}") == count
    assert parse_target(f"-{-count:X}") == count
    assert parse_target(f"p{count & 0xFFFF:04x}"[1:]) == count


@settings(max_examples=200, deadline=None)
@given(st.integers(1, 0x7FFF))
def test_positive_targets_are_always_refused(count):
    """A positive target never parses: encoder counts are never positive."""
    for text in (f"{count:X}", f"{count:04X}", f"+{count:X}"):
        try:
            parse_target(text)
        except CommandError:
            continue
        raise AssertionError(f"{text} was accepted")
