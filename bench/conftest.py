"""Benchmark helpers: the tests/ references on the path, and a ratio summary.

Benchmarks that call the ``record`` fixture after timing have their mean
time kept under a key; at the end of the run the native-kernel figures are
printed per call and per axis, with their ratios against the comparators
and the targets (``-s`` not needed: it goes to the terminal summary).
"""

from __future__ import annotations

import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

def board_sim(world: str) -> Iterator[str]:
    """``pyrt board-sim WORLD`` in a subprocess (watchdog 5 s): yields its URL."""
    proc = subprocess.Popen([sys.executable, "-m", "pyrt", "board-sim", world, "--listen",
                             "127.0.0.1:0", "--watchdog", "5"], stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        m = re.search(r" on (tcp://\S+) ", proc.stdout.readline())
        assert m, "board-sim did not say where it serves"
        yield m.group(1)
    finally:
        proc.kill()
        proc.wait(10)


@pytest.fixture(scope="module")
def gripper_url() -> Iterator[str]:
    """A gripper board-sim in a subprocess."""
    yield from board_sim("gripper")


@pytest.fixture(scope="module")
def manipulator_url() -> Iterator[str]:
    """A prototype-station board-sim in a subprocess."""
    yield from board_sim("prototype")


_MEANS: dict[str, float] = {}  # medians: robust on a shared machine
_MINS: dict[str, float] = {}


@pytest.fixture
def record():
    """record(benchmark): keep its mean time (s) under a key made of its extra_info
    (``fuzzy<axes>/<impl>`` or ``findpos/<ropes>/<impl>``)."""

    def keep(benchmark) -> None:
        stats = getattr(benchmark, "stats", None)
        if stats is None:
            return
        info = benchmark.extra_info
        key = (f"fuzzy{info['axes']}/{info['impl']}" if "axes" in info
               else f"findpos/{info['ropes']}/{info['impl']}")
        _MEANS[key] = stats.stats.median
        _MINS[key] = stats.stats.min

    return keep


def _us(key: str) -> str:
    if key not in _MEANS:
        return "(not run)"
    return f"{_MEANS[key] * 1e6:.3f} us (min {_MINS[key] * 1e6:.3f})"


def _ratio(slow: str, fast: str) -> str:
    if slow in _MEANS and fast in _MEANS:
        return f"{_MEANS[slow] / _MEANS[fast]:.0f}x"
    return "(n/a)"


def pytest_terminal_summary(terminalreporter):
    if not any(k.startswith(("fuzzy", "findpos")) for k in _MEANS):
        return
    w = terminalreporter.write_line
    w("")
    w("native kernels: median per call (min), per axis for 5 axes, and ratios of medians")
    for n in (1, 5):
        c = f"fuzzy{n}/c-batch"
        per_axis = f"  ({_MEANS[c] / n * 1e6:.3f} us per axis)" if c in _MEANS else ""
        w(f"  fuzzy {n} axis  C batch {_us(c)}{per_axis}; one-shot {_us(f'fuzzy{n}/c-oneshot')}")
        w(f"      python {_us(f'fuzzy{n}/python')} = {_ratio(f'fuzzy{n}/python', c)} C;"
          f"  scikit-fuzzy {_us(f'fuzzy{n}/skfuzzy')} = {_ratio(f'fuzzy{n}/skfuzzy', c)} C")
    if "fuzzy5/c-batch" in _MEANS:
        ok = _MEANS["fuzzy5/c-batch"] < 0.6e-6
        w(f"  target: 5 axes in one call < 0.6 us: {'met' if ok else 'NOT met'};"
          f" >= 1000x scikit-fuzzy")
    for ropes in ("3 ropes", "5 ropes"):
        c = f"findpos/{ropes}/c-prepared"
        w(f"  findpos {ropes}  C prepared {_us(c)}; poll path {_us(f'findpos/{ropes}/c-poll')};"
          f" one-shot {_us(f'findpos/{ropes}/c-oneshot')}")
        for other in ("numpy", "least_squares-lm-jac", "least_squares-lm"):
            key = f"findpos/{ropes}/{other}"
            w(f"      {other:22s} {_us(key)} = {_ratio(key, c)} C prepared")
    for impl in ("c-prepared", "c-poll"):
        key = f"findpos/5 ropes/{impl}"
        if key in _MEANS:
            ok = _MEANS[key] < 1.5e-6
            w(f"  target: {impl} 5-rope solve < 1.5 us: {'met' if ok else 'NOT met'};"
              f" >= 100x least_squares")
