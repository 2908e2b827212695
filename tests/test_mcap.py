"""Runs and scope frames as MCAP: pyrt export RUN.pj OUT.mcap, scope save FILE.mcap, read back by the mcap library."""

from __future__ import annotations

import io
import json
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

import pytest

from pyrt.journal import BlackBox, Header, Journal, JournalReader
from pyrt.scope.mcapfile import export_journal

mcap_reader = pytest.importorskip("mcap.reader")

ROOT = Path(__file__).resolve().parent.parent
JOURNALS = sorted((ROOT / "tests" / "journals").glob("*.pj"))


def _read(path: Path) -> tuple[dict[str, list[tuple[int, dict]]], dict[str, dict], list]:
    """Every message by topic as (log time, decoded JSON); each topic's schema; attachments."""
    by_topic: dict[str, list[tuple[int, dict]]] = defaultdict(list)
    schemas: dict[str, dict] = {}
    with open(path, "rb") as fh:
        reader = mcap_reader.make_reader(fh, validate_crcs=True)
        for schema, channel, message in reader.iter_messages():
            assert channel.message_encoding == "json" and schema.encoding == "jsonschema"
            schemas[channel.topic] = json.loads(schema.data)
            assert message.publish_time == message.log_time
            by_topic[channel.topic].append((message.log_time, json.loads(message.data)))
        attachments = list(reader.iter_attachments())
    return by_topic, schemas, attachments


def _expected(path: Path) -> dict[str, list[int]]:
    """The log times each topic must have, from the journal itself."""
    reader = JournalReader(path)
    h = reader.header
    want: dict[str, list[int]] = defaultdict(list)
    in_boards = sorted({n.partition(".")[0] for n in h.inputs})
    out_boards = sorted({n.partition(".")[0] for n in h.outputs})
    for t in reader.ticks():
        for b in in_boards:
            want[f"/inputs/{b}"].append(t.time_ns)
        for b in out_boards:
            want[f"/outputs/{b}"].append(t.time_ns)
        want["/ticks"].append(t.time_ns)
        want["/writes"] += [t.time_ns] * len(t.outputs)
        want["/commands"] += [t.time_ns] * len(t.commands)
        want["/faults"] += [t.time_ns for e in t.events if e.name == "fault"]
        want["/events"] += [t.time_ns for e in t.events if e.name != "fault"]
    return {k: v for k, v in want.items() if v}


@pytest.mark.parametrize("journal", JOURNALS, ids=[p.stem for p in JOURNALS])
def test_an_exported_journal_reads_back_with_the_journals_counts_and_times(journal, tmp_path):
    """Each kept journal as MCAP: per channel, the message count and the first and last
    log times are the journal's (ticks, writes, commands, faults); every message has its
    schema's fields."""
    out = tmp_path / f"{journal.stem}.mcap"
    done = export_journal(journal, out)
    by_topic, schemas, attachments = _read(out)
    want = _expected(journal)
    summary = JournalReader(journal).summary()
    assert done.ticks == summary.ticks
    assert {k: len(v) for k, v in by_topic.items()} == {k: len(v) for k, v in want.items()}
    for topic, times in want.items():
        got = [t for t, _ in by_topic[topic]]
        assert (got[0], got[-1]) == (times[0], times[-1]), topic
        assert got == sorted(got)
    assert len(by_topic["/faults"]) >= 1  # every kept case holds a fault
    for topic, messages in by_topic.items():
        fields = set(schemas[topic]["properties"])
        assert all(set(m) == fields for _, m in messages), topic
    first = next(JournalReader(journal).ticks())
    h = JournalReader(journal).header
    board, _, reg = h.inputs[0].partition(".")
    assert by_topic[f"/inputs/{board}"][0][1][reg] == first.inputs[0]
    assert {a.name for a in attachments} == set(h.databases)


def test_a_black_box_exports_from_its_first_kept_tick(tmp_path):
    """A black box (the last seconds before a fault) exports too: its ticks start where
    the ring starts, not at tick 0, and the fault is on /faults at its tick's time."""
    header = Header(station="toy", period_ns=1_000_000, inputs=["b.x", "b.y"],
                    outputs=["b.out"], writers=["T"])
    journal = Journal(header, None, black_box=BlackBox(seconds=0.5), lossless=True)
    for k in range(2000):
        events = [("fault", 1, "toy: tripped")] if k == 1990 else []
        journal.record_tick(k, k * 1_000_000, 0, 0, [k, 2 * k], [(0, k % 7, 0)], events=events)
    box = tmp_path / "toy-fault-1.pj"
    assert journal.dump_black_box(box).result(timeout=30) > 0
    journal.close()
    ticks = list(JournalReader(box).ticks())
    assert ticks[0].tick > 0
    by_topic, _schemas, _ = _read(export_journal(box, tmp_path / "box.mcap").path)
    assert len(by_topic["/inputs/b"]) == len(ticks)
    assert by_topic["/inputs/b"][0] == (ticks[0].time_ns, {"x": ticks[0].tick,
                                                          "y": 2 * ticks[0].tick})
    assert by_topic["/faults"] == [(1990 * 1_000_000, {"tick": 1990, "id": 1,
                                                       "message": "toy: tripped"})]


def _pyrt(cwd: Path, *argv: str, code: str = "") -> subprocess.CompletedProcess[str]:
    pre = [sys.executable, "-c", code + "import sys; from pyrt.cli import entry; "
           "sys.argv[0] = 'pyrt'; entry()"] if code else [sys.executable, "-m", "pyrt"]
    return subprocess.run([*pre, *argv], cwd=cwd, capture_output=True, text=True, timeout=120)


def test_pyrt_export_exit_codes_and_sizes(tmp_path):
    """pyrt export: 0 and a line with both sizes; 2 for a name not ending .mcap (nothing
    read); 1 for a journal that cannot be read; without mcap, one line saying what to
    install."""
    gripper = ROOT / "tests" / "journals" / "gripper.pj"
    done = _pyrt(tmp_path, "export", str(gripper), "g.mcap")
    assert done.returncode == 0, done.stderr
    size = (tmp_path / "g.mcap").stat().st_size
    assert f"in g.mcap ({size} bytes; the journal {gripper.stat().st_size} bytes)" in done.stdout
    done = _pyrt(tmp_path, "export", str(gripper), "g.json")
    assert done.returncode == 2 and "pyrt export: error: g.json" in done.stderr
    done = _pyrt(tmp_path, "export", str(tmp_path / "none.pj"), "n.mcap")
    assert done.returncode == 1 and done.stderr.startswith("pyrt export: journal ")
    done = _pyrt(tmp_path, "export", str(gripper), "m.mcap",
                 code="import sys; sys.modules['mcap'] = None; ")
    assert done.returncode == 1 and "pip install 'pyrt[mcap]'" in done.stderr
    assert "Traceback" not in done.stderr and not (tmp_path / "m.mcap").exists()


def test_scope_save_mcap_holds_every_sample_as_the_csv_does(tmp_path, monkeypatch):
    """scope save FILE.mcap: a channel per object, a message per sample at its loop time,
    the values those of scope save FILE.csv; units in the schema."""
    from pyrt.commands import RobotShell
    from pyrt.scheduler import Loop, SimClock
    from pyrt.station.gripper import build_gripper

    monkeypatch.chdir(tmp_path)
    station = build_gripper(Loop(SimClock()))
    station.start()
    try:
        shell = RobotShell(station, io.StringIO())
        for line in ("I", "scope add encoder gripper.dac sim.x", "scope run roll", "P-400",
                     "sleep 0.3", "scope stop", "scope save f.csv", "scope save f.mcap"):
            shell.onecmd(line)
    finally:
        station.shutdown()
    rows = [r.split(",") for r in (tmp_path / "f.csv").read_text().splitlines()[1:]]
    by_topic, schemas, _ = _read(tmp_path / "f.mcap")
    assert set(by_topic) == {"/scope", "/scope/gripper", "/scope/sim"}
    assert schemas["/scope"]["properties"]["encoder"]["description"] == "counts"
    assert [len(v) for v in by_topic.values()] == [len(rows)] * 3
    for i, row in enumerate(rows):
        t_ns = by_topic["/scope"][i][0]
        assert abs(t_ns / 1e9 - float(row[0])) < 1e-9
        assert by_topic["/scope"][i][1]["encoder"] == pytest.approx(float(row[1]))
        assert by_topic["/scope/gripper"][i][1]["dac"] == pytest.approx(float(row[2]))
        assert by_topic["/scope/sim"][i][1]["x"] == pytest.approx(float(row[3]), rel=1e-8)


def test_a_damaged_journal_is_refused_or_salvaged_around_the_damage(tmp_path):
    """A byte flipped inside a tick block: pyrt export refuses (exit 1, naming the frame and
    offset, nothing written); --salvage exports every readable tick, the lost ones on /gaps."""
    from pyrt.journal.format import HEADER_SIZE

    data = bytearray((ROOT / "tests" / "journals" / "gripper.pj").read_bytes())
    offs, pos = [], 0
    while pos < len(data):
        offs.append(pos)
        pos += HEADER_SIZE + int.from_bytes(data[pos + 5:pos + 9], "little")
    mid = offs[len(offs) // 2]
    data[mid + HEADER_SIZE + 20] ^= 0x55
    bad = tmp_path / "bad.pj"
    bad.write_bytes(bytes(data))
    done = _pyrt(tmp_path, "export", str(bad), "bad.mcap")
    assert done.returncode == 1 and f"at offset {mid}" in done.stderr, done.stderr
    assert not (tmp_path / "bad.mcap").exists()
    done = _pyrt(tmp_path, "export", "--salvage", str(bad), "bad.mcap")
    assert done.returncode == 0, done.stderr
    by_topic, _schemas, _ = _read(tmp_path / "bad.mcap")
    kept = [t for t in JournalReader(bad, salvage=True).ticks()]
    assert len(by_topic["/ticks"]) == len(kept) < JournalReader(GRIPPER_PJ).summary().ticks
    (gap,) = by_topic["/gaps"]
    assert "damaged bytes" in gap[1]["cause"]


GRIPPER_PJ = ROOT / "tests" / "journals" / "gripper.pj"


def test_an_arms_export_carries_its_joint_states_every_tick(tmp_path):
    """pyrt export of the example arm's journal writes /joint_states as
    sensor_msgs/msg/JointState: one message a tick (first and last at the journal's
    first and last tick), the URDF's joint names, positions and velocities in rad and
    rad/s equal to the replay's samples of the declared signals; the URDF once."""
    pytest.importorskip("pyrt_arm", reason="the example arm is not installed")
    np = pytest.importorskip("numpy")
    arm = ROOT / "tests" / "journals" / "arm.pj"
    done = _pyrt(tmp_path, "export", str(arm), "arm.mcap")
    assert done.returncode == 0, done.stderr
    by_topic, schemas, _ = _read(tmp_path / "arm.mcap")
    ticks = [t.time_ns for t in JournalReader(arm).ticks()]
    states = by_topic["/joint_states"]
    assert len(states) == len(ticks)
    assert (states[0][0], states[-1][0]) == (ticks[0], ticks[-1])
    assert schemas["/joint_states"]["title"] == "sensor_msgs/msg/JointState"
    assert set(schemas["/joint_states"]["required"]) == {"header", "name", "position",
                                                        "velocity", "effort"}
    t, last = states[-1]
    assert last["header"]["stamp"] == {"sec": t // 10**9, "nsec": t % 10**9}
    assert last["name"] == ["shoulder", "elbow"]
    [(_, desc)] = by_topic["/robot_description"]
    assert '<joint name="elbow"' in desc["data"]
    chans = "q0,q1,shoulder.velocity,elbow.velocity"
    done = _pyrt(tmp_path, "replay", str(arm), "--scope", chans, "--scope-save", "j.npz")
    assert done.returncode == 0, done.stderr
    saved = np.load(tmp_path / "j.npz")
    assert list(saved["channels"]) == chans.split(",")
    assert saved["t_ns"].tolist() == [t for t, _ in states]
    data = saved["data"]
    got = np.array([m["position"] + m["velocity"] for _, m in states])
    assert got == pytest.approx(np.radians(data), abs=1e-12)
