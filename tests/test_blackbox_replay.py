"""A black box replays: its snapshot of the controller lets pyrt replay resume mid-run."""

from __future__ import annotations

import io
import json
import re
import subprocess
import sys
import zlib
from pathlib import Path

import numpy as np
import pytest
from _manipulator_rig import TICK_NS
from _replay_rig import assert_each_snapshot_replays

from pyrt.cli import main
from pyrt.commands import RobotShell
from pyrt.db import copy_station
from pyrt.journal import JournalReader
from pyrt.journal.format import HEADER_SIZE, KIND_SNAPSHOT, frame, snapshot_payload
from pyrt.scheduler import Loop, SimClock
from pyrt.station.gripper import build_gripper
from pyrt.station.manipulator import ManipulatorStation
from pyrt.station.recording import Recorder
from pyrt.station.snapshot import (
    SNAPSHOT_FORMAT,
    Snapshot,
    SnapshotError,
    compress_snapshot,
    decompress_snapshot,
    plain_state,
    restore_into,
    state_of,
    take_snapshot,
)

#: A bound only a hang reaches (a recorded run on virtual time takes seconds).
HANG_S = 600


def _pyrt(tmp_path: Path, stdin: str, *argv: str, status: int) -> str:
    done = subprocess.run([sys.executable, "-m", "pyrt", *argv], input=stdin,
                          capture_output=True, text=True, cwd=tmp_path, timeout=HANG_S)
    assert done.returncode == status, done.stdout + done.stderr
    return done.stdout


def _replay(path: Path, capsys) -> tuple[int, str, str]:
    status = main(["replay", str(path)])
    out, err = capsys.readouterr()
    return status, out, err


def _box(directory: Path) -> Path:
    (pj,) = directory.glob("*-fault-*.pj")
    return pj


def _check_identical(pj: Path, capsys) -> None:
    """The black box replays identically from its snapshot through the fault."""
    reader = JournalReader(pj)
    (snap_tick, _data), = reader.snapshots
    fault = next(t.tick for t in reader.ticks() for e in t.events if e.name == "fault")
    summary = reader.summary()
    assert summary.first_tick <= snap_tick < fault <= summary.last_tick
    assert snap_tick > int(reader.header.metadata["tick_index"])  # it starts mid-run
    status, out, err = _replay(pj, capsys)
    assert status == 0, out + err
    assert f"replayed {summary.last_tick - snap_tick + 1} ticks (ticks {snap_tick}.." \
           f"{summary.last_tick}), identical" in out


# -- both robots, end to end ------------------------------------------------------------------


def test_a_gripper_black_box_replays_its_fault_identically(tmp_path, capsys):
    """A gripper on virtual time, a fault (the move supervision) after several seconds of
    moves: its black box replays from its snapshot to the fault and after, identical."""
    _pyrt(tmp_path, "P 30mm\nwait\nP 10mm\nwait\nP 40mm\nwait\nM\nC 45 30\nQ\nP 20mm\nwait\n",
          "gripper", "--speed", "max", "--black-box", "3", status=1)
    _check_identical(_box(tmp_path), capsys)


def test_a_manipulator_black_box_replays_its_fault_identically(tmp_path, capsys):
    """A manipulator on virtual time, a stalled motor tripping the tracking fault after two
    moves: its black box (beside the databases) replays identically from its snapshot."""
    db = tmp_path / "db"
    _pyrt(tmp_path, "prototype to 0 0 60\nwait\nprototype to 10 0 80\nwait\n"
          "sim fault axis0 stall\nprototype to 0 0 93\nwait\n",
          "manipulator", "--speed", "max", "--black-box", "8", "--init-db", str(db), status=1)
    _check_identical(_box(db), capsys)


def test_a_station_without_a_snapshot_is_refused_by_name(tmp_path, capsys):
    """A station that has no snapshot hook (the example arm) writes a black box that says so,
    and pyrt replay refuses it with that reason, naming the station."""
    pytest.importorskip("pyrt_arm")
    _pyrt(tmp_path, "arm to 30 60\nwait\narm to -30 20\nwait\narm to 30 60\nwait\n"
          "arm to -30 20\nwait\nsim fault jam q0\narm to 0 0\nwait\n",
          "arm", "--speed", "max", "--black-box", "2", status=1)
    pj = _box(tmp_path)
    (_tick, data), = JournalReader(pj).snapshots
    said = json.loads(zlib.decompress(data))
    assert said["refused"] == "cannot snapshot: arm has no snapshot"
    status, out, err = _replay(pj, capsys)
    assert status == 1 and "replayed" not in out
    assert "could not save its state there: cannot snapshot: arm has no snapshot" in err
    assert "Traceback" not in err


# -- every snapshot of a run resumes it ------------------------------------------------------


def _gripper_run(tmp_path: Path, every: int):
    st = build_gripper(Loop(SimClock()), boards="sim:")
    pj = tmp_path / "run.pj"
    rec = Recorder(st, pj, metadata={"factory": "gripper"})
    shell = RobotShell(st, io.StringIO())
    st.runner.start()
    shell.onecmd("I")
    return st, rec, pj, lambda: [shell.onecmd(c) for c in
                                 ("P 30mm", "wait", "X 20", "P 10mm", "wait", "M", "C 45 30",
                                  "Q", "P 20mm", "wait", "ack", "M", "C 45 01", "Q", "P 40mm")]


def _manipulator_run(tmp_path: Path, every: int):
    directory = copy_station("prototype", tmp_path / "prototype")
    st = ManipulatorStation(directory, tick_ns=TICK_NS, boards="sim:")
    pj = tmp_path / "run.pj"
    rec = Recorder(st, pj, metadata={"factory": "manipulator",
                                     "args": {"db": str(directory), "tick_us": TICK_NS // 1000}})
    st.start()

    shell = RobotShell(st, io.StringIO())

    def drive():
        for line in ("prototype to 0 0 60", "wait", "prototype to 10 0 70"):
            shell.onecmd(line)
        st.runner.sleep(2.0)
    return st, rec, pj, drive


@pytest.mark.parametrize("run, every", [(_gripper_run, 700), (_manipulator_run, 130)],
                         ids=["gripper", "manipulator"])
def test_a_full_run_replays_identically_from_each_of_its_snapshots(tmp_path, run, every):
    """Snapshots taken every few hundred ticks of a run (moves, a supervision fault and its
    ack; the manipulator's moves and polls): a replay that resumes from any of them is
    identical to the end, so a snapshot holds all the controller's state."""
    st, rec, pj, drive = run(tmp_path, every)
    snaps: list[Snapshot] = []

    def grab(tick: int, now_ns: int) -> None:
        if tick % every == every - 1:
            snaps.append(take_snapshot(st, rec.image.last_inputs, rec.image.output_values()))

    rec.tick_listeners.append(grab)
    try:
        drive()
    finally:
        st.close()
        rec.close()
    taken = [s for s in snaps if not s.refused]
    assert len(taken) >= 5, [s.refused for s in snaps]
    assert_each_snapshot_replays(pj, taken, st.name, tmp_path)


# -- damage and refusals -------------------------------------------------------------------


def _tamper(pj: Path, change) -> Path:
    """``pj`` with its snapshot's JSON changed by ``change(doc)`` (checksums made anew)."""
    data = pj.read_bytes()
    end = HEADER_SIZE + int.from_bytes(data[5:9], "little")
    assert data[end + 4:end + 5] == KIND_SNAPSHOT
    s_end = end + HEADER_SIZE + int.from_bytes(data[end + 5:end + 9], "little")
    (tick, raw), = JournalReader(pj).snapshots
    doc = json.loads(zlib.decompress(raw))
    change(doc)
    new = frame(KIND_SNAPSHOT, snapshot_payload(tick, zlib.compress(json.dumps(doc).encode())))
    out = pj.with_name("tampered.pj")
    out.write_bytes(data[:end] + new + data[s_end:])
    return out


@pytest.fixture(scope="module")
def gripper_box(tmp_path_factory) -> Path:
    tmp = tmp_path_factory.mktemp("box")
    _pyrt(tmp, "P 30mm\nwait\nP 10mm\nwait\nM\nC 45 30\nQ\nP 20mm\nwait\n",
          "gripper", "--speed", "max", "--black-box", "2", status=1)
    return _box(tmp)


def _cut_ram(doc: dict) -> None:
    doc["state"]["gripper"]["$o"]["ram"] = {"$ba": "00"}


def _foreign_class(doc: dict) -> None:
    doc["state"]["gripper"]["$c"] = "os:system"


def _no_state(doc: dict) -> None:
    del doc["state"]


def _other_format(doc: dict) -> None:
    doc["format"] = "pyrt-snapshot/9"


def _bad_inputs(doc: dict) -> None:
    doc["inputs"] = ["x"]


@pytest.mark.parametrize("change, said", [
    (_cut_ram, r"the snapshot's gripper.ram is 1 bytes, the station's 128"),
    (_foreign_class, "names a class of 'os', not of pyrt"),
    (_no_state, "the snapshot is damaged: it has no state"),
    (_other_format, "format is 'pyrt-snapshot/9'; this pyrt reads 'pyrt-snapshot/1'"),
    (_bad_inputs, "the snapshot is damaged: its tick, time, inputs or outputs"),
])
def test_a_damaged_snapshot_is_refused_cleanly(gripper_box, capsys, change, said):
    """A snapshot whose content is wrong (a RAM of the wrong size, a class not of pyrt, no
    state, another format, inputs that are not numbers) is refused in one line, exit 1,
    nothing replayed and no code of the snapshot's choosing run."""
    status, out, err = _replay(_tamper(gripper_box, change), capsys)
    assert status == 1 and "replayed" not in out, out + err
    assert "Traceback" not in err
    assert err.startswith("pyrt replay: ")
    assert re.search(said, err), err


def test_a_snapshot_frame_with_a_flipped_byte_is_damage_named_by_offset(gripper_box, capsys):
    """A byte flipped inside the snapshot's frame is found by its checksum: the replay names
    the frame and its offset and replays nothing."""
    data = bytearray(gripper_box.read_bytes())
    end = HEADER_SIZE + int.from_bytes(data[5:9], "little")
    data[end + HEADER_SIZE + 3] ^= 0xFF
    bad = gripper_box.with_name("flipped.pj")
    bad.write_bytes(bytes(data))
    status, out, err = _replay(bad, capsys)
    assert status == 1 and "replayed" not in out
    assert f"damaged at offset {end} (frame 1: payload checksum mismatch" in err


def test_a_station_without_the_hook_says_so_when_snapshot():
    """The default hook refuses by the station's name, and take_snapshot gives that reason."""
    from pyrt import Station

    class Bare(Station):
        name = "bare"

    st = Bare(Loop(SimClock()))
    with pytest.raises(SnapshotError, match="cannot snapshot: bare has no snapshot"):
        st.snapshot_state()
    with pytest.raises(SnapshotError, match="cannot restore a snapshot: bare has no snapshot"):
        st.restore_state({})


def test_a_foreground_job_makes_the_snapshot_say_which():
    """While the gripper's init job runs (a generator), the snapshot is refused naming it."""
    st = build_gripper(Loop(SimClock()), boards="sim:")
    try:
        st.runner.start()
        st.runner.call(st.controller.start_init)
        snap = st.runner.call(lambda: take_snapshot(st, [], []))
        assert snap.refused.startswith("cannot snapshot: the foreground job init is running")
    finally:
        st.close()


# -- the format -------------------------------------------------------------------------------


class _Plain:
    def __init__(self) -> None:
        self.n = 3
        self.x = float("nan")
        self.words = ["a", ("b", 2)]
        self.table = {1: 0.5, "k": [1, 2]}
        self.buf = bytearray(b"\x00\x01")
        self.arr = np.arange(6, dtype=np.float64).reshape(2, 3)
        self.scalar = np.float32(1.25)
        self.fn = len
        self.child = _Child(self)


class _Child:
    def __init__(self, parent: _Plain) -> None:
        self.parent = parent
        self.count = 7


def test_state_round_trips_bit_for_bit_in_place(monkeypatch):
    """Numbers (NaN too), text, tuples, dicts, bytearrays, arrays and numpy scalars come back
    exactly; bytearrays and arrays in place (views keep seeing them); functions are left."""
    monkeypatch.setattr(_Plain, "__module__", "pyrt.test_objects")
    monkeypatch.setattr(_Child, "__module__", "pyrt.test_objects")
    a, b = _Plain(), _Plain()
    a.n, a.words, a.table = 9, ["z", ("y", 3)], {2: -1.0}
    a.buf[:] = b"\xff\xfe"
    a.arr *= 2
    a.child.count = 11
    buf, arr = b.buf, b.arr
    state = json.loads(json.dumps(plain_state(state_of({"p": a}))))
    restore_into({"p": b}, state)
    assert (b.n, b.words, b.table, b.child.count) == (9, ["z", ("y", 3)], {2: -1.0}, 11)
    assert b.x != b.x and b.buf is buf and bytes(buf) == b"\xff\xfe"
    assert b.arr is arr and np.array_equal(arr, a.arr)
    assert type(b.scalar) is np.float32 and b.scalar == 1.25
    assert b.child.parent is b and b.fn is len


def test_snapshot_encodes_and_decodes():
    """A snapshot's JSON names its format and gives back what was put in."""
    snap = Snapshot("gripper", 12, 34, (1, 2), (3,), {"tick": 12}, {"robots": []}, {"g": 1})
    data = snap.encode()
    assert json.loads(data)["format"] == SNAPSHOT_FORMAT
    assert Snapshot.decode(data) == snap
    refused = Snapshot("arm", refused="cannot snapshot: arm has no snapshot")
    assert decompress_snapshot(compress_snapshot(refused)) == refused


def test_journals_of_version_1_are_read_and_a_later_version_is_refused_by_name(tmp_path):
    """The kept journals (version 1, no snapshots) still read; a journal now is version 2; a
    header of a version this pyrt does not know is refused, naming it and those it reads."""
    from pyrt.journal import Header, Journal, JournalError
    from pyrt.journal.format import FORMAT_VERSION, KIND_HEADER, _Cursor

    root = Path(__file__).resolve().parent / "journals"
    old = JournalReader(root / "gripper.pj")
    head = old._frames[0].payload
    assert _Cursor(bytes(head)).uvarint() == 1 and old.snapshots == []
    path = tmp_path / "new.pj"
    with Journal(Header(station="s", period_ns=1000, inputs=["a"], outputs=["b"]), path):
        pass
    assert FORMAT_VERSION == 2 and _Cursor(bytes(JournalReader(path)._frames[0].payload)
                                           ).uvarint() == 2
    payload = bytes([3]) + bytes(JournalReader(path)._frames[0].payload)[1:]
    (tmp_path / "v3.pj").write_bytes(frame(KIND_HEADER, payload))
    with pytest.raises(JournalError, match="journal format version 3; this pyrt reads "
                                           "versions 1, 2"):
        JournalReader(tmp_path / "v3.pj")


@pytest.mark.parametrize("cost_ns, work_ns, every", [
    (100_000, 7_000, 2_000),     # the gripper's: 1 % of 7 µs ticks is 1,429 ticks, under 2 s
    (2_000_000, 35_000, 5_715),  # the manipulator's at 1 ms ticks: 1 % of its work
    (50_000_000, 35_000, 7_500),  # costlier still: 75 % of the 10 s box at most
    (1_000, 0, 7_500),           # no work measured: as far apart as the box allows
])
def test_snapshots_are_spaced_by_what_they_cost_against_the_loop_s_work(cost_ns, work_ns, every):
    """Snapshots are as far apart as keeps them within SNAPSHOT_SHARE (1 %) of the loop
    thread's work a tick, at least SNAPSHOT_S and at most MAX_SNAPSHOT_SPAN of the box."""
    from pyrt.station import blackbox as bb

    assert (bb.SNAPSHOT_SHARE, bb.SNAPSHOT_S, bb.MAX_SNAPSHOT_SPAN) == (0.01, 2.0, 0.75)
    assert bb.snapshot_interval(cost_ns, work_ns, 2_000, 7_500) == every


def test_a_black_box_always_holds_a_snapshot(monkeypatch):
    """However much a snapshot costs (the CPU clock is given, not measured: 50 ms a
    reading), the next is at most MAX_SNAPSHOT_SPAN of the black box's span later (3 s:
    2.25 s), so that every black box holds one."""
    cost_ns, every_s = 50_000_000, 2.25
    from pyrt.journal import BlackBox
    from pyrt.station import blackbox as bb

    clock = iter(range(0, 10**15, cost_ns))
    monkeypatch.setattr(bb.time, "thread_time_ns", lambda: next(clock))
    st = build_gripper(Loop(SimClock()), boards="sim:")
    rec = bb.FaultRecorder(st, None, black_box=BlackBox(3.0), seconds=3.0)
    try:
        st.runner.start()
        st.runner.sleep(2.5)  # no foreground job: the first snapshot is taken at once
        box = rec.fault_box
        assert len(box.snapshots) == 2 and not box.snapshot_refused
        assert box.snapshot_every == round(every_s * 1000)  # ticks of 1 ms
    finally:
        st.close()
        rec.close()


def _spaced_box(monkeypatch, refuse_second: bool) -> tuple[list[int], int]:
    """A gripper's black box (10 s) on a loop whose thread's CPU clock is given: 10 µs a
    tick of work and 0.5 ms a snapshot (1 % of the work: one every 5,000 ticks); the
    ticks of the snapshots taken in 6 s, and the interval it settled on."""
    from pyrt.journal import BlackBox
    from pyrt.station import blackbox as bb

    st = build_gripper(Loop(SimClock()), boards="sim:")
    rec = bb.FaultRecorder(st, None, black_box=BlackBox(10.0), seconds=10.0)
    spent = [0]
    monkeypatch.setattr(bb.time, "thread_time_ns",
                        lambda: st.loop.tick_index * 10_000 + spent[0])
    take, asked = bb.take_snapshot, []

    def costly(station, inputs, outputs):
        asked.append(station.loop.tick_index)
        spent[0] += 500_000
        if refuse_second and len(asked) == 2:
            return Snapshot(station.name, refused="cannot snapshot: busy")
        return take(station, inputs, outputs)

    monkeypatch.setattr(bb, "take_snapshot", costly)
    try:
        st.runner.start()
        st.runner.sleep(6.0)
        box = rec.fault_box
        return [s.tick for s in box.snapshots], box.snapshot_every
    finally:
        st.close()
        rec.close()


def test_the_first_interval_is_kept_to_the_share_too(monkeypatch):
    """The snapshot after the first is taken when the loop's work since the first says
    (5,000 ticks), not at the least interval (2,000) before the work was known."""
    ticks, every = _spaced_box(monkeypatch, refuse_second=False)
    assert every == 5_000
    assert len(ticks) == 2 and ticks[1] - ticks[0] == 5_000


def test_a_refused_snapshot_is_asked_again_a_tenth_of_the_interval_later(monkeypatch):
    """A station that cannot give its state when a snapshot is due is asked again 200
    ticks later (a tenth of 2 s), not a whole interval later."""
    ticks, _every = _spaced_box(monkeypatch, refuse_second=True)
    assert len(ticks) == 2 and ticks[1] - ticks[0] == 5_200
