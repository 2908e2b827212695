"""Help that tells the truth: summaries, ranges, help OBJECT VERB, plain --help text, banners."""

from __future__ import annotations

import argparse
import io
import os
import re
import subprocess
import sys

import pytest
from _manipulator_rig import make_station

from pyrt.cli import build_parser
from pyrt.commands import RobotShell
from pyrt.component import first_paragraph, plain_text
from pyrt.scheduler import Loop, SimClock
from pyrt.station.gripper import build_gripper
from pyrt.station.urdf import URDF


@pytest.fixture(scope="module")
def manip(tmp_path_factory):
    station, _runner = make_station(tmp_path_factory.mktemp("help"))
    yield station
    station.close()


def ask(station, line: str) -> str:
    out = io.StringIO()
    RobotShell(station, out).onecmd(line)
    return out.getvalue()


def test_to_shows_the_range_of_its_coordinates(manip):
    """help prototype shows the x, y, z ranges of 'to' (the position signals' display range)."""
    text = ask(manip, "help prototype")
    line = next(ln for ln in text.splitlines() if ln.strip().startswith("to x y z"))
    lim = manip.polyaxis.position_limits(2)
    assert f"z {lim.lopr:g}..{lim.hopr:g} cm" in line
    assert "x " in line.split("[", 1)[1]


def test_summaries_are_whole_sentences(manip):
    """setpos and survey show their whole first paragraph, not a line cut mid-sentence."""
    text = ask(manip, "help prototype")
    setpos = next(ln for ln in text.splitlines() if "setpos" in ln)
    survey = next(ln for ln in text.splitlines() if "survey" in ln)
    assert "moves are allowed again" in setpos
    assert survey.rstrip().endswith("encoder re-zeroed.")


def test_help_object_verb_and_word_sub(manip):
    """help prototype to gives the verb's whole help; help scope trigger the sub-command's."""
    to = ask(manip, "help prototype to")
    assert "no help" not in to and "'blend' joins the turn" in to and "Range:" in to
    trig = ask(manip, "help scope trigger")
    assert trig.startswith("scope trigger CH LEVEL") and "pre-trigger" in trig
    bad = ask(manip, "help prototype nosuch")
    assert bad.startswith("error: help prototype: no command 'nosuch'")


def test_help_object_verb_names_the_object_once(manip):
    """help OBJECT VERB starts with the object's name once, whether or not the verb's help names it."""
    assert ask(manip, "help prototype to").startswith("prototype to x y z")
    station = URDF.build(Loop(SimClock()), argparse.Namespace(boards=None, urdf=None, start=None))
    try:
        text = ask(station, "help puma560 movej")
    finally:
        station.close()
    assert text.startswith("puma560 movej Q1") and "puma560 puma560" not in text


def test_first_paragraph_and_plain_text():
    """first_paragraph joins the first paragraph and drops reST markup; the Range line is not in it."""
    doc = "a ``b`` c:\nd :class:`~pyrt.x.Y` e.\n\nmore\n"
    assert first_paragraph(doc) == "a b c: d Y e."
    assert first_paragraph("one.\nRange: X 1..2.") == "one."
    assert plain_text(":meth:`pyrt.a.b`") == "pyrt.a.b"


def test_no_rest_markup_in_any_help():
    """No --help of any pyrt command shows reST double backticks."""
    parser = build_parser()
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    texts = [parser.format_help(), *(p.format_help() for p in sub.choices.values())]
    assert len(texts) > 5
    for text in texts:
        assert "``" not in text and ":class:`" not in text


def _start_help(text: str) -> str:
    flat = " ".join(text.split())
    return flat[flat.index("--start HEX jaw"):][:300]


def test_start_default_is_written_one_way():
    """--start's default is F400 in pyrt gripper's help and in board-sim gripper's, and only that."""
    parser = build_parser()
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    here = _start_help(sub.choices["gripper"].format_help())
    proc = subprocess.run([sys.executable, "-m", "pyrt", "board-sim", "gripper", "--help"],
                          capture_output=True, text=True, timeout=60)
    there = _start_help(proc.stdout)
    for text in (here, there):
        assert "default F400" in text and "0C00 (the default" not in text
        assert "F400 (the default" not in text


def test_manipulator_help_lists_every_shell_word(tmp_path):
    """The manipulator's --help names every word its console takes."""
    parser = build_parser()
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    text = " ".join(sub.choices["manipulator"].format_help().split())
    words_part = text[text.index("plus the shared words"):][:400]
    station = build_gripper(Loop(SimClock()))
    try:
        words = [w.name for w in RobotShell(station, io.StringIO()).words()]
    finally:
        station.close()
    for w in words:
        assert re.search(rf"\b{w}\b", words_part), w


def test_headless_banner_does_not_say_type_help(tmp_path):
    """A headless run's banner says there is no console instead of 'type help'."""
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen([sys.executable, "-m", "pyrt", "gripper", "--speed", "max",
                             "--serve", "127.0.0.1:0", "--headless"],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env,
                            cwd=tmp_path)
    try:
        assert proc.stdout is not None
        first = ""
        while not first.startswith("pyrt gripper:"):
            line = proc.stdout.readline()
            assert line, first
            first = line
    finally:
        proc.terminate()
        proc.wait(timeout=30)
    assert first.startswith("pyrt gripper:"), first
    assert "type help" not in first and "headless: no console" in first


def test_help_and_the_usage_error_give_the_same_words_for_choices(manip):
    """Where a command takes a choice ('to x y z [blend|stop]'), its help line names the
    choices exactly as the usage in its refusal does."""
    for comp in manip.components():
        for rec in comp.commands():
            head = rec.help.split(":")[0].strip()
            if "|" in rec.usage and head.split()[:1] == [rec.name]:
                assert head == rec.usage, (comp.name, head, rec.usage)
    text = ask(manip, "help prototype")
    assert any(ln.strip().startswith("to x y z [blend|stop]: ") for ln in text.splitlines())
    assert "usage: to x y z [blend|stop]" in ask(manip, "prototype to 1 2")


def test_quit_with_an_argument_is_refused_without_suggesting_quit(manip):
    """'quit now': quit takes no argument; the answer does not ask 'did you mean quit?'."""
    said = ask(manip, "quit now")
    assert said == "error: quit takes no argument (got 'now')\n"
    assert "did you mean" not in ask(manip, "wait x")
    assert "did you mean 'wait'" in ask(manip, "wiat")
