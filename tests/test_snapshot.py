"""Snapshots read a controller as it stands and leave it as it was."""

from __future__ import annotations

import gc
import json
import subprocess
import sys
from pathlib import Path

import pytest

from pyrt.db import copy_station
from pyrt.scheduler import Loop, SimClock
from pyrt.station import snapshot as sn
from pyrt.station.gripper import build_gripper
from pyrt.station.manipulator import ManipulatorStation


def _dict_backed(objects: list[object]) -> list[bool]:
    """For each object: whether its attributes are held in a dict (its only reference
    besides its class is a dict) rather than in its class's shared array of values."""
    return [[type(r) for r in gc.get_referents(o) if r is not type(o)] == [dict]
            for o in objects]


def _station_objects(station) -> list[object]:
    """Every object of pyrt's classes reachable from the station's snapshot hook."""
    found: dict[int, object] = {}
    todo = list(station._snapshot_objects().values()) if hasattr(
        station, "_snapshot_objects") else [c for c in station.components]
    while todo:
        o = todo.pop()
        if id(o) in found or type(o).__module__.split(".")[0] != "pyrt" \
                or isinstance(o, type) or not hasattr(type(o), "__dictoffset__") \
                or not type(o).__dictoffset__:
            continue
        found[id(o)] = o
        todo.extend(r for r in gc.get_referents(o) if r is not type(o))
    return list(found.values())


def _build(robot: str, tmp_path: Path):
    """A station of ``robot`` on virtual time, started, a few ticks in."""
    if robot == "gripper":
        st = build_gripper(Loop(SimClock()), boards="sim:")
    else:
        st = ManipulatorStation(copy_station("prototype", tmp_path / "prototype"),
                                tick_ns=5_000_000, boards="sim:")
    st.runner.start()
    st.runner.sleep(0.2)
    return st


@pytest.fixture(params=["gripper", "manipulator"])
def station(request, tmp_path):
    st = _build(request.param, tmp_path)
    yield st
    st.close()


#: Run in a fresh interpreter: whether a class's new objects keep their attributes in
#: its shared array of values depends on what the process did with the class before
#: (other tests), so the objects' state before the snapshot is known only there.
_FRESH = """
import json, sys
from pathlib import Path
sys.path.insert(0, sys.argv[1])
import test_snapshot as t
from pyrt.station.snapshot import take_snapshot
st = t._build(sys.argv[2], Path(sys.argv[3]))
try:
    objects = t._station_objects(st)
    before = t._dict_backed(objects)
    take_snapshot(st, [], [])
    take_snapshot(st, [], [])
    after = t._dict_backed(objects)
finally:
    st.close()
print(json.dumps({"n": len(objects), "before": before, "after": after}))
"""


def _state(st, through_dict: bool, monkeypatch) -> str:
    if through_dict:
        monkeypatch.setattr(sn, "_read", lambda v, cls: None)
    try:
        return json.dumps(st.snapshot_state(), default=sn._plain).replace("NaN", "null")
    finally:
        monkeypatch.undo()


@pytest.mark.parametrize("robot", ["gripper", "manipulator"])
def test_a_snapshot_leaves_every_object_s_attributes_where_they_were(robot, tmp_path):
    """Taking a snapshot turns no object's attributes into a dict (on CPython 3.11/3.12 a
    dict, once asked for, stays: every later attribute read of the object is slower)."""
    done = subprocess.run([sys.executable, "-c", _FRESH, str(Path(__file__).parent), robot,
                           str(tmp_path)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    seen = json.loads(done.stdout.strip().splitlines()[-1])
    assert seen["n"] > 5
    assert not all(seen["before"])
    assert seen["after"] == seen["before"]


def test_the_attributes_read_without_a_dict_are_those_the_dict_has(station, monkeypatch):
    """The state read from the objects' values is the state read through ``__dict__``,
    name for name and value for value."""
    without = json.loads(_state(station, False, monkeypatch))
    through = json.loads(_state(station, True, monkeypatch))
    assert without == through and len(json.dumps(without)) > 1000


class _Thing:
    limit = 0  # a class default that an instance shadows with the same value

    def __init__(self) -> None:
        self.a = 1.5
        self.b = [1, 2]
        self.limit = 0


def test_an_object_is_read_by_its_values_or_else_through_its_dict():
    """An object's attributes are found by the names its class's code uses (a class
    default it shadows included); one with an attribute no code names is left to
    ``__dict__`` (None), and a snapshot still holds all of it."""
    t = _Thing()
    assert sn._instance_attributes(t, _Thing) == {"a": 1.5, "b": [1, 2], "limit": 0}
    assert _dict_backed([t]) == [False]
    setattr(t, "zz_" + "unnamed", 3)  # a name no code of pyrt or of the class uses
    assert sn._instance_attributes(t, _Thing) is None
    assert _dict_backed([t]) == [False]


def test_c_memory_is_taken_at_the_snapshot_s_tick(tmp_path):
    """A kernel's C memory is copied when the snapshot is taken: what the kernel does
    after it is not in the snapshot's encoding."""
    import cffi

    ffi = cffi.FFI()
    mem = ffi.new("double[]", [1.0, 2.0, 3.0])
    enc = sn._Encoder("")
    got = enc._cdata(mem)
    mem[1] = 99.0
    assert json.loads(json.dumps({"m": got}, default=sn._plain)) == {"m": {"$cd": [1.0, 2.0, 3.0]}}


def test_c_memory_taken_in_a_snapshot_restores_as_taken_or_as_read_back():
    """The copy of a kernel's C memory restores into the kernel's memory both as the
    snapshot holds it in memory and as its encoding is read back."""
    import cffi

    ffi = cffi.FFI()
    mem = ffi.new("double[]", [1.0, 2.0, 3.0])
    got = sn._Encoder("")._cdata(mem)
    for held in (got, json.loads(json.dumps(got, default=sn._plain))):
        mem[0:3] = [0.0, 0.0, 0.0]
        assert sn._Decoder("").value(held, mem, "m") is mem
        assert list(mem) == [1.0, 2.0, 3.0]
