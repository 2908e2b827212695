"""The component contract, checked over every robot: names, help, grammar, classification,
signals, the reflex, garbage arguments, and the tables derived from the records.

The classification rule (one per record, asserted below):

* ``reads_only``: changes nothing of the robot (its RAM, its registers, its
  settings); allowed while faulted; any client may give it;
* ``moves``: may start an actuator; refused while faulted and never
  ``anyone``; a record that is not ``reads_only`` and does not move is a
  *setting* (it changes the robot, but starts nothing);
* ``anyone`` beyond the reads only for the stop (``stop`` records), which
  must not move;
* a record not marked ``moves`` never starts an actuator from rest (checked
  by running it with sample arguments and looking at the simulation's truth).

The simulated world's ``sim`` component is the world, not the controller:
its ``jog`` moves (the hand on the front-panel switch) and stays allowed
while faulted, so that ``sim jog off`` can always release the switch.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.util
import io
import math
import numbers
from pathlib import Path

import pytest
from _manipulator_rig import make_station
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pyrt.boards.gripper import DAC_NULL
from pyrt.boards.i8031 import COMMAND_CNT, FLAGS, STOPCNT
from pyrt.boards.tio10 import AWO_BITS
from pyrt.commands.robot import RobotShell
from pyrt.component import Arg, Command, Component, walk
from pyrt.errors import CommandError, PyrtError, PyrtInternalError
from pyrt.robots.gripper import _MASK_DRVON
from pyrt.scheduler import Loop, SimClock
from pyrt.server import ServedStation, Server
from pyrt.server.epics import FIXED_PVS, caproto_available
from pyrt.station.gripper import build_gripper

#: The arm of examples/arm (pip install ./examples/arm), built only from pyrt's public API.
ARM_INSTALLED = importlib.util.find_spec("pyrt_arm") is not None
ROBOTS = ["gripper", "prototype", "sno",
          pytest.param("arm", marks=pytest.mark.skipif(
              not ARM_INSTALLED, reason="pyrt_arm is not installed (pip install ./examples/arm)"))]


def _build(name: str, tmp_path: Path):
    if name == "arm":  # through its factory, as 'pyrt arm' builds it
        from pyrt_arm.station import ARM

        station = ARM.build(Loop(SimClock()), argparse.Namespace(boards=None, start=None))
        runner = station.start()
        runner.poll()
        return station, runner
    if name == "gripper":
        station = build_gripper(Loop(SimClock()))
        runner = station.start()
        runner.poll()
        return station, runner
    return make_station(tmp_path, name)


@pytest.fixture(params=ROBOTS)
def robot(request, tmp_path):
    station, runner = _build(request.param, tmp_path)
    yield station, runner
    station.close()


def _tree(station) -> list[Component]:
    return [c for top in [station.root, *station.extras] for c in walk(top)]


def _records(station) -> list[tuple[Component | None, Command]]:
    """Every record: the components', the station's own words, the shell's words."""
    out: list[tuple[Component | None, Command]] = list(station.all_commands())
    words = getattr(station, "words", None)
    if words is not None:
        out += [(words, r) for r in words.commands()]
    shell = RobotShell(station, io.StringIO())
    out += [(None, r) for r in shell.words() if r.console]
    return out


# -- the truth of the simulation: is anything driven? ------------------------------------


def _driven(station) -> list[str]:
    """What the simulated boards say is driven now (empty: every actuator at rest)."""
    if station.name == "gripper":
        out = []
        if station.board.dac != DAC_NULL:
            out.append(f"DAC {station.board.dac:02X}")
        if station.controller.moving:
            out.append(f"drive/jog bits in FLAGS {station.cpu.ram[FLAGS]:02X}")
        return out
    if station.name == "arm":  # the servo board's outputs
        board = station.board
        return [f"{reg}[{j}] = {board.read(reg, j)}" for reg in ("drive", "enable")
                for j in (0, 1) if board.read(reg, j) != 0]
    tio = station.tio10
    out = []
    for a in station.axes:
        ch = a.motor.channel
        if tio.armed(ch):
            out.append(f"{a.motor.name}: channel {ch} armed")
        if not tio.bit(*AWO_BITS[ch]):
            out.append(f"{a.motor.name}: windings on")
    return out


def _at_rest(station, runner) -> list[str]:
    """Driven actuators, a running move, or queued moves (loop thread)."""
    return runner.call(lambda: _driven(station) + (["busy"] if station.busy() else []),
                       take_fault=False)


def _settings(station) -> tuple:
    """The robot's state a reading command must leave as it is (loop thread)."""
    if station.name == "gripper":
        return bytes(station.cpu.ram), station.board.dac, station.cpu.sp, len(station.motion)
    if station.name == "arm":
        board = station.board
        regs = tuple(board.read(r.name, j) for r in board.kind.registers for j in range(r.count))
        joints = tuple((jt.engaged, jt.drive, jt.servo.config) for jt in station.controller.joints)
        return (regs, joints, station.controller.state, tuple(station.plant.active_faults()),
                len(station.motion))
    regs = tuple(station.tio10.register_file())
    devs = tuple((a.motor.state, a.motor.mode, a.motor.cruise_speed, a.encoder.zero_length,
                  a.loadcell.slope, a.loadcell.offset, a.mode) for a in station.axes)
    pa = station.polyaxis
    return regs, devs, pa.active, pa.tension_stop, pa.signal_all, len(station.motion)


# -- names, help, grammar, classification ------------------------------------------------


def test_every_component_has_a_name(robot):
    """Every component of the tree (and the simulation beside it) has a non-empty name, unique in its station."""
    station, _ = robot
    names = [c.name for c in _tree(station)]
    assert all(isinstance(n, str) and n.strip() == n and n for n in names)
    assert len({n.lower() for n in names}) == len(names)
    assert station.names() == names


def test_every_record_has_help_a_grammar_and_a_class(robot):
    """Every command record has a help summary, a grammar of named Args with parsers, and obeys the classification rule."""
    station, _ = robot
    problems = []
    for comp, rec in _records(station):
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
            problems.append(f"{who}: read-only sub-commands on a record that is classified whole")
    assert problems == []


# Sample arguments of the records that need some, by "ComponentClass.record":
# each a list of argument lists, run in order (the last one is the one that counts).
_SAMPLES: dict[str, list[list[str]]] = {
    "GripperController.X": [["33"]],
    # the target's high byte far closed, STOPCNT, then the drive bit in FLAGS (what P does)
    "GripperMonitor.C": [[f"{COMMAND_CNT + 1:02X}", "E4"], [f"{STOPCNT:02X}", "FF"],
                         [f"{FLAGS:02X}", f"{_MASK_DRVON:02X}"]],
    "GripperMonitor.D": [["4A"]],
    "GripperMonitor.L": [["FFFF"]],
    "GripperSim.object": [["20"]],
    "GripperSim.jog": [["close", "0.5"]],
    "GripperSim.fault": [["none"]],
    "ArmSim.fault": [["none"]],
    "ManipulatorSim.fault": [["0", "none"]],
    "ManipulatorSim.load": [["0", "10"]],
    "ManipulatorSim.unload": [["0"]],
    "Axis.point": [["10 N"]],
    "Axis.maxspeed": [["3"]],
    "Loadcell.point": [["10 N"]],
    "Motor.maxspeed": [["3"]],
    "Encoder.setZeroLength": [["100"]],
    "PolyAxis.setpos": [["0", "0", "1e5"]],
}


def _samples(comp: Component, rec: Command) -> list[list[str]]:
    key = f"{type(comp).__name__}.{rec.name}"
    if key in _SAMPLES:
        return _SAMPLES[key]
    assert not any(not a.optional for a in rec.args), f"no sample arguments for {key}"
    return [[]]


def _run(station, runner, comp: Component, rec: Command, words: list[str]):
    args = rec.parse(words, " ".join(words))
    return runner.call(station.execute, comp, rec, args, take_fault=False)


def test_a_record_not_marked_moves_never_starts_an_actuator(robot, tmp_path, monkeypatch):
    """Each component record that is not 'moves', run with sample arguments on a robot at rest, leaves every actuator at rest (the simulation's truth)."""
    station, runner = robot
    monkeypatch.chdir(tmp_path)
    assert _at_rest(station, runner) == []
    started = []
    for comp, rec in station.all_commands():
        if rec.moves or rec.console:
            continue
        for words in _samples(comp, rec):
            with contextlib.suppress(CommandError):
                _run(station, runner, comp, rec, words)
        runner.sleep(0.3)
        driven = _at_rest(station, runner)
        if driven:
            started.append(f"{comp.name} {rec.name}: {', '.join(driven)}")
            runner.call(station.stop, take_fault=False)
            if station.name == "gripper":
                runner.call(station.plant.jog, "off", None, take_fault=False)
            runner.sleep(0.3)
        if station.name == "gripper" and not station.controller.clock_enabled:
            runner.call(station.controller.toggle_clock, take_fault=False)  # monitor I
    assert started == []


def test_a_reading_record_changes_nothing(robot):
    """Each reads_only component record leaves the robot's RAM, registers and settings as they were, in the same tick."""
    station, runner = robot
    changed = []
    for comp, rec in station.all_commands():
        if not rec.reads_only:
            continue
        for words in _samples(comp, rec):
            args = rec.parse(words, " ".join(words))

            def act(comp=comp, rec=rec, args=args):
                before = _settings(station)
                station.execute(comp, rec, args)
                return before, _settings(station)

            before, after = runner.call(act, take_fault=False)
            if before != after:
                changed.append(f"{comp.name} {rec.name}")
    assert changed == []


# -- signals -------------------------------------------------------------------------------


def test_every_signal_has_units_and_reads_a_number(robot):
    """Every signal (and status field) has units and reads, in the loop thread, to a number or a bool."""
    station, runner = robot
    sigs = [(n, s) for n, s in station.signals()]
    sigs += [(f"status.{k}", s) for k, s, _fmt in station.status_fields()]
    assert all(s.units.strip() for _n, s in sigs), [n for n, s in sigs if not s.units.strip()]
    values = runner.call(lambda: [(n, s.read()) for n, s in sigs], take_fault=False)
    bad = [(n, v) for n, v in values
           if isinstance(v, str) or not isinstance(v, (numbers.Number, bool))]
    assert bad == []
    for n, v in values:
        assert not isinstance(v, float) or not math.isinf(v), n


# -- the reflex ------------------------------------------------------------------------------


def _trip_and_look(station, runner) -> list[str]:
    """Trip the station and read the truth in the same mailbox call (one tick)."""

    def act() -> list[str]:
        station.trip("conformance trip", "test")
        return _driven(station)

    return runner.call(act, take_fault=False)


def _start_gripper_move(station, runner) -> None:
    ctl = station.controller
    job = runner.call(ctl.start_init)
    assert runner.wait_until(lambda: job.done, 60.0) and job.value().ok
    runner.call(ctl.run_command, "P", "E47A")
    assert runner.wait_until(lambda: station.board.dac != DAC_NULL and ctl.moving, 5.0)


def test_the_reflex_stops_the_gripper_drive_in_the_same_tick():
    """Gripper: I, then P E47A; a trip nulls the DAC and clears the drive and jog bits before any further tick."""
    station = build_gripper(Loop(SimClock()))
    runner = station.start()
    try:
        _start_gripper_move(station, runner)
        assert _driven(station)
        assert _trip_and_look(station, runner) == []
        runner.sleep(0.2)
        assert _at_rest(station, runner) == []
        assert station.fault is not None
    finally:
        station.close()


@pytest.mark.parametrize("name", ["prototype", "sno"])
@pytest.mark.parametrize("how", ["polyaxis", "axis"])
def test_the_reflex_disarms_every_manipulator_motor_in_the_same_tick(tmp_path, name, how):
    """Manipulator: a 'to' move or an axis move running, a trip disarms every TIO10 channel and turns the windings off before any further tick."""
    station, runner = make_station(tmp_path, name)
    try:
        pa = station.polyaxis
        if how == "polyaxis":
            x, y, z = pa.position
            runner.call(pa.run_command, "to", f"{x:.2f}", f"{y:.2f}", f"{z - 20:.2f}")
        else:
            runner.call(station.axes[0].run_command, "up", "2")
        assert runner.wait_until(lambda: bool(_driven(station)), 30.0)
        assert _trip_and_look(station, runner) == []
        runner.sleep(0.2)
        assert _at_rest(station, runner) == []
    finally:
        station.close()


@pytest.mark.skipif(not ARM_INSTALLED, reason="pyrt_arm is not installed")
def test_the_reflex_turns_every_arm_drive_and_amplifier_off_in_the_same_tick(tmp_path):
    """Arm: an 'arm to' move running (amplifiers enabled, drives non-zero), a trip writes every drive and enable register 0 before any further tick."""
    station, runner = _build("arm", tmp_path)
    try:
        runner.call(station.controller.run_command, "to", "60", "30")
        assert runner.wait_until(lambda: len(_driven(station)) == 4, 5.0)
        assert _trip_and_look(station, runner) == []
        runner.sleep(0.2)
        assert _at_rest(station, runner) == []
        assert station.fault is not None
    finally:
        station.close()


# -- garbage arguments --------------------------------------------------------------------

#: Argument words that are no valid argument of any command (file names aside).
_NASTY = ["nan", "NaN", "inf", "-inf", "1e400", "-1e400", "0x1g", "--1", "1..2", "''", "§"]
_garbage_word = st.one_of(
    st.sampled_from(_NASTY),
    st.text(st.characters(blacklist_categories=("Cc", "Cs", "Zs", "Zl", "Zp", "Nd", "No",
                                                "Nl")), max_size=10).map(lambda t: "§" + t),
)
_garbage = st.lists(_garbage_word, min_size=1, max_size=4)
#: Records whose argument is a free file name: any text is a valid name.
_FREE_TEXT = {"log"}


@pytest.mark.parametrize("name", ROBOTS)
@settings(max_examples=300, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(data=st.data())
def test_garbage_arguments_give_a_command_error_and_move_nothing(name, tmp_path_factory,
                                                                monkeypatch, data):
    """For every command record, random garbage argument words give a CommandError (never another exception) and move nothing."""
    station, runner = _GARBAGE_STATIONS.get(name) or _garbage_station(name, tmp_path_factory)
    monkeypatch.chdir(_GARBAGE_DIRS[name])  # where a garbage 'log FILE' name lands
    records = _records(station)
    comp, rec = data.draw(st.sampled_from(records), label="record")
    arity = max(1, len(rec.args))  # as many nasty words as the grammar takes, or any garbage
    words = data.draw(st.one_of(st.lists(st.sampled_from(_NASTY), min_size=arity,
                                         max_size=arity), _garbage), label="words")
    if rec.console:  # a shell word: through the shell, which shows a CommandError as error:
        out = io.StringIO()
        err = io.StringIO()
        shell = RobotShell(station, out, runner=runner)
        shell.stderr = err
        shell.onecmd(" ".join([rec.name, *words]))
        text = out.getvalue()
        assert "internal error" not in text and err.getvalue() == ""
        assert "error:" in text, text
    else:
        try:
            _run(station, runner, comp, rec, words)
        except CommandError:
            pass
        else:
            assert rec.name in _FREE_TEXT, f"{comp.name} {rec.name} {words!r} was accepted"
            if rec.name == "log":
                runner.call(station.stop_log, take_fault=False)
    assert _at_rest(station, runner) == []
    assert station.fault is None


def test_every_nasty_word_in_every_argument_gives_a_command_error(robot, tmp_path, monkeypatch):
    """Every component record with each nasty word (nan, inf, 1e400 ...) as all its arguments: a CommandError, and nothing moves."""
    station, runner = robot
    monkeypatch.chdir(tmp_path)
    accepted = []
    for comp, rec in _records(station):
        if rec.console or rec.name in _FREE_TEXT:
            continue
        for w in _NASTY:
            words = [w] * max(1, len(rec.args))
            try:
                _run(station, runner, comp, rec, words)
            except CommandError:
                continue
            accepted.append(f"{comp.name} {rec.name} {' '.join(words)}")
    assert accepted == []
    assert _at_rest(station, runner) == []
    assert station.fault is None


_GARBAGE_STATIONS: dict[str, tuple] = {}
_GARBAGE_DIRS: dict[str, Path] = {}


def _garbage_station(name: str, factory) -> tuple:
    """One station per robot for every example (garbage must change nothing)."""
    tmp = factory.mktemp(f"garbage-{name}")
    station, runner = _build(name, tmp)
    _GARBAGE_DIRS[name] = tmp
    _GARBAGE_STATIONS[name] = (station, runner)
    return station, runner


@pytest.fixture(autouse=True, scope="module")
def _close_garbage_stations():
    yield
    for station, _runner in _GARBAGE_STATIONS.values():
        with contextlib.suppress(PyrtError):
            station.close()
    _GARBAGE_STATIONS.clear()


# -- the derived tables agree --------------------------------------------------------------


def test_the_tables_derived_from_the_records_agree(robot):
    """help lists exactly the records; the server's privilege is rec.anyone or only_reads; EPICS PVs are the status signals, every component signal and the state, plus the fixed PVs; completion is the words, the prompt level's letters and every component's records."""
    station, runner = robot
    out = io.StringIO()
    shell = RobotShell(station, out, runner=runner)
    records = _records(station)
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
    for comp, rec in records:
        lines_to_try = []
        if comp is None or comp is getattr(station, "words", None):
            lines_to_try = [rec.name, *(f"{rec.name} {s}" for s in rec.reads_only_subcommands)]
            lines_to_try.append(f"{rec.name} frob")
        elif comp is level:
            lines_to_try = [rec.name]
        elif comp is getattr(level, "monitor", None):
            continue  # letters of another level: not reachable as a line at CMD:
        else:
            lines_to_try = [f"{comp.name} {rec.name}", f"{comp.name} {rec.name} 1 2"]
        for line in lines_to_try:
            parts = line.split()
            rest = parts[1:] if comp is None or comp is level or comp is getattr(
                station, "words", None) else parts[2:]
            assert served.is_read_only(line) == (rec.anyone or rec.only_reads(rest)), line

    # EPICS: the status fields' names, upper case, every component signal as
    # OBJECT:SIGNAL, the station's state fields, plus the fixed PVs
    if caproto_available():
        from pyrt.server.epics import EpicsService, pv_name

        server = Server(runner, served, "127.0.0.1", 0)
        epics = EpicsService(runner, served, server, "T:")
        pvs = {name[len("T:"):] for name in epics.pvdb}
        fields = {k.upper() for k, _s, _f in station.status_fields()}
        signals = {f"{c.name}:{s.name}".upper() for c in station.components()
                   for s in c.signals()}
        extras = {pv_name(f.name) for f in served.extra_fields}
        assert signals <= extras and {"STATE", "STOP_REASON"} <= extras
        assert pvs == fields | extras | set(FIXED_PVS)

    # completion: exactly the words, and every component's records (with their aliases)
    # (a word's own table, e.g. help's topics or scope's channels, is nested under it)
    table = shell.completions()
    objects = [c for c in station.components() if c is not getattr(station, "words", None)]
    level = {r.name for r in shell.level.commands()} if shell.level is not None else set()
    assert set(table) == {w.name for w in words} | {c.name for c in objects} | level
    for comp in objects:
        verbs = {}
        for r in comp.commands():
            verbs[r.name] = None
            verbs.update(dict.fromkeys(r.aliases))
        assert table[comp.name] == (verbs or None), comp.name
    assert set(table["help"]) == set(table) - {"help"}
    assert set(table["status"]) == {c.name for c in station.components() if c.signals()}


# -- a bug in pyrt is not the operator's error ------------------------------------------------


def test_a_bug_is_an_internal_error_with_its_traceback_and_the_console_goes_on(monkeypatch):
    """An unexpected exception prints 'internal error: Type: msg (a bug in pyrt ...)' with the traceback on the error stream; a CommandError stays 'error: ...'; the next line runs."""
    station = build_gripper(Loop(SimClock()))
    runner = station.start()
    try:
        out, err = io.StringIO(), io.StringIO()
        shell = RobotShell(station, out, runner=runner)
        shell.stderr = err

        def broken() -> str:
            raise KeyError("no such register")

        monkeypatch.setattr(station, "status", broken)
        assert shell.onecmd("status") is False
        text = out.getvalue()
        assert text.splitlines() == [
            "internal error: KeyError: 'no such register' (a bug in pyrt; please report it "
            "with this traceback)"]
        assert "Traceback (most recent call last)" in err.getvalue()
        assert "in broken" in err.getvalue() and "KeyError" in err.getvalue()

        out.seek(0)
        out.truncate()
        shell.onecmd("P 1234")  # the operator's mistake: positive target
        assert out.getvalue().startswith("error: ") and "internal" not in out.getvalue()
        out.seek(0)
        out.truncate()
        shell.onecmd("W")  # the console keeps running
        assert out.getvalue().strip() == "0000"

        def invariant() -> str:
            raise PyrtInternalError("ready queue image corrupt")

        monkeypatch.setattr(station, "status", invariant)
        out.seek(0)
        out.truncate()
        shell.onecmd("status")  # pyrt's own invariant broken: a bug as well
        assert out.getvalue().startswith("internal error: PyrtInternalError: ready queue")
    finally:
        station.close()
