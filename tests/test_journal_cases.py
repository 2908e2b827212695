"""Kept journals as regression cases: real-time runs of the gripper and the manipulator,
each with a move, an injected fault, its ack and a stop, replay identically; a changed
gain is caught at the first tick it changes, naming the register and the task.

The journals are in tests/journals/ (tests/journals/record.py records them again,
and says when one must)."""

from __future__ import annotations

import dataclasses
import json
import re
from pathlib import Path
from typing import NamedTuple

import pytest

import pyrt.cli
from pyrt.cli.replay import _arguments
from pyrt.journal import Command, JournalReader, Tick
from pyrt.native import FuzzyParams
from pyrt.scheduler import Loop
from pyrt.station.factory import find_station
from pyrt.station.replay import Replay
from pyrt.tasks import jawmove

JOURNALS = Path(__file__).resolve().parent / "journals"

#: "replay differs at tick N: output REG: recorded V (written by TASK), replayed W (...)"
_DIFFERS = re.compile(r"replay differs at tick (?P<tick>\d+): output (?P<reg>\S+): "
                      r"recorded (?P<rec>-?\d+) \(written by (?P<rec_by>[^)]+)\), "
                      r"replayed (?P<rep>-?\d+) \(written by (?P<rep_by>[^)]+)\) "
                      r"\((?P<n>\d+) ticks replayed\)$")
_IDENTICAL = re.compile(r"replayed (?P<n>\d+) ticks \(ticks 0\.\.(?P<last>\d+)\), identical$")


class Case(NamedTuple):
    file: str
    station: str
    #: The injected fault's request (``sim fault ...``), as the console gave it.
    injected: tuple[str, ...]
    #: What the fault's message says.
    fault: str
    #: The station's command a move is.
    move: str


CASES = {
    "gripper": Case("gripper.pj", "gripper", ("jam",),
                    "P move oscillating about the target: error ±", '{"$r":"P"}'),
    "manipulator": Case("manipulator.pj", "prototype", ("axis0", "slip", 0.3),
                        "axis0: position estimate lost: distErr", '{"$r":"to"}'),
}


def replay(path: Path, capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    """``pyrt replay PATH`` in this process: its status and its last line."""
    rc = pyrt.cli.main(["replay", str(path)])
    out = capsys.readouterr().out.strip().splitlines()
    assert out, "the replay said nothing"
    return rc, out[-1]


def ticks(path: Path) -> list[Tick]:
    reader = JournalReader(path)
    out = [t for t in reader if isinstance(t, Tick)]
    assert reader.complete and not reader.gaps
    return out


def first(ts: list[Tick], pred) -> tuple[int, Command | None]:
    """The first tick (and its command) whose command satisfies ``pred``."""
    for t in ts:
        for c in t.commands:
            if pred(c):
                return t.tick, c
    return -1, None


def replayed_until(path: Path, until: int, tmp: Path):
    """The station of ``path`` replayed up to and including tick ``until`` (as
    ``pyrt replay --until`` builds and runs it), and the replay's verdict."""
    rp = Replay(path)
    factory = find_station(rp.factory)
    args = _arguments(rp, factory, str(tmp))
    factory.configure(args, lambda line: None)
    loop = Loop(rp.clock, period_ns=rp.header.period_ns, timing=True)
    with rp.building():
        station = factory.build(loop, args)
    rp.attach(station)
    result = rp.run(until)
    rp.close()
    return station, result


def check_difference(line: str, path: Path, not_before: int) -> re.Match[str]:
    """``line`` names a real first difference: the journal's tick N has the recorded write
    (register, value, task), every tick before it replayed, N at or after ``not_before``."""
    m = _DIFFERS.match(line)
    assert m, line
    tick = int(m["tick"])
    assert int(m["n"]) == tick  # ticks 0..N-1 were identical
    assert tick >= not_before
    assert m["rec"] != m["rep"]
    reader = JournalReader(path)
    t = next(t for t in reader if isinstance(t, Tick) and t.tick == tick)
    reg = list(reader.header.outputs).index(m["reg"])
    writes = [(i, v, reader.writers[w]) for i, v, w in t.outputs]
    assert (reg, int(m["rec"]), m["rec_by"]) in writes
    return m


@pytest.mark.parametrize("name", sorted(CASES))
def test_kept_journal_replays_identically(name, capsys):
    """Each kept real-time journal replays on virtual time: every output and fault, identical."""
    path = JOURNALS / CASES[name].file
    rc, line = replay(path, capsys)
    assert rc == 0, line
    m = _IDENTICAL.match(line)
    assert m, line
    s = JournalReader(path).summary()
    assert int(m["n"]) == s.ticks and int(m["last"]) == s.last_tick


@pytest.mark.parametrize("name", sorted(CASES))
def test_kept_journal_holds_a_move_the_fault_the_ack_and_a_stop(name):
    """The run was at real time, and in order: a move, the injected fault, the trip with its message, ack, stop."""
    case = CASES[name]
    path = JOURNALS / case.file
    reader = JournalReader(path)
    assert reader.header.station == case.station
    assert reader.header.metadata["args"]["speed"] == 1.0
    assert path.stat().st_size < 200_000
    ts = ticks(path)
    move, _ = first(ts, lambda c: case.move in c.text)
    injected, c = first(ts, lambda c: '{"$r":"fault"}' in c.text)
    assert c is not None and json.loads(c.text)["a"][2] == list(case.injected)
    faults = [(t.tick, e) for t in ts for e in t.events if e.name == "fault"]
    assert len(faults) == 1
    fault_tick, event = faults[0]
    assert event.message.startswith(f"{case.station}: fault in ")
    assert f"at tick {fault_tick} " in event.message and case.fault in event.message
    ack, c = first(ts, lambda c: c.source == "ack")
    assert c is not None and '"m":"acknowledge"' in c.text
    stop, c = first(ts, lambda c: c.source == "stop" and '"m":"stop"' in c.text)
    assert 0 <= move < injected < fault_tick < ack < stop


def test_the_jammed_move_ended_short_by_the_stopped_bit_in_the_replay(tmp_path):
    """Replayed up to the jam's clearing, the jammed move ended where the jam held it, by STOPCNT."""
    ts = ticks(JOURNALS / "gripper.pj")
    jam, _ = first(ts, lambda c: '{"$r":"fault"},["jam"]' in c.text)
    cleared, _ = first(ts, lambda c: '{"$r":"fault"},["none"]' in c.text)
    station, result = replayed_until(JOURNALS / "gripper.pj", cleared - 1, tmp_path)
    try:
        assert result.identical and result.last_tick == cleared - 1
        assert station.last_move is not None
        report = station.last_move.report[0]
        assert report.startswith("stopped short of the target by ")
        assert "(the stopped bit ended the move (STOPCNT ran out))" in report
        assert station.fault is None and station.controller.dac == 0x80
        assert jam < cleared
    finally:
        station.close()


def test_a_patched_jaw_gain_is_caught_at_the_first_tick_it_changes(monkeypatch, capsys):
    """MVJAWS driving twice the error: the replay stops at the first DAC byte it changes, naming MVJAWS."""
    excess128 = jawmove.excess128
    monkeypatch.setattr(jawmove, "excess128", lambda v: excess128(2 * v))
    path = JOURNALS / "gripper.pj"
    rc, line = replay(path, capsys)
    assert rc == 1
    move, _ = first(ticks(path), lambda c: '{"$r":"P"}' in c.text)
    m = check_difference(line, path, not_before=move)
    assert m["reg"] == "gripper.dac" and m["rec_by"] == m["rep_by"] == "MVJAWS"


def test_a_patched_fuzzy_gain_is_caught_at_the_first_tick_it_changes(monkeypatch, capsys):
    """Every rope's length gain (dv_length) half as large again: the replay names the first
    changed motor register and the POLYAXIS task."""
    from_mapping = FuzzyParams.from_mapping.__func__

    def stronger(cls, values, base=None):
        p = from_mapping(cls, values, base)
        return dataclasses.replace(p, dv_length=p.dv_length * 1.5)

    monkeypatch.setattr(FuzzyParams, "from_mapping", classmethod(stronger))
    path = JOURNALS / "manipulator.pj"
    rc, line = replay(path, capsys)
    assert rc == 1
    move, _ = first(ticks(path), lambda c: '{"$r":"to"}' in c.text)
    m = check_difference(line, path, not_before=move)
    assert m["reg"].startswith("tio10.") and m["rec_by"] == m["rep_by"] == "POLYAXIS"
