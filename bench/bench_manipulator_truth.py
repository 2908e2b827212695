"""The truth property on a larger sample: worst true endpoint error and run time per station.

Run: ``python -m pytest bench/bench_manipulator_truth.py -s`` (not a timing
benchmark: it reports figures).  The same property as tests/test_truth.py
(every ENDPOINT_STOP with the simulated source within the station's
tolerance, prototype 0.5 cm and sno 1.0 cm; any other ending a named stop
with the source where it says) over ``SAMPLE`` random feasible moves per
station with another seed; prints the worst true error at ENDPOINT_STOP,
the stops seen per region and the wall time.
"""

from __future__ import annotations

import time

import pytest
from _truth_rig import TOLERANCE, Workspace, sample_moves

SAMPLE = 60
SEED = 1996


@pytest.mark.parametrize("name", ["prototype", "sno"])
def test_truth_large_sample(name, tmp_path_factory):
    """SAMPLE random feasible moves: the worst true error at ENDPOINT_STOP is within tolerance."""
    ws = Workspace(tmp_path_factory.mktemp(f"ws-{name}"), name)
    w0 = time.perf_counter()
    try:
        results = sample_moves(ws, name, SAMPLE, SEED, tmp_path_factory)
    finally:
        ws.close()
    wall = time.perf_counter() - w0
    ended = [r["error"] for _, r in results if r["stop"] == "ENDPOINT_STOP"]
    by_region: dict[str, dict[str, int]] = {}
    for region, r in results:
        by_region.setdefault(region, {}).setdefault(r["stop"], 0)
        by_region[region][r["stop"]] += 1
    print(f"\n{name}: {len(results)} moves in {wall:.1f} s wall; ENDPOINT_STOP {len(ended)}, "
          f"worst true error {max(ended):.3f} cm (tolerance {TOLERANCE[name]} cm); {by_region}")
    assert max(ended) <= TOLERANCE[name]
