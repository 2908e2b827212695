"""The journal's C tick encoder under AddressSanitizer and UBSan (``pytest -m sanitize``).

The extension is rebuilt from a private copy of csrc/ with
``-fsanitize=address,undefined``; a driver in a subprocess (libasan
preloaded) records random runs through :class:`pyrt.journal.Journal` (the
C encoder, its refusals and its hand-over to the Python reference), checks
the bytes against the Python encoder, and calls the raw entry points with
the NULL pointers, bad sizes and short buffers the Python layer never
passes.
"""

from __future__ import annotations

import textwrap

import pytest
from _sanitize import PRELUDE, assert_clean, run_under_asan

pytestmark = pytest.mark.sanitize

DRIVER = textwrap.dedent(
    """
    import io, random, struct, sys
    sys.path.insert(0, "TESTS")
    import pyrt.native._lib as bound
    assert bound.lib is native.lib, "pyrt.native is not using the sanitized build"
    from pyrt.journal import Journal, JournalError
    from pyrt.journal.encoder import NativeBlockEncoder
    from pyrt.journal.format import BlockEncoder
    from test_journal import header, run

    ffi, lib = native.ffi, native.lib
    rnd = random.Random(3)
    for seed in range(120):
        n_in, n_out = rnd.randrange(0, 40), rnd.randrange(1, 6)
        recs = run(rnd.randrange(1, 400), n_in, n_out, seed)
        if seed % 9 == 0:  # a refused tick in the middle: an output index out of range
            k = len(recs) // 2
            recs[k] = (*recs[k][:5], ((n_out, 1, 0),), (), ())
        if seed % 13 == 0:  # values beyond the C encoder's bounds: the reference takes over
            k = len(recs) // 3
            recs[k] = (*recs[k][:4], [v * 2**61 for v in recs[k][4]], *recs[k][5:])
        h = header(n_in, n_out)
        a, b = BlockEncoder(h, 0), NativeBlockEncoder(h, 0)
        block = rnd.randrange(1, 300)
        want, got = [], []
        for r in recs:
            if a.count >= block:
                want.append(a.take())
            try:
                a.add(*r)
            except JournalError:
                pass
        i = 0
        while i < len(recs):
            if b.count >= block:
                got.append(b.take())
            m = min(block - b.count, rnd.randrange(1, 80))
            b.add_many(recs[i:i + m])
            i += m
        want.append(a.take())
        got.append(b.take())
        assert want == got, seed
        buf = io.BytesIO()
        j = Journal(h, buf, lossless=True, block_ticks=block)
        for r in recs:
            j.record_tick(*r)
        try:
            j.close()
        except JournalError:
            pass

    # ticks of many writes each outgrow the encoder's first body
    many = [(k, k * 1000, 0, 0, [k], tuple((i, rnd.randrange(-10**9, 10**9), 3)
                                           for i in range(64) for _ in range(3)), (), ())
            for k in range(120)]
    h = header(1, 64)
    a, b = BlockEncoder(h, 0), NativeBlockEncoder(h, 0)
    for r in many:
        a.add(*r)
    assert not b.add_many(many) and a.take() == b.take()

    # straight into C: what the Python layer never passes
    st = ffi.new("pyrt_journal_state *")
    assert lib.pyrt_journal_init(ffi.NULL, 1, 1, 1) == lib.PYRT_EINVAL
    assert lib.pyrt_journal_init(st, 0, 1, 1) == lib.PYRT_EINVAL
    assert lib.pyrt_journal_init(st, 1000, -1, 1) == lib.PYRT_EINVAL
    assert lib.pyrt_journal_init(st, 1000, 2, 2) == lib.PYRT_OK
    bound = ffi.new("int64_t *")
    assert lib.pyrt_journal_record_bound(ffi.NULL, 0, bound) == lib.PYRT_EINVAL
    assert lib.pyrt_journal_record_bound(st, -1, bound) == lib.PYRT_EINVAL
    assert lib.pyrt_journal_record_bound(st, 0, ffi.NULL) == lib.PYRT_EINVAL
    assert lib.pyrt_journal_record_bound(st, 3, bound) == lib.PYRT_OK and bound[0] > 0
    prev, outs = ffi.new("int64_t[]", 2), ffi.new("int64_t[]", 2)
    rows = ffi.new("int64_t[]", [0, 0, 0, 0, 1, 2, 1, 10, 0, 0, 1, 3])
    per = ffi.new("int32_t[]", 2)
    pos, done = ffi.new("int64_t *"), ffi.new("int32_t *")
    small = ffi.new("uint8_t[]", 8)
    body = ffi.new("uint8_t[]", 4096)
    enc = lib.pyrt_journal_encode
    assert enc(ffi.NULL, prev, outs, rows, per, ffi.NULL, 0, 2, body, 4096, pos, done) \\
        == lib.PYRT_EINVAL
    assert enc(st, prev, outs, ffi.NULL, per, ffi.NULL, 0, 2, body, 4096, pos, done) \\
        == lib.PYRT_EINVAL
    assert enc(st, prev, outs, rows, per, ffi.NULL, 0, -1, body, 4096, pos, done) \\
        == lib.PYRT_EINVAL
    assert enc(st, prev, outs, rows, per, ffi.NULL, 1, 2, body, 4096, pos, done) \\
        == lib.PYRT_EINVAL
    assert enc(st, prev, outs, rows, per, ffi.NULL, 0, 2, body, 4096, ffi.NULL, done) \\
        == lib.PYRT_EINVAL
    per[1] = 1  # a write with no rows of writes
    assert enc(st, prev, outs, rows, per, ffi.NULL, 0, 2, body, 4096, pos, done) \\
        == lib.PYRT_EINVAL and done[0] == 1
    per[1] = 0
    # a body too small for one record: nothing written, nothing changed
    pos[0] = 0
    lib.pyrt_journal_init(st, 1000, 2, 2)
    assert enc(st, prev, outs, rows, per, ffi.NULL, 0, 2, small, 8, pos, done) == lib.PYRT_OK
    assert done[0] == 0 and pos[0] == 0 and st.count == 0
    pos[0] = 9
    assert enc(st, prev, outs, rows, per, ffi.NULL, 0, 2, small, 8, pos, done) \\
        == lib.PYRT_EINVAL
    pos[0] = 0
    assert enc(st, prev, outs, rows, per, ffi.NULL, 0, 2, body, 4096, pos, done) == lib.PYRT_OK
    assert done[0] == 2 and st.count == 2
    # a tick that does not follow the last, and missed < 0: refused, nothing changed
    again = ffi.new("int64_t[]", [1, 20, 0, 0, 5, 5])
    at = pos[0]
    assert enc(st, prev, outs, again, per, ffi.NULL, 0, 1, body, 4096, pos, done) \\
        == lib.PYRT_EINVAL and done[0] == 0 and pos[0] == at
    again[0], again[3] = 2, -1
    assert enc(st, prev, outs, again, per, ffi.NULL, 0, 1, body, 4096, pos, done) \\
        == lib.PYRT_EINVAL and pos[0] == at and list(prev) == [1, 3]
    print("SANITIZE-DRIVER-OK")
    """
)


def test_journal_encoder_is_clean_under_asan_and_ubsan(tmp_path):
    """The journal's C encoder, on good and bad input, runs with no ASan or UBSan report
    and writes what the Python encoder writes."""
    tests = str(__import__("pathlib").Path(__file__).resolve().parent)
    assert_clean(run_under_asan(PRELUDE + DRIVER.replace("TESTS", tests), tmp_path))


IMAGE_DRIVER = textwrap.dedent(
    """
    import io, random, sys
    from array import array
    sys.path.insert(0, "TESTS")
    import pyrt.native._lib as bound
    assert bound.lib is native.lib, "pyrt.native is not using the sanitized build"
    from pyrt.journal import Journal
    from pyrt.native import InputGather, RingRows, output_changes
    from test_journal import header

    ffi, lib = native.ffi, native.lib
    rnd = random.Random(11)
    for seed in range(60):
        n = rnd.randrange(0, 300)
        inputs = array("q", bytes(8 * n))
        srcs, at = [], 0
        while at < n:
            c = rnd.randrange(0, n - at + 1)
            srcs.append((array("q", [rnd.randrange(-2**62, 2**62) for _ in range(c)]), at, c))
            at += c + rnd.randrange(0, 3)
        InputGather(inputs, [s for s in srcs if s[1] + s[2] <= n])()
        rows = rnd.randrange(1, 9)
        ring = bytearray(8 * rows * (4 + n))
        RingRows(ring, rows, inputs).put(rows - 1, seed, 2, 3, 4)
        cur = array("q", [rnd.randrange(-9, 9) for _ in range(n)])
        output_changes(cur, [rnd.randrange(-9, 9) for _ in range(n)], seed % 2 == 0)
        # plain ticks through the one-call hand-over, the others through record_tick
        j = Journal(header(n, 2), io.BytesIO(), lossless=True, queue_ticks=rnd.randrange(1, 40))
        hand = j.hand_over(inputs)
        c = hand.state
        c.slow = 0
        for k in range(rnd.randrange(1, 200)):
            if n:
                inputs[rnd.randrange(n)] = k
            late = rnd.choice((0, 0, 1, 2000))
            if k % 7 == 0 or hand(k * 1000 + late) != 0:
                j.record_tick(k, k * 1000 + late, late, 0, inputs.tolist(), ((0, k, 0),))
                c.tick, c.deadline_ns = k + 1, (k + 1) * 1000
        j.close()

    # straight into C: what the Python layer never passes
    src = ffi.new("pyrt_image_source[]", 1)
    vals = ffi.new("int64_t[]", 4)
    dst = ffi.new("int64_t[]", 4)
    src[0].values, src[0].at, src[0].count = vals, 2, 3
    assert lib.pyrt_image_gather(dst, 4, src, 1) == lib.PYRT_EINVAL
    src[0].at, src[0].count = -1, 1
    assert lib.pyrt_image_gather(dst, 4, src, 1) == lib.PYRT_EINVAL
    src[0].at, src[0].values = 0, ffi.NULL
    assert lib.pyrt_image_gather(dst, 4, src, 1) == lib.PYRT_EINVAL
    assert lib.pyrt_image_gather(ffi.NULL, 4, src, 0) == lib.PYRT_EINVAL
    assert lib.pyrt_image_gather(dst, 4, ffi.NULL, 1) == lib.PYRT_EINVAL
    assert lib.pyrt_image_gather(dst, -1, src, 0) == lib.PYRT_EINVAL
    assert lib.pyrt_image_gather(ffi.NULL, 0, ffi.NULL, 0) == lib.PYRT_OK
    ring = ffi.new("int64_t[]", 2 * 8)
    assert lib.pyrt_image_row(ring, 2, 2, 0, 0, 0, 0, dst, 4) == lib.PYRT_EINVAL
    assert lib.pyrt_image_row(ring, 2, -1, 0, 0, 0, 0, dst, 4) == lib.PYRT_EINVAL
    assert lib.pyrt_image_row(ring, 0, 0, 0, 0, 0, 0, dst, 4) == lib.PYRT_EINVAL
    assert lib.pyrt_image_row(ffi.NULL, 2, 0, 0, 0, 0, 0, dst, 4) == lib.PYRT_EINVAL
    assert lib.pyrt_image_row(ring, 2, 0, 0, 0, 0, 0, ffi.NULL, 4) == lib.PYRT_EINVAL
    assert lib.pyrt_image_row(ring, 2, 1, 9, 0, 0, 0, dst, 4) == lib.PYRT_OK and ring[8] == 9
    h = ffi.new("pyrt_image_handover *")
    assert lib.pyrt_image_hand_over(ffi.NULL, 0) == lib.PYRT_EINVAL
    assert lib.pyrt_image_hand_over(h, 0) == lib.PYRT_EINVAL  # no ring
    h.ring, h.rows, h.n_inputs, h.period_ns, h.open = ring, 2, 4, 1000, 1
    assert lib.pyrt_image_hand_over(h, 0) == lib.PYRT_EINVAL  # no inputs
    h.inputs = dst
    for name, bad in (("rows", 0), ("n_inputs", -1), ("put", -1), ("period_ns", -5)):
        old = getattr(h, name)
        setattr(h, name, bad)
        assert lib.pyrt_image_hand_over(h, 0) == lib.PYRT_EINVAL
        setattr(h, name, old)
    h.late_hi, h.listen_at = 10, 1
    assert lib.pyrt_image_hand_over(h, 5) == lib.PYRT_OK and h.put == 1 and ring[0] == 0
    assert lib.pyrt_image_hand_over(h, 1005) == lib.PYRT_IMAGE_DUE and h.tick == 2
    assert lib.pyrt_image_hand_over(h, 2005) == lib.PYRT_IMAGE_SLOW  # the ring is full
    h.taken = 2
    extreme = (2**63 - 1, -2**63, 2**62, -2**62)
    for now in extreme:
        for dl in extreme:
            h.deadline_ns = dl
            assert lib.pyrt_image_hand_over(h, now) == lib.PYRT_IMAGE_SLOW
    h.deadline_ns, h.tick = 0, 2**63 - 1
    assert lib.pyrt_image_hand_over(h, 0) == lib.PYRT_IMAGE_SLOW
    h.tick, h.put, h.taken = 0, 2**63 - 1, 2**63 - 1
    assert lib.pyrt_image_hand_over(h, 0) == lib.PYRT_IMAGE_SLOW
    h.put, h.taken = 5, -2**63
    assert lib.pyrt_image_hand_over(h, 0) == lib.PYRT_IMAGE_SLOW
    h.taken, h.period_ns, h.deadline_ns = 5, 2**61 - 1, 2**61 - 1
    assert lib.pyrt_image_hand_over(h, 2**61 - 1) == lib.PYRT_OK  # the largest step
    changed, k = ffi.new("int32_t[]", 4), ffi.new("int32_t *")
    assert lib.pyrt_image_changes(dst, vals, 4, 0, changed, ffi.NULL) == lib.PYRT_EINVAL
    assert lib.pyrt_image_changes(dst, ffi.NULL, 4, 0, changed, k) == lib.PYRT_EINVAL
    assert lib.pyrt_image_changes(dst, vals, -1, 0, changed, k) == lib.PYRT_EINVAL
    assert lib.pyrt_image_changes(ffi.NULL, ffi.NULL, 0, 0, ffi.NULL, k) == lib.PYRT_OK
    print("SANITIZE-DRIVER-OK")
    """
)


def test_image_kernels_are_clean_under_asan_and_ubsan(tmp_path):
    """The process image's C side (gather, ring rows, change detection) and the journal's
    one-call hand-over, on good and bad input, run with no ASan or UBSan report."""
    tests = str(__import__("pathlib").Path(__file__).resolve().parent)
    assert_clean(run_under_asan(PRELUDE + IMAGE_DRIVER.replace("TESTS", tests), tmp_path))
