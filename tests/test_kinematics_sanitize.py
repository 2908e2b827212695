"""csrc/kinematics.c under AddressSanitizer and UBSan (run with ``pytest -m sanitize``).

A driver loads the sanitized build (tests/_sanitize.py) and calls every
kinematics entry point through pyrt.kinematics over random chains of 1 to
7 joints (fk, frames, Jacobian, the inverse on reachable and unreachable
poses, RNEA, mass matrix, forward dynamics), then the C functions directly
with NULL pointers, sizes out of range and NaN, which must be refused.
"""

from __future__ import annotations

import textwrap

import pytest
from _sanitize import PRELUDE, assert_clean, run_under_asan

pytestmark = pytest.mark.sanitize

DRIVER = textwrap.dedent(
    """
    import math, sys
    sys.path.insert(0, sys.argv[2])
    import numpy as np
    import _ref_kinematics as ref
    from pyrt.kinematics import Chain, Inertial, Joint
    from pyrt.errors import NativeError

    ffi, lib = native.ffi, native.lib
    import pyrt.native._lib as bound
    assert bound.lib is lib, "pyrt.native is not using the sanitized build"

    rng = np.random.default_rng(0)
    for n in range(1, 8):
        for _ in range(5):
            d = ref.random_chain(rng, n)
            chain = Chain("s", [Joint(d["names"][i], d["kinds"][i], d["origins"][i],
                                      d["axes"][i], d["lower"][i], d["upper"][i],
                                      inertial=Inertial(d["masses"][i], d["coms"][i],
                                                        d["inertias"][i])) for i in range(n)],
                          base=d["base"], tool=d["tool"], offsets=d["offsets"])
            q = rng.uniform(-1, 1, n)
            chain.fk(q); chain.frames(q); chain.jacobian(q)
            chain.rnea(q, q, q); chain.mass_matrix(q); chain.aba(q, q, q)
            chain.ik(chain.fk(q), q + 0.1)
            far = chain.fk(q); far[:3, 3] += 100.0
            chain.ik(far, q, max_iter=20)
            try:
                chain.fk(np.full(n, math.nan))
            except NativeError:
                pass

    c = ffi.new("pyrt_kin_chain *")
    ws = ffi.new("double[]", 10)
    out = ffi.new("double[]", 64)
    assert lib.pyrt_kin_check(ffi.NULL) == lib.PYRT_EINVAL
    assert lib.pyrt_kin_check(c) == lib.PYRT_EINVAL
    size = ffi.new("int32_t *")
    assert lib.pyrt_kin_workspace_size(0, size) == lib.PYRT_EINVAL
    assert lib.pyrt_kin_workspace_size(lib.PYRT_KIN_MAX_JOINTS + 1, size) == lib.PYRT_EINVAL
    assert lib.pyrt_kin_workspace_size(6, ffi.NULL) == lib.PYRT_EINVAL
    assert lib.pyrt_kin_call(ffi.NULL) == lib.PYRT_EINVAL
    call = ffi.new("pyrt_kin_call_args *")
    call.op = 7
    assert lib.pyrt_kin_call(call) == lib.PYRT_EINVAL
    call.op = lib.PYRT_KIN_OP_FK
    assert lib.pyrt_kin_call(call) == lib.PYRT_EINVAL
    for fn in (lib.pyrt_kin_fk, lib.pyrt_kin_frames, lib.pyrt_kin_mass_matrix):
        assert fn(ffi.NULL, ws, out, out) == lib.PYRT_EINVAL
        assert fn(c, ffi.NULL, out, out) == lib.PYRT_EINVAL
    assert lib.pyrt_kin_jacobian(c, ws, out, out, ffi.NULL) == lib.PYRT_EINVAL
    assert lib.pyrt_kin_rnea(c, ws, out, ffi.NULL, ffi.NULL, ffi.NULL, out) == lib.PYRT_EINVAL
    assert lib.pyrt_kin_forward_dynamics(c, ws, out, ffi.NULL, out, ffi.NULL, out) == lib.PYRT_EINVAL
    opts = ffi.new("pyrt_kin_ik_opts *")
    assert lib.pyrt_kin_ik(c, ws, out, out, out, opts) == lib.PYRT_EINVAL
    print("SANITIZE-DRIVER-OK")
    """
)


def test_kinematics_kernels_are_clean_under_the_sanitizers(tmp_path):
    """Every kinematics entry point, good input and bad, runs without an ASan or UBSan report."""
    from pathlib import Path

    tests = str(Path(__file__).resolve().parent)
    run = run_under_asan(PRELUDE + DRIVER.replace("sys.argv[2]", repr(tests)), tmp_path)
    assert_clean(run)
