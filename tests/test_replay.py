"""The flight recorder end to end: record a station's run (--journal), replay it on virtual time."""

from __future__ import annotations

import io
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pyrt.boards import open_boards
from pyrt.boards.gripper import DAC_NULL
from pyrt.cli import main
from pyrt.commands import RobotShell
from pyrt.errors import CommandError, ConfigError
from pyrt.journal import JournalError, JournalReader
from pyrt.robots.gripper import GripperController
from pyrt.scheduler import Loop, SimClock
from pyrt.scheduler.motion import MotionRecord
from pyrt.sim.world import GRIPPER_BOARDS
from pyrt.station.gripper import build_gripper
from pyrt.station.recording import Recorder, decode_request, encode_request
from pyrt.station.replay import Replay

ROOT = Path(__file__).resolve().parent.parent


def _record(tmp_path: Path, station: str, stdin: str, *extra: str, name: str = "run.pj",
            timeout: float = 120, status: int = 0) -> Path:
    path = tmp_path / name
    args = [sys.executable, "-m", "pyrt", station, "--journal", str(path), *extra]
    done = subprocess.run(args, input=stdin, capture_output=True, text=True, cwd=tmp_path,
                          timeout=timeout)
    assert done.returncode == status, done.stdout + done.stderr
    assert path.is_file(), done.stdout
    ticks = JournalReader(path).summary().ticks
    assert f"journal: {ticks} ticks in {path}" in done.stdout  # said at the end, with
    assert f"'pyrt replay {path}' re-runs them" in done.stdout  # what to do with it
    return path


def _replay(path: Path, *argv: str) -> tuple[int, str]:
    out = io.StringIO()
    old = sys.stdout
    sys.stdout = out
    try:
        status = main(["replay", str(path), *argv])
    finally:
        sys.stdout = old
    return status, out.getvalue()


def _wait_for_ticks(path: Path, ticks: int, seconds: float = 60) -> int:
    """Poll a journal being written until it holds ``ticks`` complete ticks (or time is up)."""
    deadline = time.monotonic() + seconds
    have = 0
    while time.monotonic() < deadline and have < ticks:
        time.sleep(0.05)
        if path.exists():
            try:
                have = JournalReader(path).summary().ticks
            except JournalError:
                have = 0
    return have


def _events(path: Path) -> list[tuple[int, str, str]]:
    return [(t.tick, e.name, e.message) for t in JournalReader(path).ticks() for e in t.events]


def _requests(path: Path) -> list[str]:
    return [c.text for t in JournalReader(path).ticks() for c in t.commands]


# -- real time, both robots ---------------------------------------------------------------------


def test_a_real_time_gripper_run_with_a_jam_replays_identically(tmp_path):
    """A gripper run at real time (a move, a jam ending a move short, a stop) replays identically."""
    path = _record(tmp_path, "gripper",
                   "P 30mm\nwait\nsim fault jam\nP 60mm\nwait\nstop\nquit\n")
    r = JournalReader(path)
    assert r.complete and r.summary().ticks > 1000
    texts = _requests(path)
    assert any('"$r":"P"' in t for t in texts) and any('"m":"stop"' in t for t in texts)
    writes = [w for t in r.ticks() for w in t.outputs]
    assert any(r.header.outputs[i] == "gripper.dac" and v != DAC_NULL for i, v, _ in writes)
    status, out = _replay(path)
    assert status == 0, out
    assert f"replayed {r.summary().ticks} ticks" in out and "identical" in out


def test_a_real_time_manipulator_fault_and_ack_replay_identically(tmp_path):
    """A manipulator run at real time with a stalled motor (the tracking fault trips), ack and stop
    replays identically: every output, the fault at the same tick with the same message."""
    db = tmp_path / "db"
    path = _record(tmp_path, "manipulator",
                   "sim fault axis0 stall\nprototype to 0 0 93\nwait\nack\nstop\nquit\n",
                   "--init-db", str(db), "-k", status=1)  # the fault fails the script
    events = _events(path)
    assert len(events) == 1 and "TRACKING_FAULT" in events[0][2], events
    assert any('"m":"acknowledge"' in t for t in _requests(path))
    assert set(JournalReader(path).header.databases) >= {"POLYAXIS.dat", "AXIS.dat"}
    status, out = _replay(path)
    assert status == 0, out
    assert "identical" in out


# -- what a replay catches ------------------------------------------------------------------------


def _virtual_gripper_journal(tmp_path: Path) -> Path:
    return _record(tmp_path, "gripper", "P 30mm\nwait\nP 10mm\nwait\nstop\nquit\n",
                   "--speed", "max", name="virtual.pj")


def test_a_patched_gain_is_caught_naming_tick_register_and_task(tmp_path, monkeypatch):
    """A code change that alters an output (the drive one count stronger) is reported at the
    first tick it shows, with the register, both values and the task that wrote each."""
    path = _virtual_gripper_journal(tmp_path)
    first_drive = next(t for t in JournalReader(path).ticks()
                       if any(v not in (DAC_NULL, 255) and i == 3 for i, v, _ in t.outputs))
    original = GripperController.drive

    def stronger(self, byte):
        return original(self, byte if byte in (DAC_NULL, 255) else min(254, byte + 1))

    monkeypatch.setattr(GripperController, "drive", stronger)
    status, out = _replay(path)
    assert status == 1, out
    line = next(x for x in out.splitlines() if x.startswith("replay differs"))
    w = next(w for w in first_drive.outputs if w[0] == 3)
    assert f"at tick {first_drive.tick}: output gripper.dac: recorded {w[1]}" in line
    assert f"replayed {w[1] + 1}" in line
    assert line.count("written by MVJAWS") == 2


def test_a_request_that_changes_differently_is_caught(tmp_path, monkeypatch):
    """A command whose effect changed (P refuses everything) shows as missing output writes."""
    path = _virtual_gripper_journal(tmp_path)
    monkeypatch.setattr(GripperController, "drive", lambda self, byte: None)
    status, out = _replay(path)
    assert status == 1 and "not written" in out, out


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(where=st.floats(0.0, 1.0, exclude_max=True), bit=st.integers(0, 7))
def test_a_corrupted_byte_is_reported_with_its_offset(tmp_path, where, bit):
    """Any byte of a journal flipped: the replay refuses it, naming the offset; nothing runs."""
    src = tmp_path / "clean.pj"
    if not src.exists():
        src.write_bytes(_virtual_gripper_journal(tmp_path).read_bytes())
    data = bytearray(src.read_bytes())
    pos = int(where * len(data))
    data[pos] ^= 1 << bit
    bad = tmp_path / "bad.pj"
    bad.write_bytes(bytes(data))
    with pytest.raises(JournalError) as info:
        Replay(bad)
    assert info.value.offset is not None and info.value.offset <= pos
    assert "offset" in str(info.value)
    status, out = _replay(bad)
    assert status == 1 and "ticks identical" not in out


def test_a_journal_killed_mid_move_replays_to_its_last_complete_tick(tmp_path):
    """SIGKILL during a real-time move: the journal reads up to its last complete block and
    replays identically that far, saying that the run was cut off."""
    path = tmp_path / "killed.pj"
    db = tmp_path / "db"
    proc = subprocess.Popen(
        [sys.executable, "-m", "pyrt", "manipulator", "--init-db", str(db), "--journal",
         str(path)], stdin=subprocess.PIPE, stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL, cwd=tmp_path, text=True)
    try:
        assert proc.stdin is not None
        proc.stdin.write("prototype to 0 0 93\n")
        proc.stdin.flush()
        assert _wait_for_ticks(path, 600) >= 600  # three seconds of the move at 200 Hz
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
    r = JournalReader(path)
    assert not r.complete
    moving = [t for t in r.ticks() if t.outputs]
    assert moving, "the move wrote no output before the kill"
    status, out = _replay(path)
    assert status == 0, out
    assert f"replayed {r.summary().ticks} ticks" in out and "cut off" in out


# -- the pieces -----------------------------------------------------------------------------------


def _station() -> tuple[Loop, object]:
    loop = Loop(SimClock(), period_ns=1_000_000)
    return loop, build_gripper(loop, boards="sim:")


def test_sim_has_one_tick_shape_and_refuses_image_by_name(tmp_path):
    """sim: always reaches its boards through the process image (what a journal records);
    ?image=1 is an unknown option, refused by name."""
    with pytest.raises(ConfigError, match="sim: takes no option image"):
        open_boards("sim:?image=1", "gripper", GRIPPER_BOARDS)
    loop = Loop(SimClock(), period_ns=1_000_000)
    station = build_gripper(loop, boards="sim:")
    try:
        boards = station.boards
        assert boards.image is not None and boards.simulated is not None
        assert boards.simulated["gripper"] is not boards["gripper"]  # the world's side apart
        recorder = Recorder(station, tmp_path / "run.pj")
        recorder.close()
    finally:
        station.close()


_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.text(max_size=8)
    | st.floats(allow_nan=False),
    lambda inner: st.lists(inner, max_size=3) | st.tuples(inner, inner)
    | st.dictionaries(st.text(max_size=4), inner, max_size=3),
    max_leaves=8)


@given(args=st.lists(_values, max_size=4))
def test_a_request_round_trips_through_its_text(args):
    """A station method's call with plain arguments encodes to text and decodes to the same call."""
    _loop, station = _station()
    try:
        seen = []
        station.journal_probe = lambda *a: seen.append(a)
        text = encode_request(station, "x", station.journal_probe, tuple(args))
        assert text is None  # a lambda is not a method: not recorded
        text = encode_request(station, "x", station.acknowledge, tuple(args))
        assert text is not None
        called = []
        station.acknowledge = lambda *a: called.append(a)  # the decoder looks the method up
        decode_request(station, text)()
        assert called == [tuple(args)]
    finally:
        station.close()


def test_requests_name_components_commands_and_motion_records():
    """execute(component, command, args) and a motion record come back as the same objects."""
    _loop, station = _station()
    try:
        comp = station.component("gripper")
        rec = next(r for c, r in station.all_commands() if c is comp and r.name == "P")
        text = encode_request(station, "P", station.execute, (comp, rec, ["30mm"]))
        got = []
        station.execute = lambda *a: got.append(a)
        decode_request(station, text)()
        assert got == [(comp, rec, ["30mm"])]
        m = encode_request(station, "motion", None, (), MotionRecord("line", {"x": 1.5}))
        decode_request(station, m)()
        assert station.runner.motion.get() == MotionRecord("line", {"x": 1.5})
    finally:
        station.close()


def test_a_recorded_request_for_a_missing_method_is_an_error():
    """A journal naming a method the station has not, or one a journal does not replay
    (closing, writing files): ConfigError, nothing called."""
    _loop, station = _station()
    try:
        for name in ("no_such_thing", "__class__", "close", "open_audit_log", "write_back"):
            with pytest.raises(ConfigError, match="names no method a journal replays"):
                decode_request(station, f'{{"o":"","m":"{name}","a":["/tmp/x"]}}')
        assert encode_request(station, "x", station.close, ()) is None  # never recorded
        with pytest.raises(ConfigError, match="not JSON"):
            decode_request(station, "{oops")
    finally:
        station.close()


def test_until_stops_at_the_tick_and_the_console_only_reads(tmp_path, monkeypatch):
    """--until TICK stops there; the console answers reads and refuses a move."""
    path = _virtual_gripper_journal(tmp_path)
    monkeypatch.setattr(sys, "stdin", io.StringIO("W\nP 20mm\nstop\nquit\n"))
    status, out = _replay(path, "--until", "1500")
    assert status == 0, out
    assert "replayed 1501 ticks (ticks 0..1500), identical" in out
    assert "would change the controller" in out
    assert out.count("a replay is read-only") == 2  # P and stop refused


def test_scope_samples_any_signal_over_the_replay(tmp_path):
    """--scope samples a signal nobody watched in the run; --scope-save writes it."""
    path = _virtual_gripper_journal(tmp_path)
    saved = tmp_path / "dac.csv"
    status, out = _replay(path, "--scope", "dac,encoder", "--scope-save", str(saved))
    assert status == 0, out
    lines = saved.read_text().splitlines()
    ticks = JournalReader(path).summary().ticks
    assert "dac" in lines[0] and len(lines) == ticks + 1  # every replayed tick
    dac = [int(row.split(",")[1]) for row in lines[1:]]
    assert any(v != DAC_NULL for v in dac)  # the moves drove the jaws


def test_replay_boards_exist_only_while_a_replay_builds():
    """replay: is no scheme outside pyrt replay: a station asking for it gets a clear error."""
    loop = Loop(SimClock(), period_ns=1_000_000)
    with pytest.raises(ConfigError, match="no board back end for scheme 'replay'"):
        build_gripper(loop, boards="replay:")


def test_frozen_shell_refuses_what_waits(tmp_path):
    """The stopped replay's runner refuses to wait or move."""
    from pyrt.cli.replay import FrozenRunner

    _loop, station = _station()
    try:
        runner = FrozenRunner(station)
        with pytest.raises(CommandError):
            runner.wait_until(lambda: True, 1.0)
        shell = RobotShell(station, io.StringIO(), runner=runner)
        assert shell.runner is runner
    finally:
        station.close()


def test_a_fault_of_the_clock_is_replayed_where_it_came(tmp_path):
    """Consecutive overruns trip the station at real time (--max-overruns): the replay applies
    the clock's decision at the same place, and every output and the fault match."""
    path = _record(tmp_path, "gripper", "sleep 0.5\nack\nstop\nquit\n",
                   "--tick-us", "50", "--max-overruns", "2", "-k",
                   status=1)  # the fault fails the script
    events = [e for e in _events(path) if e[1] == "fault"]
    assert events and "consecutive overruns" in events[0][2], events
    status, out = _replay(path)
    assert status == 0, out
    assert "identical" in out


def test_a_run_over_tcp_replays_without_its_board_sim(tmp_path):
    """A gripper recorded over tcp:// against board-sim replays identically with board-sim gone;
    'sim' (which asked board-sim) says the world was not replayed."""
    sim = subprocess.Popen([sys.executable, "-m", "pyrt", "board-sim", "gripper", "--listen",
                            "127.0.0.1:0"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                           text=True, cwd=tmp_path)
    try:
        assert sim.stdout is not None
        first = sim.stdout.readline()
        url = first.split(" on ", 1)[1].split()[0]
        assert url.startswith("tcp://127.0.0.1:"), first
        path = _record(tmp_path, "gripper", "P 30mm\nwait\nsim\nstop\nquit\n", "--boards", url)
    finally:
        sim.kill()
        sim.wait(10)
    assert JournalReader(path).header.metadata["in_process"] is False
    status, out = _replay(path)
    assert status == 0, out
    assert "identical" in out


def test_a_headless_run_ended_by_sigterm_replays_identically(tmp_path):
    """A headless station stopped by SIGTERM stops every motor through the mailbox: the journal
    records that stop as the station's, and the replay matches to the end."""
    path = tmp_path / "headless.pj"
    proc = subprocess.Popen(
        [sys.executable, "-m", "pyrt", "gripper", "--headless", "--serve", "127.0.0.1:0",
         "--journal", str(path)], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
        cwd=tmp_path, text=True)
    try:
        assert _wait_for_ticks(path, 1500) >= 1500  # past the power-up's I
        proc.send_signal(signal.SIGTERM)
        out, _ = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
    assert proc.returncode == 0, out
    assert any('"m":"stop"' in t for t in _requests(path))
    status, replayed = _replay(path)
    assert status == 0, replayed
    assert "identical" in replayed


def test_each_write_is_named_by_the_task_or_job_that_ran(tmp_path):
    """The recorder stamps every output write with what the loop and queue say runs: the
    init job's writes are "init", a move's are MVJAWS; none is "outside a task"."""
    loop = Loop(SimClock(), period_ns=1_000_000)
    station = build_gripper(loop, boards="sim:")
    rec = Recorder(station, tmp_path / "named.pj")
    shell = RobotShell(station, io.StringIO())
    try:
        station.start()
        for line in ("I", "wait", "P 30mm", "wait", "stop"):
            shell.onecmd(line)
    finally:
        station.close()
        rec.close()
    reader = JournalReader(tmp_path / "named.pj")
    dac = list(reader.header.outputs).index("gripper.dac")
    by = {reader.writers[w] for t in reader.ticks() for i, _v, w in t.outputs if i == dac}
    assert {"init", "MVJAWS"} <= by, by
    assert "outside a task" not in by


def test_a_statistics_reset_in_a_recorded_run_records_the_ticks_missed_since(tmp_path):
    """Missed deadlines counted before and after a statistics reset (which zeroes the
    count) are each recorded once and never as a negative count: no tick is refused."""
    loop = Loop(SimClock(), period_ns=1_000_000)
    station = build_gripper(loop, boards="sim:")
    rec = Recorder(station, tmp_path / "reset.pj")
    try:
        loop.run(5)
        # three deadlines skipped, as an overrun at real time skips them: counted, and
        # the next deadline three periods on
        loop.missed += 3
        loop.resume_at(loop.now_ns, loop.deadline_ns + 3 * loop.period_ns)
        loop.run(1)
        loop.reset_statistics()
        loop.run(1)
        loop.missed += 2
        loop.resume_at(loop.now_ns, loop.deadline_ns + 2 * loop.period_ns)
        loop.run(1)
    finally:
        station.close()
        rec.close()  # raises if a tick was refused
    ticks = list(JournalReader(tmp_path / "reset.pj").ticks())
    assert [t.missed for t in ticks[-4:]] == [0, 3, 0, 2]
