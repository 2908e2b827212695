"""The Arg grammar's ranges: checked before a handler runs, shown in help."""

from __future__ import annotations

import io
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pyrt.component import (
    PREPARE_TRIES,
    Arg,
    Component,
    Prepared,
    Snapshot,
    Stale,
    command,
    finite,
    run_prepared,
    serve_prepared,
)
from pyrt.errors import CommandError


class Rope(Component):
    """A component with a fixed and an object-held range."""

    name = "rope"

    def __init__(self) -> None:
        self.span = (10.0, 20.0)
        self.got: list[object] = []

    @command(Arg("LEN", str, lo=0.0, units="cm", bounds="span", what="the rope"), name="to")
    def to(self, length: str) -> None:
        """to LEN: go to LEN."""
        self.got.append(length)

    @command(Arg("V", finite("speed"), lo=0.07, hi=7.0, units="cm/s"), name="speed")
    def speed(self, v: float) -> None:
        """speed V: set the speed."""
        self.got.append(v)

    @command(Arg("NAME", str), name="plain")
    def plain(self, name: str) -> None:
        """plain NAME: no range."""
        self.got.append(name)


def test_range_is_in_help_and_read_from_the_object():
    """The summary shows each range; a 'bounds' range is read when the records are made."""
    r = Rope()
    assert r.find_command("to").summary == "to LEN: go to LEN [LEN 10..20 cm (the rope)]"
    assert "Range: V 0.07..7 cm/s." in r.find_command("speed").help
    r.span = (1.0, 2.0)
    assert r.find_command("to").args[0].range_text == "LEN 1..2 cm (the rope)"
    assert r.find_command("plain").summary == "plain NAME: no range."


@pytest.mark.parametrize("words,match", [
    (["to", "1e300"], r"rope to: LEN 1e\+300 is out of range: LEN 10..20 cm \(the rope\)"),
    (["to", "1e400"], "LEN must be a number"),
    (["to", "nan"], "LEN must be a number"),
    (["to", "9.99"], "out of range"),
    (["speed", "8"], r"V 8 is out of range: V 0.07..7 cm/s"),
])
def test_out_of_range_never_reaches_the_handler(words, match):
    """A value outside its range (or not a finite number) is a CommandError naming the
    range; the handler never runs."""
    r = Rope()
    with pytest.raises(CommandError, match=match):
        r.run_command(*words)
    assert r.got == []


@settings(max_examples=200, derandomize=True, deadline=None)
@given(text=st.one_of(st.text(max_size=12),
                      st.floats(allow_nan=True, allow_infinity=True).map(repr)))
def test_any_text_is_accepted_in_range_or_refused_cleanly(text):
    """Any word given for a ranged argument is either a finite number inside the range
    (handed on) or a CommandError; nothing else escapes."""
    r = Rope()
    try:
        r.run_command("to", text)
    except CommandError:
        assert r.got == []
        return
    v = float(r.got[0])  # type: ignore[arg-type]
    assert math.isfinite(v) and 10.0 <= v <= 20.0


# -- text signals ------------------------------------------------------------------------


def test_a_text_signal_is_read_and_shown_as_text_and_never_sampled():
    """Signal.text: kind text, units text, format gives the text as it is ('' when empty), scope_source refuses with CommandError naming it."""
    from pyrt.component import Signal

    said = ["at home"]
    s = Signal.text("where", lambda: said[0], "where the robot is")
    assert s.is_text and s.units == "text" and s.length == 0
    assert s.format(s.read()) == "at home"
    said[0] = ""
    assert s.format(s.read()) == "''"
    with pytest.raises(CommandError, match=r"where is text \(where the robot is\): the scope "
                                           "samples numbers"):
        s.scope_source()
    assert not Signal("x", "mm", lambda: 1.0).is_text


@pytest.mark.parametrize("kw", [{"kind": "string"}, {"kind": "", "length": 10},
                                {"kind": "text", "length": -1}])
def test_a_signal_of_an_unknown_kind_or_a_length_that_bounds_no_text_is_refused(kw):
    """kind must be '' or 'text'; a length only bounds a text signal and is not negative."""
    from pyrt.component import Signal

    with pytest.raises(ValueError, match="signal 'v'"):
        Signal("v", "text", lambda: "", **kw)


class Planned(Component):
    """A component whose ``go`` is prepared in the caller's thread."""

    name = "planned"

    def __init__(self) -> None:
        self.version = 0
        self.log: list[tuple[str, object]] = []
        #: Something to do between a snapshot and its hand-over (once), or None.
        self.between: object = None

    def take(self) -> int:
        self.log.append(("snapshot", self.version))
        return self.version

    def work(self, snap: int, x: float) -> tuple[int, float]:
        self.log.append(("prepare", snap))
        return snap, 2 * x

    @command(Arg("X", float, lo=0.0, hi=10.0), name="go", moves=True, prepare="work",
             snapshot="take")
    def go(self, work: tuple[int, float]) -> str:
        """go X: prepared, then handed over."""
        snap, value = work
        if callable(self.between):
            act, self.between = self.between, None
            act()
        if snap != self.version:
            raise Stale("planned: changed meanwhile")
        self.version += 1
        return f"went {value:g}"


def test_a_prepared_command_takes_its_snapshot_prepares_then_hands_over():
    """A record with prepare: the snapshot, then prepare (with the snapshot and the parsed arguments), then the handler with prepare's result; run_command and serve_prepared do the same in one thread."""
    p = Planned()
    rec = p.find_command("go")
    assert rec is not None and rec.prepare is not None and rec.snapshot is not None
    assert "Range: X 0..10" in rec.help
    assert p.run_command("go", "3") == "went 6"
    assert p.log == [("snapshot", 0), ("prepare", 0)]
    calls: list[object] = []

    def call(arg: object) -> object:
        calls.append(type(arg).__name__)
        return serve_prepared(rec, [arg], kept)

    kept: dict[int, object] = {}
    assert run_prepared(rec, rec.parse(["4"]), call) == "went 8"
    assert calls == ["Snapshot", "Prepared"] and kept == {}


def test_a_stale_snapshot_is_prepared_again_then_refused():
    """The handler says Stale: prepared again from a new snapshot (it then succeeds); stale every time: refused after PREPARE_TRIES with a clear error."""
    p = Planned()
    rec = p.find_command("go")
    assert rec is not None

    def bump() -> None:
        p.version += 1

    p.between = bump
    assert p.run_command("go", "1") == "went 2"
    assert [w for w, _ in p.log].count("prepare") == 2

    class Always(Planned):
        @command(Arg("X", float), name="go", moves=True, prepare="work", snapshot="take")
        def go(self, work: tuple[int, float]) -> str:
            """go X: never holds."""
            raise Stale("always")

    a = Always()
    with pytest.raises(CommandError, match="refused: the motion queue kept changing"):
        a.run_command("go", "1")
    assert [w for w, _ in a.log].count("prepare") == PREPARE_TRIES


def test_a_replayed_hand_over_prepares_again_from_the_snapshot_taken_at_its_tick():
    """A Prepared without its work (what a journal keeps) is prepared from the snapshot the loop kept under its number, giving the same result."""
    p = Planned()
    rec = p.find_command("go")
    assert rec is not None
    kept: dict[int, object] = {}
    assert serve_prepared(rec, [Snapshot(7)], kept) == 0
    assert serve_prepared(rec, [Prepared(7, (5.0,))], kept) == "went 10"
    assert kept == {}


def test_a_command_named_alone_is_the_record_the_whole_list_gives():
    """find_command and the shell's word (any case, name or alias) give the record the
    whole list of records gives for that name; an unknown name gives None."""
    from pyrt.commands import RobotShell
    from pyrt.component import record_named, records_of, walk
    from pyrt.scheduler import Loop, SimClock
    from pyrt.station.gripper import build_gripper

    station = build_gripper(Loop(SimClock()))
    try:
        checked = 0
        for comp in {id(c): c for root in station.components() for c in walk(root)}.values():
            for rec in comp.commands():
                for name in (rec.name, rec.name.upper(), *rec.aliases):
                    first = next(c for c in comp.commands() if c.answers_to(name))
                    assert comp.find_command(name) == first
                    checked += 1
            assert comp.find_command("no-such-command") is None
        shell = RobotShell(station, io.StringIO())
        for rec in records_of(shell, ""):
            for name in (rec.name, rec.name.title(), *rec.aliases):
                assert shell.word(name) == record_named(shell, name, "") == next(
                    w for w in shell.words() if w.answers_to(name))
                checked += 1
        assert shell.word("no-such-word") is None
        assert checked > 40
    finally:
        station.close()
