"""show [PREFIX]: every signal and parameter of a station in one table, and TABLE, the same rows over the DAQ link."""

from __future__ import annotations

import io
import json
import math
import re

import numpy as np
import pytest
from _manipulator_rig import make_station
from _server_rig import TOKEN, served
from hypothesis import given, settings
from hypothesis import strategies as st

from pyrt import Component, Signal, Station
from pyrt.client import ServerError
from pyrt.commands import RobotShell
from pyrt.commands.show import COLUMNS, MAX_ROWS, Row, Table, data_lines, read_table
from pyrt.component import Limits, Param
from pyrt.scheduler import Loop, SimClock
from pyrt.server import ServedStation
from pyrt.station.gripper import build_gripper
from pyrt.station.urdf import build_urdf


def _run(shell: RobotShell, line: str) -> list[str]:
    """The lines ``line`` prints on ``shell``."""
    out = io.StringIO()
    shell.stdout = out
    shell.onecmd(line)
    return out.getvalue().splitlines()


def _rows(lines: list[str]) -> dict[str, tuple[str, ...]]:
    """The table's rows by name: (value, units, range, writable); the header, the rule
    and the note after the table are not rows."""
    assert re.split(r"\s{2,}", lines[0].strip()) == list(COLUMNS), lines[0]
    assert set(lines[1].replace(" ", "")) == {"-"}
    rows = {}
    for line in lines[2:]:
        cells = re.split(r"\s{2,}", line.strip())
        if len(cells) != len(COLUMNS):
            break  # the note after the table
        rows[cells[0]] = tuple(cells[1:])
    return rows


def _aligned(lines: list[str]) -> bool:
    """Every column of the table starts at the same character on every line."""
    widths = [len(c) for c in lines[1].split("  ")]
    starts = [sum(widths[:k]) + 2 * k for k in range(len(widths))]
    body = [ln for ln in lines[2:] if len(re.split(r"\s{2,}", ln.strip())) == len(COLUMNS)]
    for ln in body:
        for s in starts[2:]:  # the left-aligned columns after the value
            if ln[s - 2:s] != "  " or ln[s] == " ":
                return False
        if ln[starts[1] + widths[1] - 1] == " ":  # the value: right-aligned
            return False
    return True


# -- the four robots ---------------------------------------------------------------------


@pytest.fixture(scope="module")
def gripper():
    """A gripper station on simulated time and its console."""
    station = build_gripper(Loop(SimClock()))
    station.start()
    yield station, RobotShell(station, io.StringIO())
    station.close()


@pytest.fixture(scope="module")
def manipulator(tmp_path_factory):
    """The prototype manipulator on simulated time and its console."""
    station, _runner = make_station(tmp_path_factory.mktemp("show"))
    yield station, RobotShell(station, io.StringIO())
    station.close()


@pytest.fixture(scope="module")
def puma():
    """The URDF station (the packaged PUMA 560) and its console."""
    station = build_urdf(Loop(SimClock()))
    station.start()
    yield station, RobotShell(station, io.StringIO())
    station.close()


@pytest.fixture(scope="module")
def arm():
    """The example two-joint arm (examples/arm) and its console."""
    from pyrt_arm.station import build_arm

    station = build_arm(Loop(SimClock()))
    station.start()
    yield station, RobotShell(station, io.StringIO())
    station.close()


#: Rows each robot's table must hold: (value, units, range, writable), value None: any.
KNOWN = {
    "gripper": {
        "gripper.encoder": (None, "counts", "-", "no"),
        "gripper.speed": ("7F", "speed byte", "01..7F", "yes"),
        "gripper.SYSCLKPD": ("04", "ticks", "01..FF", "yes"),
        "sim.x": (None, "counts", "-", "no"),
    },
    "manipulator": {
        "prototype.x": (None, "cm", "-320..320", "no"),
        "prototype.MAX_TENSION": ("200", "N", "12..222.411", "yes"),
        "axis0.tension": (None, "N", "0..200", "no"),
        "axis1Motor.CRUISE_SPEED": ("7", "cm/s", "0.07..7", "yes"),
        "axis2Loadcell.SLOPE": (None, "N/count", "-100..100", "yes"),
        "axis0.LENGTH_MAX": ("713.7", "cm", "-", "no"),
    },
    "puma": {
        "puma560.q2": (None, "deg", "-45..225", "no"),
        "joint6.position": (None, "deg", "-266..266", "no"),
        "joint1.torque": (None, "N m", "-", "no"),
        "sim.x": (None, "mm", "-", "no"),
    },
    "arm": {
        "arm.q0": (None, "deg", "-170..170", "no"),
        "shoulder.error": (None, "deg", "-1..1", "no"),
        "elbow.velocity": (None, "deg/s", "-", "no"),
    },
}


@pytest.mark.parametrize("robot", list(KNOWN))
def test_the_table_of_each_robot_lists_its_signals_and_parameters_with_units_and_ranges(
        robot, request):
    """show alone, on each robot: an aligned table with a row for every signal and parameter of every object (OBJECT.NAME), the known ones with their units and ranges."""
    station, shell = request.getfixturevalue(robot)
    lines = _run(shell, "show")
    rows = _rows(lines)
    expected = [f"{c.name}.{s.name}" for c in station.components()
                for s in station.signals_of(c)]  # a robot's root: its text signals too
    expected += [f"{c.name}.{p.name}" for c in station.components()
                 for p in station.params_of(c)]
    assert sorted(rows) == sorted(expected)
    assert len(lines) == 2 + len(expected)  # every row shown: no note
    for name, (value, units, rng, writable) in KNOWN[robot].items():
        assert rows[name][1:] == (units, rng, writable), name
        if value is not None:
            assert rows[name][0] == value, name
    assert _aligned(lines)


def test_a_prefix_keeps_the_rows_whose_name_starts_with_it_in_any_case(manipulator):
    """show AXIS0 lists axis0's rows and its motor's, encoder's and loadcell's, no other; show prototype. the root's alone (with the robot's text signals)."""
    _station, shell = manipulator
    rows = _rows(_run(shell, "show AXIS0"))
    assert rows and all(n.lower().startswith("axis0") for n in rows)
    assert {n.split(".")[0] for n in rows} == {"axis0", "axis0Motor", "axis0Encoder",
                                               "axis0Loadcell"}
    root = _rows(_run(shell, "show prototype."))
    assert set(root) == {"prototype.x", "prototype.y", "prototype.z", "prototype.distErr",
                         "prototype.netForce", "prototype.active", "prototype.MAX_TENSION",
                         "prototype.END_ERROR", "prototype.where", "prototype.last_stop",
                         "prototype.statusline"}


def test_show_lists_the_robot_text_signals_as_the_station_says_them(manipulator):
    """show prototype.where / statusline / last_stop: text rows (units text) holding what the station's where and status say; last_stop is '' before any move."""
    station, shell = manipulator
    rows = _rows(_run(shell, "show prototype."))
    where = station.runner.call(station.where)
    status = station.runner.call(station.status)
    assert rows["prototype.where"] == (" ".join(where.split()), "text", "-", "no")
    assert rows["prototype.statusline"][0].rstrip(".") in " ".join(status.split())
    assert rows["prototype.last_stop"] == ("''", "text", "-", "no")


def test_a_value_set_shows_up_in_the_table(gripper):
    """set gripper.speed 33, then show gripper.speed shows 33; set back, 7F again."""
    _station, shell = gripper
    try:
        assert "33" in _run(shell, "set gripper.speed 33")[0]
        assert _rows(_run(shell, "show gripper.speed")) == {
            "gripper.speed": ("33", "speed byte", "01..7F", "yes")}
    finally:
        _run(shell, "set gripper.speed 7F")
    assert _rows(_run(shell, "show gripper.speed"))["gripper.speed"][0] == "7F"


def test_a_manipulator_parameter_set_shows_up(manipulator):
    """set prototype.MAX_TENSION 150 shows as 150 in the table."""
    _station, shell = manipulator
    try:
        _run(shell, "set prototype.MAX_TENSION 150")
        assert _rows(_run(shell, "show prototype.MAX"))["prototype.MAX_TENSION"][0] == "150"
    finally:
        _run(shell, "set prototype.MAX_TENSION 200")


@pytest.mark.parametrize("prefix", ["nope", "gripp.x", "sim.zz", "x" * 500, "'é'"])
def test_a_prefix_that_matches_nothing_says_so_and_changes_nothing(gripper, prefix):
    """show with a prefix that names nothing: one error line saying nothing matches, with the objects there are; every value of the table is as before."""
    station, shell = gripper
    params = {p.name: p.read() for p in station.params_of(station.root)}
    lines = _run(shell, f"show {prefix}")
    assert len(lines) == 1
    assert lines[0].startswith(f"error: show: nothing matches {prefix[:40]!r}")
    assert "objects: gripper, monitor, sim" in lines[0]
    assert len(lines[0]) < 200  # a long prefix is cut, not echoed whole
    assert {p.name: p.read() for p in station.params_of(station.root)} == params


def test_a_near_miss_of_an_object_is_named(gripper):
    """show gripp.x names the object meant."""
    _station, shell = gripper
    assert "did you mean 'gripper'?" in _run(shell, "show gripp.x")[0]


@settings(max_examples=60, deadline=None)
@given(prefix=st.text(alphabet="abcdeginoprstxyzAEGMPS._:0 ", max_size=12))
def test_the_rows_shown_are_exactly_those_the_prefix_names(gripper, prefix):
    """For any prefix, the table's names are exactly the station's OBJECT.NAMEs that start with it in any case (a reference computed from the records), in the tree's order."""
    station, _shell = gripper
    table = read_table(station, prefix, runner=station.runner)
    names = [f"{c.name}.{x.name}" for c in station.components()
             for x in [*station.signals_of(c), *station.params_of(c)]]
    want = [n for n in names if n.lower().startswith(prefix.strip().lower())]
    assert [r.name for r in table.rows] == want
    assert table.matched == len(want) and table.total == len(names)


def test_the_prefixes_help_gives_as_examples_name_rows(gripper, manipulator, puma):
    """Each example of help show (show axis0, show puma560., show gripper.s) lists rows on the robot it is written for."""
    _station, shell = gripper
    text = " ".join(_run(shell, "help show"))
    for example in ("show axis0 (", "show puma560. (", "show gripper.s."):
        assert example in text, example
    for (_st, sh), prefix in ((manipulator, "axis0"), (puma, "puma560."), (gripper, "gripper.s")):
        assert _rows(_run(sh, f"show {prefix}")), prefix


def test_help_show_says_what_the_table_has_and_its_bound(gripper):
    """help show names the columns, the prefix, the bound the table keeps and TABLE; help lists show among the words."""
    _station, shell = gripper
    text = " ".join(" ".join(_run(shell, "help show")).split())
    for word in (*COLUMNS, "PREFIX", f"At most {MAX_ROWS} rows", "TABLE [PREFIX]"):
        assert word in text, word
    assert any(ln.strip().startswith("show [PREFIX]:") for ln in _run(shell, "help"))


# -- a huge station ----------------------------------------------------------------------


class _Bank(Component):
    """A component of many signals (one NaN) and a parameter."""

    def __init__(self, name: str, n: int):
        self.name = name
        self.values = [float(k) for k in range(n)]
        self.values[0] = math.nan
        self.gain = 1.5

    def signals(self) -> list[Signal]:
        return [Signal.item(f"s{k:03d}", "V", self.values, k,
                            limits=Limits(-10.0, 10.0)) for k in range(len(self.values))]

    def params(self) -> list[Param]:
        return [Param("gain", "V/V", lambda: self.gain, self._set, lo=0.0, hi=10.0)]

    def _set(self, value: float) -> None:
        self.gain = value


class _Rack(Component):
    name = "rack"

    def __init__(self, banks: list[_Bank]):
        self.banks = banks

    def children(self) -> list[Component]:
        return list(self.banks)


@pytest.fixture(scope="module")
def huge():
    """A station of 30 objects of 20 signals and a parameter each, and the robot's 3 text signals on its root (633 rows)."""
    station = Station(Loop(SimClock()))
    station.name = "rack"
    station.adopt(_Rack([_Bank(f"bank{k:02d}", 20) for k in range(30)]))
    station.start()
    yield station, RobotShell(station, io.StringIO())
    station.close()


def test_a_huge_station_shows_a_bounded_table_and_says_how_to_narrow_it(huge):
    """show on 633 rows: MAX_ROWS rows, then a line saying how many were left out and which prefix narrows; following it lists that object's rows whole."""
    _station, shell = huge
    lines = _run(shell, "show")
    assert len(_rows(lines)) == MAX_ROWS
    assert len(lines) == 2 + MAX_ROWS + 1
    note = lines[-1]
    assert note.startswith(f"{633 - MAX_ROWS} of 633 rows left out")
    hint = re.search(r"e\.g\. (show \S+);", note)
    assert hint is not None, note
    narrowed = _run(shell, hint.group(1))
    assert len(_rows(narrowed)) == 21 and len(narrowed) == 2 + 21


def test_nothing_matching_on_a_huge_station_names_a_bounded_list_of_objects(huge):
    """show nope on 31 objects: one error line naming the first 16 and how many there are."""
    _station, shell = huge
    lines = _run(shell, "show nope")
    assert len(lines) == 1 and lines[0].startswith("error: show: nothing matches 'nope'")
    assert lines[0].endswith("bank14, ... (31 objects)") and "bank15" not in lines[0]


_VALUES = st.one_of(
    st.none(), st.booleans(), st.integers(), st.floats(), st.text(max_size=20),
    st.floats(width=32).map(np.float32), st.integers(-2**31, 2**31 - 1).map(np.int32),
    st.booleans().map(np.bool_), st.tuples(st.floats(), st.floats()))


def _strict(text: str):
    """JSON as a strict reader takes it: NaN and Infinity refused."""
    def refuse(word):
        raise ValueError(f"not JSON: {word}")
    return json.loads(text, parse_constant=refuse)


@settings(max_examples=200, deadline=None)
@given(value=_VALUES)
def test_every_row_is_strict_json_whatever_its_value(value):
    """A row of any value (NaN, infinity, numpy scalars, text, a tuple) is one line of strict JSON; a finite number or a flag keeps its value, anything else is null or text."""
    row = Row("obj.x", "signal", value, str(value), "V", "", None, None, False)
    table = Table("", (row,), 1, 1, (), ("obj",))
    lines = data_lines(table)
    assert all("\n" not in ln for ln in lines)
    got = _strict(lines[0])["value"]
    plain = value.item() if isinstance(value, np.generic) else value
    if isinstance(plain, bool | int | str) or plain is None:
        assert got == plain and type(got) is type(plain)
    elif isinstance(plain, float):
        assert got == plain if math.isfinite(plain) else got is None
    else:
        assert got == str(value)


class _Counting:
    """A runner that counts its mailbox calls and the values each one reads."""

    def __init__(self, runner):
        self.runner = runner
        self.calls: list[int] = []

    def call(self, fn, *args, **kw):
        self.calls.append(len(args[0]) if args and isinstance(args[0], list) else -1)
        return self.runner.call(fn, *args, **kw)


def test_show_reads_in_one_mailbox_call_only_the_rows_it_shows(huge):
    """show on the huge station is one mailbox call reading MAX_ROWS values (not 630); show bank03 one call reading bank03's 21."""
    station, _shell = huge
    counting = _Counting(station.runner)
    shell = RobotShell(station, io.StringIO(), runner=counting)
    _run(shell, "show")
    assert counting.calls == [MAX_ROWS]
    counting.calls.clear()
    _run(shell, "show bank03")
    assert counting.calls == [21]


def test_over_the_bound_the_data_says_the_same(huge):
    """TABLE's rows over a huge station are the console's, and its last object counts what was left out and says the same note; a NaN value is null, never NaN."""
    station, shell = huge
    lines = ServedStation(station).table(station.runner, "")
    rows = [json.loads(x) for x in lines[:-1]]
    tail = json.loads(lines[-1])
    assert len(rows) == tail["rows"] == MAX_ROWS
    assert tail["matched"] == tail["total"] == 633 and tail["left_out"] == 633 - MAX_ROWS
    assert tail["note"] == _run(shell, "show")[-1]
    assert rows[3] == {"name": "bank00.s000", "kind": "signal", "value": None,
                       "text": "nan", "units": "V", "range": "-10..10", "lo": -10.0,
                       "hi": 10.0, "writable": False}
    gain = [json.loads(x) for x in ServedStation(station).table(station.runner, "bank07.g")]
    assert gain[0] == {"name": "bank07.gain", "kind": "param", "value": 1.5, "text": "1.5",
                       "units": "V/V", "range": "0..10", "lo": 0.0, "hi": 10.0,
                       "writable": True}


# -- over the DAQ link -------------------------------------------------------------------


def _as_cells(row: dict) -> tuple[str, ...]:
    return (row["text"], row["units"] or "-", row["range"] or "-",
            "yes" if row["writable"] else "no")


@pytest.mark.parametrize("robot", list(KNOWN))
def test_the_served_table_has_the_consoles_rows(robot, request):
    """The served station's TABLE rows are the console's show rows, row for row (names, values as shown, units, ranges, writable), with and without a prefix."""
    station, shell = request.getfixturevalue(robot)
    served_station = ServedStation(station)
    for prefix in ("", station.root.name[:3].upper()):
        data = served_station.table(station.runner, prefix)
        rows = {r["name"]: _as_cells(r) for r in map(json.loads, data[:-1])}
        shown = _rows(_run(shell, f"show {prefix}".strip()))
        changing = {n for n in shown if n.startswith("sim.") or n.split(".")[0] in (
            "gripper", "monitor")}  # a running world moves between the two reads
        assert list(rows) == list(shown)
        for name in rows:
            if name not in changing:
                assert rows[name][1:] == shown[name][1:], name


def test_table_over_the_link_is_served_to_a_reader_and_equals_show():
    """Over TCP, an unprivileged client's TABLE gripper.s gives the rows show gripper.s gives (the same names, values, units, ranges); a value the operator sets shows up."""
    with served() as s:
        reader = s.client()
        operator = s.client()
        try:
            data = reader.command("TABLE gripper.s")
            rows = [json.loads(x) for x in data[:-1]]
            assert json.loads(data[-1]) == {"rows": 6, "matched": 6, "total": 24,
                                            "left_out": 0, "note": ""}  # with statusline
            shown = _rows(reader.command("show gripper.s"))
            line = shown.pop("gripper.statusline")  # a long text: the console cuts it
            cells = {r["name"]: _as_cells(r) for r in rows}
            assert cells.pop("gripper.statusline")[1:] == line[1:] == ("text", "-", "no")
            assert cells == shown
            assert next(r for r in rows if r["name"] == "gripper.speed") == {
                               "name": "gripper.speed", "kind": "param", "value": 127,
                               "text": "7F", "units": "speed byte", "range": "01..7F",
                               "lo": 1, "hi": 127, "writable": True}
            operator.auth(TOKEN)
            operator.command("set gripper.speed 33")
            speed = json.loads(reader.command("table GRIPPER.SPEED")[0])
            assert speed["value"] == 0x33 and speed["text"] == "33"
        finally:
            reader.close()
            operator.close()


def test_table_that_matches_nothing_is_a_command_error_and_a_bad_request_a_syntax_error():
    """TABLE nope: ERR command saying nothing matches, as show nope says it; TABLE a b: ERR syntax; the connection serves on."""
    with served() as s:
        c = s.client()
        try:
            with pytest.raises(ServerError) as err:
                c.command("TABLE nope")
            assert err.value.code == "command"
            assert err.value.text.startswith("show: nothing matches 'nope'")
            shown = c.request("show nope")
            assert (shown.code, shown.text) == ("command", err.value.text)
            with pytest.raises(ServerError) as err:
                c.command("TABLE a b")
            assert err.value.code == "syntax"
            assert c.command("help")[-2].startswith("server (any case):")
            assert "TABLE [PREFIX]" in c.command("help")[-2]
        finally:
            c.close()


def test_a_reserved_slot_may_not_read_the_table_as_it_may_not_read_anything():
    """With every slot taken, a newcomer in a reserved slot gets ERR full for TABLE (AUTH and stop only there); the clients in slots read it."""
    with served(max_clients=2, reserved_slots=1) as sv:
        a, b = sv.client(), sv.client()
        try:
            assert a.command("W") == b.command("W") == ["0000"]  # both asked: not evictable
            spare = sv.client()
            assert "reserved slot" in spare.greeting
            assert spare.request("TABLE").code == "full"
            assert json.loads(a.command("TABLE sim.x")[-1])["rows"] == 1
        finally:
            a.close()
            b.close()


def test_show_through_the_gripper_command_piped():
    """pyrt gripper with show piped in prints the table (the console's word, not only the interpreter's) and exits 0."""
    import subprocess
    import sys

    proc = subprocess.run([sys.executable, "-m", "pyrt", "gripper", "--speed", "max"],
                          input="show gripper.SYS\nquit\n", capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    head = next(k for k, ln in enumerate(lines) if ln.rstrip().endswith("writable"))
    table = [lines[head][lines[head].index("name"):], *lines[head + 1:head + 3]]  # no prompt
    assert _rows(table) == {"gripper.SYSCLKPD": ("04", "ticks", "01..FF", "yes")}
