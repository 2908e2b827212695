"""The duration histogram's one bin formula: stats.bin_index, and the vectorised form checked against it."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from pyrt.scheduler._handlertiming import HandlerTimes
from pyrt.scheduler._routinetiming import _bin_indices
from pyrt.scheduler.stats import NBINS, bin_edges, bin_index

_durations = st.integers(-10, 2**45) | st.integers(0, 4096)


@given(st.lists(_durations, min_size=1, max_size=50))
def test_vectorised_bins_are_bin_index(ds):
    """readyqueue's vectorised bins are stats.bin_index, element by element (negatives as 0)."""
    d = np.maximum(np.array(ds, dtype=np.int64), 0)
    assert _bin_indices(d).tolist() == [bin_index(v) for v in ds]


@given(_durations)
def test_loop_records_in_bin_index(d):
    """The loop's record (a tick's lateness, taken and folded) puts a duration in stats.bin_index's bin."""
    times = HandlerTimes()
    times.lateness.samples.append(max(d, 0))
    times.fold(times.take(0))
    acc = times.lateness.acc
    assert acc.hist[bin_index(d)] == 1 and sum(acc.hist) == 1


@given(st.integers(0, 2**40))
def test_a_duration_lies_within_its_bin(d):
    """Below the last bin, bin_edges(bin_index(d)) holds d."""
    i = bin_index(d)
    lo, hi = bin_edges(i)
    assert lo <= d < hi or i == NBINS - 1
