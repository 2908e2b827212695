"""The manipulator station: scope channels, Table 2 queries, errorSignalAll, blended neck moves."""

from __future__ import annotations

import math

import numpy as np
import pytest
from _manipulator_rig import make_station, move

from pyrt.errors import CommandError
from pyrt.robots.stops import StopReason
from pyrt.scope import compile_sources


@pytest.fixture
def proto(tmp_path):
    station, runner = make_station(tmp_path)
    yield station, runner
    station.close()


def test_scope_channels_resolve(proto):
    """resolve_signal gives live sources for the robot, axes and devices (case-insensitive)."""
    station, runner = proto
    names = ["prototype.x", "PROTOTYPE.z", "prototype.distErr", "prototype.netForce",
             "axis0.tension", "axis1.length", "Axis2.errorLength", "axis0Motor.velocity",
             "axis1Encoder.length", "axis2Loadcell.tension", "axis0.velocity"]
    read = compile_sources([station.resolve_signal(n).scope_source() for n in names])
    values = runner.call(read)
    pa = station.polyaxis
    assert values[0] == pa.position[0] and values[1] == pa.position[2]
    assert values[4] == pa.tensions[0] and values[5] == pa.lengths[1]
    assert values[8] == pytest.approx(station.axes[1].encoder.length())
    for bad in ["prototype", "axis9.tension", "axis0.colour", "axis0Motor.tension", ".x"]:
        with pytest.raises(CommandError):
            station.resolve_signal(bad)


@pytest.mark.parametrize("name", ["prototype", "sno"])
def test_rope_lengths_agree(tmp_path, name):
    """The poll's C rope geometry equals the Python form (ring contact included) everywhere."""
    station, _ = make_station(tmp_path, name)
    pa = station.polyaxis
    r = station.av.vessel_radius
    rng = np.random.default_rng(1)
    wrapped = 0
    for _ in range(300):
        x = tuple(rng.uniform(-r, r, 3))
        if pa.model.refusal(x) is not None:
            continue
        fast = pa.model.lengths_at(x)
        for i in range(pa.n):
            length, contact, _, _ = pa.model.rope_geometry(i, x)
            wrapped += contact is not None
            assert fast[i] == pytest.approx(length, abs=1e-6)
            assert pa.model.length_at(i, x) == pytest.approx(length, abs=1e-9)
    assert wrapped > 0
    station.close()


def test_table2_queries(proto):
    """tensions, netForce [x y z] and tensionFind answer from the current state."""
    station, runner = proto
    pa = station.polyaxis
    text = runner.call(pa.run_command, "tensions")
    assert text.startswith("prototype: desired tensions axis0 ")
    assert "axis1 10.00 N" in text  # the off-side rope (the source is at x < 0)
    here = runner.call(pa.run_command, "netForce")
    assert float(here.split("net force ")[1].split()[0]) < 5.0
    far = runner.call(pa.run_command, "netForce", "100", "0", "100")
    assert float(far.split("net force ")[1].split()[0]) > 10.0
    def from_true_tensions():  # tensionFind's statics, without the loadcells' errors
        pa.tensions[:] = station.plant.tensions()
        return pa.tension_find()

    assert math.dist(runner.call(from_true_tensions), station.plant.position) < 0.1
    assert "position from tensions" in runner.call(pa.run_command, "tensionFind")


def test_error_signal_all_moves_too(proto):
    """With errorSignalAll every rope is driven toward its equilibrium tension; the move ends."""
    station, runner = proto
    pa = station.polyaxis
    assert "every rope" in runner.call(pa.run_command, "errorSignalAll")
    stop = move(station, runner, (20.0, 0.0, 110.0))
    assert stop.reason is StopReason.ENDPOINT_STOP
    assert pa.free == [0.0, 0.0, 0.0]


def test_blended_neck_move(proto):
    """'to x y z blend' into the neck keeps moving through the turn (Paul's transition)."""
    station, runner = proto
    pa = station.polyaxis
    move(station, runner, (60.0, 0.0, 250.0))
    text = runner.call(pa.run_command, "to", "5.7", "0", "370", "blend")
    assert "2 blended segments" in text
    hare = pa.hare
    waited = []
    runner.wait_until(lambda: (waited.append(hare.at_turn), not pa.active)[1], 600.0)
    assert not any(waited)
    corner = pa.via
    assert min(math.dist(p, corner) for p in hare.sample(0.5)) > 0.3  # the corner is cut
    assert pa.last_stop.reason is StopReason.ENDPOINT_STOP
    assert math.dist(pa.position, (5.7, 0.0, 370.0)) <= 1.0


# -- the database directory: one process, the right station, a sane POSITION ---------


def test_second_station_on_one_directory_is_refused(tmp_path):
    """Two stations on one database directory: the second is refused naming the pid;
    after the first closes the directory opens again."""
    import os

    from pyrt.errors import ConfigError
    from pyrt.station.manipulator import ManipulatorStation

    station, _ = make_station(tmp_path)
    try:
        with pytest.raises(ConfigError, match=f"in use by process {os.getpid()} "):
            ManipulatorStation(station.directory)
    finally:
        station.close()
    ManipulatorStation(station.directory).close()


def test_station_database_mismatch_is_an_error(tmp_path):
    """--station sno with a prototype database: a ConfigError naming both; nothing locked."""
    from pyrt.db import copy_station
    from pyrt.errors import ConfigError
    from pyrt.station.manipulator import ManipulatorStation

    d = copy_station("prototype", tmp_path / "p")
    with pytest.raises(ConfigError, match="holds the 'prototype' station, not 'sno'"):
        ManipulatorStation(d, expect="sno")
    ManipulatorStation(d, expect="prototype").close()


def test_position_outside_the_vessel_names_file_and_line(tmp_path):
    """A database POSITION outside the vessel: ConfigError at POLYAXIS.dat's POSITION line."""
    from pyrt.db import copy_station
    from pyrt.errors import ConfigError
    from pyrt.station.manipulator import ManipulatorStation

    d = copy_station("prototype", tmp_path / "p")
    f = d / "POLYAXIS.dat"
    lines = f.read_text().splitlines(keepends=True)
    n = next(i for i, ln in enumerate(lines) if ln.startswith("POSITION:"))
    lines[n] = "POSITION: 0. 0. 1000. // by hand\n"
    f.write_text("".join(lines))
    with pytest.raises(ConfigError, match=rf"POLYAXIS\.dat:{n + 1}: .*POSITION \(0, 0, 1000\) "
                                          "cm is outside the vessel"):
        ManipulatorStation(d)


def test_startup_reconciles_the_database_with_the_encoders(tmp_path):
    """Start-up says what it did with ZEROLENGTH and LENGTH: the packaged values (000's
    numbers) are set from POSITION and named; after a run they are kept as written."""
    from pyrt.db import load_station
    from pyrt.station.manipulator import ManipulatorStation

    station, runner = make_station(tmp_path)
    notes = station.startup_notes
    assert any(n.startswith("axis1Encoder ZEROLENGTH 1067.249 cm is -2.459 cm") for n in notes)
    assert any(n.startswith("AXIS AXIS2 LENGTH 613.783 cm") for n in notes)
    move(station, runner, (0.0, 0.0, 80.0))
    station.close()
    db = load_station(station.directory)
    again = ManipulatorStation(station.directory, tick_ns=5_000_000)
    try:
        assert again.startup_notes == ["encoders and lengths agree with POSITION (ZEROLENGTH "
                                       "and LENGTH kept)"]
        pa = db.polyaxis()
        for a, rec in zip(again.axes, db.axes_of(pa), strict=True):
            assert a.encoder.zero_length == db.encoder_of(rec).zerolength
    finally:
        again.close()
