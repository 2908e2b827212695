"""pyrt urdf's black box replays: the PUMA's snapshot resumes a run mid-move, identically."""

from __future__ import annotations

import io
import subprocess
import sys
from pathlib import Path

import pytest
from _replay_rig import assert_each_snapshot_replays

from pyrt.cli import main
from pyrt.commands import RobotShell
from pyrt.journal import JournalReader
from pyrt.scheduler import Loop, SimClock
from pyrt.station.recording import Recorder
from pyrt.station.snapshot import Snapshot, take_snapshot
from pyrt.station.urdf import build_urdf

#: A bound only a hang reaches (a recorded run on virtual time takes seconds).
HANG_S = 600

#: Joint moves, a pose move, straight lines queued to blend, a stop mid-line, a tool
#: frame and a gain changed, a conveyor tracked, and a following-error fault (the tool
#: driven into the table) and its ack.
SCRIPT = ("puma560 movej 10 30 -150 20 -30 40", "wait",
          "puma560 moveto 450 -150 450 160 20 45", "wait",
          "puma560 movel 450 150 450 160 20 45", "puma560 movel 350 150 300 150 20 60",
          "sleep 0.4", "stop", "wait",
          "puma560 tool 0 0 50 0 0 0", "set puma560.bandwidth 10",
          "puma560 movej -20 60 -170 -30 -50 -40", "wait",
          "puma560 moveto 450 -150 450 160 20 45", "wait",
          "puma560 conveyor 0 20 0", "puma560 movel 450 -100 450 160 20 45", "wait",
          "sleep 0.3", "puma560 movej 0 30 -160 0 -40 0", "wait",
          "puma560 conveyor 0 0 0", "sim table 350",
          "puma560 moveto 450 -150 250 160 20 45", "wait", "ack", "sim table off",
          "puma560 movej 10 30 -150 20 -30 40", "wait")


def _pyrt(tmp_path: Path, stdin: str, *argv: str, status: int) -> str:
    done = subprocess.run([sys.executable, "-m", "pyrt", *argv], input=stdin,
                          capture_output=True, text=True, cwd=tmp_path, timeout=HANG_S)
    assert done.returncode == status, done.stdout + done.stderr
    return done.stdout


def test_a_puma_black_box_replays_its_fault_identically(tmp_path, capsys):
    """pyrt urdf (the PUMA) on virtual time: joint, pose and line moves, then a pose move
    into the table that trips the following error; pyrt replay NAME-fault-ID.pj resumes
    from the box's snapshot mid-run and replays through the fault, identical."""
    script = "\n".join((
        "puma560 movej 10 30 -150 20 -30 40", "wait",
        "puma560 moveto 450 -150 450 160 20 45", "wait",
        "puma560 movel 450 150 450 160 20 45", "puma560 movel 350 150 300 150 20 60", "wait",
        "puma560 moveto 450 -150 450 160 20 45", "wait",
        "sim table 400", "puma560 moveto 450 -150 300 160 20 45", "wait", ""))
    out = _pyrt(tmp_path, script, "urdf", "--speed", "max", "--black-box", "3", status=1)
    assert "FAULT: joint joint2: following error" in out
    (pj,) = tmp_path.glob("puma560-fault-*.pj")
    reader = JournalReader(pj)
    (snap_tick, _data), = reader.snapshots
    fault = next(t.tick for t in reader.ticks() for e in t.events if e.name == "fault")
    summary = reader.summary()
    assert summary.first_tick < snap_tick < fault <= summary.last_tick  # it starts mid-run
    status = main(["replay", str(pj)])
    out, err = capsys.readouterr()
    assert status == 0, out + err
    assert f"replayed {summary.last_tick - snap_tick + 1} ticks (ticks {snap_tick}.." \
           f"{summary.last_tick}), identical" in out


def _run(shell: RobotShell, lines) -> None:
    for line in lines:
        if line.startswith("sleep "):
            shell.station.runner.sleep(float(line.split()[1]))
        else:
            shell.onecmd(line)


@pytest.mark.parametrize("hardware, every, least", [("b", 691, 12), ("a", 1499, 5)],
                         ids=["passive-board", "motion-control-board"])
def test_a_full_run_replays_identically_from_each_of_its_snapshots(tmp_path,
                                                                   hardware, every, least):
    """Snapshots taken every few hundred ticks of a PUMA run (power-on, joint and pose
    moves, blended lines, a stop mid-line, a tool frame and a gain set, a conveyor
    tracked, a fault and its ack): a replay that resumes from any of them is identical
    to the end, so the snapshot holds all the arm's state (the servo's C state, its
    encoders' totals, the motion under way, a command's snapshot awaiting its commit); on
    either of 004's boards."""
    st = build_urdf(Loop(SimClock()), boards="sim:", hardware=hardware)
    pj = tmp_path / "run.pj"
    rec = Recorder(st, pj, metadata={"factory": "urdf", "args": {"hardware": hardware}})
    shell = RobotShell(st, io.StringIO())
    snaps: list[Snapshot] = []
    # every: not a multiple of the trajectory's 10 ticks (snapshots between its ticks)

    def grab(tick: int, now_ns: int) -> None:
        if tick % every == 3:
            snaps.append(take_snapshot(st, rec.image.last_inputs, rec.image.output_values()))

    rec.tick_listeners.append(grab)
    try:
        st.runner.start()
        _run(shell, SCRIPT)
    finally:
        st.close()
        rec.close()
    taken = [s for s in snaps if not s.refused]
    assert len(taken) >= least and len(taken) == len(snaps), [s.refused for s in snaps]
    assert_each_snapshot_replays(pj, taken, st.name, tmp_path)
