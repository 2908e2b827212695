"""The station contract is a lifecycle with a few hooks: at most 12, each listed in the guide."""

from __future__ import annotations

import inspect
from pathlib import Path

import pytest

import pyrt
from pyrt.station.base import Station
from pyrt.station.gripper import GripperStation
from pyrt.station.manipulator import ManipulatorStation

GUIDE = Path(pyrt.__file__).resolve().parent.parent / "docs" / "writing-a-robot.md"
#: A station's overridable hooks fit on one screen.
MAX_HOOKS = 12


def _members() -> dict[str, object]:
    """Every public method of Station and of its parts (the classes it is made of)."""
    out: dict[str, object] = {}
    for klass in reversed(Station.__mro__[:-1]):
        out.update({n: m for n, m in vars(klass).items()
                    if not n.startswith("_") and inspect.isfunction(m)})
    return out


def hooks() -> list[str]:
    """The public methods of Station not marked typing.final: what a station may override."""
    return [name for name, member in _members().items()
            if not getattr(member, "__final__", False)]


def _stations() -> list[type[Station]]:
    out: list[type[Station]] = [GripperStation, ManipulatorStation]
    try:
        from pyrt_arm.station import ArmStation
    except ImportError:  # the example arm is not installed
        return out
    return [*out, ArmStation]


def test_station_has_at_most_twelve_hooks():
    """Station has at most 12 overridable hooks; everything else is final."""
    found = hooks()
    assert 0 < len(found) <= MAX_HOOKS, found
    assert len(_members()) > 2 * len(found)  # the rest is there, marked final


@pytest.mark.skipif(not GUIDE.is_file(), reason="no docs/ in this tree")
def test_the_guide_lists_each_hook_on_one_line():
    """docs/writing-a-robot.md lists every hook, one line each ('* `name(...)`: ...'), and no other."""
    lines = GUIDE.read_text(encoding="utf-8").splitlines()
    listed = [ln for ln in lines if ln.startswith("* `") and "(" in ln.split("`")[1]]
    names = [ln.split("`")[1].split("(")[0] for ln in listed]
    hook_lines = [n for n in names if n in hooks()]
    assert sorted(hook_lines) == sorted(hooks())  # each once
    # the list is the hooks' own: a line of it that names no hook is a stale one
    start = lines.index(next(ln for ln in listed if ln.split("`")[1].split("(")[0] in hooks()))
    block = []
    for ln in lines[start:]:
        if not ln.startswith("* `"):
            break
        block.append(ln.split("`")[1].split("(")[0])
    assert sorted(block) == sorted(hooks())


@pytest.mark.parametrize("cls", _stations(), ids=lambda c: c.__name__)
def test_the_stations_override_only_hooks(cls):
    """Every built-in station (and the example arm) overrides hooks only, never a final member."""
    overridden = [n for n, m in vars(cls).items()
                  if not n.startswith("_") and callable(m) and n in _members()]
    assert set(overridden) <= set(hooks()), set(overridden) - set(hooks())
