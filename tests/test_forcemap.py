"""pyrt forcemap: per-rope force maps over a grid, with a header naming columns and units."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from pyrt.cli import main
from pyrt.cli.forcemap import COLUMNS
from pyrt.sim.manipulator import GRAVITY


@pytest.mark.parametrize(("station", "ropes", "step"), [("prototype", 3, "40"),
                                                        ("sno", 5, "100")])
def test_force_maps_balance_the_weight(tmp_path, capsys, station, ropes, step):
    """One map per rope, a CSV table whose header line (after the '#' lines) names the
    columns; at every position the rope forces sum to the net weight."""
    assert main(["forcemap", "--station", station, "--out", str(tmp_path), "--step", step]) == 0
    maps = []
    for i in range(ropes):
        lines = (tmp_path / f"axis{i}.map").read_text().splitlines()
        head = [ln for ln in lines if ln.startswith("#")]
        assert lines[:len(head)] == head and lines[len(head)] == ",".join(COLUMNS)
        assert all(c.endswith(("_cm", "_N")) for c in COLUMNS[:-1])  # then holdable, 0 or 1
        rows = list(csv.DictReader(lines[len(head):]))  # as pandas.read_csv(comment="#")
        assert list(rows[0]) == list(COLUMNS)
        named = np.genfromtxt(tmp_path / f"axis{i}.map", delimiter=",", names=True,
                              skip_header=len(head))
        assert named.dtype.names == COLUMNS and len(named) == len(rows)
        maps.append(np.array([[float(r[c]) for c in COLUMNS] for r in rows]))
    assert all(m.shape == maps[0].shape for m in maps) and len(maps[0]) > 10
    total = sum(m[:, 4:7] for m in maps)
    z = maps[0][:, 2]
    buoyant = 1.10 * 1.0 if station == "sno" else 0.0  # 1 l in D2O below the neck ring
    weight = (5.3357 - np.where(z < 595.8, buoyant, 0.0)) * GRAVITY
    # the free ropes balance the net weight at every grid position (in the rope
    # plane: the prototype's central pulley is 5 cm out of it, Table 3)
    assert np.abs(total[:, 0]).max() < 0.6
    if station == "sno":
        assert np.abs(total[:, 1]).max() < 0.5
    # (least squares shares the prototype's out-of-plane pull with z: 2 N of 52 N)
    assert np.abs(total[:, 2] - weight).max() < (0.5 if station == "sno" else 2.0)
    for m in maps:
        assert np.all(np.isfinite(m))
    # a tension-free rope puts no force on the source
    assert all(np.allclose(m[m[:, 3] == 0.0, 4:7], 0.0) for m in maps)
    assert np.all(maps[0][:, 1] == 0.0)
    assert f"axis{ropes - 1}.map" in capsys.readouterr().out


def test_bad_step_refused(tmp_path, capsys):
    """A step that is not a positive length: one error line, exit 2 (a usage error),
    nothing written."""
    assert main(["forcemap", "--out", str(tmp_path), "--step", "-5"]) == 2
    assert "--step" in capsys.readouterr().err
    assert not list(tmp_path.glob("*.map"))


@pytest.mark.parametrize("args,match", [
    (["--y", "nan"], "--y must be a finite number of cm, got nan"),
    (["--y", "1e9"], "--y 1e+09 cm misses the vessel"),
    (["--step", "1e-9"], "grid cells, more than 250000"),
    (["--step", "inf"], "--step must be a positive finite number"),
    (["--step", "nan"], "--step must be a positive finite number"),
])
def test_bad_grid_is_one_line_error(tmp_path, capsys, args, match):
    """NaN planes, planes off the vessel, too fine or infinite steps: one error line, exit 2
    (a usage error), no traceback, nothing written."""
    assert main(["forcemap", "--out", str(tmp_path), *args]) == 2
    err = capsys.readouterr().err
    assert match in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1
    assert not list(tmp_path.glob("*.map"))


def test_negative_tensions_are_explained_and_marked_not_holdable(tmp_path, capsys):
    """A negative tension (a push no rope can give) is said in the header and the printed line, its position is marked holdable 0, and the controller refuses every position marked 0 as a target."""
    from pyrt.cli.forcemap import force_map
    from pyrt.db import copy_station
    from pyrt.errors import CommandError
    from pyrt.station.manipulator import ManipulatorStation

    assert main(["forcemap", "--out", str(tmp_path), "--step", "40"]) == 0
    printed = capsys.readouterr().out
    lines = (tmp_path / "axis0.map").read_text().splitlines()
    header = [ln for ln in lines if ln.startswith("#")]
    assert lines[len(header)] == ",".join(COLUMNS)
    table = np.loadtxt(lines[len(header) + 1:], delimiter=",")
    pushes = int(np.sum(table[:, 3] < 0))
    assert pushes > 0
    assert COLUMNS[-1] == "holdable"
    assert any("a negative tension_N is a push the rope would have to give, which no rope "
               f"can: the source cannot be held there ({pushes} of {len(table)} positions"
               in ln for ln in header)
    assert f"axis0 would have to push (tension_N < 0) at {pushes}" in printed
    assert set(np.unique(table[:, 7])) <= {0.0, 1.0}
    assert np.all(table[table[:, 3] < 0, 7] == 0.0)  # a push is never holdable
    assert np.any(table[:, 7] == 1.0)

    station = ManipulatorStation(copy_station("prototype", tmp_path / "db"))
    try:
        rows = force_map(station, 40.0)
        for row in rows[0]:
            if row[7] == 0.0:
                with pytest.raises(CommandError, match="refused"):
                    station.polyaxis.check_target(row[:3])
    finally:
        station.close()
