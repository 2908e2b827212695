"""The truth test: every ENDPOINT_STOP has the simulated source within the station's tolerance.

On both packaged stations, over random feasible targets drawn from the
interior, the edge of the workspace (the wall margin: as far out as the
tensions allow, 1-30 cm inside) and the neck region on and off its axis,
each reached from a feasible start 15-40 cm away: a move that ends at
ENDPOINT_STOP has the simulated source (the world's truth) within the
station's endpoint tolerance (prototype 0.5 cm, sno 1.0 cm) of the target,
and any other ending is a named stop with the source where its message
says.  Hypothesis with a fixed seed and the sample size below, on SimClock;
a larger sample is ``bench/bench_manipulator_truth.py``.
"""

from __future__ import annotations

import pytest
from _truth_rig import REGIONS, Workspace, sample_moves

#: Moves per station in the default suite (each a fresh station on SimClock).
SAMPLE = {"prototype": 16, "sno": 12}
SEED = 14


@pytest.fixture(scope="module")
def workspaces(tmp_path_factory):
    spaces = {name: Workspace(tmp_path_factory.mktemp(f"ws-{name}"), name) for name in SAMPLE}
    yield spaces
    for ws in spaces.values():
        ws.close()


@pytest.mark.parametrize("name", sorted(SAMPLE))
def test_endpoint_stop_is_where_the_source_is(name, workspaces, tmp_path_factory):
    """Random feasible moves on a packaged station: ENDPOINT_STOP only with the simulated
    source within the station's tolerance; any other ending names where the source is."""
    results = sample_moves(workspaces[name], name, SAMPLE[name], SEED, tmp_path_factory)
    assert len(results) == SAMPLE[name]
    assert {region for region, _ in results} == set(REGIONS)
    ended = [r for _, r in results if r["stop"] == "ENDPOINT_STOP"]
    assert len(ended) >= SAMPLE[name] // 2  # the property is about real endings
    worst = max(r["error"] for r in ended)
    print(f"\n{name}: {len(results)} moves, {len(ended)} ENDPOINT_STOP, worst true error "
          f"{worst:.3f} cm; stops {sorted({r['stop'] for _, r in results})}")
