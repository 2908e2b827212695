"""One radix per view: the gripper's positions in hex counts with mm beside them, in every console view."""

from __future__ import annotations

import io
import re

import pytest

from pyrt.commands import RobotShell
from pyrt.scheduler import Loop, SimClock
from pyrt.station.gripper import build_gripper

HEX_MM = r"[0-9A-F]{4} \(\d+\.\d mm\)"


@pytest.fixture
def run():
    station = build_gripper(Loop(SimClock()))
    station.start()
    out = io.StringIO()
    shell = RobotShell(station, out)

    def go(*lines: str) -> list[str]:
        out.seek(0)
        out.truncate()
        for line in lines:
            shell.onecmd(line)
        return out.getvalue().splitlines()

    go("I")
    yield go
    station.close()


def test_status_object_shows_positions_in_hex_with_mm(run):
    """status gripper gives encoder, target and old_enc as the letters do (hex) with mm beside them."""
    said = run("P E47A", "sleep 2", "status gripper")
    for name in ("encoder", "target", "old_enc"):
        line = next(ln for ln in said if ln.startswith(f"gripper.{name} = "))
        assert re.fullmatch(rf"gripper\.{name} = {HEX_MM}", line), line
    assert "gripper.target = E47A (26.2 mm)" in said


def test_scope_show_uses_the_same_radix(run):
    """scope show prints the gripper's counts in hex with mm; other channels as numbers."""
    said = run("scope add encoder target gripper.rate", "scope run roll", "P E47A", "sleep 0.5",
               "scope show 2")
    rows = said[-2:]
    for row in rows:
        assert re.fullmatch(rf"\d+\.\d{{6}} {HEX_MM} E47A \(26\.2 mm\) -?\d+", row), row


def test_status_line_reads_hex_with_mm(run):
    """The status line gives position and target in hex with mm, as status OBJECT does."""
    said = run("P E47A", "sleep 2", "status")
    assert re.match(rf"position {HEX_MM}, target E47A \(26\.2 mm\)", said[-1])
