"""Small doors: numbers in ASCII digits only, a start-up that corrects at most a stated
amount, and a pattern error that never shows what the file holds."""

from __future__ import annotations

import io
import re
from pathlib import Path

import pytest

from pyrt.commands import RobotShell
from pyrt.component import Param
from pyrt.db import MAX_STARTUP_CORRECTION_CM, copy_station, load_station
from pyrt.errors import CommandError, ConfigError
from pyrt.robots.gripper_commands import parse_target
from pyrt.robots.pattern import parse_pattern, read_pattern
from pyrt.scheduler import Loop, SimClock
from pyrt.station.gripper import build_gripper
from pyrt.station.manipulator import ManipulatorStation
from pyrt.units import UnitError, parse_number, parse_quantity, parse_value

#: Digits of other scripts: Arabic-Indic, extended Arabic-Indic, Devanagari, fullwidth,
#: mathematical bold; and Python's extras the number grammar refuses.
FOREIGN = ["\u0663\u0660", "\u06f3\u06f0", "\u0969\u0966", "\uff13\uff10",
           "\U0001d7d1\U0001d7ce", "3\u0660", "1e\u0663"]


@pytest.mark.parametrize("digits", FOREIGN)
def test_the_number_grammar_takes_ascii_digits_only(digits):
    """parse_number, parse_value (with and without a unit) and parse_quantity refuse the
    digits of other scripts, which Python's float() would take as 30."""
    for parse in (parse_number, lambda t: parse_value(t, "mm"),
                  lambda t: parse_value(t + "mm", "mm"), lambda t: parse_quantity(t, "length")):
        with pytest.raises(UnitError):
            parse(digits)


def test_p_with_arabic_indic_digits_moves_nothing():
    """The gripper's ``P \u0663\u0660mm`` (30 mm in Arabic-Indic digits): refused, the target
    unchanged, nothing moved; ``P 30mm`` is taken."""
    st = build_gripper(Loop(SimClock()))
    out = io.StringIO()
    shell = RobotShell(st, out)
    st.runner.start()
    try:
        shell.onecmd("I")
        dac = st.controller.dac
        out.truncate(0)
        out.seek(0)
        shell.onecmd("P \u0663\u0660mm")
        assert "is not a hexadecimal number" in out.getvalue()
        assert st.controller.dac == dac and not st.busy()
        with pytest.raises(CommandError):
            parse_target("\u0663\u0660")
    finally:
        st.close()


@pytest.mark.parametrize("text", ["\u0660\u0664", "\uff10\uff14", "0x4", "0_4", "+4", " "])
def test_a_hexadecimal_parameter_takes_ascii_hex_digits_only(text):
    """A hex parameter (the gripper's RAM periods): other scripts' digits, 0x, 1_0 and a
    sign are refused, nothing changed."""
    p = Param("SYSCLKPD", "ticks", read=lambda: 4, write=lambda v: None, lo=1, hi=0xFF,
              hex=True)
    with pytest.raises(CommandError, match="is not a hexadecimal number"):
        p.parse("set gripper.SYSCLKPD", text)
    assert p.parse("set gripper.SYSCLKPD", "0C") == 12


# -- start-up corrections --------------------------------------------------------------


def _edit(path: Path, key: str, value: str, nth: int = 0) -> int:
    """Set the ``nth`` ``KEY:`` line of ``path`` to ``value``; its 1-based line number."""
    lines = path.read_text().splitlines(keepends=True)
    at = [i for i, ln in enumerate(lines) if ln.startswith(f"{key}:")][nth]
    lines[at] = f"{key}: {value} // by hand\n"
    path.write_text("".join(lines))
    return at + 1


def test_deadlength_minus_zero_is_refused_at_its_line(tmp_path):
    """``DEADLENGTH: -0`` (a sign slip) is refused naming the file and line."""
    d = copy_station("prototype", tmp_path / "p")
    line = _edit(d / "AXIS.dat", "DEADLENGTH", "-0")
    with pytest.raises(ConfigError) as err:
        load_station(d)
    assert (err.value.file, err.value.line) == (str(d / "AXIS.dat"), line)
    assert "-0" in err.value.message and "cannot be negative" in err.value.message


def test_a_startup_correction_beyond_the_limit_is_refused_naming_both_values(tmp_path):
    """DEADLENGTH 0 would move encoder0's ZEROLENGTH by some 453 cm at start-up: refused
    at ZEROLENGTH's line with the held and the new value, nothing written; writing the
    new value there (the confirmation the sentence names) starts normally."""
    d = copy_station("prototype", tmp_path / "p")
    _edit(d / "AXIS.dat", "DEADLENGTH", "0")
    before = {p.name: p.read_bytes() for p in d.glob("*.dat")}
    zl = load_station(d).encoder("encoder0").zerolength
    with pytest.raises(ConfigError) as err:
        ManipulatorStation(d, tick_ns=5_000_000)
    e = err.value
    lines = (d / "ENCODER.dat").read_text().splitlines()
    assert e.file == str(d / "ENCODER.dat") and lines[e.line - 1].startswith("ZEROLENGTH:")
    m = re.search(r"ZEROLENGTH (\d+\.\d+) cm: start-up would set it to (\d+\.\d+) cm .*"
                  r"a change of (-\d+\.\d+) cm, more than the (\d+) cm", e.message)
    assert m, e.message
    held, new, change, limit = (float(x) for x in m.groups())
    assert held == pytest.approx(zl, abs=1e-3) and abs(change) > 450
    assert limit == MAX_STARTUP_CORRECTION_CM and "nothing moved" in e.message
    assert "DEADLENGTH" in e.message
    assert {p.name: p.read_bytes() for p in d.glob("*.dat")} == before
    _edit(d / "ENCODER.dat", "ZEROLENGTH", f"{new:.3f}")  # the operator confirms it
    st = ManipulatorStation(d, tick_ns=5_000_000)
    st.close()


def test_a_small_startup_correction_is_made_and_said(tmp_path):
    """Within the limit (the packaged values' few cm) start-up corrects and says so."""
    d = copy_station("prototype", tmp_path / "p")
    st = ManipulatorStation(d, tick_ns=5_000_000)
    try:
        assert any("ZEROLENGTH" in n and "set to" in n for n in st.startup_notes)
    finally:
        st.close()


# -- patterns --------------------------------------------------------------------------


SECRET = "root:$6$salt$hashhashhash:19000:0:99999:7:::"


@pytest.mark.parametrize("second", [SECRET, "1 2 3 4", "1 2", "a b c", "nan 0 0",
                                    "\u0663\u0660 0 50", "1_0 0 50", "inf 0 0"])
def test_a_pattern_error_names_file_and_line_and_echoes_nothing(tmp_path, second):
    """Any file given as a pattern whose line 2 is not an endpoint: refused naming the file
    and line 2, and nothing of what the file holds is in the answer."""
    f = tmp_path / "passwd"
    f.write_text(f"first-line-{SECRET}\n{second}\n0 0 50\n")
    with pytest.raises(CommandError) as err:
        read_pattern(str(f))
    text = str(err.value)
    assert text.startswith(f"pattern {f}:2: expected an endpoint 'x y z'")
    for piece in (second, SECRET, "first-line", "hashhash", "\u0663"):
        assert piece not in text


def test_a_pattern_whose_log_cannot_be_written_does_not_echo_its_first_line(tmp_path):
    """Line 1 names the log; one that cannot be written is refused without showing it."""
    blocker = tmp_path / "not-a-dir"
    blocker.write_text("")
    f = tmp_path / "p.pat"
    f.write_text(f"not-a-dir/{SECRET}\n0 0 50\n")
    with pytest.raises(CommandError) as err:
        read_pattern(str(f))
    text = str(err.value)
    assert text.startswith(f"pattern {f}:1: cannot write the log file named on that line")
    assert SECRET not in text and "not-a-dir" not in text


def test_a_good_pattern_still_reads(tmp_path):
    """Endpoints with commas, comments and blank lines read as before."""
    f = tmp_path / "p.pat"
    f.write_text("p.log\n// a comment\n0, 0, 50\n\n1.5 -2 6e1 // trailing\n")
    log, points = parse_pattern(f)
    assert log == tmp_path / "p.log" and points == [(0.0, 0.0, 50.0), (1.5, -2.0, 60.0)]
