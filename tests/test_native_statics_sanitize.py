"""The statics kernel under AddressSanitizer and UBSan (run with ``pytest -m sanitize``).

The extension is rebuilt from a private copy of csrc/ with
``-fsanitize=address,undefined``; a driver in a subprocess (libasan
preloaded) solves many random 1-, 3- and 5-rope problems with and without
the neck ring, and calls the raw entry points with the NULL pointers and
out-of-range sizes the Python layer never lets through.
"""

from __future__ import annotations

import textwrap

import pytest
from _sanitize import PRELUDE, assert_clean, run_under_asan

pytestmark = pytest.mark.sanitize



DRIVER = textwrap.dedent(
    """
    import math, random, sys
    from pyrt.native import StaticsSolver
    from pyrt.errors import NativeError
    ffi, lib = native.ffi, native.lib

    tops = [(0, 0, 1299.0), (60, 0, 1299.0), (-60, 0, 1299.0), (0, 60, 1299.0), (0, -60, 1299.0)]
    bots = [None, (545.44, 0, -250.0), (-545.44, 0, -250.0), (0, 545.44, -250.0),
            (0, -545.44, -250.0)]
    ring = ((0.0, 0.0, 595.8), (0.0, 0.0, 1.0), 72.5)
    rnd = random.Random(1)
    for n in (1, 3, 5):
        for use_ring in (None, ring):
            s = StaticsSolver(tops[:n], bots[:n], None, [50.0] * n, [2e-5] * n, [2000.0] * n,
                              ring=use_ring, weight=52.0, floor_z=-600.0)
            for _ in range(60):
                x = (rnd.uniform(-400, 400), rnd.uniform(-400, 400), rnd.uniform(-500, 500))
                try:
                    g, _, _ = s.evaluate(x)
                except NativeError:
                    continue
                s.set_payouts([50.0 + gi + rnd.uniform(-2, 5) for gi in g])
                s.set_position(x)
                try:
                    s.solve()
                except NativeError:
                    pass
                for i in range(n):
                    s.set_intact(i, rnd.random() > 0.2)

    p = ffi.new("pyrt_statics_problem *")
    assert lib.pyrt_statics_solve(ffi.NULL) == lib.PYRT_EINVAL
    assert lib.pyrt_statics_solve(p) == lib.PYRT_EINVAL
    buf = ffi.new("double[]", 3 * 20)
    ib = ffi.new("int32_t[]", 20)
    p.tops = p.bottoms = p.payout = p.dead = p.compliance = p.position = p.tension = buf
    p.intact = p.wrapped = ib
    p.tol = p.max_step = 1.0
    p.max_iter = 1
    for n in (0, -1, lib.PYRT_STATICS_MAX_ROPES + 1):
        p.n = n
        assert lib.pyrt_statics_solve(p) == lib.PYRT_EINVAL
    p.n = 1
    assert lib.pyrt_statics_evaluate(p, ffi.NULL, ffi.NULL, buf, ffi.NULL) == lib.PYRT_EINVAL
    print("SANITIZE-DRIVER-OK")
    """
)


def test_statics_is_clean_under_asan_and_ubsan(tmp_path):
    """The statics kernel, on good and bad input, runs with no ASan or UBSan report."""
    assert_clean(run_under_asan(PRELUDE + DRIVER, tmp_path))
