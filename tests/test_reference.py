"""The shipped station reference (docs/reference.md) is what the records say now."""

from __future__ import annotations

from pathlib import Path

from pyrt.cli import main
from pyrt.cli.reference import reference

DOC = Path(__file__).resolve().parents[1] / "docs" / "reference.md"
BUILT_IN = ["gripper", "manipulator"]


def test_the_shipped_reference_is_current(capsys):
    """pyrt reference --check: docs/reference.md is the reference generated from the records."""
    status = main(["reference", *BUILT_IN, "--check", str(DOC)])
    assert status == 0, capsys.readouterr().err


def test_the_reference_lists_every_command_and_signal_with_ranges():
    """Every object, command record and signal of both stations is in the reference, ranges too."""
    text = reference(BUILT_IN)
    for needle in ("### `gripper`", "### `monitor`", "### `prototype`", "### `axis0`",
                   "### `axis0Motor`", "`P target ...`", "`to x y z", "| `tension` | N; 0..",
                   "LOLO", "`hare_path`", "`gripper_move`", "`wait [ARGS ...]`"):
        assert needle in text, needle


def test_a_stale_reference_is_reported(tmp_path, capsys):
    """--check on a file that differs exits 1 and says how to write it again."""
    stale = tmp_path / "reference.md"
    stale.write_text("# old\n", encoding="utf-8")
    assert main(["reference", "gripper", "--check", str(stale)]) == 1
    assert "is not current" in capsys.readouterr().err
