"""The station conformance suite, for a station of one's own: ``pyrt.testing``.

Every station pyrt ships passes it, and so can yours: subclass
:class:`StationConformance` in your tests (its name starting ``Test``, as
pytest collects classes) and say how to build the station and how its
simulated world tells whether anything is driven::

    # tests/test_conformance.py of your package
    from pyrt import Loop, SimClock
    from pyrt.testing import StationConformance

    from my_robot.station import build_my_robot


    class TestMyRobotConformance(StationConformance):
        samples = {"MyController.speed": [["3"]]}  # arguments of records that need some

        def build(self, tmp_path):
            return build_my_robot(Loop(SimClock()))  # started by the suite

        def driven(self, station):  # the simulation's truth: what is driven now
            return [f"drive {j}" for j, v in enumerate(station.board.drives) if v]

        def settings(self, station):  # what a reading command must leave as it is
            return tuple(station.board.registers()), len(station.motion)

        def start_move(self, station, runner):  # a move under way, for the reflex check
            runner.call(station.controller.run_command, "to", "30", "60")
            assert runner.wait_until(lambda: bool(self.driven(station)), 5.0)

Then ``pytest`` runs every check on it (needs pytest and hypothesis:
``pip install 'pyrt[testing]'``):

* every component has a name, unique in the station;
* every command record has help, a grammar of named arguments, and a class
  that obeys the rule: ``reads_only`` changes nothing and is allowed while
  faulted and to any client; ``moves`` is refused while faulted and never
  ``anyone``; only ``stop`` may be ``anyone`` without reading only;
* a record not marked ``moves``, run with sample arguments on a robot at
  rest, starts no actuator (the simulation's truth, :meth:`driven`);
* a ``reads_only`` record leaves :meth:`settings` as they were, in the tick;
* every signal and status field has units and reads to a number;
* a trip during a move (:meth:`start_move`) leaves nothing driven in the
  same tick;
* nasty argument words (``nan``, ``inf``, ``1e400`` ...) and random garbage
  give a ``CommandError``, never another exception, and move nothing;
* help, the server's privileges, the EPICS PVs and the completion table
  are what the records say.

A station of several robots is checked whole and then robot by robot: set
:attr:`~StationConformance.robot_name` in a subclass, and make its
:meth:`~StationConformance.driven` say only what that robot drives.  Its
checks then run that robot's component records only, ask that robot whether
it is busy, and trip that robot alone, which must leave every other robot
without a fault (unless the station declares them coupled)::

    class TestCellPumaConformance(TestCellConformance):
        robot_name = "puma"

        def driven(self, station):
            return arm_driven(station)
"""

from __future__ import annotations

import contextlib
import io
import math
import numbers
from collections.abc import Hashable, Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any, ClassVar

import pytest
from hypothesis import HealthCheck, given
from hypothesis import settings as hypothesis_settings
from hypothesis import strategies as st

from pyrt.commands.robot import RobotShell
from pyrt.component import Command, Component, run_prepared, walk
from pyrt.errors import CommandError, PyrtError
from pyrt.scheduler.clock import SimClock
from pyrt.server import ServedStation, Server
from pyrt.server.epics import FIXED_PVS, caproto_available
from pyrt.station.base import Station

__all__ = ["NASTY", "StallClock", "StationConformance"]


class StallClock(SimClock):
    """Virtual time that can stall, for a test of control on the time that really
    passed: after :meth:`stall` every tick starts that much after its deadline (the
    deadlines passed meanwhile skipped, never run back to back), as a loop that
    stalled on a loaded machine.  Deterministic like a :class:`~pyrt.SimClock`; the
    handlers see the time that really passed::

        clock = StallClock()
        station = build_my_robot(Loop(clock))
        ...
        clock.stall(30_000_000)  # the loop stalls 30 ms before its next tick
    """

    offset = 0

    def stall(self, ns: int) -> None:
        """The loop stalls ``ns`` before its next tick (and every later tick with it)."""
        self.offset += int(ns)

    def now_ns(self) -> int:
        return super().now_ns() + self.offset

    def start_tick(self, deadline_ns: int) -> int:
        return super().start_tick(deadline_ns) + self.offset

#: Argument words that are no valid argument of any command (file names aside).
NASTY = ["nan", "NaN", "inf", "-inf", "1e400", "-1e400", "0x1g", "--1", "1..2", "''", "§"]

_garbage_word = st.one_of(
    st.sampled_from(NASTY),
    st.text(st.characters(blacklist_categories=("Cc", "Cs", "Zs", "Zl", "Zp", "Nd", "No",
                                                "Nl")), max_size=10).map(lambda t: "§" + t),
)
_garbage = st.lists(_garbage_word, min_size=1, max_size=4)


class StationConformance:
    """The conformance checks over one station (see the module text).  Define
    :meth:`build`, :meth:`driven`, :meth:`settings` and :meth:`start_move`;
    :attr:`samples` where a record needs arguments."""

    #: Sample arguments of the records that need some, by ``"ComponentClass.record"``:
    #: each a list of argument lists, run in order (the last one is the one that counts).
    samples: ClassVar[Mapping[str, list[list[str]]]] = {}
    #: Records whose argument is a free file name: any text is a valid one.
    free_text: ClassVar[frozenset[str]] = frozenset({"log"})
    #: The robot under test in a station of several (its name); None: the station whole.
    robot_name: ClassVar[str | None] = None

    # -- what a station says about itself ---------------------------------------------

    def build(self, tmp_path: Path) -> Station:
        """The station under test, built on a ``SimClock`` (``tmp_path``: a directory of
        its own for databases); the suite starts it if it is not started, and closes it."""
        raise NotImplementedError(f"{type(self).__name__}: define build(self, tmp_path)")

    def driven(self, station: Station) -> list[str]:
        """What the simulated world says is driven now, one phrase each (empty: every
        actuator at rest); called in the loop thread."""
        raise NotImplementedError(f"{type(self).__name__}: define driven(self, station)")

    def settings(self, station: Station) -> Hashable:
        """The robot's state a reading command must leave as it is (registers, settings,
        queued moves); called in the loop thread."""
        raise NotImplementedError(f"{type(self).__name__}: define settings(self, station)")

    def start_move(self, station: Station, runner: Any) -> None:
        """Start a move and return once :meth:`driven` says something is driven."""
        raise NotImplementedError(f"{type(self).__name__}: define start_move(self, station, "
                                  "runner)")

    def rest(self, station: Station, runner: Any) -> None:
        """Bring a robot that a check found driven back to rest (default: ``stop``)."""
        runner.call(station.stop, take_fault=False)

    def ready(self, station: Station, runner: Any) -> None:
        """Called once the station is started, before any check: wait here for
        what a robot does on its own at power-on (default: nothing)."""

    def after_record(self, station: Station, runner: Any) -> None:
        """Called after each record the no-move check ran (default: nothing)."""

    # -- fixtures -------------------------------------------------------------------------

    def _started(self, tmp_path: Path) -> tuple[Station, Any]:
        station = self.build(tmp_path)
        runner = station.runner
        if runner is None or not runner.running:
            runner = station.start()
        runner.poll()
        self.ready(station, runner)
        return station, runner

    @pytest.fixture
    def robot(self, tmp_path: Path) -> Iterator[tuple[Station, Any]]:
        """The station, started, closed after the test."""
        station, runner = self._started(tmp_path)
        yield station, runner
        station.close()

    @pytest.fixture(scope="class")
    @classmethod
    def garbage_robot(cls, tmp_path_factory: pytest.TempPathFactory
                      ) -> Iterator[tuple[Station, Any, Path]]:
        """One station for every garbage example (garbage must change nothing)."""
        tmp = tmp_path_factory.mktemp("garbage")
        station, runner = cls()._started(tmp)
        yield station, runner, tmp
        with contextlib.suppress(PyrtError):
            station.close()

    # -- helpers ----------------------------------------------------------------------------

    def records(self, station: Station) -> list[tuple[Component | None, Command]]:
        """Every record: the components', the station's own words, the shell's words."""
        out: list[tuple[Component | None, Command]] = list(station.all_commands())
        words = station.profile.words  # the station's own console words (ShellProfile)
        if words is not None:
            out += [(words, r) for r in words.commands()]
        shell = RobotShell(station, io.StringIO())
        out += [(None, r) for r in shell.words() if r.console]
        return out

    def own_records(self, station: Station, records: Iterable[tuple[Component | None, Command]]
                    ) -> list[tuple[Component | None, Command]]:
        """``records`` as the checks run them: all, or with :attr:`robot_name` those
        of that robot's components."""
        if self.robot_name is None:
            return list(records)
        robot = station.robot(self.robot_name)
        own: list[tuple[Component | None, Command]] = [
            (c, r) for c, r in records if c is not None and robot.owns(c)]
        assert own, f"robot {robot.name}: none of its components has a record to check"
        return own

    def own_fault(self, station: Station) -> Any:
        """The fault of the station, or with :attr:`robot_name` of that robot."""
        if self.robot_name is None:
            return station.fault
        return station.robot(self.robot_name).fault

    def at_rest(self, station: Station, runner: Any) -> list[str]:
        """Driven actuators, a running move, or queued moves (through the loop)."""
        busy = station.busy if self.robot_name is None else station.robot(self.robot_name).busy
        return list(runner.call(lambda: self.driven(station)
                                + (["busy"] if busy() else []), take_fault=False))

    def sample_arguments(self, comp: Component, rec: Command) -> list[list[str]]:
        """The argument lists a check runs ``rec`` with."""
        key = f"{type(comp).__name__}.{rec.name}"
        if key in self.samples:
            return self.samples[key]
        assert not any(not a.optional for a in rec.args), \
            f"no sample arguments for {key}: give them in {type(self).__name__}.samples"
        return [[]]

    @staticmethod
    def execute(station: Station, runner: Any, comp: Component, rec: Command,
                words: list[str]) -> Any:
        """Parse ``words`` by ``rec``'s grammar and run it through the loop."""
        args = rec.parse(words, " ".join(words))
        if rec.prepare is not None:  # planned in this thread, enqueued by the loop
            return run_prepared(rec, args, lambda arg: runner.call(
                station.execute, comp, rec, [arg], take_fault=False))
        return runner.call(station.execute, comp, rec, args, take_fault=False)

    # -- names, help, grammar, classification ------------------------------------------------

    def test_every_component_has_a_name(self, robot: tuple[Station, Any]) -> None:
        """Every component of the tree (and the simulation beside it) has a non-empty name, unique in its station."""
        station, _ = robot
        names = [c.name for top in [station.root, *station.extras] for c in walk(top)]
        assert all(isinstance(n, str) and n.strip() == n and n for n in names)
        assert len({n.lower() for n in names}) == len(names)
        assert station.names() == names

    def test_every_record_has_help_a_grammar_and_a_class(self, robot: tuple[Station, Any]
                                                         ) -> None:
        """Every command record has a help summary, a grammar of named Args with parsers, and obeys the classification rule."""
        from pyrt.component import Arg

        station, _ = robot
        problems = []
        for comp, rec in self.records(station):
            who = f"{comp.name if comp is not None else 'word'} {rec.name}"
            if not rec.help.strip() or not rec.summary.strip():
                problems.append(f"{who}: no help")
            if not isinstance(rec.args, tuple) or not all(isinstance(a, Arg) for a in rec.args):
                problems.append(f"{who}: the grammar is not a tuple of Args")
                continue
            for i, a in enumerate(rec.args):
                if not a.name or not callable(a.parse):
                    problems.append(f"{who}: argument {i} has no name or no parser")
                if a.rest and i != len(rec.args) - 1:
                    problems.append(f"{who}: a rest argument is not the last")
            opt = [a.optional for a in rec.args]
            if opt != sorted(opt):
                problems.append(f"{who}: a required argument follows an optional one")
            if rec.reads_only and rec.moves:
                problems.append(f"{who}: both reads_only and moves")
            if rec.reads_only and not (rec.while_faulted and rec.anyone):
                problems.append(f"{who}: reads only, yet refused while faulted or privileged")
            if rec.moves and rec.anyone:
                problems.append(f"{who}: moves, yet any client may give it")
            in_world = comp is not None and comp in station.extras
            if rec.moves and rec.while_faulted and not in_world:
                problems.append(f"{who}: moves, yet allowed while faulted")
            if rec.anyone and not rec.reads_only and rec.name != "stop":
                problems.append(f"{who}: any client may give it, yet it changes the robot")
            if rec.reads_only_subcommands and (rec.reads_only or rec.moves):
                problems.append(f"{who}: read-only sub-commands on a record that is "
                                "classified whole")
        assert problems == []

    def test_a_record_not_marked_moves_never_starts_an_actuator(
            self, robot: tuple[Station, Any], tmp_path: Path,
            monkeypatch: pytest.MonkeyPatch) -> None:
        """Each component record that is not 'moves', run with sample arguments on a robot at rest, leaves every actuator at rest (the simulation's truth)."""
        station, runner = robot
        monkeypatch.chdir(tmp_path)
        assert self.at_rest(station, runner) == []
        started = []
        for comp, rec in self.own_records(station, station.all_commands()):
            if rec.moves or rec.console or comp is None:
                continue
            for words in self.sample_arguments(comp, rec):
                with contextlib.suppress(CommandError):
                    self.execute(station, runner, comp, rec, words)
            runner.sleep(0.3)
            driven = self.at_rest(station, runner)
            if driven:
                started.append(f"{comp.name} {rec.name}: {', '.join(driven)}")
                self.rest(station, runner)
                runner.sleep(0.3)
            self.after_record(station, runner)
        assert started == []

    def test_a_reading_record_changes_nothing(self, robot: tuple[Station, Any]) -> None:
        """Each reads_only component record leaves the robot's registers and settings as they were, in the same tick."""
        station, runner = robot
        changed = []
        for comp, rec in self.own_records(station, station.all_commands()):
            if not rec.reads_only or comp is None:
                continue
            for words in self.sample_arguments(comp, rec):
                args = rec.parse(words, " ".join(words))

                def act(comp: Component = comp, rec: Command = rec, args: Any = args
                        ) -> tuple[Hashable, Hashable]:
                    before = self.settings(station)
                    station.execute(comp, rec, args)
                    return before, self.settings(station)

                before, after = runner.call(act, take_fault=False)
                if before != after:
                    changed.append(f"{comp.name} {rec.name}")
        assert changed == []

    # -- signals -------------------------------------------------------------------------------

    def test_every_signal_has_units_and_reads_a_number(self, robot: tuple[Station, Any]
                                                       ) -> None:
        """Every signal (and status field) has units and reads, in the loop thread, to a number or a bool (a text signal to text)."""
        station, runner = robot
        sigs = [(n, s) for n, s in station.signals()]
        sigs += [(f"status.{k}", s) for k, s, _fmt in station.status_fields()]
        assert all(s.units.strip() for _n, s in sigs), [n for n, s in sigs if not s.units.strip()]
        values = runner.call(lambda: [(n, s, s.read()) for n, s in sigs], take_fault=False)
        bad = [(n, v) for n, s, v in values
               if (not isinstance(v, str) if s.is_text
                   else isinstance(v, str) or not isinstance(v, numbers.Number | bool))]
        assert bad == []
        for n, _s, v in values:
            assert not isinstance(v, float) or not math.isinf(v), n

    # -- the reflex ------------------------------------------------------------------------------

    def test_a_trip_during_a_move_stops_every_actuator_in_the_same_tick(
            self, robot: tuple[Station, Any]) -> None:
        """A move under way (start_move), a trip leaves nothing driven before any further tick; the robot stays at rest and holds the fault."""
        station, runner = robot
        self.start_move(station, runner)
        assert self.driven_now(station, runner), "start_move returned with nothing driven"

        def act() -> list[str]:
            station.trip("conformance trip", "test", robot=self.robot_name)
            return self.driven(station)

        assert runner.call(act, take_fault=False) == []
        runner.sleep(0.2)
        assert self.at_rest(station, runner) == []
        assert self.own_fault(station) is not None
        if self.robot_name is not None and not station.coupled:  # its own fault domain
            assert [r.name for r in station.robots if r.fault is not None] == [self.robot_name]

    def driven_now(self, station: Station, runner: Any) -> list[str]:
        """:meth:`driven`, read in the loop thread."""
        return list(runner.call(lambda: self.driven(station), take_fault=False))

    # -- garbage arguments --------------------------------------------------------------------

    # one method for every station class: each class is an executor of its own, and the
    # examples it draws depend on its station's records
    @hypothesis_settings(max_examples=300, deadline=None,
                         suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                HealthCheck.too_slow,
                                                HealthCheck.differing_executors])
    @given(data=st.data())
    def test_garbage_arguments_give_a_command_error_and_move_nothing(
            self, garbage_robot: tuple[Station, Any, Path], monkeypatch: pytest.MonkeyPatch,
            data: st.DataObject) -> None:
        """For every command record, random garbage argument words give a CommandError (never another exception) and move nothing."""
        station, runner, directory = garbage_robot
        monkeypatch.chdir(directory)  # where a garbage 'log FILE' name lands
        comp, rec = data.draw(st.sampled_from(self.own_records(station, self.records(station))), label="record")
        arity = max(1, len(rec.args))  # as many nasty words as the grammar takes, or any
        words = data.draw(st.one_of(st.lists(st.sampled_from(NASTY), min_size=arity,
                                             max_size=arity), _garbage), label="words")
        if rec.console:  # a shell word: through the shell, which shows a CommandError
            out, err = io.StringIO(), io.StringIO()
            shell = RobotShell(station, out, runner=runner)
            shell.stderr = err
            shell.onecmd(" ".join([rec.name, *words]))
            text = out.getvalue()
            assert "internal error" not in text and err.getvalue() == ""
            assert "error:" in text, text
        else:
            assert comp is not None
            try:
                self.execute(station, runner, comp, rec, words)
            except CommandError:
                pass
            else:
                assert rec.name in self.free_text, \
                    f"{comp.name} {rec.name} {words!r} was accepted"
                if rec.name == "log":
                    runner.call(station.stop_log, take_fault=False)  # type: ignore[attr-defined]
        assert self.at_rest(station, runner) == []
        assert self.own_fault(station) is None

    def test_every_nasty_word_in_every_argument_gives_a_command_error(
            self, robot: tuple[Station, Any], tmp_path: Path,
            monkeypatch: pytest.MonkeyPatch) -> None:
        """Every component record with each nasty word (nan, inf, 1e400 ...) as all its arguments: a CommandError, and nothing moves."""
        station, runner = robot
        monkeypatch.chdir(tmp_path)
        accepted = []
        for comp, rec in self.own_records(station, self.records(station)):
            if rec.console or rec.name in self.free_text:
                continue
            assert comp is not None
            for w in NASTY:
                words = [w] * max(1, len(rec.args))
                try:
                    self.execute(station, runner, comp, rec, words)
                except CommandError:
                    continue
                accepted.append(f"{comp.name} {rec.name} {' '.join(words)}")
        assert accepted == []
        assert self.at_rest(station, runner) == []
        assert self.own_fault(station) is None

    # -- the derived tables agree --------------------------------------------------------------

    def test_the_tables_derived_from_the_records_agree(self, robot: tuple[Station, Any]
                                                       ) -> None:
        """help lists exactly the records; the server's privilege is rec.anyone or only_reads; EPICS PVs are the status signals, every component signal and the state, plus the fixed PVs; completion is the words, the prompt level's letters and every component's records."""
        station, runner = robot
        out = io.StringIO()
        shell = RobotShell(station, out, runner=runner)
        records = self.records(station)
        words = shell.words()

        # help: the level's records, the objects, the words; nothing else
        shell.onecmd("help")
        lines = out.getvalue().splitlines()
        objects = next(i for i, ln in enumerate(lines) if ln.startswith("objects"))
        at_words = lines.index("words:")
        level = station.profile.level
        level_recs = level.commands() if level is not None else []
        assert [ln.strip() for ln in lines[1:objects]] == [
            r.summary if r.summary[:1].upper() == r.name.upper() else f"{r.name}  {r.summary}"
            for r in level_recs]
        assert lines[objects + 1].strip() == " ".join(station.names())
        assert [ln.strip() for ln in lines[at_words + 1:-1]] == [w.summary for w in words]
        for comp in station.components():
            out.seek(0)
            out.truncate()
            shell.onecmd(f"help {comp.name}")
            got = [ln.strip() for ln in out.getvalue().splitlines()[1:]
                   if not ln.strip().startswith("signals:")]
            assert got == [r.summary for r in comp.commands()], comp.name

        # the server's privilege decision, for every record, with and without arguments
        served = ServedStation(station)
        station_words = getattr(station, "words", None)
        for owner, rec in records:
            lines_to_try = []
            if owner is None or owner is station_words:
                lines_to_try = [rec.name, *(f"{rec.name} {s}" for s in rec.reads_only_subcommands)]
                lines_to_try.append(f"{rec.name} frob")
            elif owner is level:
                lines_to_try = [rec.name]
            elif owner is getattr(level, "monitor", None):
                continue  # letters of another level: not reachable as a line at the prompt
            else:
                lines_to_try = [f"{owner.name} {rec.name}", f"{owner.name} {rec.name} 1 2"]
            for line in lines_to_try:
                parts = line.split()
                top = owner is None or owner is level or owner is station_words
                rest = parts[1:] if top else parts[2:]
                assert served.is_read_only(line) == (rec.anyone or rec.only_reads(rest)), line

        # EPICS: the status fields' names, upper case, every component signal as
        # OBJECT:SIGNAL (of several robots, a robot's as ROBOT:OBJECT:SIGNAL, its root's
        # as ROBOT:SIGNAL), the station's state fields, plus the fixed PVs
        if caproto_available():
            from pyrt.server.epics import EpicsService, pv_name

            server = Server(runner, served, "127.0.0.1", 0)
            epics = EpicsService(runner, served, server, "T:")
            pvs = {name[len("T:"):] for name in epics.pvdb}
            fields = {k.upper() for k, _s, _f in station.status_fields()}
            several = len(station.robots) > 1

            def under(c: Component) -> str:
                r = station.robot_of(c) if several else None
                return c.name if r is None or r.name.lower() == c.name.lower() \
                    else f"{r.name}:{c.name}"

            signals = {f"{under(c)}:{s.name}".upper() for c in station.components()
                       for s in c.signals()}
            extras = {pv_name(f.name) for f in served.extra_fields}
            assert signals <= extras and {"STATE", "STOP_REASON"} <= extras
            assert pvs == fields | extras | set(FIXED_PVS)

        # completion: exactly the words, and every component's records (with their aliases)
        # (a word's own table, e.g. help's topics or scope's channels, is nested under it)
        table = shell.completions()
        objs = [c for c in station.components() if c is not station_words]
        at_level = {r.name for r in shell.level.commands()} if shell.level is not None else set()
        assert set(table) == {w.name for w in words} | {c.name for c in objs} | at_level
        for comp in objs:
            verbs: dict[str, None] = {}
            for r in comp.commands():
                verbs[r.name] = None
                verbs.update(dict.fromkeys(r.aliases))
            assert table[comp.name] == (verbs or None), comp.name
        assert set(table["help"]) == set(table) - {"help"}
        assert set(table["status"]) == {c.name for c in station.components() if c.signals()}
