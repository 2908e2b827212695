"""The arm's kept journal (tests/journals/arm.pj, recorded at real time by
tests/journals/record.py): a move, a jammed shoulder that trips the following error, ack
and stop replay identically; a changed servo gain is caught at its first tick."""

from __future__ import annotations

import dataclasses
import json
import re
from pathlib import Path

import pyrt.cli
import pytest
from pyrt.journal import JournalReader, Tick

arm_station = pytest.importorskip("pyrt_arm.station")

JOURNAL = Path(__file__).resolve().parents[3] / "tests" / "journals" / "arm.pj"

_DIFFERS = re.compile(r"replay differs at tick (?P<tick>\d+): output (?P<reg>\S+): "
                      r"recorded (?P<rec>-?\d+) \(written by (?P<rec_by>[^)]+)\), "
                      r"replayed (?P<rep>-?\d+) \(written by (?P<rep_by>[^)]+)\) "
                      r"\((?P<n>\d+) ticks replayed\)$")


def replay(capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    """``pyrt replay arm.pj`` in this process: its status and its last line."""
    rc = pyrt.cli.main(["replay", str(JOURNAL)])
    out = capsys.readouterr().out.strip().splitlines()
    assert out, "the replay said nothing"
    return rc, out[-1]


def ticks() -> list[Tick]:
    reader = JournalReader(JOURNAL)
    out = [t for t in reader if isinstance(t, Tick)]
    assert reader.complete and not reader.gaps
    return out


def first_tick(ts: list[Tick], source: str, text: str = "") -> int:
    """The tick of the first request from ``source`` whose text holds ``text`` (-1: none)."""
    return next((t.tick for t in ts for c in t.commands
                 if c.source == source and text in c.text), -1)


def test_the_arm_journal_replays_identically(capsys):
    """The real-time run replays on virtual time: every drive, enable and the fault, identical."""
    rc, line = replay(capsys)
    s = JournalReader(JOURNAL).summary()
    assert rc == 0, line
    assert line == f"replayed {s.ticks} ticks (ticks 0..{s.last_tick}), identical"


def test_the_arm_journal_holds_a_move_the_jam_the_following_error_ack_and_stop():
    """At real time, in order: a move, sim fault jam q0, the following error with its message, ack, stop."""
    reader = JournalReader(JOURNAL)
    assert reader.header.station == "arm"
    assert reader.header.metadata["args"]["speed"] == 1.0
    ts = ticks()
    move = first_tick(ts, "arm to")
    jam = next(t.tick for t in ts for c in t.commands
               if c.source == "sim fault" and json.loads(c.text)["a"][2] == ["jam", "q0"])
    faults = [(t.tick, e.message) for t in ts for e in t.events if e.name == "fault"]
    assert len(faults) == 1
    tick, message = faults[0]
    assert message.startswith(f"arm: fault in shoulder at tick {tick} ")
    assert ": q0 following error -" in message and "exceeds the limit 1.000 deg" in message
    ack = first_tick(ts, "ack", '"m":"acknowledge"')
    stop = first_tick(ts, "stop", '"m":"stop"')
    assert 0 <= move < jam < tick < ack < stop


def test_a_patched_shoulder_gain_is_caught_at_the_first_tick_it_changes(monkeypatch, capsys):
    """The shoulder's kp half as large again: the replay names the first drive it changes and the servo task."""
    stiffer = dataclasses.replace(arm_station.SHOULDER,
                                  kp_nm_per_deg=arm_station.SHOULDER.kp_nm_per_deg * 1.5)
    monkeypatch.setattr(arm_station, "SHOULDER", stiffer)
    rc, line = replay(capsys)
    assert rc == 1
    m = _DIFFERS.match(line)
    assert m, line
    tick = int(m["tick"])
    assert int(m["n"]) == tick and tick >= first_tick(ticks(), "arm to")
    assert m["reg"] == "servo.drive[0]" and m["rec_by"] == m["rep_by"] == "servo"
    assert m["rec"] != m["rep"]
    reader = JournalReader(JOURNAL)
    t = next(t for t in reader if isinstance(t, Tick) and t.tick == tick)
    reg = list(reader.header.outputs).index(m["reg"])
    assert (reg, int(m["rec"]), "servo") in [(i, v, reader.writers[w]) for i, v, w in t.outputs]
