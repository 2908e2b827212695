"""The C boundary's shape: the cdef is the public headers only, and the kernels'
default parameters are written once, in those headers, and read from ``lib``."""

from __future__ import annotations

import dataclasses
import inspect
import re
import runpy
from pathlib import Path

import _ref_polyctl
import pytest

import pyrt.native as nat
from pyrt.native._lib import lib

CSRC = Path(__file__).resolve().parent.parent / "csrc"


@pytest.fixture(scope="module")
def build():
    return runpy.run_path(str(CSRC / "build_native.py"))


def test_cdef_comes_from_the_public_headers(build):
    """pyrt_native.h and one header per kernel source, each after the headers it includes."""
    headers = build["HEADERS"]
    kernels = {p.stem + ".h" for p in CSRC.glob("*.c")}
    assert headers[0] == "pyrt_native.h"
    assert set(headers) == kernels | {"pyrt_native.h"}
    for i, name in enumerate(headers):
        for dep in re.findall(r'#include "([^"]+)"', (CSRC / name).read_text()):
            assert headers.index(dep) < i, f"{name} before {dep}"


def test_every_lib_function_is_declared_in_a_public_header(build):
    """Nothing callable reaches Python that a public header does not declare."""
    declared = set()
    for name in build["HEADERS"]:
        declared |= set(re.findall(r"\b(pyrt_\w+)\s*\(", (CSRC / name).read_text()))
    functions = {n for n in dir(lib) if callable(getattr(lib, n))}
    assert functions == declared


def test_constants_are_left_to_the_compiler(build):
    """Integer defines become ``#define NAME ...``, floating ones ``static const double``."""
    cdef = build["_cdef_from_header"](
        "#define PYRT_A 3\n#define PYRT_B 0.1\n#define PYRT_C 1e-10\n"
        "#define PYRT_D (PYRT_A | 4)\n#define PYRT_X_H\n")
    assert "#define PYRT_A ..." in cdef and "#define PYRT_D ..." in cdef
    assert "static const double PYRT_B;" in cdef and "static const double PYRT_C;" in cdef
    assert "PYRT_X_H" not in cdef
    assert isinstance(lib.PYRT_NECK_STEP_TOL, float) and isinstance(lib.PYRT_NECK_MAX_ITER, int)


def test_fuzzy_defaults_are_the_header_constants():
    """Every FuzzyParams default, and the poll period they are tuned for, is read from fuzzy.h."""
    defaults = nat.FuzzyParams()
    for f in dataclasses.fields(nat.FuzzyParams):
        assert getattr(defaults, f.name) == getattr(lib, f"PYRT_FUZZY_DEFAULT_{f.name.upper()}")
    assert nat.FuzzyParams.REFERENCE_POLL_S == lib.PYRT_FUZZY_REFERENCE_POLL_S


@pytest.mark.parametrize("fn, names", [
    (nat.find_position, {"tol": "PYRT_FINDPOS_DEFAULT_TOL",
                         "max_iter": "PYRT_FINDPOS_DEFAULT_MAX_ITER"}),
    (nat.PositionFinder, {"tol": "PYRT_FINDPOS_DEFAULT_TOL",
                          "max_iter": "PYRT_FINDPOS_DEFAULT_MAX_ITER"}),
    (nat.StaticsSolver, {"tol": "PYRT_STATICS_DEFAULT_TOL",
                         "max_step": "PYRT_STATICS_DEFAULT_MAX_STEP",
                         "max_iter": "PYRT_STATICS_DEFAULT_MAX_ITER"}),
    (_ref_polyctl.RefPolyControl, {"tol": "PYRT_FINDPOS_DEFAULT_TOL"}),
])
def test_solver_defaults_are_the_header_constants(fn, names):
    """Solver tolerances and iteration limits default to the header's values."""
    params = inspect.signature(fn).parameters
    for arg, const in names.items():
        assert params[arg].default == getattr(lib, const), arg


def test_header_defaults_are_the_documented_numbers():
    """The numbers the design names: 0.1 cm solver tolerance, the 50 ms reference poll."""
    assert lib.PYRT_FINDPOS_DEFAULT_TOL == 0.1
    assert lib.PYRT_FUZZY_REFERENCE_POLL_S == 0.05


def test_neck_reference_reads_the_one_model():
    """The reference's neck constants are the header's, not a copy."""
    assert _ref_polyctl.ITERATIONS == lib.PYRT_NECK_MAX_ITER
    assert _ref_polyctl.STEP_TOL == lib.PYRT_NECK_STEP_TOL
    assert _ref_polyctl.MAX_STEP == lib.PYRT_NECK_MAX_STEP
    assert _ref_polyctl.FALLBACK_STEP == lib.PYRT_NECK_FALLBACK_STEP
    assert _ref_polyctl.TIE == lib.PYRT_NECK_TIE
    assert _ref_polyctl.MIN_SEGMENT == lib.PYRT_MIN_SEGMENT_CM
    assert _ref_polyctl.CONTROLLER_SEGMENTS == nat.PolyControl.RING_SEGMENTS
