"""Object databases: parsing, records, references, write-back, atomicity, packaged stations."""

from __future__ import annotations

import dataclasses
import os
import random
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pyrt.db import (
    FILES,
    MAX_DB_BYTES,
    STATIONS,
    TYPES,
    AxisRecord,
    PolyAxisRecord,
    UnknownNameError,
    copy_station,
    default_working_directory,
    load_station,
    lock_directory,
    parse_file,
    parse_records,
    read_regular_file,
    station_directory,
)
from pyrt.db import __all__ as db_all
from pyrt.errors import ConfigError, DiskError

LB = 4.4482216152605


def _station(tmp_path: Path, name: str = "prototype") -> Path:
    return copy_station(name, tmp_path / name)


def _mutate(directory: Path, filename: str, old: str, new: str, count: int = 1) -> None:
    path = directory / filename
    text = path.read_text()
    assert old in text, f"{old!r} not in {filename}"
    path.write_text(text.replace(old, new, count))


def _line_of(directory: Path, filename: str, marker: str, nth: int = 1) -> int:
    seen = 0
    for i, line in enumerate((directory / filename).read_text().split("\n"), start=1):
        if marker in line:
            seen += 1
            if seen == nth:
                return i
    raise AssertionError(f"{marker!r} not in {filename}")


# -- the packaged stations ---------------------------------------------------


def test_exports_sorted() -> None:
    """pyrt.db exports a sorted __all__ of names that exist."""
    # isort-style, as ruff (RUF022) keeps it: CONSTANTS, Classes, functions
    assert list(db_all) == sorted(db_all, key=lambda n: (
        0 if n.isupper() else 1 if n[0].isupper() else 2, n))
    import pyrt.db

    for name in db_all:
        assert hasattr(pyrt.db, name)


@pytest.mark.parametrize("station", STATIONS)
@pytest.mark.parametrize("type_", TYPES)
def test_shipped_files_round_trip_byte_for_byte(station: str, type_: str) -> None:
    """Every shipped file parses and renders back to exactly its bytes."""
    path = station_directory(station) / FILES[type_]
    dat, records = parse_file(path)
    assert dat.encode() == path.read_bytes()
    assert records


@pytest.mark.parametrize("station", STATIONS)
def test_unchanged_write_back_writes_nothing(tmp_path: Path, station: str) -> None:
    """Writing back the values already in the files leaves every byte as it was."""
    d = _station(tmp_path, station)
    before = {f: (d / f).read_bytes() for f in FILES.values()}
    s = load_station(d)
    changes = {}
    for p in s.records("POLYAXIS"):
        changes[("POLYAXIS", p.name, "POSITION")] = p.position
        changes[("POLYAXIS", p.name, "SOURCE_MASS")] = p.source_mass
    for a in s.records("AXIS"):
        changes[("AXIS", a.name, "LENGTH")] = a.length
    for e in s.records("ENCODER"):
        changes[("ENCODER", e.name, "ZEROLENGTH")] = e.zerolength
    for c in s.records("LOADCELL"):
        changes[("LOADCELL", c.name, "SLOPE")] = c.slope
        changes[("LOADCELL", c.name, "OFFSET")] = c.offset
    assert s.write_back(changes) == []
    assert {f: (d / f).read_bytes() for f in FILES.values()} == before


def test_prototype_values_are_the_documents() -> None:
    """The prototype records hold Tables 1, 3, 5, 6, 7 and 9 in base units."""
    s = load_station(station_directory("prototype"))
    p = s.polyaxis("prototype")
    assert p.name == "PROTOTYPE"
    assert p.axes == ("AXIS0", "AXIS1", "AXIS2")
    assert p.position == (-0.199943, 0.0, 95.569618419)
    assert p.source_mass == 5.3357 and p.source_volume == 0.0
    assert p.av == "PROTOVESSEL"
    a0, a1, a2 = s.axes_of(p)
    assert a0 == s.axis("axis0") and a0.central and a0.bottom is None
    assert (a0.motor, a0.loadcell, a0.encoder) == ("motor0", "loadcell0", "encoder0")
    assert a0.length == pytest.approx(293.405273) and a0.deadlength == 453.0
    assert a0.offset == (0.0, 0.0, 0.0) and a0.top == (0.0, 0.0, 389.0)
    assert a1.length == pytest.approx(614.2491466) and a1.top == (50.0, 0.0, 391.0)
    assert a1.bottom == (317.0, 0.0, 89.53)
    # AXIS2 is AXIS1 mirrored in x = 0
    assert a2.top == (-50.0, 0.0, 391.0) and a2.bottom == (-317.0, 0.0, 89.53)
    m = s.motor_of(a0)
    assert (m.channel, m.start_speed, m.cruise_speed) == (7, 0.5, 7.0)
    e = s.encoder_of("AXIS0")
    assert (e.slope, e.address, e.zerolength, e.date) == (0.2392, 168, 747.04541, "00-00-0000")
    c = s.loadcell_of("axis0")
    assert c.maxload == pytest.approx(50 * LB)
    assert (c.slope, c.offset, c.channel) == (0.6777730537, -482.53598, 3)
    av = s.av_of(p)
    assert av.neck_ring_static_position == (5.7, 0.0, 364.0)
    assert (av.neck_ring_radius, av.neck_radius, av.neck_length) == (42.0, 42.0, 27.0)
    assert av.vessel_radius == pytest.approx(320.0)


def test_sno_station_geometry() -> None:
    """The SNO station has five ropes in two perpendicular planes at Figure 2's size."""
    s = load_station(station_directory("sno"))
    p = s.polyaxis()
    axes = s.axes_of(p)
    assert len(axes) == 5 and axes[0].central
    av = s.av_of(p)
    assert av.vessel_radius == 600.5 and av.neck_length == 703.2
    assert av.neck_ring_radius == 72.5
    neck_top = av.neck_ring_static_position[2] + av.neck_length
    planes = set()
    for a in axes[1:]:
        bx, by, bz = a.bottom
        assert bz < 0, "side ropes are attached low on the wall"
        assert (bx * bx + by * by + bz * bz) ** 0.5 <= av.vessel_radius
        tx, ty, tz = a.top
        assert tz == pytest.approx(neck_top)
        assert (tx * tx + ty * ty) ** 0.5 < av.neck_ring_radius
        planes.add("xz" if by == 0 else "yz")
    assert planes == {"xz", "yz"}
    # stored lengths are the rope lengths with the source at POSITION (centre)
    import math

    for a in axes:
        carriage = tuple(x + d for x, d in zip(p.position, a.offset, strict=True))
        expected = math.dist(a.top, carriage)
        if a.bottom is not None:
            expected += math.dist(carriage, a.bottom)
        assert a.length == pytest.approx(expected, abs=1e-3)
        # ZEROLENGTH is the unstretched rope: LENGTH + DEADLENGTH less its stretch at
        # the holding tension (STRETCH 2e-5/N: under a centimetre here).
        z = s.encoder_of(a).zerolength
        assert a.length + a.deadlength - 1.0 < z < a.length + a.deadlength
    channels = [s.motor_of(a).channel for a in axes]
    assert len(set(channels)) == 5 and not {4, 5} & set(channels)


def test_lookups_are_case_insensitive_and_resolve_compound_names() -> None:
    """Names match in any case; axis0Motor finds the motor of axis0 (section 6)."""
    s = load_station(station_directory("prototype"))
    assert s.axis("AxIs1").name == "AXIS1"
    ref = s.find("axis0Motor")
    assert ref.kind == "MOTOR" and ref.record.name == "motor0" and ref.axis == "AXIS0"
    assert s.find("AXIS2ENCODER").record.name == "encoder2"
    assert s.find("axis1loadcell").record.name == "loadcell1"
    assert s.find("prototype").kind == "POLYAXIS"
    assert s.find("protovessel").kind == "AV"
    assert "AXIS0Motor" in s.object_names()
    with pytest.raises(UnknownNameError, match="axis9"):
        s.find("axis9")
    with pytest.raises(UnknownNameError, match="there are"):
        s.motor("motor7")


def test_records_are_frozen() -> None:
    """Records cannot be changed in place."""
    a = load_station(station_directory("prototype")).axis("axis0")
    assert isinstance(a, AxisRecord)
    with pytest.raises(dataclasses.FrozenInstanceError):
        a.length = 1.0  # type: ignore[misc]


def test_copy_station_keeps_existing_working_files(tmp_path: Path) -> None:
    """copy_station fills a working directory but never overwrites its files unasked."""
    d = copy_station("prototype", tmp_path / "w")
    s = load_station(d)
    s.update("AXIS", "axis0", "LENGTH", 300.0)
    copy_station("prototype", d)
    assert load_station(d).axis("axis0").length == 300.0
    copy_station("prototype", d, overwrite=True)
    assert load_station(d).axis("axis0").length == pytest.approx(293.405273)
    with pytest.raises(ConfigError, match="no packaged station"):
        station_directory("nowhere")


# -- optional keys -------------------------------------------------------------


def test_optional_keys_and_fuzzy_overrides(tmp_path: Path) -> None:
    """Optional keys override their defaults; FUZZY_<NAME> keys become a mapping."""
    d = _station(tmp_path)
    _mutate(d, "AXIS.dat", "TOP: 0. 0. 389.0 // top pulley position",
            "TOP: 0. 0. 389.0 // top pulley position\nFUZZY_Low_T: 4.5\nfuzzy_dv: -0.25\n"
            "STRETCH: 1e-5")
    _mutate(d, "POLYAXIS.dat", "END;", "MAX_TENSION: 40 lb\nHARE_SPEED: 0.02 m/s\nEND;")
    _mutate(d, "MOTOR.dat", "CRUISE_SPEED: 7.0\nEND;",
            "CRUISE_SPEED: 7.0\nSTEPS_PER_CM: 80\nDV_LIMIT: 0.25\nEND;")
    s = load_station(d)
    a = s.axis("axis0")
    assert dict(a.fuzzy) == {"low_t": 4.5, "dv": -0.25}
    assert a.stretch == 1e-5
    assert s.axis("axis1").fuzzy == {} and s.axis("axis1").stretch == 2.0e-5
    p = s.polyaxis()
    assert p.max_tension == pytest.approx(40 * LB)
    assert p.hare_speed == pytest.approx(2.0)
    assert p.low_tension == 2.0 and p.offside_tension == 10.0
    assert s.motor("motor0").steps_per_cm == 80.0 and s.motor("motor0").dv_limit == 0.25
    assert s.motor("motor1").steps_per_cm == 40.0


def test_av_name_needed_when_several_vessels(tmp_path: Path) -> None:
    """With two AV entries a PolyAxis must say which one it uses."""
    d = _station(tmp_path)
    text = (d / "AV.dat").read_text()
    (d / "AV.dat").write_text(text + "\nAV: other\nNECK_RING_STATIC_POSITION: 0 0 1\n"
                              "NECK_RING_RADIUS: 1 cm\nNECK_RADIUS: 1 cm\nNECK_LENGTH: 1 cm\n"
                              "VESSEL_RADIUS: 1 m\nEND;\n")
    with pytest.raises(ConfigError, match="needs an 'AV: name' line") as e:
        load_station(d)
    assert e.value.file.endswith("POLYAXIS.dat") and e.value.line == _line_of(
        d, "POLYAXIS.dat", "POLYAXIS: PROTOTYPE")
    _mutate(d, "POLYAXIS.dat", "END;", "AV: Other\nEND;")
    assert load_station(d).av_of().name == "other"


# -- malformed files -----------------------------------------------------------

MALFORMED = [
    # (id, file, old, new, marker of the line the error must name (None: line 1), message)
    ("missing-version", "AXIS.dat", "VERSION1.00\n", "", None, "VERSION1.00"),
    ("wrong-version", "MOTOR.dat", "VERSION1.00", "VERSION2.00", None, "VERSION2.00"),
    ("version-with-space", "AV.dat", "VERSION1.00", "VERSION 1.00", None, "no spaces"),
    ("missing-end-before-entry", "AXIS.dat", "TOP: 0. 0. 389.0 // top pulley position\nEND;",
     "TOP: 0. 0. 389.0 // top pulley position", "AXIS: AXIS1", "expected 'END;'"),
    ("missing-end-at-eof", "AV.dat", "END;", "", "AV: PROTOVESSEL",
     "before the end of the file"),
    ("end-outside-entry", "MOTOR.dat", "MOTOR: motor1", "END;\nMOTOR: motor1", "END;#2",
     "outside an entry"),
    ("duplicate-name", "MOTOR.dat", "MOTOR: motor2", "MOTOR: MOTOR1", "MOTOR: MOTOR1",
     "duplicate MOTOR entry"),
    ("unknown-unit", "AV.dat", "3.20 m", "3.20 furlong", "VESSEL_RADIUS", "unknown length unit"),
    ("wrong-quantity-unit", "POLYAXIS.dat", "5.3357 kg", "5.3357 cm", "SOURCE_MASS",
     "unknown mass unit"),
    ("units-required", "POLYAXIS.dat", "5.3357 kg", "5.3357", "SOURCE_MASS", "with its unit"),
    ("bad-number", "AXIS.dat", "293.4052730000000", "293.40x5", "LENGTH: 293.40x5", "LENGTH"),
    ("bad-int", "ENCODER.dat", "ADDRESS: 168", "ADDRESS: 16.8", "ADDRESS: 16.8", "integer"),
    ("short-vector", "AXIS.dat", "TOP: 50.0 0. 391.0", "TOP: 50.0 391.0", "TOP: 50.0 391.0",
     "three numbers"),
    ("unknown-key", "AXIS.dat", "DEADLENGTH: 453.0", "DEADLENGHT: 453.0", "DEADLENGHT",
     "did you mean DEADLENGTH"),
    ("duplicate-key", "LOADCELL.dat", "CHANNEL: 3 // ADC", "CHANNEL: 3\nCHANNEL: 3 // ADC",
     "CHANNEL: 3 // ADC", "duplicate key CHANNEL"),
    ("missing-required-key", "ENCODER.dat", "SLOPE: 0.2392 // conversion from ADC value to cm\n",
     "", "ENCODER: encoder0", "no SLOPE: key"),
    ("missing-value", "AXIS.dat", "LENGTH: 293.4052730000000", "LENGTH:", "LENGTH:",
     "expected a value"),
    ("not-a-field", "AXIS.dat", "DEADLENGTH: 453.0 // unchanging length",
     "DEADLENGTH 453.0 // unchanging length", "DEADLENGTH 453.0", "expected 'KEY: value'"),
    ("foreign-entry", "MOTOR.dat", "MOTOR: motor1", "AXIS: motor1", "AXIS: motor1",
     "expected 'MOTOR: name'"),
    ("dangling-motor", "AXIS.dat", "MOTOR: motor1", "MOTOR: motor9", "MOTOR: motor9",
     "MOTOR 'motor9' is not in MOTOR.dat"),
    ("dangling-axis", "POLYAXIS.dat", "AXIS: AXIS2", "AXIS: AXIS7", "AXIS: AXIS7",
     "AXIS 'AXIS7' is not in AXIS.dat"),
    ("dangling-av", "POLYAXIS.dat", "END;", "AV: VESSEL9\nEND;", "AV: VESSEL9", "not in AV.dat"),
    ("axis-listed-twice", "POLYAXIS.dat", "AXIS: AXIS2", "AXIS: axis1", "AXIS: AXIS0",
     "listed twice"),
    ("shared-motor", "AXIS.dat", "MOTOR: motor2", "MOTOR: motor1", "MOTOR: motor1#2",
     "used by both"),
    ("shared-channel", "MOTOR.dat", "CHANNEL: 9", "CHANNEL: 8", "CHANNEL: 8#2",
     "has CHANNEL 8"),
    ("rtc-channel", "MOTOR.dat", "CHANNEL: 7", "CHANNEL: 4", "CHANNEL: 4", "real-time clock"),
    ("speed-limit", "MOTOR.dat", "CRUISE_SPEED: 7.0", "CRUISE_SPEED: 9.0", "CRUISE_SPEED: 9.0",
     "0.07 and 7.0"),
    ("start-above-cruise", "MOTOR.dat", "CRUISE_SPEED: 7.0", "CRUISE_SPEED: 0.3",
     "START_SPEED: 0.5", "above CRUISE_SPEED"),
    ("negative-mass", "POLYAXIS.dat", "5.3357 kg", "-5.3357 kg", "SOURCE_MASS", "> 0"),
    ("fuzzy-not-number", "AXIS.dat", "DEADLENGTH: 453.0 // unchanging length",
     "DEADLENGTH: 453.0 // unchanging length\nFUZZY_LOW_T: low", "FUZZY_LOW_T",
     "FUZZY_LOW_T"),
    ("bad-name", "AV.dat", "AV: PROTOVESSEL", "AV: PROTO VESSEL", "AV: PROTO", "expected a name"),
]


@pytest.mark.parametrize(("file", "old", "new", "marker", "message"),
                         [m[1:] for m in MALFORMED], ids=[m[0] for m in MALFORMED])
def test_malformed_files_give_file_and_line(tmp_path: Path, file: str, old: str, new: str,
                                            marker: str | None, message: str) -> None:
    """A malformed or inconsistent file refuses to load, naming file:line and what was wanted."""
    d = _station(tmp_path)
    _mutate(d, file, old, new)
    if marker is None:
        line = 1
    else:
        text, _, nth = marker.partition("#")
        line = _line_of(d, file, text, int(nth or 1))
    with pytest.raises(ConfigError) as err:
        load_station(d)
    e = err.value
    assert Path(e.file).name == file
    assert e.line == line, str(e)
    assert message in e.message
    assert str(e).startswith(f"{e.file}:{line}: ")


def test_missing_file_is_named(tmp_path: Path) -> None:
    """A station without one of its six files names the missing file."""
    d = _station(tmp_path)
    (d / "LOADCELL.dat").unlink()
    with pytest.raises(ConfigError, match="missing database file") as e:
        load_station(d)
    assert e.value.file.endswith("LOADCELL.dat")
    with pytest.raises(ConfigError, match="station directory"):
        load_station(tmp_path / "absent")


# -- write-back ----------------------------------------------------------------


def _changed_lines(before: str, after: str) -> list[tuple[str, str]]:
    a, b = before.splitlines(keepends=True), after.splitlines(keepends=True)
    assert len(a) == len(b)
    return [(x, y) for x, y in zip(a, b, strict=True) if x != y]


def test_write_back_changes_only_the_numbers(tmp_path: Path) -> None:
    """A write-back changes the changed numbers' characters and nothing else."""
    d = _station(tmp_path)
    before = {f: (d / f).read_text() for f in FILES.values()}
    s = load_station(d)
    written = s.write_back({
        ("AXIS", "axis0", "LENGTH"): 293.41,
        ("POLYAXIS", "PROTOTYPE", "POSITION"): (1.5, 0.0, 96.25),
        ("encoder", "ENCODER1", "zerolength"): 1070.5,
    })
    assert sorted(p.name for p in written) == ["AXIS.dat", "ENCODER.dat", "POLYAXIS.dat"]
    after = {f: (d / f).read_text() for f in FILES.values()}
    for f in ("MOTOR.dat", "LOADCELL.dat", "AV.dat"):
        assert after[f] == before[f]
    assert _changed_lines(before["AXIS.dat"], after["AXIS.dat"]) == [
        ("LENGTH: 293.4052730000000 // re-written length\n",
         "LENGTH: 293.4100000000000 // re-written length\n")]
    # the unchanged middle component keeps its text; the others keep their decimals
    assert _changed_lines(before["POLYAXIS.dat"], after["POLYAXIS.dat"]) == [
        ("POSITION: -0.199943 0.000000 95.569618419 // last known position\n",
         "POSITION: 1.500000 0.000000 96.250000000 // last known position\n")]
    assert _changed_lines(before["ENCODER.dat"], after["ENCODER.dat"]) == [
        ("ZEROLENGTH: 1067.249147 // rope length when encoder reads zero\n",
         "ZEROLENGTH: 1070.500000 // rope length when encoder reads zero\n")]
    assert s.axis("AXIS0").length == 293.41
    assert s.polyaxis().position == (1.5, 0.0, 96.25)
    reloaded = load_station(d)
    assert reloaded.axis("axis0") == s.axis("axis0")
    assert reloaded.polyaxis() == s.polyaxis()
    # no temporary files are left behind
    assert sorted(os.listdir(d)) == sorted(FILES.values())


def test_write_back_keeps_units_and_line_endings(tmp_path: Path) -> None:
    """A value written in g stays in g; CRLF lines stay CRLF; other bytes stay."""
    d = _station(tmp_path)
    path = d / "POLYAXIS.dat"
    raw = path.read_bytes().replace(b"5.3357 kg", b"5335.7 g").replace(b"\n", b"\r\n")
    path.write_bytes(raw)
    s = load_station(d)
    assert s.polyaxis().source_mass == pytest.approx(5.3357)
    s.update("POLYAXIS", "prototype", "SOURCE_MASS", 5.5)
    new = path.read_bytes()
    assert new == raw.replace(b"5335.7 g", b"5500.000000 g")
    s.update("POLYAXIS", "prototype", "SOURCE_VOLUME", 2000.0)
    assert b"SOURCE_VOLUME: 2000.000000 cm3 // volume" in path.read_bytes()


def test_loadcell_calibration_written(tmp_path: Path) -> None:
    """SLOPE, OFFSET and DATE of a loadcell are written back in place."""
    d = _station(tmp_path)
    s = load_station(d)
    s.write_back({("LOADCELL", "loadcell1", "SLOPE"): 0.681234567891,
                  ("LOADCELL", "loadcell1", "OFFSET"): -480.25,
                  ("LOADCELL", "loadcell1", "DATE"): "22-11-2026"})
    c = load_station(d).loadcell("loadcell1")
    assert (c.slope, c.offset, c.date) == (0.6812345679, -480.25, "22-11-2026")
    assert load_station(d).loadcell("loadcell0").slope == 0.6777730537


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (("AXIS", "axis0", "LENGTH", float("nan")), "finite"),
        (("AXIS", "axis0", "LENGTH", "long"), "number"),
        (("AXIS", "axis0", "LENGTH", -5.0), ">= 0"),
        (("AXIS", "axis0", "TOP", (1, 2, 3)), "not written back"),
        (("AXIS", "axis0", "MOTOR", "motor2"), "not written back"),
        (("AXIS", "axis9", "LENGTH", 1.0), "no AXIS entry"),
        (("AXIS", "axis0", "BOTTOM", (1, 2, 3)), "not written back"),
        (("POLYAXIS", "prototype", "POSITION", (1, 2)), "three numbers"),
        (("LOADCELL", "loadcell0", "DATE", "a // b"), "without '//'"),
        (("LOADCELL", "loadcell0", "SLOPE", 0.0), "non-zero"),
        (("GRIPPER", "x", "LENGTH", 1.0), "unknown object type"),
    ],
)
def test_bad_write_back_changes_nothing(tmp_path: Path, change: tuple, message: str) -> None:
    """A refused value raises ConfigError and writes no file, even in a batch with good ones."""
    d = _station(tmp_path)
    before = {f: (d / f).read_bytes() for f in FILES.values()}
    s = load_station(d)
    t, name, key, value = change
    with pytest.raises(ConfigError, match=message):
        s.write_back({("ENCODER", "encoder0", "ZEROLENGTH"): 800.0, (t, name, key): value})
    assert {f: (d / f).read_bytes() for f in FILES.values()} == before
    assert s.encoder("encoder0").zerolength == 747.04541


def test_failed_rename_leaves_old_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """If the rename fails the old file and the in-memory records stay; no temp file is left;
    the error is a DiskError naming the file and the reason."""
    d = _station(tmp_path)
    before = (d / "AXIS.dat").read_bytes()
    s = load_station(d)

    def boom(src: str, dst: str) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", boom)
    with pytest.raises(DiskError, match=re.escape(f"cannot write {d / 'AXIS.dat'}: No space "
                                                  "left on device (the disk is full)")):
        s.update("AXIS", "axis0", "LENGTH", 1.0)
    assert (d / "AXIS.dat").read_bytes() == before
    assert s.axis("axis0").length == pytest.approx(293.405273)
    assert sorted(os.listdir(d)) == sorted(FILES.values())


_CHILD = """
import sys
from pyrt.db import load_station
s = load_station(sys.argv[1])
i = 0
while True:
    s.write_back({("AXIS", "axis1", "LENGTH"): 1000.0 + i,
                  ("POLYAXIS", "prototype", "POSITION"): (float(i), 0.0, -float(i))})
    if i == 0:
        print("ready", flush=True)
    i += 1
"""


def test_killed_writer_leaves_old_or_new_file(tmp_path: Path) -> None:
    """SIGKILL at random moments of continuous write-back always leaves a whole file:
    the old values or one written set, with every other byte unchanged."""
    d = _station(tmp_path)
    axis_before = (d / "AXIS.dat").read_text()
    poly_before = (d / "POLYAXIS.dat").read_text()
    rng = random.Random(96026)
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    seen_values: set[float] = set()
    for _ in range(30):
        child = subprocess.Popen([sys.executable, "-c", _CHILD, str(d)],
                                 stdout=subprocess.PIPE, env=env)
        assert child.stdout is not None
        assert child.stdout.readline() == b"ready\n"
        time.sleep(rng.uniform(0.0, 0.02))
        child.send_signal(signal.SIGKILL)
        child.wait()
        child.stdout.close()
        s = load_station(d)  # parseable, references intact
        length = s.axis("axis1").length
        assert length == 614.2491466 or (length >= 1000.0 and length.is_integer())
        seen_values.add(length)
        text = (d / "AXIS.dat").read_text()
        old_line = "LENGTH: 614.2491466000000 // re-written length"
        assert old_line in axis_before
        written = f"LENGTH: {length:.13f} // re-written length" if length >= 1000 else old_line
        assert text == axis_before.replace(old_line, written)
        x, y, z = s.polyaxis().position
        assert y == 0.0
        if x != -0.199943:
            assert x.is_integer() and z == -x
            assert (d / "POLYAXIS.dat").read_text() == poly_before.replace(
                "-0.199943 0.000000 95.569618419", f"{x:.6f} 0.000000 {-x:.9f}".replace(
                    "-0.000000000", "0.000000000"))
        # reset for the next round so "old" is always the shipped value
        (d / "AXIS.dat").write_text(axis_before)
        (d / "POLYAXIS.dat").write_text(poly_before)
    assert len(seen_values) > 1, "the kills never landed after a write"


# -- grammar properties ----------------------------------------------------------

_KEY_CHARS = st.sampled_from(["MOTOR", "CHANNEL", "START_SPEED", "END;", "VERSION1.00", ":",
                              "//", " ", "\t", "\n", "\r\n", "7", "0.5", "-", "x", "motor0",
                              "cm/s", "\x00", "\u00e9", "END", ";", "\ufeff"])


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(junk=st.one_of(st.text(max_size=200), st.lists(_KEY_CHARS, max_size=60).map("".join)),
       type_=st.sampled_from(TYPES))
def test_random_junk_raises_only_config_error(junk: str, type_: str) -> None:
    """Any text either parses (and round-trips byte-for-byte) or raises ConfigError."""
    for text in (junk, "VERSION1.00\n" + junk):
        try:
            dat, _ = parse_records(text, "junk.dat", type_)
        except ConfigError as e:
            assert e.file == "junk.dat" and e.line is not None and e.line >= 1
            continue
        assert dat.text() == text


_SPACE = st.sampled_from(["", " ", "  ", "\t"])
_COMMENT = st.sampled_from(["", " // a comment", "\t// x: y END;", "//"])
_CASE = st.sampled_from([str.upper, str.lower, str.title])


@st.composite
def _motor_file(draw: st.DrawFn) -> tuple[str, list[tuple[str, int, float, float]]]:
    n = draw(st.integers(min_value=1, max_value=4))
    channels = draw(st.lists(st.sampled_from([0, 1, 2, 3, 6, 7, 8, 9]), min_size=n, max_size=n,
                             unique=True))
    out = ["VERSION1.00" + draw(_COMMENT) + draw(st.sampled_from(["\n", "\r\n"]))]
    expected = []
    for i, ch in enumerate(channels):
        start = draw(st.floats(min_value=0.07, max_value=3.5)).__round__(4)
        cruise = draw(st.floats(min_value=3.5, max_value=7.0)).__round__(4)
        name = f"m{i}"
        lines = [
            f"{draw(_CASE)('motor')}:{draw(_SPACE)}{name}",
            f"{draw(_SPACE)}{draw(_CASE)('channel')}{draw(_SPACE)}:{draw(_SPACE)}{ch}",
            f"START_SPEED: {start}{draw(_SPACE)}{draw(st.sampled_from(['', 'cm/s']))}",
            f"cruise_speed:{cruise}",
        ]
        draw(st.randoms()).shuffle(lines[1:])
        for line in lines:
            out.append(line + draw(_COMMENT) + "\n")
            if draw(st.booleans()):
                out.append(draw(_SPACE) + draw(_COMMENT) + "\n")
        out.append(draw(_SPACE) + draw(st.sampled_from(["END;", "end;"])) + draw(_COMMENT)
                   + "\n")
        expected.append((name, ch, start, cruise))
    return "".join(out), expected


@settings(max_examples=150, deadline=None)
@given(generated=_motor_file())
def test_generated_files_parse_to_their_values(
        generated: tuple[str, list[tuple[str, int, float, float]]]) -> None:
    """Files written with any case, spacing, comments and key order give their values."""
    text, expected = generated
    dat, records = parse_records(text, "MOTOR.dat", "MOTOR")
    assert dat.text() == text
    assert [(r.name, r.channel, r.start_speed, r.cruise_speed) for r in records.values()] == \
        expected
    for name, *_ in expected:
        assert name.upper().lower() in records


def test_polyaxis_record_defaults_are_documented() -> None:
    """Every optional key's default is stated in the record's docstring."""
    doc = PolyAxisRecord.__doc__ or ""
    for key in ("END_ERROR", "LOW_TENSION", "MAX_TENSION", "NET_FORCELIMIT",
                "OFFSIDE_TENSION", "HARE_SPEED", "HARE_RAMP", "STUCK_TIME",
                "FIND_TOLERANCE", "D2O_DENSITY"):
        assert key in doc


def test_stale_temp_files_removed_at_load(tmp_path: Path) -> None:
    """Leftovers of a killed write-back are removed at load once they are stale; fresh ones stay."""
    d = _station(tmp_path)
    stale = d / ".AXIS.dat.abc123.tmp"
    fresh = d / ".AXIS.dat.def456.tmp"
    stale.write_text("half a file")
    fresh.write_text("a write in progress")
    old = time.time() - 3600
    os.utime(stale, (old, old))
    load_station(d)
    assert not stale.exists()
    assert fresh.exists()


def test_default_working_directory(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """The working copy lives under PYRT_HOME, else the XDG state directory."""
    monkeypatch.setenv("PYRT_HOME", str(tmp_path / "home"))
    assert default_working_directory("SNO") == tmp_path / "home" / "stations" / "sno"
    monkeypatch.delenv("PYRT_HOME")
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "state"))
    assert default_working_directory("prototype") == \
        tmp_path / "state" / "pyrt" / "stations" / "prototype"
    with pytest.raises(ConfigError):
        default_working_directory("elsewhere")


_PROTO_AXIS = (station_directory("prototype") / "AXIS.dat").read_text()


@settings(max_examples=300, deadline=None)
@given(edits=st.lists(st.tuples(st.integers(0, len(_PROTO_AXIS)), st.integers(0, 8),
                                st.text(max_size=8)), min_size=1, max_size=4))
def test_mutated_file_raises_only_config_error(edits: list[tuple[int, int, str]]) -> None:
    """A shipped file with random bytes cut and inserted parses or raises ConfigError."""
    text = _PROTO_AXIS
    for pos, cut, insert in edits:
        text = text[:pos] + insert + text[pos + cut:]
    try:
        dat, _ = parse_records(text, "AXIS.dat", "AXIS")
    except ConfigError as e:
        assert e.line is not None and 1 <= e.line <= max(1, text.count("\n") + 1)
        return
    assert dat.text() == text


_VALUES = st.floats(min_value=-1e4, max_value=1e4, allow_nan=False)


@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(length=st.floats(min_value=0, max_value=1e5, allow_nan=False),
       position=st.tuples(_VALUES, _VALUES, _VALUES),
       mass=st.floats(min_value=1e-3, max_value=1e3, allow_nan=False))
def test_write_back_property(tmp_path: Path, length: float,
                             position: tuple[float, float, float], mass: float) -> None:
    """Any writable value is written in place: only its line changes, and it
    reads back equal within the decimals the file carries."""
    d = tmp_path / f"p{abs(hash((length, position, mass)))}"
    copy_station("prototype", d, overwrite=True)
    before = {f: (d / f).read_text() for f in ("AXIS.dat", "POLYAXIS.dat")}
    s = load_station(d)
    s.write_back({("AXIS", "axis1", "LENGTH"): length,
                  ("POLYAXIS", "prototype", "POSITION"): position,
                  ("POLYAXIS", "prototype", "SOURCE_MASS"): mass})
    r = load_station(d)
    assert r.axis("axis1").length == pytest.approx(length, abs=1e-12 + 1e-13 * length)
    for got, want in zip(r.polyaxis().position, position, strict=True):
        assert got == pytest.approx(want, abs=1e-6)
    assert r.polyaxis().source_mass == pytest.approx(mass, abs=1e-6)
    assert r.polyaxis() == s.polyaxis() and r.axis("axis1") == s.axis("axis1")
    for f, old in before.items():
        changed = [(a, b) for a, b in zip(old.split("\n"), (d / f).read_text().split("\n"),
                                           strict=True) if a != b]
        for a, b in changed:
            assert a.split(":")[0] == b.split(":")[0]
            assert a.partition("//")[2] == b.partition("//")[2]
        keys = {a.split(":")[0] for a, _ in changed}
        assert keys <= {"LENGTH", "POSITION", "SOURCE_MASS"}


def test_working_directory_is_in_the_platforms_state_directory(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """Without PYRT_HOME the working copy is under platformdirs' user state directory for pyrt."""
    import platformdirs

    monkeypatch.delenv("PYRT_HOME", raising=False)
    asked: list[str] = []

    def state_dir(app: str, appauthor: object = None) -> str:
        asked.append(app)
        return str(tmp_path / "platform-state" / app)

    monkeypatch.setattr(platformdirs, "user_state_dir", state_dir)
    assert default_working_directory("sno") == tmp_path / "platform-state" / "pyrt" / "stations" / "sno"
    assert asked == ["pyrt"]


@pytest.mark.parametrize("make", ["missing", "empty"])
def test_manipulator_db_without_a_database_says_how_to_seed_it(tmp_path: Path, make: str,
                                                              capsys: pytest.CaptureFixture) -> None:
    """--db DIR that is missing or empty: one line naming DIR and the --init-db line that seeds it; nothing created."""
    from pyrt.cli import main

    target = tmp_path / "db"
    if make == "empty":
        target.mkdir()
    # a --db that is not a database is a usage error (exit 2, as argparse's), changed with them
    assert main(["manipulator", "--db", str(target), "--speed", "max"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(target) in err and "pyrt manipulator: error: " in err
    assert f"seed it with 'pyrt manipulator --init-db {target} --station prototype|sno'" in err
    assert target.exists() == (make == "empty") and not (target.exists() and any(target.iterdir()))


def test_manipulator_init_db_seeds_the_directory_and_runs_on_it(tmp_path: Path) -> None:
    """--init-db DIR --station sno copies the packaged station into DIR and runs the console on it."""
    import subprocess
    import sys

    target = tmp_path / "new" / "db"
    done = subprocess.run([sys.executable, "-m", "pyrt", "manipulator", "--init-db", str(target),
                           "--station", "sno", "--speed", "max"], input="status\n",
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert f"{target} seeded from the packaged sno station" in done.stdout
    assert f"database {target}" in done.stdout and "T [" in done.stdout
    assert sorted(p.name for p in target.iterdir() if p.name != ".pyrt.lock") == sorted(FILES.values())
    again = subprocess.run([sys.executable, "-m", "pyrt", "manipulator", "--db", str(target),
                            "--init-db", str(target), "--speed", "max"], input="",
                           capture_output=True, text=True, timeout=60)
    assert again.returncode == 2 and "error: give --db DIR" in again.stderr  # a usage error


# -- bounded reads and the directory lock ------------------------------------------


def test_device_and_fifo_are_not_read(tmp_path: Path) -> None:
    """/dev/zero and a FIFO are refused at once as not regular files (nothing read)."""
    with pytest.raises(ConfigError, match="not a regular file"):
        read_regular_file("/dev/zero", 1024)
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    with pytest.raises(ConfigError, match="not a regular file"):
        read_regular_file(fifo, 1024)


def test_oversized_file_is_refused(tmp_path: Path) -> None:
    """A file over the bound is refused naming its size; one at the bound is read whole."""
    f = tmp_path / "big"
    f.write_bytes(b"x" * 1025)
    with pytest.raises(ConfigError, match="1025 bytes, more than the 1024 bytes allowed"):
        read_regular_file(f, 1024)
    f.write_bytes(b"y" * 1024)
    assert read_regular_file(f, 1024) == b"y" * 1024


def test_database_file_that_is_a_device_is_a_config_error(tmp_path: Path) -> None:
    """AXIS.dat linked to /dev/zero: a one-line ConfigError naming the file, no hang."""
    d = copy_station("prototype", tmp_path / "p")
    (d / "AXIS.dat").unlink()
    (d / "AXIS.dat").symlink_to("/dev/zero")
    with pytest.raises(ConfigError, match=r"AXIS\.dat: not a regular file"):
        load_station(d)
    assert MAX_DB_BYTES == 1 << 20


def test_directory_lock_names_the_holder(tmp_path: Path) -> None:
    """A second lock on a station directory, from another process, names the holder's pid;
    released, the directory can be locked again."""
    d = copy_station("prototype", tmp_path / "p")
    code = ("import sys; from pyrt.db import lock_directory; l = lock_directory(sys.argv[1]); "
            "print('locked', flush=True); sys.stdin.readline()")
    child = subprocess.Popen([sys.executable, "-c", code, str(d)], stdin=subprocess.PIPE,
                             stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout.readline().strip() == "locked"
        with pytest.raises(ConfigError, match=f"in use by process {child.pid} "):
            lock_directory(d)
    finally:
        child.communicate("\n", timeout=30)
    lock = lock_directory(d)
    assert lock.held
    with pytest.raises(ConfigError, match=f"in use by process {os.getpid()} "):
        lock_directory(d)
    lock.release()
    lock.release()
    lock_directory(d).release()


def test_a_stale_working_copy_says_how_to_start_afresh(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                        capsys: pytest.CaptureFixture) -> None:
    """A working copy an earlier pyrt left (central top pulley at 000's y = 5 cm) is refused
    in one line that names the directory to move aside; nothing in it is changed."""
    from pyrt.cli import main

    monkeypatch.setenv("PYRT_HOME", str(tmp_path))
    d = copy_station("prototype", tmp_path / "stations" / "prototype")
    axis = d / "AXIS.dat"
    axis.write_text(axis.read_text().replace("TOP: 0. 0. 389.0", "TOP: 0. 5.0 389.0"))
    before = {f: (d / f).read_bytes() for f in FILES.values()}
    assert main(["manipulator", "--speed", "max"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "out of the plane" in err
    assert f"move {d} aside to start again from the packaged prototype station" in err
    assert {f: (d / f).read_bytes() for f in FILES.values()} == before
    assert main(["manipulator", "--speed", "max"]) == 1  # the refused start left no lock
    assert "out of the plane" in capsys.readouterr().err
