"""The C kernels under AddressSanitizer and UBSan (run with ``pytest -m sanitize``).

The extension is rebuilt from csrc/ into a temporary directory with
``-fsanitize=address,undefined`` (build_native.py reads PYRT_CFLAGS and
PYRT_LDFLAGS), then a driver runs in a subprocess with libasan preloaded:
it loads that build as ``pyrt._native`` and calls every findpos, fuzzy,
neck, polyctl, readyq and convert entry point, good input and bad
(including the NULL pointers and sizes the Python layer never lets through).  Any sanitizer report aborts
the driver (``-fno-sanitize-recover=all``), so the test asserts a clean exit;
a deliberate overflow against the same build shows the sanitizer is live.
"""

from __future__ import annotations

import textwrap

import pytest
from _sanitize import PRELUDE, assert_clean, run_under_asan

pytestmark = pytest.mark.sanitize



DRIVER = textwrap.dedent(
    """
    import math, sys

    import numpy as np
    import pyrt.native as nat
    from pyrt.errors import NativeError

    ffi, lib = native.ffi, native.lib
    NAN = math.nan
    import pyrt.native._lib as bound
    assert bound.lib is lib, "pyrt.native is not using the sanitized build"

    def refused(fn, *args, **kw):
        try:
            fn(*args, **kw)
        except NativeError:
            return
        raise AssertionError(f"{fn.__name__} accepted bad input")

    # ---- findpos through the Python API
    tops = np.array([[0, 5, 389.0], [50, 0, 391], [-50, 0, 391], [0, 50, 391], [0, -50, 391]])
    bots = np.array([[NAN] * 3, [317, 0, 89.53], [-317, 0, 89.53], [0, 317, 89.53],
                     [0, -317, 89.53]])
    rng = np.random.default_rng(0)
    for n in (1, 3, 5):
        t, b = tops[:n], bots[:n]
        freeze = (1, 1, 0) if n == 1 else None
        for _ in range(50):
            x = rng.uniform(-200, 200, 3)
            if n == 3:
                x[1] = 0.0
            L = nat.rope_lengths(x, t, b)
            nat.rope_segments(x, t, b, offsets=rng.normal(size=(n, 3)))
            start = x + (0, 0, 10.0) if n == 1 else x + rng.uniform(-10, 10, 3) * (1, n != 3, 1)
            r = nat.find_position(t, b, L + rng.normal(0, 0.1, n), start, freeze=freeze)
            assert np.isfinite(r.position).all()
        nat.freeze_mask(b)
    f = nat.PositionFinder(tops, bots)
    x = np.array([10.0, -20.0, 100.0])
    for k in range(100):
        f.set_top(k % 5, tops[k % 5] + rng.normal(0, 0.5, 3))
        f.solve(nat.rope_lengths(x + 0.1 * k, f.tops, bots), x if k == 0 else None)
    bad_len = np.full(5, 600.0)
    bad_len[1] = NAN
    refused(f.solve, bad_len)
    refused(nat.find_position, tops[:2], bots[:2], [500.0, 600.0], x, freeze=(0, 0, 0))
    refused(nat.find_position, tops, bots, np.full(5, 600.0), x, max_iter=1)
    refused(nat.rope_lengths, tops[1], tops, bots)
    refused(nat.find_position, tops, bots, np.full(5, 600.0), bots[1])
    b2 = bots.copy()
    b2[2, 0] = NAN
    refused(nat.rope_lengths, x, tops, b2)
    b2[2, 0] = math.inf
    refused(nat.rope_lengths, x, tops, b2)

    # ---- findpos straight into C: what the Python layer never passes
    buf = ffi.new("double[]", 3 * 17)
    out = ffi.new("double[]", 17)
    fz = ffi.new("int32_t[3]")
    assert lib.pyrt_findpos_solve(ffi.NULL) == lib.PYRT_EINVAL
    p = ffi.new("pyrt_findpos_problem *")
    for n in (0, -1, 17):
        p.n = n
        assert lib.pyrt_findpos_solve(p) == lib.PYRT_EINVAL
        assert lib.pyrt_findpos_freeze_mask(n, buf, fz) == lib.PYRT_EINVAL
        assert lib.pyrt_rope_lengths(n, buf, buf, ffi.NULL, buf, out, ffi.NULL, ffi.NULL,
                                     ffi.NULL, ffi.NULL) == lib.PYRT_EINVAL
    p.n = 1
    assert lib.pyrt_findpos_solve(p) == lib.PYRT_EINVAL          # NULL arrays
    assert lib.pyrt_findpos_freeze_mask(1, ffi.NULL, fz) == lib.PYRT_EINVAL
    assert lib.pyrt_findpos_freeze_mask(1, buf, ffi.NULL) == lib.PYRT_EINVAL
    assert lib.pyrt_rope_lengths(1, buf, buf, ffi.NULL, ffi.NULL, out, ffi.NULL, ffi.NULL,
                                 ffi.NULL, ffi.NULL) == lib.PYRT_EINVAL
    p.tops = p.bottoms = p.lengths = p.position = p.residuals = buf
    p.tol, p.max_iter = 0.0, 10
    assert lib.pyrt_findpos_solve(p) == lib.PYRT_EINVAL
    p.tol, p.max_iter = 0.1, 0
    assert lib.pyrt_findpos_solve(p) == lib.PYRT_EINVAL
    p.max_iter = 10
    p.freeze = (1, 1, 1)
    assert lib.pyrt_findpos_solve(p) == lib.PYRT_EINVAL
    p.freeze = (0, 0, 0)
    assert lib.pyrt_findpos_solve(p) == lib.PYRT_EDEGENERATE     # source on its own pulley

    # ---- fuzzy through the Python API
    params = [nat.FuzzyParams(), nat.FuzzyParams().for_poll_period(0.02)]
    for n in (1, 5, 16):
        rows = np.column_stack([
            rng.uniform(0, 120, n), rng.uniform(0, 60, n), rng.uniform(0, 1, n),
            rng.uniform(-5, 5, n), rng.uniform(-8, 8, n), rng.uniform(-3, 3, n),
            rng.uniform(-50, 50, n), rng.uniform(-1, 1, n), rng.uniform(0, 1, n),
            np.full(n, 3.0), np.full(n, 100.0),
        ])
        nat.fuzzy_step(params[0], rows)
        nat.fuzzy_step([params[k % 2] for k in range(n)], rows)
        batch = nat.FuzzyBatch(params[1], n)
        batch.inputs[:] = rows
        for _ in range(20):
            batch.step()
        batch.inputs[0, nat.FuzzyInput.TENSION] = NAN
        refused(batch.step)
        batch.inputs[0, nat.FuzzyInput.TENSION] = 10.0
        batch.inputs[0, nat.FuzzyInput.FREE] = 2.0
        refused(batch.step)
    refused(nat.FuzzyParams, len_full=0.0)
    refused(nat.FuzzyParams, dv_damping=NAN)

    # ---- fuzzy straight into C
    fp = ffi.new("pyrt_fuzzy_params[]", 17)
    for i in range(17):
        assert lib.pyrt_fuzzy_default_params(fp + i) == lib.PYRT_OK
    assert lib.pyrt_fuzzy_default_params(ffi.NULL) == lib.PYRT_EINVAL
    assert lib.pyrt_fuzzy_run(ffi.NULL) == lib.PYRT_EINVAL
    assert lib.pyrt_fuzzy_check_params(ffi.NULL) == lib.PYRT_EINVAL
    inp = ffi.new("double[]", 17 * lib.PYRT_FUZZY_NINPUTS)
    dv = ffi.new("double[]", 17)
    rules = ffi.new("double[]", 17 * lib.PYRT_FUZZY_NRULES)
    for i in range(17):
        inp[i * lib.PYRT_FUZZY_NINPUTS + lib.PYRT_FUZZY_IN_TENSION_HIGH] = 100.0
    for n in (0, -3, 17):
        assert lib.pyrt_fuzzy_step(n, fp, 1, inp, dv, rules) == lib.PYRT_EINVAL
    assert lib.pyrt_fuzzy_step(16, fp, 16, inp, dv, rules) == lib.PYRT_OK
    assert lib.pyrt_fuzzy_step(16, fp, 16, inp, dv, ffi.NULL) == lib.PYRT_OK
    assert lib.pyrt_fuzzy_step(16, fp, 2, inp, dv, rules) == lib.PYRT_EINVAL
    assert lib.pyrt_fuzzy_step(2, ffi.NULL, 1, inp, dv, rules) == lib.PYRT_EINVAL
    assert lib.pyrt_fuzzy_step(2, fp, 1, ffi.NULL, dv, rules) == lib.PYRT_EINVAL
    assert lib.pyrt_fuzzy_step(2, fp, 1, inp, ffi.NULL, rules) == lib.PYRT_EINVAL
    fp[0].len_full = -1.0
    assert lib.pyrt_fuzzy_step(1, fp, 1, inp, dv, rules) == lib.PYRT_EINVAL
    fp[0].len_full = math.inf
    assert lib.pyrt_fuzzy_step(1, fp, 1, inp, dv, rules) == lib.PYRT_ENONFINITE

    # ---- polyctl (the control poll) through the Python API
    ring = (0.0, 0.0, 595.8, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 72.5)
    ptops = [(0.0, 0.0, 1299.0), (60.0, 0.0, 1299.0), (-60.0, 0.0, 1299.0),
             (0.0, 60.0, 1299.0), (0.0, -60.0, 1299.0)]
    pbots = [None, (545.44, 0.0, -250.0), (-545.44, 0.0, -250.0), (0.0, 545.44, -250.0),
             (0.0, -545.44, -250.0)]
    pnan = np.array([(NAN,) * 3 if b is None else b for b in pbots])
    for x in ((400.0, 0.0, 100.0), (0.0, 0.0, 100.0), (5.0, 3.0, 700.0)):
        pf = nat.PositionFinder(np.array(ptops), pnan)
        pb = nat.FuzzyBatch(nat.FuzzyParams(), 5)
        pb.inputs[:, nat.FuzzyInput.TENSION_HIGH] = 200.0
        ctl = nat.PolyControl(pf, pb, tops=ptops, bottoms=pbots, offsets=[(0.0,) * 3] * 5,
                              stretch=[2e-5] * 5, dead=[50.0] * 5, ring=ring,
                              axis_point=(0.0, 0.0), weight_air=52.3, weight_liquid=41.5,
                              liquid_level=595.8, offside_tension=10.0, near_end_cm=10.0,
                              position=x)
        L = [0.0] * 5
        ctl.set_endpoint((x[0], x[1], x[2] + 5.0))
        for k in range(10):
            tens = [20.0 + k, 10.0, 30.0, 15.0, 12.0]
            enc = [600.0 + k * 0.1, 1100.0, 1100.0, 1100.0, 1100.0]
            try:
                ctl.measure(tens, enc, L)
            except NativeError:
                continue
            el, et, want, free = [0.0] * 5, [0.0] * 5, [0.0] * 5, [1.0] * 5
            ctl.drive((x[0], x[1], x[2] + k), [0.5] * 5, 20.0, el, et, want, free,
                      signal_all=bool(k % 2))
        ctl.set_endpoint(None)
        ctl.reset_rates()
        refused(ctl.measure, [NAN] * 5, [600.0] * 5, L)
        refused(ctl.drive, (NAN, 0.0, 0.0), [0.0] * 5, 20.0, L, L[:], L[:], L[:])
        neck = nat.NeckRing(ring[0:3], ring[3:6], ring[12])
        neck.contact(ptops[1], (x[0] + 1.0, x[1], x[2]), 0.3)
        neck.contact(ptops[1], x)
        neck.contact(pbots[1], (x[0], x[1], 700.0))
        for segments in range(4):
            neck.rope_path(ptops[1], pbots[1], x, segments)
            neck.rope_path(ptops[0], None, x, segments)
        refused(neck.contact, ptops[1], (72.50001, 0.0, 595.79999))   # the carriage on the rim
        refused(neck.rope_path, ptops[1], (NAN, 0.0, 0.0), x, 3)

    # ---- polyctl straight into C
    c = ffi.new("pyrt_polyctl *")
    assert lib.pyrt_polyctl_measure(ffi.NULL) == lib.PYRT_EINVAL
    assert lib.pyrt_polyctl_drive(ffi.NULL) == lib.PYRT_EINVAL
    for n in (0, -1, 17):
        c.n = n
        assert lib.pyrt_polyctl_measure(c) == lib.PYRT_EINVAL
        assert lib.pyrt_polyctl_drive(c) == lib.PYRT_EINVAL
    c.n = 1
    assert lib.pyrt_polyctl_measure(c) == lib.PYRT_EINVAL     # NULL arrays
    assert lib.pyrt_polyctl_drive(c) == lib.PYRT_EINVAL
    pbuf = ffi.new("double[]", 64)
    c.tops = c.bottoms = c.offsets = c.tension = c.length = c.phi = c.position = pbuf
    c.phi_lower = pbuf
    c.stretch = c.dead = c.encoder_length = c.result = pbuf
    assert lib.pyrt_polyctl_measure(c) == lib.PYRT_EINVAL     # no finder
    fpp = ffi.new("pyrt_findpos_problem *")
    fpp.n = 2
    c.finder = fpp
    c.finder_tops = c.finder_lengths = c.finder_bottoms = pbuf
    assert lib.pyrt_polyctl_measure(c) == lib.PYRT_EINVAL     # a finder of another size
    c.ring.radius = NAN
    assert lib.pyrt_polyctl_measure(c) == lib.PYRT_ENONFINITE   # a ring that is no ring

    # ---- neck straight into C
    nr = ffi.new("pyrt_neck_ring *")
    seg = ffi.new("pyrt_neck_segment *")
    rope = ffi.new("pyrt_neck_rope *")
    three = ffi.new("double[3]", [1.0, 2.0, 3.0])
    assert lib.pyrt_neck_init(ffi.NULL, three, three, 1.0) == lib.PYRT_EINVAL
    assert lib.pyrt_neck_init(nr, ffi.NULL, three, 1.0) == lib.PYRT_EINVAL
    assert lib.pyrt_neck_init(nr, three, ffi.NULL, 1.0) == lib.PYRT_EINVAL
    assert lib.pyrt_neck_init(nr, three, ffi.new("double[3]"), 1.0) == lib.PYRT_EINVAL
    assert lib.pyrt_neck_init(nr, three, three, math.inf) == lib.PYRT_ENONFINITE
    assert lib.pyrt_neck_check(ffi.NULL) == lib.PYRT_EINVAL
    assert lib.pyrt_neck_init(nr, three, three, 1.0) == lib.PYRT_OK
    assert lib.pyrt_neck_check(nr) == lib.PYRT_OK
    assert lib.pyrt_neck_contact(ffi.NULL, three, three, NAN, seg) == lib.PYRT_EINVAL
    assert lib.pyrt_neck_contact(nr, ffi.NULL, three, NAN, seg) == lib.PYRT_EINVAL
    assert lib.pyrt_neck_contact(nr, three, ffi.NULL, NAN, seg) == lib.PYRT_EINVAL
    assert lib.pyrt_neck_contact(nr, three, three, NAN, ffi.NULL) == lib.PYRT_EINVAL
    assert lib.pyrt_neck_contact(nr, three, three, math.inf, seg) == lib.PYRT_ENONFINITE
    assert lib.pyrt_neck_contact(nr, three, three, NAN, seg) == lib.PYRT_EDEGENERATE
    for k in range(5):
        args = [nr, three, three, three, rope]
        args[k] = ffi.NULL
        assert lib.pyrt_neck_rope_path(args[0], 3, args[1], args[2], args[3], ffi.NULL,
                                       args[4]) == lib.PYRT_EINVAL
    inf2 = ffi.new("double[2]", [0.0, math.inf])
    assert lib.pyrt_neck_rope_path(nr, 3, three, three, three, inf2, rope) == lib.PYRT_ENONFINITE
    nr.e1 = (0.0, 0.0, 1.0)
    assert lib.pyrt_neck_check(nr) == lib.PYRT_EINVAL

    # ---- convert
    assert nat.excess128_many(list(range(-300, 300))).shape == (600,)
    assert [nat.from_excess128(nat.excess128(v)) for v in range(-128, 128)] == list(
        range(-128, 128))
    assert lib.pyrt_excess128_many(ffi.NULL, ffi.NULL, 3) == lib.PYRT_EINVAL
    assert lib.pyrt_excess128_many(ffi.NULL, ffi.NULL, -1) == lib.PYRT_EINVAL
    assert lib.pyrt_excess128(5, ffi.NULL) == lib.PYRT_EINVAL
    assert lib.pyrt_from_excess128(5, ffi.NULL) == lib.PYRT_EINVAL

    # ---- readyq straight into C
    rq = ffi.new("pyrt_rq *")
    assert lib.pyrt_rq_check(ffi.NULL) == lib.PYRT_EINVAL
    assert lib.pyrt_rq_check(rq) == lib.PYRT_EINVAL
    rq.mem, rq.ready = ffi.new("uint8_t[]", 8), ffi.new("uint16_t[]", 4)
    rq.mem_len, rq.capacity, rq.t_addr, rq.q_addr = 8, 4, 0, 2      # Q runs past the image
    assert lib.pyrt_rq_check(rq) == lib.PYRT_EINVAL

    # ---- readyq with 32-bit schedule words: through the wrapper, then straight into C
    image = bytearray(4 * 3 + 2 * 3)
    image[0:4] = (1).to_bytes(4, "little")
    image[12:14] = bytes([0x34, 0x12])
    assert nat.QueueChecker(image, 0, 12, 3, wide=True).check() == [0x1234]
    assert lib.pyrt_rq_check_wide(ffi.NULL) == lib.PYRT_EINVAL
    rq.mem_len, rq.capacity, rq.t_addr, rq.q_addr = 8, 1, 5, 0      # T runs past the image
    assert lib.pyrt_rq_check_wide(rq) == lib.PYRT_EINVAL
    print("SANITIZE-DRIVER-OK")
    """
)


CANARY = textwrap.dedent(
    """
    ffi, lib = native.ffi, native.lib
    # Deliberately read and write past two-element buffers.
    lib.pyrt_excess128_many(ffi.new("int32_t[]", 2), ffi.new("uint8_t[]", 2), 4096)
    print("CANARY-NOT-CAUGHT")
    """
)


def test_kernels_are_clean_under_asan_and_ubsan(tmp_path):
    """Every C entry point, on good and bad input, runs with no ASan or UBSan report."""
    assert_clean(run_under_asan(PRELUDE + DRIVER, tmp_path))
    # The harness itself is live: a deliberate overflow in the same build is caught.
    caught = run_under_asan(PRELUDE + CANARY, tmp_path)
    assert caught.returncode != 0
    assert "CANARY-NOT-CAUGHT" not in caught.stdout
    assert "AddressSanitizer" in caught.stderr, caught.stderr
