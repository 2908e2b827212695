"""docs/writing-a-robot.md stays current: every code excerpt it attributes to a file of the
example is still in that file, line for line and in order."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

PACKAGE_ROOT = Path(__file__).resolve().parents[1]
GUIDE = PACKAGE_ROOT.parents[1] / "docs" / "writing-a-robot.md"
_BLOCK = re.compile(r"```(?:python|toml)\n# ((?:pyrt_arm/)?[\w./]+\.(?:py|toml))\n(.*?)```", re.S)


def excerpts(text: str) -> list[tuple[str, list[str]]]:
    """(file, lines) of every code block that opens with ``# FILE``; ``...`` lines skip."""
    return [(m.group(1), m.group(2).splitlines()) for m in _BLOCK.finditer(text)]


def missing_lines(excerpt: list[str], source: list[str]) -> list[str]:
    """The excerpt's lines not found in ``source`` in order (each after the one before)."""
    at = 0
    missing = []
    for line in excerpt:
        if not line.strip() or line.strip() == "...":
            continue
        try:
            at = source.index(line.rstrip(), at) + 1
        except ValueError:
            missing.append(line)
    return missing


@pytest.mark.skipif(not GUIDE.exists(), reason="the guide lives in pyrt's repository")
def test_every_excerpt_of_the_guide_is_in_the_file_it_names():
    """Each code block of the guide headed '# pyrt_arm/X.py' or '# pyproject.toml' appears, line by line in order, in that file of examples/arm."""
    found = excerpts(GUIDE.read_text())
    assert len(found) >= 10
    stale = {}
    for name, lines in found:
        source = (PACKAGE_ROOT / name).read_text().splitlines()
        missing = missing_lines(lines, source)
        if missing:
            stale[name] = missing
    assert stale == {}


def test_the_checker_finds_a_changed_line():
    """A line that is not in the source, or out of order, is reported; '...' skips freely."""
    source = ["a = 1", "b = 2", "c = 3"]
    assert missing_lines(["a = 1", "...", "c = 3"], source) == []
    assert missing_lines(["c = 3", "a = 1"], source) == ["a = 1"]
    assert missing_lines(["a = 2"], source) == ["a = 2"]


#: What the guide spells like a pyrt name but is not one: an entry-point group, a log.
_NOT_PYTHON = {"pyrt.stations", "pyrt.motion_types", "pyrt.messages"}


def _is_module(name: str) -> bool:
    import importlib.util

    try:
        return importlib.util.find_spec(name) is not None
    except ModuleNotFoundError:  # a name below a module that is not a package
        return False


@pytest.mark.skipif(not GUIDE.exists(), reason="the guide lives in pyrt's repository")
def test_every_pyrt_name_the_guide_gives_is_public():
    """Each `pyrt.NAME...` the guide names is a public pyrt module, or a name in pyrt.__all__ (then its attributes resolve)."""
    import importlib

    import pyrt

    bad = []
    for dotted in sorted(set(re.findall(r"`(pyrt(?:\.[A-Za-z_]\w*)+)", GUIDE.read_text()))):
        if dotted in _NOT_PYTHON or dotted.endswith("__"):
            continue
        parts = dotted.split(".")
        k = len(parts)
        while k > 1 and not _is_module(".".join(parts[:k])):
            k -= 1  # the longest prefix that is a module
        module, rest = ".".join(parts[:k]), parts[k:]
        if any(p.startswith("_") for p in parts) or (
                module == "pyrt" and rest and rest[0] not in pyrt.__all__):
            bad.append(dotted)
            continue
        obj = importlib.import_module(module)
        if rest and module != "pyrt" and rest[0] not in getattr(obj, "__all__", ()):
            bad.append(dotted)
            continue
        for name in rest:
            if not hasattr(obj, name):
                bad.append(dotted)
                break
            obj = getattr(obj, name)
    assert bad == []


@pytest.mark.skipif(not GUIDE.exists(), reason="the guide lives in pyrt's repository")
def test_the_guides_session_is_what_the_arm_says():
    """The guide's session (a printf piped into pyrt arm --speed max -k) is, line for line, what the arm says, and its jam fails line 6 and the exit status."""
    import subprocess
    import sys

    text = GUIDE.read_text()
    m = re.search(r"^\$ printf '(?P<script>[^']*)' \| pyrt arm --speed max -k\n(?P<out>.*?)^```",
                  text, re.S | re.M)
    assert m, "no session in the guide"
    script = m["script"].replace("\\n", "\n")
    run = subprocess.run([sys.executable, "-m", "pyrt", "arm", "--speed", "max", "-k"],
                         input=script, text=True, capture_output=True, timeout=120)
    assert run.returncode == 1, run.stderr
    assert "stdin:6: 'wait' failed: FAULT" in run.stderr
    assert run.stdout.splitlines() == m["out"].splitlines()
