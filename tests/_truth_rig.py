"""Manipulator stations that start with the source at a chosen point (the truth tests)."""

from __future__ import annotations

import contextlib
import math
import re
from pathlib import Path

from _manipulator_rig import TICK_NS

from pyrt.db import copy_station
from pyrt.scheduler.runner import Runner
from pyrt.station.manipulator import ManipulatorStation

#: A station's endpoint tolerance: END_ERROR of its packaged POLYAXIS.dat.
TOLERANCE = {"prototype": 0.5, "sno": 1.0}


def station_at(tmp: Path, name: str, position: tuple[float, float, float], **kw
               ) -> tuple[ManipulatorStation, Runner]:
    """A working copy of packaged station ``name`` with its POSITION (the world's
    start and the controller's) at ``position``, built and started."""
    directory = copy_station(name, tmp)
    path = directory / "POLYAXIS.dat"
    text = path.read_text()
    x, y, z = position
    text, n = re.subn(r"^POSITION:.*$", f"POSITION: {x!r} {y!r} {z!r} // start",
                      text, count=1, flags=re.M)
    assert n == 1
    path.write_text(text)
    station = ManipulatorStation(directory, tick_ns=kw.pop("tick_ns", TICK_NS), **kw)
    runner = station.start()
    runner.sleep(0.2)
    return station, runner


def motors_still(station: ManipulatorStation) -> bool:
    """Every motor stopped: not stepping, no velocity."""
    return not station.motors_running() and all(a.motor.velocity == 0.0 for a in station.axes)


def true_error(station: ManipulatorStation, point) -> float:
    """Distance of the simulated source (the world's truth) from ``point`` (cm)."""
    return math.dist(station.plant.position, point)


# -- the truth property: random feasible moves against the simulated source -------------

#: Regions the truth test draws targets from.
REGIONS = ("interior", "edge", "neck-axis", "neck-off-axis")


class Workspace:
    """One station's geometry and feasibility (its PolyAxis's own checks), built once:
    which points a ``to`` accepts, and the edge of that set along a ray."""

    def __init__(self, tmp: Path, name: str):
        self.name = name
        self.station, self.runner = station_at(tmp, name, _PACKAGED_START[name])
        pa = self.station.polyaxis
        av = self.station.av
        self.planar = bool(pa.plane)
        self.radius = av.vessel_radius
        self.centre = av.vtog((0.0, 0.0, 0.0))
        self.ring = av.neck_ring_position
        self.neck_radius = av.neck_radius
        self.neck_top = min(self.ring[2] + av.neck_length,
                            min(t[2] for t in pa.tops)) - 15.0

    def close(self) -> None:
        self.station.close()

    def feasible(self, x) -> bool:
        """``to`` would accept ``x`` as a target (containment, plane, pulleys, tensions)."""
        from pyrt.errors import CommandError
        try:
            self.station.polyaxis.check_target(x)
        except CommandError:
            return False
        return True

    def edge(self, direction, margin: float):
        """The point ``margin`` cm inside the edge of the feasible set from the centre
        along ``direction`` (bisection on :meth:`feasible`), or None."""
        d = math.sqrt(sum(c * c for c in direction))
        if d == 0.0:
            return None
        u = [c / d for c in direction]

        def at(r):
            return tuple(self.centre[k] + r * u[k] for k in range(3))
        lo, hi = 0.0, self.radius
        if not self.feasible(at(lo)):
            return None
        for _ in range(30):
            mid = 0.5 * (lo + hi)
            if self.feasible(at(mid)):
                lo = mid
            else:
                hi = mid
        r = lo - margin
        return at(r) if r > 0 else None


#: A start inside both packaged workspaces near their default positions.
_PACKAGED_START = {"prototype": (-0.2, 0.0, 95.57), "sno": (0.0, 0.0, 0.0)}


def draw_case(draw, ws: Workspace, region: str | None = None):
    """(region, start, target): a feasible target in ``region`` (default: one of
    :data:`REGIONS`, drawn) and a feasible start 15-40 cm from it (a hypothesis ``draw``)."""
    from hypothesis import assume
    from hypothesis import strategies as st

    if region is None:
        region = draw(st.sampled_from(REGIONS))
    unit = st.floats(-1.0, 1.0)
    cx, cy, cz = ws.centre
    if region == "interior":
        r = draw(st.floats(0.0, 0.5)) * ws.radius
        v = (draw(unit), 0.0 if ws.planar else draw(unit), draw(unit))
        n = math.sqrt(sum(c * c for c in v))
        assume(n > 1e-3)
        target = (cx + r * v[0] / n, cy + r * v[1] / n, cz + r * v[2] / n)
    elif region == "edge":
        v = (draw(unit), 0.0 if ws.planar else draw(unit), draw(unit))
        found = ws.edge(v, draw(st.floats(1.0, 30.0)))
        assume(found is not None)
        target = found
    else:
        rx, ry, rz = ws.ring
        top = ws.neck_top
        z = draw(st.floats(rz - 60.0, top))
        if region == "neck-axis":
            target = (rx, ry, z)
        else:
            r = draw(st.floats(0.2, 0.8)) * ws.neck_radius
            a = 0.0 if ws.planar else draw(st.floats(0.0, 2.0 * math.pi))
            sign = draw(st.sampled_from((-1.0, 1.0))) if ws.planar else 1.0
            target = (rx + sign * r * math.cos(a), ry + r * math.sin(a), z)
    assume(ws.feasible(target))
    length = draw(st.floats(15.0, 40.0))
    v = (draw(unit), 0.0 if ws.planar else draw(unit), draw(unit))
    n = math.sqrt(sum(c * c for c in v))
    assume(n > 1e-3)
    start = tuple(target[k] + length * v[k] / n for k in range(3))
    assume(ws.feasible(start))
    return region, start, target


def run_case(tmp: Path, name: str, start, target) -> dict:
    """Build ``name`` with the source at ``start``, move to ``target`` and compare the
    ending with the simulated source: a dict with the stop, the true error and
    the wall time.  Raises AssertionError when the ending is not the truth."""
    import time

    from pyrt.errors import CommandError, FaultError
    from pyrt.robots.stops import StopReason

    w0 = time.perf_counter()
    station, runner = station_at(tmp, name, start)
    pa = station.polyaxis
    tol = TOLERANCE[name]
    try:
        try:
            runner.call(pa.to, target)
        except CommandError as exc:  # refused with its reason: nothing may have moved
            runner.sleep(0.5)
            assert motors_still(station) and "refused" in str(exc)
            return {"stop": "refused", "error": None, "wall": time.perf_counter() - w0}
        with contextlib.suppress(FaultError):  # a safety stop: its record is checked below
            assert runner.wait_until(lambda: not pa.active, 1800.0), "the move never ended"
        rec = pa.last_stop
        assert rec is not None
        truth = station.plant.position
        error = math.dist(truth, target)
        assert motors_still(station)
        if rec.reason is StopReason.ENDPOINT_STOP:
            assert error <= tol, (f"{name}: ENDPOINT_STOP for {target} with the simulated "
                                  f"source at {truth}, {error:.3f} cm away (tolerance {tol} cm)")
        else:
            assert rec.reason is not StopReason.DONE
            if "position estimate lost" not in rec.detail:  # else it says not to trust it
                off = math.dist(truth, rec.position)
                assert off <= tol, (f"{name}: {rec} but the simulated source is at {truth}, "
                                    f"{off:.3f} cm from where it says")
        return {"stop": rec.reason.value, "error": error, "wall": time.perf_counter() - w0}
    finally:
        station.close()


def sample_moves(ws: Workspace, name: str, size: int, seed_value: int,
                 tmp_path_factory) -> list[tuple[str, dict]]:
    """``size`` random feasible moves on station ``name`` (hypothesis, seeded): for each,
    its region and :func:`run_case`'s result.  The regions take turns (every region is
    covered whatever the draws: hypothesis biases its draws by the constants of the
    modules loaded, so a drawn region depends on what else the run imported)."""
    from hypothesis import HealthCheck, given, seed, settings
    from hypothesis import strategies as st

    results: list[tuple[str, dict]] = []

    def sample(region: str, count: int) -> None:
        @seed(seed_value)
        @settings(max_examples=count, database=None, deadline=None,
                  suppress_health_check=list(HealthCheck))
        @given(st.data())
        def check(data):
            got, start, target = data.draw(st.composite(lambda d: draw_case(d, ws, region))(),
                                           label="case")
            results.append((got, run_case(tmp_path_factory.mktemp(name), name, start,
                                          target)))

        check()

    share, extra = divmod(size, len(REGIONS))
    for i, region in enumerate(REGIONS):
        sample(region, share + (1 if i < extra else 0))
    return results
