"""The black box on every fault: the journal's ring, every signal as CSV and PNG, within budget."""

from __future__ import annotations

import csv
import io
import re
import time
from pathlib import Path

import numpy as np
import pytest
from _manipulator_rig import TICK_NS
from hypothesis import given, settings
from hypothesis import strategies as hst

from pyrt.cli import main
from pyrt.cli._journal import add_journal_options, start_recorder
from pyrt.commands import RobotShell
from pyrt.component import Signal
from pyrt.db import copy_station
from pyrt.errors import ConfigError, FaultError
from pyrt.journal import DEFAULT_BUDGET, BlackBox, JournalReader
from pyrt.scheduler import Loop, SimClock, WallClock
from pyrt.station import blackbox
from pyrt.station.blackbox import (
    AFTER_S,
    SIGNAL_BUDGET,
    SIGNAL_RATE_HZ,
    TOTAL_BUDGET,
    FaultBox,
    FaultRecorder,
    SignalRing,
)
from pyrt.station.gripper import build_gripper
from pyrt.station.manipulator import ManipulatorStation
from pyrt.station.recording import Recorder

#: The span kept before a fault in most tests here (short: the tests run it first).
N_S = 3.0
#: How long a test waits for a black box's files: only a hang takes this long (a plot takes
#: seconds of CPU, and a loaded machine shares it).
HANG_S = 180.0


@pytest.fixture(autouse=True)
def _black_box_at_the_tests_priority(monkeypatch):
    """The black box's writer and plotting process at the tests' own priority.  pyrt lowers
    them (NICE, PLOT_NICE) so that a running station's loop never waits for them; with every
    core busy a process at nice 19 gets about 1 % of one, and a plot of 1.5 s of CPU takes
    minutes, past the plot's own bound: the machine's load, not what these tests check."""
    monkeypatch.setattr(blackbox, "NICE", 0)
    niced = f"os.nice({blackbox.PLOT_NICE})"
    assert niced in blackbox._CHILD
    monkeypatch.setattr(blackbox, "_CHILD", blackbox._CHILD.replace(niced, "os.nice(0)"))
LINE = re.compile(r"^black box of fault (\d+): (\S+)\.pj \((.*)\)$")


def gripper(seconds: float = N_S, loop: Loop | None = None, **kw):
    """A gripper on ``sim:`` with a process image and a black box of ``seconds``; started."""
    st = build_gripper(loop or Loop(SimClock()), boards="sim:")
    rec = FaultRecorder(st, None, black_box=BlackBox(seconds + AFTER_S), seconds=seconds, **kw)
    out = io.StringIO()
    shell = RobotShell(st, out)
    st.runner.start()
    shell.onecmd("I")
    assert out.getvalue().startswith("jaws wide open"), out.getvalue()
    return st, rec, shell


def manipulator(tmp_path: Path, seconds: float = N_S):
    """A prototype manipulator in a working copy under ``tmp_path``, with a black box; started."""
    directory = copy_station("prototype", tmp_path / "prototype")
    st = ManipulatorStation(directory, tick_ns=TICK_NS, boards="sim:")
    rec = FaultRecorder(st, None, black_box=BlackBox(seconds + AFTER_S), seconds=seconds)
    st.start()
    return st, rec


def jam_and_trip(st, shell) -> None:
    """A jammed motor under a P move whose MVJAWS is frozen: the stall watchdog trips."""
    shell.onecmd("sim fault jam")
    ctl = st.controller
    st.runner.call(lambda: ctl.move(-0x400))
    st.runner.sleep(0.05)
    st.runner.call(lambda: setattr(ctl.queue, "interrupts_enabled", False))
    with pytest.raises(FaultError, match="stall watchdog"):
        st.runner.wait_until(lambda: False, 30)


def trip(st, cause: str):
    """``station.trip(cause)`` in the loop; the fault taken (shown here, not raised later)."""
    fault = st.runner.call(st.trip, cause)
    assert st.runner.take_faults() == [fault]
    return fault


def read_csv(path: Path) -> tuple[list[str], np.ndarray]:
    """The CSV's header and its rows as numbers."""
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    return rows[0], np.array(rows[1:], dtype=float)


def check_journal(path: Path, fault) -> None:
    """The .pj reads back on its own, holds the fault's tick with its event, and N s before it."""
    reader = JournalReader(path)
    assert reader.complete
    ticks = list(reader.ticks())
    at = [t for t in ticks if t.tick == fault.tick]
    assert at and ("fault", fault.id, str(fault)) in [tuple(e) for e in at[0].events]
    assert ticks[0].keyframe and ticks[0].time_ns <= fault.time_ns - N_S * 1e9
    assert ticks[-1].time_ns >= fault.time_ns + AFTER_S * 1e9 - 2 * TICK_NS


def check_csv(path: Path, names: list[str], rate_hz: float) -> np.ndarray:
    """Header t_s and every signal; rows N s before the fault to AFTER_S after, at the rate."""
    header, table = read_csv(path)
    assert [h.split(" [")[0] for h in header] == ["t_s", *names]  # each with its units
    t = table[:, 0]
    dt = 1.0 / rate_hz
    assert -N_S <= t[0] <= -N_S + dt + 1e-9
    assert AFTER_S - 2 * dt <= t[-1] <= AFTER_S + dt
    assert np.allclose(np.diff(t), dt)
    return table


def test_a_jam_the_supervision_trips_writes_the_black_box(tmp_path, monkeypatch):
    """Gripper jam tripped by the stall watchdog: .pj/.csv/.png in the working directory, named
    in the line right after the fault's; the journal holds the fault, the CSV N s before it."""
    monkeypatch.chdir(tmp_path)
    st, rec, shell = gripper()
    try:
        st.runner.sleep(N_S + 1)
        jam_and_trip(st, shell)
        messages = st.runner.messages()
        st.runner.sleep(AFTER_S + 0.1)
        (dump,) = rec.fault_box.dumps
        assert dump.wait(HANG_S) and not dump.errors
    finally:
        st.shutdown()
        rec.close()
    fault = dump.fault
    k = next(i for i, m in enumerate(messages) if m.startswith("FAULT "))
    m = LINE.match(messages[k + 1])
    assert m is not None, messages
    assert m.group(1) == str(fault.id) and m.group(3) == "+ .csv, .png"
    pj = Path(m.group(2) + ".pj")
    assert pj == dump.path(".pj") and pj.parent == tmp_path.resolve()
    assert re.fullmatch(rf"gripper-fault-{fault.id}-\d{{8}}T\d{{6}}", pj.stem)
    assert sorted(p.name for p in tmp_path.iterdir()) == [pj.stem + x
                                                           for x in (".csv", ".pj", ".png")]
    assert dump.path(".png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    check_journal(pj, fault)
    ring = rec.fault_box.ring
    assert ring.rate_hz == SIGNAL_RATE_HZ and ring.every == 50  # 20 Hz at a 1 ms tick
    names = [n for n, s in st.signals() if not s.is_text]  # text signals: not sampled
    table = check_csv(dump.path(".csv"), names, ring.rate_hz)
    dac = table[:, names.index("gripper.dac") + 1]
    t = table[:, 0]
    assert (dac[t < -0.5] == 0x80).all() and (dac[(t > -0.3) & (t < 0)] != 0x80).all()
    assert (dac[t > 0.01] == 0x80).all()  # the reflex nulled the drive: the aftermath shows it


def test_a_manipulator_fault_is_written_beside_its_databases(tmp_path, monkeypatch):
    """Manipulator encoder slip mid-move: the black box lands in the station directory."""
    work = tmp_path / "cwd"
    work.mkdir()
    monkeypatch.chdir(work)
    st, rec = manipulator(tmp_path)
    shell = RobotShell(st, io.StringIO())
    r = st.runner
    try:
        shell.onecmd("sim fault axis1 slip 0.5")
        shell.onecmd("prototype to 0 0 60")
        with pytest.raises(FaultError, match="slip"):
            r.wait_until(lambda: False, 60)
        messages = r.messages()
        r.sleep(AFTER_S + 0.2)
        (dump,) = rec.fault_box.dumps
        assert dump.wait(HANG_S) and not dump.errors
    finally:
        st.close()
        rec.close()
    fault = dump.fault
    assert fault.time_ns > N_S * 1e9  # the ring was full before the fault
    assert list(work.iterdir()) == []
    assert dump.stem.parent == st.directory.resolve()
    assert sorted(p.suffix for p in st.directory.glob("prototype-fault-*")) == \
        [".csv", ".pj", ".png"]
    k = next(i for i, m in enumerate(messages) if m.startswith("FAULT "))
    assert messages[k + 1] == f"black box of fault {fault.id}: {dump.path('.pj')} (+ .csv, .png)"
    check_journal(dump.path(".pj"), fault)
    names = [n for n, s in st.signals() if not s.is_text]  # text signals: not sampled
    table = check_csv(dump.path(".csv"), names, rec.fault_box.ring.rate_hz)
    z = table[:, names.index("prototype.z") + 1]
    assert z[0] - z[-1] > 0.5  # the move down shows in the signals


def test_without_matplotlib_the_first_line_says_there_is_no_png(tmp_path, monkeypatch):
    """No matplotlib: .pj and .csv only; the first fault's line says why there is no PNG, once."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(blackbox, "plotting_available", lambda: False)
    st, rec, _ = gripper()
    lines = []
    try:
        for _ in range(2):
            st.runner.sleep(0.2)
            trip(st, "test fault")
            lines += [m for m in st.runner.messages() if m.startswith("black box")]
            st.runner.sleep(AFTER_S + 0.1)
            st.runner.call(st.acknowledge)
    finally:
        st.shutdown()
        rec.close()
    d1, d2 = rec.fault_box.dumps
    assert lines == [f"black box of fault {d1.fault.id}: {d1.path('.pj')} "
                     "(+ .csv; no PNG: matplotlib is not installed)",
                     f"black box of fault {d2.fault.id}: {d2.path('.pj')} (+ .csv)"]
    assert sorted(p.suffix for p in tmp_path.iterdir()) == [".csv", ".csv", ".pj", ".pj"]


def test_one_black_box_per_fault_episode(tmp_path, monkeypatch):
    """A fault while a black box is due is in that one; the same fault id twice is one."""
    monkeypatch.chdir(tmp_path)
    st, rec, _ = gripper()
    loop = st.loop
    try:
        st.runner.sleep(0.2)
        first = trip(st, "first")
        st.runner.call(loop.report_fault, first, take_fault=False)  # heard twice: still one
        second = st.runner.call(loop.make_fault, "gripper", "second", take_fault=False)
        st.runner.call(loop.report_fault, second, take_fault=False)
        st.runner.take_faults()
        lines = [m for m in st.runner.messages() if m.startswith("black box")]
        st.runner.sleep(AFTER_S + 0.1)
    finally:
        st.shutdown()
        rec.close()
    (dump,) = rec.fault_box.dumps
    assert lines == [f"black box of fault {first.id}: {dump.path('.pj')} (+ .csv, .png)",
                     f"black box of fault {second.id}: in that of fault {first.id}, "
                     f"{dump.path('.pj')}"]
    assert len(list(tmp_path.iterdir())) == 3
    events = [e for t in JournalReader(dump.path(".pj")).ticks() for e in t.events]
    assert [e.id for e in events] == [first.id, first.id, second.id]


def test_closing_first_writes_the_black_box_at_once(tmp_path, monkeypatch):
    """The recorder closed before the aftermath ran: the files are written then, up to the fault."""
    monkeypatch.chdir(tmp_path)
    st, rec, _ = gripper()
    st.runner.sleep(N_S + 0.5)
    fault = trip(st, "test fault")
    st.shutdown()
    rec.close()
    (dump,) = rec.fault_box.dumps
    assert dump.done.is_set() and not dump.errors
    assert {p.suffix for p in tmp_path.iterdir()} == {".pj", ".csv", ".png"}
    _, table = read_csv(dump.path(".csv"))
    dt = 1 / SIGNAL_RATE_HZ  # a sample period: the first and last rows are within one
    assert -N_S <= table[0, 0] < -N_S + dt and -dt - 0.001 < table[-1, 0] < 0.011
    ticks = list(JournalReader(dump.path(".pj")).ticks())
    assert any(e.id == fault.id for t in ticks for e in t.events)


def test_an_unwritable_directory_is_said_not_raised(tmp_path):
    """The files cannot be written: a line says which and why; the loop runs on."""
    st = build_gripper(Loop(SimClock()), boards="sim:")
    rec = Recorder(st, None, black_box=BlackBox(1.0))
    box = FaultBox(rec, directory=tmp_path / "missing", plot=True)
    st.runner.start()
    try:
        st.runner.sleep(0.2)
        fault = trip(st, "test fault")
        st.runner.sleep(AFTER_S + 0.1)
        assert box.dumps[0].wait(HANG_S)
        st.runner.sleep(0.1)
        assert st.loop.tick_index > fault.tick + box.after_ticks + 90
    finally:
        st.shutdown()
        box.close()
        rec.close()
    errors = [m for m in st.runner.messages() if "not all written" in m]
    assert len(errors) == 1 and errors[0].startswith(f"black box of fault {fault.id}: ")
    assert all(f"{box.dumps[0].stem.name}{x}: " in errors[0] for x in (".csv", ".png", ".pj"))
    assert "No such file or directory" in errors[0]
    assert box.dumps[0].written == [] and not (tmp_path / "missing").exists()


def test_a_recorder_without_a_black_box_is_refused():
    """A FaultBox needs the journal's black box: ConfigError, nothing attached."""
    st = build_gripper(Loop(SimClock()), boards="sim:")
    rec = Recorder(st, io.BytesIO())
    listeners = list(st.loop.fault_listeners)
    with pytest.raises(ConfigError, match="black box"):
        FaultBox(rec)
    assert st.loop.fault_listeners == listeners and rec.tick_listeners == []
    rec.close()
    st.shutdown()


# -- the signal ring -----------------------------------------------------------------------


class Values:
    """Signals over a list the test changes, one of them text, one that fails now and then."""

    def __init__(self, n: int):
        self.v = [0.0] * n
        self.mode = "idle"
        self.broken = False
        self.calls = 0

    def flaky(self) -> float:
        self.calls += 1
        if self.broken:
            raise RuntimeError("not now")
        return float(self.calls)

    def signals(self) -> list[tuple[str, Signal]]:
        out = [(f"obj.s{k}", Signal.item(f"s{k}", "cm", self.v, k)) for k in range(len(self.v))]
        out.append(("obj.mode", Signal("mode", "text", lambda: self.mode)))
        out.append(("obj.flaky", Signal("flaky", "counts", self.flaky)))
        return out


def test_signal_ring_keeps_numbers_leaves_text_out_and_survives_failing_reads():
    """Text signals are left out, a failing read is nan for that sample only, values in order."""
    vals = Values(3)
    ring = SignalRing(vals.signals(), 1.0, 1_000_000, extra_s=0.0, rate_hz=100.0)
    for k in range(100):
        vals.v[0] = k
        vals.v[2] = -k
        vals.broken = 30 <= k < 50
        ring.tick(k * 1_000_000)
    assert ring.every == 10 and ring.samples == 10 and ring.text == {3}
    t, v, cols = ring.window(ring.samples)
    assert t.tolist() == [k * 10_000_000 for k in range(10)]
    assert v.shape == (10, 4) and cols == [0, 1, 2, 4]
    assert v[:, 0].tolist() == [10.0 * k for k in range(10)]
    assert v[:, 2].tolist() == [-10.0 * k for k in range(10)]
    flaky = v[:, 3]
    assert np.isnan(flaky).tolist() == [False] * 3 + [True] * 2 + [False] * 5
    assert (np.diff(flaky[5:]) > 0).all()  # read again once it works


def test_signal_ring_window_drops_what_the_loop_overwrote():
    """A window older than the ring holds is cut to what is still there, oldest first."""
    vals = Values(1)
    ring = SignalRing(vals.signals()[:1], 0.05, 10_000_000, extra_s=0.0, rate_hz=100.0)  # a few rows
    for k in range(20):
        vals.v[0] = k
        ring.tick(k * 10_000_000)
    rows = ring.rows
    assert 3 <= rows <= 8 and ring.samples == 20
    _, v, _ = ring.window(20)
    assert v[:, 0].tolist() == list(range(21 - rows, 20))
    _, v, _ = ring.window(19)  # the oldest of these is being overwritten: left out
    assert v[:, 0].tolist() == list(range(21 - rows, 19))
    t, v, _ = ring.window(20, since_ns=17 * 10_000_000)
    assert v[:, 0].tolist() == [17.0, 18.0, 19.0] and t[0] == 17 * 10_000_000


@given(span=hst.floats(0.02, 0.2), taken=hst.integers(0, 60), back=hst.integers(0, 30),
       since=hst.integers(-5, 70))
@settings(max_examples=200, deadline=None)
def test_signal_ring_window_is_the_samples_still_there(span, taken, back, since):
    """Any fill and any window: exactly the samples not yet overwritten, in order, none newer
    than asked, none older than ``since_ns``; times and values agree."""
    vals = Values(2)
    ring = SignalRing(vals.signals()[:2], span, 10_000_000, extra_s=0.0, rate_hz=100.0)
    for k in range(taken):
        vals.v[0] = k
        vals.v[1] = 2 * k
        ring.sample(k * 10_000_000)
    end = max(0, taken - back)
    t, v, cols = ring.window(end, since_ns=since * 10_000_000)
    oldest = max(0, taken - ring.rows + 1, since)
    want = list(range(oldest, end))
    assert cols == [0, 1] and v[:, 0].tolist() == want and v[:, 1].tolist() == [2 * k for k in want]
    assert t.tolist() == [k * 10_000_000 for k in want]


@pytest.mark.parametrize("n, seconds", [(16, 10.0), (45, 600.0), (3000, 600.0)])
def test_signal_ring_fits_its_budget_by_lowering_the_rate(n, seconds):
    """Any number of signals and any span: the ring's memory stays within SIGNAL_BUDGET."""
    vals = Values(n)
    ring = SignalRing(vals.signals()[:n], seconds, 1_000_000)
    assert ring.nbytes <= SIGNAL_BUDGET and ring.rate_hz <= SIGNAL_RATE_HZ
    assert ring.rows >= min(seconds * ring.rate_hz, SIGNAL_BUDGET // (8 * (n + 1)))
    if n * seconds * SIGNAL_RATE_HZ * 8 > SIGNAL_BUDGET:
        assert ring.rate_hz < SIGNAL_RATE_HZ
    else:
        assert ring.rate_hz == SIGNAL_RATE_HZ


def test_both_rings_stay_within_the_stated_budget_over_ten_minutes(tmp_path):
    """A manipulator moving for 10 simulated minutes: journal ring + signal ring within budget."""
    st, rec = manipulator(tmp_path, seconds=10.0)
    box = rec.fault_box
    most = [0, 0]

    def watch(_tick: int, _now: int) -> None:
        most[0] = max(most[0], box.black_box.nbytes)
        most[1] = max(most[1], box.nbytes)

    rec.tick_listeners.append(watch)
    r = st.runner
    try:
        k = 0
        while st.loop.now_ns < 600e9:
            r.call(st.polyaxis.to, [(0.0, 0.0, 60.0), (0.0, 0.0, 120.0)][k % 2])
            k += 1
            r.wait_until(lambda: not st.polyaxis.active or st.loop.now_ns >= 600e9, 900)
        fault = trip(st, "test fault")
        r.sleep(AFTER_S + 0.1)
        assert box.dumps[0].wait(HANG_S) and not box.dumps[0].errors
    finally:
        st.close()
        rec.close()
    assert k >= 4  # it moved all along
    assert most[0] <= DEFAULT_BUDGET and most[1] <= TOTAL_BUDGET
    assert box.ring.nbytes <= SIGNAL_BUDGET and box.black_box.dropped > 0
    _, table = read_csv(box.dumps[0].path(".csv"))
    assert -10.0 <= table[0, 0] <= -9.98 and table[-1, 0] >= AFTER_S - 0.02
    ticks = list(JournalReader(box.dumps[0].path(".pj")).ticks())
    assert ticks[-1].time_ns - ticks[0].time_ns >= 10.5e9
    assert any(e.id == fault.id for t in ticks for e in t.events)


# -- the command line ----------------------------------------------------------------------


def options(*argv: str):
    import argparse

    p = argparse.ArgumentParser()
    p.add_argument("--speed", type=float, default=1.0)
    add_journal_options(p)
    return p, p.parse_args(list(argv))


def test_help_states_the_total_budget():
    """--black-box's help states both rings' budget and the files written."""
    p, _ = options()
    text = " ".join(p.format_help().split())
    assert f"at most {TOTAL_BUDGET >> 20} MiB in all" in text
    assert "NAME-fault-ID-TIME.pj" in text and ".csv" in text


@pytest.mark.parametrize("argv, seconds", [((), 10.0), (("--black-box", "4"), 4.0),
                                           (("--black-box", "off"), None),
                                           (("--speed", "0", "--black-box", "2"), 2.0),
                                           (("--speed", "0"), None),
                                           (("--journal", "run.pj", "--black-box", "off"), 0.0),
                                           (("--journal", "run.pj", "--black-box", "3"), 3.0)])
def test_start_recorder_attaches_the_black_box_as_asked(argv, seconds, tmp_path, monkeypatch):
    """--black-box SECONDS sets N (the journal's ring keeps the aftermath too); off: none (a
    journal alone if --journal is given)."""
    monkeypatch.chdir(tmp_path)
    st = build_gripper(Loop(SimClock()), boards="sim:")
    _, args = options(*argv)
    said: list[str] = []
    rec = start_recorder(st, args, "gripper", said.append)
    try:
        if seconds is None:
            assert rec is None
        elif seconds == 0.0:
            assert type(rec) is Recorder and rec.journal.black_box is None
        else:
            assert isinstance(rec, FaultRecorder)
            assert rec.fault_box.seconds == seconds
            assert rec.journal.black_box is not None
            assert rec.journal.black_box.seconds == seconds + AFTER_S
    finally:
        if rec is not None:
            rec.close()
        st.shutdown()
    assert (tmp_path / "run.pj").exists() == ("--journal" in argv)


@pytest.mark.wallclock
def test_a_fault_at_real_time_writes_the_black_box(tmp_path, monkeypatch):
    """WallClock: a jam the watchdog trips writes the black box while the loop runs on."""
    monkeypatch.chdir(tmp_path)
    st, rec, shell = gripper(seconds=1.0, loop=Loop(WallClock()))
    try:
        shell.onecmd("sim fault jam")
        ctl = st.controller
        st.runner.call(lambda: ctl.move(-0x400))
        st.runner.call(lambda: setattr(ctl.queue, "interrupts_enabled", False))
        deadline = time.monotonic() + HANG_S  # a bound for a hang only
        while not rec.fault_box.dumps and time.monotonic() < deadline:
            time.sleep(0.01)
        assert rec.fault_box.dumps, f"no fault within {HANG_S:g} s"
        dump = rec.fault_box.dumps[0]
        assert dump.wait(HANG_S) and not dump.errors
        assert st.runner.running
        messages = st.runner.messages()
    finally:
        st.shutdown()
        rec.close()
    assert dump.fault.source in ("stall watchdog", "P move")  # whichever bound first
    k = messages.index(f"FAULT {dump.fault}")
    assert messages[k + 1] == f"black box of fault {dump.fault.id}: {dump.path('.pj')} " \
        "(+ .csv, .png)"
    assert {p.suffix for p in tmp_path.iterdir()} == {".pj", ".csv", ".png"}
    ticks = list(JournalReader(dump.path(".pj")).ticks())
    assert any(e.id == dump.fault.id for t in ticks for e in t.events)
    _, table = read_csv(dump.path(".csv"))
    assert table[-1, 0] >= AFTER_S - 0.05


SCRIPT = "M\nC 45 18\nQ\nI\nP -1B86\nwait\nquit\n"  # WTCHJWSPD 18: the move oscillates


@pytest.mark.parametrize("given", ["2", "off"])
def test_pyrt_gripper_writes_the_black_box_of_a_fault_and_names_it(given, tmp_path, monkeypatch,
                                                                   capsys):
    """pyrt gripper --black-box 2: the supervision's fault is followed by the black-box line and
    the files are there when the run ends; --black-box off: neither."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr("sys.stdin", io.StringIO(SCRIPT))
    # the fault fails the piped script (status 1, docs/scripts.md); -k runs it to its quit
    assert main(["gripper", "--speed", "max", "--black-box", given, "-k"]) == 1
    out = capsys.readouterr().out.splitlines()
    k = next(i for i, line in enumerate(out) if line.startswith("fault: P move oscillating"))
    found = sorted(p.suffix for p in tmp_path.iterdir() if p.name.startswith("gripper-fault-1-"))
    if given == "off":
        assert not any(line.startswith("black box") for line in out) and found == []
        return
    assert out[k + 1].startswith("every motor stopped")
    m = LINE.match(out[k + 2])
    assert m is not None and m.group(1) == "1", out[k:]
    assert Path(m.group(2)).parent == tmp_path.resolve()
    assert found == [".csv", ".pj", ".png"]
    _, table = read_csv(Path(m.group(2) + ".csv"))
    dt = 1 / SIGNAL_RATE_HZ + 0.001  # within a sample period of the span's ends
    assert table[0, 0] == pytest.approx(-2.0, abs=dt) and table[-1, 0] >= -dt


def test_the_csv_header_gives_each_signals_units_as_the_scope_does():
    """The black box's CSV header: t_s, then OBJECT.SIGNAL [UNITS] (none where a signal has none)."""
    from pyrt.station.blackbox import _csv

    data = _csv(np.array([-0.1, 0.0]), np.array([[1.0, 2.0], [3.0, 4.0]]),
                ["gripper.encoder", "gripper.flags"], ["counts", ""]).decode()
    assert data.splitlines()[0] == "t_s,gripper.encoder [counts],gripper.flags"
    assert data.splitlines()[1] == "-0.1,1,2"


def test_the_png_title_is_the_whole_fault_wrapped_to_the_figures_width():
    """A long fault text is kept whole, on lines that each fit the PNG's width."""
    pytest.importorskip("matplotlib")
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from pyrt.station.blackbox import _title

    fault = ("gripper: STALL: P move oscillating about the target: error ±367 counts, 4 sign "
             "changes without decay; schedule SYSCLKPD 04 MVJAWSPD 0C SENSORPD 0A WTCHJWSPD 0B "
             "at tick 2543 (7.711845 s); every motor stopped")
    title = _title(fault)
    assert " ".join(title.split()) == " ".join(fault.split())
    fig = Figure(figsize=(10, 3))
    canvas = FigureCanvasAgg(fig)
    shown = fig.suptitle(title, fontsize="small")
    canvas.draw()
    box = shown.get_window_extent(canvas.get_renderer())
    assert box.x0 >= 0 and box.x1 <= fig.bbox.width


def test_signal_ring_packs_every_number_and_a_passing_none_is_nan_for_its_sample_only():
    """All-number signals are packed straight into the ring; a value that is briefly None
    is nan in that sample alone, the others and the later samples keep their numbers."""
    v = [0.0, 0.0]
    signals = [(f"obj.s{k}", Signal.item(f"s{k}", "cm", v, k)) for k in range(2)]
    ring = SignalRing(signals, 1.0, 10_000_000, extra_s=0.0)
    for k in range(6):
        v[0] = float(k)
        v[1] = None if k == 2 else k * 0.5  # type: ignore[call-overload]
        ring.sample(k * 10_000_000)
    t, values, cols = ring.window(ring.samples)
    assert cols == [0, 1] and t.tolist() == [k * 10_000_000 for k in range(6)]
    assert values[:, 0].tolist() == [0.0, 1.0, 2.0, 3.0, 4.0, 5.0]
    assert np.isnan(values[:, 1]).tolist() == [False, False, True, False, False, False]
    assert values[[0, 1, 3, 4, 5], 1].tolist() == [0.0, 0.5, 1.5, 2.0, 2.5]


def test_the_signal_ring_leaves_a_text_signal_out_without_reading_it():
    """A text signal (a robot's where) is not a column of the black box's ring and is never read by it: the ring samples numbers."""
    reads = []
    x = [1.0]
    sigs = [("r.x", Signal("x", "mm", lambda: x[0])),
            ("r.where", Signal.text("where", lambda: reads.append(1) or "here"))]
    ring = blackbox.SignalRing(sigs, 1.0, 1_000_000)
    for k in range(5):
        x[0] = float(k)
        ring.sample(k * 1_000_000)
    _t, v, cols = ring.window(ring.samples)
    assert cols == [0] and ring.text == {1} and reads == []
    assert v[:, 0].tolist() == [0.0, 1.0, 2.0, 3.0, 4.0]
