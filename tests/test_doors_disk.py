"""A full disk is a fault: write-back, the journal and the black box, at every speed.

The disk is made full by injection (a write that raises ``OSError(ENOSPC)``), so
every test is deterministic and needs no privileges; the command line is run as
a subprocess where its exit status and the absence of a traceback matter.
"""

from __future__ import annotations

import contextlib
import errno
import io
import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

import pyrt.db.station as db_station
import pyrt.station.blackbox as blackbox
from pyrt.boards.gripper import DAC_NULL
from pyrt.db import copy_station, load_station, lock_directory
from pyrt.errors import ConfigError, DiskError, FaultError
from pyrt.journal import BlackBox, JournalError
from pyrt.journal.format import KIND_HEADER, frame
from pyrt.scheduler import Loop, SimClock
from pyrt.station.blackbox import AFTER_S, FaultBox
from pyrt.station.gripper import build_gripper
from pyrt.station.manipulator import ManipulatorStation
from pyrt.station.recording import Recorder
from pyrt.tasks import SyncWriter, ThreadWriter, WriteBack

TICK_NS = 5_000_000
ENOSPC = OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
FULL = "No space left on device (the disk is full)"


class FullDisk:
    """``atomic_write`` of a module as a full disk does it while :attr:`full`: ENOSPC, the
    file untouched.  Counts the refused writes."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch, module=db_station):
        self.full = False
        self.refused = 0
        real = module.atomic_write

        def write(path, data):
            if self.full:
                self.refused += 1
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))
            return real(path, data)

        monkeypatch.setattr(module, "atomic_write", write)


def _station(tmp_path: Path, writer: str) -> ManipulatorStation:
    directory = copy_station("prototype", tmp_path / "prototype")
    return ManipulatorStation(directory, tick_ns=TICK_NS, writer=writer)


def _fault_of(st: ManipulatorStation, disk: FullDisk, timeout_s: float = 30.0):
    """Move, make the disk full, and wait for the fault: (fault, the motors running at
    the fault's report, the moves still queued then)."""
    seen: list = []

    def listener(fault) -> None:  # called in the fault's tick, right after the reflex
        seen.append((fault, [a.motor.running for a in st.axes], len(st.motion)))

    st.loop.fault_listeners.append(listener)
    r = st.runner
    r.call(st.polyaxis.to, (0.0, 0.0, 60.0))
    r.call(st.polyaxis.to, (0.0, 0.0, 80.0))  # queued behind the first
    r.wait_until(lambda: st.polyaxis.active, 10)
    disk.full = True
    with contextlib.suppress(FaultError):
        r.wait_until(lambda: bool(seen), timeout_s)
    assert seen, "no fault"
    return seen[0]


@pytest.mark.parametrize("writer", ["sync", "thread"])
def test_a_full_disk_in_write_back_is_the_same_fault_at_every_speed(tmp_path, monkeypatch,
                                                                    writer):
    """ENOSPC under either writer (virtual speed writes in the loop, real time on a
    thread): one fault, the same sentence naming the file, every motor stopped in its
    tick, the queued move dropped; the file keeps its last good text."""
    disk = FullDisk(monkeypatch)
    st = _station(tmp_path, writer)
    st.start()
    files = sorted(st.directory.glob("*.dat"))
    try:
        fault, running, queued = _fault_of(st, disk)
        before = [f.read_bytes() for f in files]
        assert fault.source == "WRITEBACK"
        assert re.fullmatch(re.escape(f"database write-back failed: cannot write "
                                      f"{st.directory}/") + r"[A-Z]+\.dat: "
                            + re.escape(FULL), fault.cause), fault.cause
        assert running == [False] * len(st.axes) and queued == 0
        assert "FAULT" in st.runner.call(st.status, take_fault=False)
        assert disk.refused >= 1
        st.runner.sleep(2.0)
        assert [f.read_bytes() for f in files] == before
    finally:
        st.close()
    assert "keep the values last written" in st.closing_note()


def test_the_cause_is_word_for_word_the_same_under_both_writers(tmp_path, monkeypatch):
    """The sentence of the fault does not depend on the writer (on the speed)."""
    causes = []
    for writer in ("sync", "thread"):
        disk = FullDisk(monkeypatch)
        st = _station(tmp_path / writer, writer)
        st.start()
        try:
            fault, _, _ = _fault_of(st, disk)
            # which file a batch reaches first depends on what was due: the sentence does not
            causes.append(re.sub(r"/[A-Z]+\.dat:", "/FILE.dat:",
                                 fault.cause.replace(str(tmp_path / writer), "DIR")))
        finally:
            st.close()
        monkeypatch.undo()
    assert causes[0] == causes[1] == f"database write-back failed: cannot write " \
        f"DIR/prototype/FILE.dat: {FULL}"


def test_after_ack_a_disk_still_full_faults_again_and_a_freed_one_gets_every_value(
        tmp_path, monkeypatch):
    """Ack with the disk still full: the next write faults again (not once and then
    silence); with room again, the refused values are written (the file moves on)."""
    disk = FullDisk(monkeypatch)
    st = _station(tmp_path, "thread")
    st.start()
    r = st.runner
    try:
        first, _, _ = _fault_of(st, disk)
        r.call(st.acknowledge, take_fault=False)
        r.call(st.polyaxis.to, (0.0, 0.0, 70.0), take_fault=False)
        with contextlib.suppress(FaultError):
            r.wait_until(lambda: st.fault is not None, 30)
        assert st.fault is not None and st.fault.id != first.id
        assert st.fault.cause.endswith(FULL)
        disk.full = False
        # a write the writer began while the disk was full fails after that fault; its
        # failure is taken here, not said after the ack as one more fault (a loaded
        # machine's writer is late); its values go out again with the next batch
        with contextlib.suppress(DiskError):
            st.writeback.flush(30)
        r.call(st.acknowledge, take_fault=False)
        r.sleep(12.0)  # a stationary write is due every 10 s
        st.writeback.flush(30)
        assert st.fault is None
    finally:
        st.close()
    db = load_station(st.directory)
    pos = db.polyaxis().position
    assert abs(pos[2] - st.polyaxis.position[2]) < 0.5


def test_the_way_out_says_what_write_back_could_not_write(tmp_path, monkeypatch):
    """A disk full only when the station closes: no exception, and the closing note says
    the databases keep the values last written, and why."""
    disk = FullDisk(monkeypatch)
    st = _station(tmp_path, "sync")
    st.start()
    st.runner.call(st.polyaxis.to, (0.0, 0.0, 60.0))
    st.runner.sleep(1.5)
    disk.full = True
    st.close()
    note = st.closing_note()
    assert "keep the values last written (database write-back failed: cannot write" in note
    assert note.endswith(f"{FULL})")


class Sink:
    """A write-back sink that fails while ``full``."""

    def __init__(self):
        self.full = False
        self.batches: list[dict] = []

    def write_back(self, changes):
        if self.full:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), "/db/AXIS.dat")
        self.batches.append(dict(changes))


@pytest.mark.parametrize("kind", [SyncWriter, ThreadWriter])
def test_either_writer_says_a_refused_write_as_one_disk_error(kind):
    """Both writers: DiskError with the same sentence; the thread's at the next check,
    whose refused batch goes out again with the next one (newer values win)."""
    sink = Sink()
    w = kind(sink)
    sink.full = True
    try:
        w.submit({("AXIS", "a", "LENGTH"): 1.0, ("AXIS", "b", "LENGTH"): 2.0})
        w.flush(10)
        w.check()
    except DiskError as exc:
        assert str(exc) == f"database write-back failed: cannot write /db/AXIS.dat: {FULL}"
        assert exc.errno == errno.ENOSPC
    else:
        pytest.fail("no DiskError")
    sink.full = False
    if kind is ThreadWriter:
        w.submit({("AXIS", "a", "LENGTH"): 3.0})
        w.flush(10)
        assert sink.batches == [{("AXIS", "a", "LENGTH"): 3.0, ("AXIS", "b", "LENGTH"): 2.0}]
    w.close()


def test_a_calibration_the_disk_refuses_comes_back_at_the_next_poll(tmp_path, monkeypatch):
    """A loadcell calibration's batch refused by the disk is not the command's error: the
    next poll raises it (where the station faults), and it is written once there is room."""
    disk = FullDisk(monkeypatch)
    directory = copy_station("prototype", tmp_path / "p")
    db = load_station(directory)
    wb = WriteBack(db, SyncWriter(db))
    disk.full = True
    wb.loadcell_calibrated("loadcell0", 0.5, 1.25)  # no exception here
    with pytest.raises(DiskError, match=r"cannot write .*LOADCELL\.dat"):
        wb.poll(0)
    disk.full = False
    wb.poll(10**10)
    assert load_station(directory).loadcell("loadcell0").slope == 0.5
    assert wb.close() is None


def test_a_refused_value_is_written_once_there_is_room_though_it_never_changes(
        tmp_path, monkeypatch):
    """A stationary value the disk refused (the thread's batch) is written again at the
    write-back's pace once there is room, with no new value to carry it."""
    disk = FullDisk(monkeypatch)
    directory = copy_station("prototype", tmp_path / "p")
    db = load_station(directory)
    wb = WriteBack(db, ThreadWriter(db))
    name = db.polyaxis().name
    wb.watch_position(name, lambda: ((1.0, 0.0, 80.0), False))
    disk.full = True
    wb.poll(0)
    with pytest.raises(DiskError):
        wb.flush(10)  # the thread's failure, reported once
    wb.poll(10**6)
    disk.full = False
    assert wb.poll(2 * 10**9) == 0  # not due: nothing tried yet
    wb.poll(11 * 10**9)  # due: the refused batch goes again
    wb.flush(10)
    assert load_station(directory).polyaxis().position == pytest.approx((1.0, 0.0, 80.0))
    assert wb.close() is None


def test_a_pattern_log_the_disk_refuses_ends_the_pattern_and_says_so(tmp_path, monkeypatch):
    """The pattern's log fails after its first line: no further move is made (none the log
    could not record), the robot stopped where the first move ended, and a line says why."""
    import pyrt.robots.pattern as pattern

    real = pattern.PatternLog.write_back
    calls = [0]

    def full(self, changes):
        calls[0] += 1
        if calls[0] > 1:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(self.path))
        return real(self, changes)

    monkeypatch.setattr(pattern.PatternLog, "write_back", full)
    st = _station(tmp_path, "sync")
    r = st.start()
    pat = tmp_path / "p.pat"
    pat.write_text("p.log\n0 0 60\n0 0 80\n")
    try:
        r.call(st.polyaxis.run_command, "pattern", str(pat))
        r.wait_until(lambda: st.polyaxis.pattern_job.done, 600)
        assert not st.polyaxis.active and not st.motors_running()
        assert abs(st.polyaxis.position[2] - 60.0) < 1.0  # the second endpoint never started
        said = [m for m in r.messages() if "pattern abandoned" in str(m)]
        assert said == [f"{st.polyaxis.name}: pattern abandoned: pattern log {tmp_path / 'p.log'} "
                        f"failed: cannot write {tmp_path / 'p.log'}: {FULL}; the robot is "
                        "stopped where its last move ended"]
    finally:
        st.close()


# -- the journal and the black box -----------------------------------------------------------


class FullAfter(io.RawIOBase):
    """A journal's stream that takes ``writes`` writes, then fails as a full disk does."""

    def __init__(self, writes: int):
        self.writes = writes
        self.taken = 0

    def writable(self):
        return True

    def write(self, b):
        if self.writes <= 0:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        self.writes -= 1
        self.taken += len(b)
        return len(b)


def _gripper():
    st = build_gripper(Loop(SimClock()), boards="sim:")
    return st


def test_a_journal_the_disk_refuses_trips_its_station(tmp_path):
    """The journal's writes fail mid-run (while the jaws are driven): the station trips
    (source JOURNAL) with the journal's reason, the drive nulled in that tick; close
    says it (JournalError)."""
    st = _gripper()
    stream = FullAfter(1)  # the header, then no more room
    rec = Recorder(st, stream)
    header_room = stream.taken
    assert header_room == len(frame(KIND_HEADER, rec.journal.header.encode()))
    seen: list = []
    st.loop.fault_listeners.append(lambda f: seen.append((f, st.controller.dac)))
    st.runner.start()
    try:
        with contextlib.suppress(FaultError):
            st.runner.wait_until(lambda: bool(seen), 30)
        fault, dac = seen[0]
        assert fault.source == "JOURNAL" and dac == DAC_NULL
        assert fault.cause.endswith(f"write failed after {header_room} bytes: {FULL}; the "
                                    "journal ends there")
    finally:
        st.close()
        with pytest.raises(JournalError, match="No space left"):
            rec.close()


def test_a_journal_on_a_full_disk_is_refused_before_the_run(tmp_path):
    """A journal whose first bytes cannot be written is refused when it is made: the
    recorder is never attached, nothing runs."""
    st = _gripper()
    with pytest.raises(JournalError, match=re.escape(f"write failed after 0 bytes: {FULL}")):
        Recorder(st, FullAfter(0))
    st.close()


def test_a_black_box_the_disk_refuses_is_a_fault_and_is_said(tmp_path, monkeypatch):
    """The black box cannot be written: its line says which files and why, and (the
    first fault acknowledged meanwhile) the station trips again, source BLACKBOX."""
    FullDisk(monkeypatch, blackbox).full = True
    st = _gripper()
    rec = Recorder(st, None, black_box=BlackBox(1.0 + AFTER_S))
    box = FaultBox(rec, seconds=1.0, directory=tmp_path / "missing", plot=False)
    r = st.runner
    r.start()
    try:
        r.sleep(0.2)
        first = r.call(st.trip, "test fault")
        r.take_faults()
        r.call(st.acknowledge, take_fault=False)
        r.sleep(AFTER_S + 0.1)
        assert box.dumps[0].wait(60)
        with contextlib.suppress(FaultError):
            r.wait_until(lambda: st.fault is not None, 10)
        assert st.fault is not None and st.fault.id != first.id
        assert st.fault.source == "BLACKBOX"
        assert st.fault.cause.startswith(f"black box of fault {first.id}: not all written: ")
    finally:
        st.close()
        box.close()
        rec.close()
    said = [m for m in r.messages() if "not all written" in str(m)]
    assert said and str(said[0]).startswith(f"black box of fault {first.id}: ")


def test_quitting_at_once_writes_the_black_box_or_says_why_not(tmp_path, monkeypatch):
    """The operator quits right after a fault (the loop stopped before the black box was
    due): it is written then; one that cannot be is said through the closing output."""
    for full in (False, True):
        disk = FullDisk(monkeypatch, blackbox)
        disk.full = full
        st = _gripper()
        said: list[str] = []
        st.close_report = said.append
        rec = Recorder(st, None, black_box=BlackBox(1.0 + AFTER_S))
        box = FaultBox(rec, seconds=1.0, directory=tmp_path / f"full{full}", plot=False)
        (tmp_path / f"full{full}").mkdir()
        st.runner.start()
        st.runner.sleep(0.2)
        st.runner.call(st.trip, "test fault")
        st.runner.take_faults()
        st.close()  # at once: the black box was not due yet
        box.close()
        rec.close()
        (dump,) = box.dumps
        assert dump.done.is_set()
        if full:
            assert dump.path(".csv").exists() is False
            assert len(said) == 1 and "not all written" in said[0] and FULL[:23] in said[0]
        else:
            assert said == [] and dump.path(".csv").exists() and dump.path(".pj").exists()
        monkeypatch.undo()


# -- start-up ------------------------------------------------------------------------------


def test_locking_a_directory_on_a_full_disk_is_refused_in_a_sentence(tmp_path, monkeypatch):
    """The lock's pid cannot be written: ConfigError naming the directory and the
    reason, the lock released (a second try with room succeeds)."""
    real = os.pwrite

    def full(fd, data, offset):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(os, "pwrite", full)
    with pytest.raises(ConfigError, match=re.escape(
            f"cannot start on the station directory: writing .pyrt.lock failed: {FULL}")):
        lock_directory(tmp_path)
    monkeypatch.setattr(os, "pwrite", real)
    lock_directory(tmp_path).release()


def test_copying_the_packaged_station_onto_a_full_disk_is_refused(tmp_path, monkeypatch):
    """Seeding a working directory on a full disk: ConfigError naming the file, no traceback."""
    import pyrt.db._stations as stations

    FullDisk(monkeypatch, stations).full = True
    with pytest.raises(ConfigError, match="cannot copy the packaged prototype station here: "
                                          f"cannot write .*: {re.escape(FULL)}"):
        copy_station("prototype", tmp_path / "p")


# -- the command line --------------------------------------------------------------------


def _pyrt(script: str, argv: list[str], stdin: str, cwd: Path, timeout: float = 300):
    """``pyrt ARGV`` in a child whose disk is made full by ``script`` first."""
    code = textwrap.dedent(script) + textwrap.dedent(f"""
        import sys
        sys.argv = ["pyrt", *{argv!r}]
        from pyrt.cli import entry
        entry()
    """)
    return subprocess.run([sys.executable, "-c", code], input=stdin, capture_output=True,
                          text=True, timeout=timeout, cwd=cwd, check=False)


_WRITEBACK_FULL = """
    import errno, os
    import pyrt.db.station as s
    def full(path, data):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))
    s.atomic_write = full
"""


def test_cli_speed_max_full_disk_faults_refuses_the_next_move_and_quits_cleanly(tmp_path):
    """pyrt manipulator --speed max on a full disk: the fault's line (not an internal
    error), the next move refused, quit with status 0 and no traceback, the closing line
    saying the databases keep their last values."""
    directory = copy_station("prototype", tmp_path / "db")
    p = _pyrt(_WRITEBACK_FULL, ["manipulator", "--db", str(directory), "--speed", "max", "-k"],
              "prototype to 0 0 60\nwait\nprototype to 0 0 80\nstatus\nquit\n", tmp_path)
    out = p.stdout + p.stderr
    # the fault and the refused move fail the piped script: status 1 (-k: it runs to quit)
    assert p.returncode == 1, out
    assert "Traceback" not in out and "internal error" not in out
    assert re.search(re.escape(f"database write-back failed: cannot write {directory}/")
                     + r"[A-Z]+\.dat: " + re.escape(FULL), out), out
    assert "stopped by a fault" in out and "nothing moved" in out
    assert "FAULT" in out.split("status")[-1]
    assert f"databases in {directory} keep the values last written" in out


def test_cli_start_up_on_a_full_disk_is_one_sentence(tmp_path):
    """Start-up whose lock cannot be written: one line, status 1, no traceback."""
    directory = copy_station("prototype", tmp_path / "db")
    script = """
        import errno, os
        def full(fd, data, offset):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        os.pwrite = full
    """
    p = _pyrt(script, ["manipulator", "--db", str(directory), "--speed", "max"], "quit\n",
              tmp_path)
    assert p.returncode == 1 and "Traceback" not in p.stderr
    assert p.stderr.strip().splitlines() == [
        f"pyrt manipulator: {directory}: cannot start on the station directory: writing "
        f".pyrt.lock failed: {FULL}; write-back could not keep the databases either: free "
        "some space (or give another --db) first"]


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="needs /dev/full (Linux)")
def test_cli_journal_on_a_full_disk_is_refused_before_the_run(tmp_path):
    """--journal /dev/full (every write: ENOSPC): refused in one line before the robot
    powers up, status 1."""
    p = subprocess.run([sys.executable, "-m", "pyrt", "gripper", "--speed", "max",
                        "--journal", "/dev/full"], input="P E47A\nquit\n",
                       capture_output=True, text=True, timeout=120, cwd=tmp_path, check=False)
    assert p.returncode == 1 and "Traceback" not in p.stderr
    assert p.stderr.strip().splitlines()[-1] == (
        f"pyrt gripper: journal /dev/full: write failed after 0 bytes: {FULL}")
    assert "CMD:" not in p.stdout


@pytest.mark.wallclock
def test_cli_real_time_quit_at_once_says_the_black_box_it_could_not_write(tmp_path):
    """At real time, write-back and the black box on a full disk, the operator quitting at
    once after the fault: the black box's failure is said before the process exits."""
    directory = copy_station("prototype", tmp_path / "db")
    script = _WRITEBACK_FULL + """
    import pyrt.station.blackbox as b
    b.atomic_write = full
    """
    p = _pyrt(script, ["manipulator", "--db", str(directory), "--speed", "1",
                       "--black-box", "2", "-k"],
              "prototype to 0 0 60\nsleep 0.5\nquit\n", tmp_path, timeout=120)
    out = p.stdout + p.stderr
    # the fault fails the piped script: status 1 (-k: it runs to quit)
    assert p.returncode == 1 and "Traceback" not in out, out
    announced = [ln for ln in out.splitlines() if ln.startswith("black box of fault")]
    assert announced, out
    assert any("not all written" in ln and ".csv: No space left on device" in ln
               for ln in announced), out
