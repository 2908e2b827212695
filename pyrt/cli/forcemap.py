"""``pyrt forcemap``: the force each rope puts on the source over a grid (000's -forceMap).

For every grid position the source may occupy (in the vessel or the neck),
the tensions that hold it there as the controller would (off-side ropes at
OFFSIDE_TENSION, the others balancing the net weight) and each rope's force
vector on the source.  One file per rope, ``axis0.map`` ..., each a CSV
table: lines starting ``#`` that describe it, then a header line naming
the columns with their units (``x_cm,y_cm,...``), then one comma-separated
row per position: ``pandas.read_csv(F, comment="#")`` reads it as it
is (000's maps had their column names in a comment, which CSV readers skip).
The grid covers the vertical plane through the first side rope's attachment (000's maps were for the
planar prototype), or the box given with ``--y``.

The free ropes' tensions are those that balance the weight exactly (least
squares, without bounds), so a tension can come out negative: the rope
would have to push on the source to hold it there, and no rope can push.
At such a position the source cannot be held (with those off-side ropes
at OFFSIDE_TENSION), and the controller refuses it as a target.  The maps
keep these rows, as the balance asks them, and say so: a last column
``holdable`` is 1 where every rope's tension is within
LOW_TENSION..MAX_TENSION and at most NET_FORCELIMIT is left unbalanced
(the controller can hold the source there), else 0; each file's header
and the line printed for it count the positions where its rope would have
to push.
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
from pathlib import Path

from pyrt.db import STATIONS, copy_station
from pyrt.errors import ConfigError, UsageError
from pyrt.fileio import atomic_write
from pyrt.station.manipulator import ManipulatorStation

__all__ = ["COLUMNS", "MAX_CELLS", "add_parser", "force_map", "grid_size", "run"]

COLUMNS = ("x_cm", "y_cm", "z_cm", "tension_N", "fx_N", "fy_N", "fz_N", "holdable")
#: The most grid cells one map may have (a 1 cm grid over the prototype is ~110 000).
MAX_CELLS = 250_000


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("forcemap", help="write per-rope force maps over a grid (axis0.map ...)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--station", choices=STATIONS, default="prototype",
                   help="packaged station to map when no --db is given (default prototype)")
    p.add_argument("--db", metavar="DIR", help="station database (read only)")
    p.add_argument("--out", metavar="DIR", default=".", help="where to write (default .)")
    p.add_argument("--step", type=float, metavar="CM", help="grid step (default: 1/20 of the "
                   f"vessel radius; at most {MAX_CELLS} grid cells)")
    p.add_argument("--y", type=float, default=0.0, metavar="CM",
                   help="y of the grid plane, inside the vessel (default 0)")
    p.set_defaults(run=run)


def grid_size(station: ManipulatorStation, step: float) -> tuple[int, int, int]:
    """``(nx, nz_lo, nz_hi)`` of the grid with ``step`` (cm): x from -nx to nx
    steps, z from -nz_lo to nz_hi steps about the vessel centre."""
    av = station.av
    c = av.vtog((0.0, 0.0, 0.0))
    r = av.vessel_radius
    top = av.neck_ring_position[2] + av.neck_length
    return math.floor(r / step), math.floor(r / step), math.floor((top - c[2]) / step)


def check_grid(station: ManipulatorStation, step: float, y: float) -> None:
    """ConfigError (one line) unless ``step`` is a positive finite number of cm
    giving at most MAX_CELLS cells and ``y`` a finite plane inside the vessel."""
    if not (math.isfinite(step) and step > 0):
        raise UsageError(f"--step must be a positive finite number of cm, got {step!r}")
    if not math.isfinite(y):
        raise UsageError(f"--y must be a finite number of cm, got {y!r}")
    av = station.av
    c = av.vtog((0.0, 0.0, 0.0))
    r = av.vessel_radius
    if abs(y - c[1]) >= r:
        raise UsageError(f"--y {y:g} cm misses the vessel: the plane must be within "
                          f"{c[1] - r:g}..{c[1] + r:g} cm")
    nx, lo, hi = grid_size(station, step)
    cells = (2 * nx + 1) * (lo + hi + 1)
    if cells > MAX_CELLS:
        raise UsageError(f"--step {step:g} cm makes {cells} grid cells, more than {MAX_CELLS}; "
                          f"give --step {math.ceil(step * math.sqrt(cells / MAX_CELLS)):g} or "
                          "more")


def force_map(station: ManipulatorStation, step: float, y: float = 0.0
              ) -> list[list[tuple[float, ...]]]:
    """Rows ``(x, y, z, tension, fx, fy, fz, holdable)`` per rope over the grid
    (ConfigError for a grid :func:`check_grid` refuses).  A negative tension
    is a push the rope cannot give; ``holdable`` is 1.0 where every tension is
    within LOW_TENSION..MAX_TENSION and at most NET_FORCELIMIT is left over,
    else 0.0 (see the module text)."""
    check_grid(station, step, y)
    pa = station.polyaxis
    av = station.av
    c = av.vtog((0.0, 0.0, 0.0))
    rows: list[list[tuple[float, ...]]] = [[] for _ in pa.axes]
    nx, nz_lo, nz_hi = grid_size(station, step)
    for i in range(-nx, nx + 1):
        for k in range(-nz_lo, nz_hi + 1):
            x = (c[0] + i * step, y, c[2] + k * step)
            if pa.refusal(x) is not None:
                continue
            try:
                dirs = pa.force_directions(x)
            except (ValueError, ZeroDivisionError):
                continue
            tensions, left = pa.equilibrium_tensions(x)
            held = float(left <= pa.net_forcelimit and all(
                pa.low_tension <= t <= pa.max_tension for t in tensions))
            for j, (t, d) in enumerate(zip(tensions, dirs, strict=True)):
                rows[j].append((x[0], x[1], x[2], t, t * d[0], t * d[1], t * d[2], held))
    return rows


def run(args: argparse.Namespace) -> int:
    with tempfile.TemporaryDirectory(prefix="pyrt-forcemap-") as tmp:
        src = Path(args.db) if args.db else copy_station(args.station, tmp)
        if args.db:  # never write back into the given database
            src = copy_tree(src, Path(tmp))
        station = ManipulatorStation(src)
        try:
            step = args.step if args.step is not None else station.av.vessel_radius / 20.0
            _write_maps(station, step, args.y, Path(args.out))
        finally:
            station.close()
    return 0


def _write_maps(station: ManipulatorStation, step: float, y: float, out: Path) -> None:
    rows = force_map(station, step, y)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError(f"cannot create {out}: {exc.strerror}") from None
    pa = station.polyaxis
    for axis, table in zip(station.axes, rows, strict=True):
        pushes = sum(1 for row in table if row[3] < 0.0)
        held = sum(1 for row in table if row[7])
        text = [f"# force map of {axis.name}, station {pa.name}: the force "
                f"the rope puts on the source, grid step {step:g} cm, plane y = {y:g} cm",
                f"# tensions: off-side ropes at OFFSIDE_TENSION ({pa.offside_tension:g} N), the "
                "others balancing the net weight exactly, without bounds",
                f"# a negative tension_N is a push the rope would have to give, which no rope "
                f"can: the source cannot be held there ({pushes} of {len(table)} positions "
                f"for {axis.name}); fx fy fz are tension_N times the rope's direction",
                f"# holdable: 1 where every rope is within LOW_TENSION..MAX_TENSION "
                f"({pa.low_tension:g}..{pa.max_tension:g} N) and at most NET_FORCELIMIT "
                f"({pa.net_forcelimit:g} N) is left unbalanced, else 0 ({held} of "
                f"{len(table)} positions are holdable)",
                ",".join(COLUMNS)]  # the header line: no '#', so CSV readers take it
        text.extend(",".join(f"{v:.4f}" for v in row[:7]) + f",{int(row[7])}" for row in table)
        target = out / f"{axis.name}.map"
        atomic_write(target, ("\n".join(text) + "\n").encode())
        print(f"{target}: {len(table)} positions, {held} holdable; {axis.name} would have to "
              f"push (tension_N < 0) at {pushes}", file=sys.stdout)


def copy_tree(src: Path, dest: Path) -> Path:
    """Copy a station directory's database files into ``dest``."""
    from pyrt.db import FILES, MAX_DB_BYTES, read_regular_file

    for name in FILES.values():
        f = src / name
        if not f.exists():
            raise ConfigError(f"no {name} in {src}", str(src))
        (dest / name).write_bytes(read_regular_file(f, MAX_DB_BYTES))
    return dest
