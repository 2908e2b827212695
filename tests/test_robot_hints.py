"""Hints that do not mislead: did you mean, the gripper's prompt typed, --fifo on --speed max, overrun lines, the DAQ transcript's wait."""

from __future__ import annotations

import argparse
import io
import re
from pathlib import Path

import pytest
from _manipulator_rig import make_station

from pyrt.cli import _loopopts
from pyrt.commands import RobotShell
from pyrt.scheduler import Loop, SimClock
from pyrt.scheduler.loop import overrun_line
from pyrt.station.gripper import build_gripper

DAQ_DOC = Path(__file__).resolve().parent.parent / "docs" / "daq.md"


@pytest.fixture(scope="module")
def gripper():
    station = build_gripper(Loop(SimClock()))
    station.start()
    yield station
    station.close()


def ask(station, *lines: str) -> list[str]:
    out = io.StringIO()
    shell = RobotShell(station, out)
    for line in lines:
        shell.onecmd(line)
    return out.getvalue().splitlines()


def test_typos_get_did_you_mean(tmp_path):
    """'prototyp', 'wiat', 'help prototyp' and a mistyped verb name the near miss; nothing runs."""
    station, _runner = make_station(tmp_path)
    try:
        said = ask(station, "prototyp", "wiat", "help prototyp", "prototype tensons")
    finally:
        station.close()
    assert said[0].startswith("error: unknown command or object 'prototyp' "
                              "(did you mean 'prototype'?)")
    assert "(did you mean 'wait'?)" in said[1]
    assert said[2] == "error: no help for 'prototyp' (did you mean 'prototype'?)"
    assert "(did you mean 'tensions'" in said[3]


def test_gripper_typo_of_a_word_is_named(gripper):
    """'wiat' at CMD: (W with an argument) says which word was meant."""
    said = ask(gripper, "wiat")
    assert said == ["error: W takes no argument (got 'iat') (did you mean 'wait'?)"]


def test_the_prompt_typed_is_named_as_the_prompt(gripper):
    """Typing CMD (or CMD:) at the gripper says it is the prompt, not 'C takes no argument'."""
    said = ask(gripper, "CMD", "cmd: P100")
    assert len(said) == 2
    for line in said:
        assert "is the prompt, not a command" in line and "C takes no argument" not in line
        assert "C E I M P S T W X" in line


def test_fifo_is_not_applied_at_speed_max(monkeypatch):
    """--fifo on a --speed max run is skipped with a line saying why; at real time it is applied."""
    calls: list[int] = []
    monkeypatch.setattr(_loopopts._rt, "set_fifo", lambda p: calls.append(p) or f"fifo {p}")
    said: list[str] = []
    args = argparse.Namespace(speed=None, fifo=50, timer_slack=None, mlock=False)
    _loopopts.apply_rt_options(args, said.append)
    assert calls == [] and len(said) == 1
    assert said[0].startswith("--fifo 50 not applied: with --speed max")
    said.clear()
    _loopopts.apply_rt_options(argparse.Namespace(speed=1.0, fifo=50, timer_slack=None,
                                                  mlock=False), said.append)
    assert calls == [50] and said == ["fifo 50"]


def test_overrun_line_never_says_zero_ms():
    """A worst overrun under 0.01 ms is given in µs; longer ones in ms."""
    assert "worst 4.2 µs over" in overrun_line(3, 4_200, 17)
    assert "worst 0.00 ms" not in overrun_line(1, 1, 5)
    assert "worst 1.50 ms over at tick 9" in overrun_line(1, 1_500_000, 9)


def test_daq_transcript_shows_what_wait_answers(gripper):
    """The DAQ transcript (docs/daq.md) gives wait's answer in the form the gripper gives it now."""
    said = ask(gripper, "I", "P E47A", "wait")[-1]
    shape = re.sub(r"[0-9A-F]{4}", "HHHH", re.sub(r"-?\d+\.\d", "N.N", said))
    shape = re.sub(r"error [-+]?\d+", "error E", shape)
    text = DAQ_DOC.read_text(encoding="utf-8")
    after_wait = text[text.index("C: wait\n"):]
    answer = next(ln[len("S: OK "):] for ln in after_wait.splitlines()
                  if ln.startswith("S: OK "))
    got = re.sub(r"[0-9A-F]{4}", "HHHH", re.sub(r"-?\d+\.\d", "N.N", answer))
    got = re.sub(r"error [-+]?\d+", "error E", got)
    assert got == shape, (answer, said)
