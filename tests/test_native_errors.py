"""One error convention at the C boundary: status codes from csrc/pyrt_native.h, one
exception family (NativeError), mapped in one place (pyrt.native._errors)."""

from __future__ import annotations

import math
import re
import struct
from pathlib import Path

import numpy as np
import pytest

import pyrt.native as nat
import pyrt.native._errors as errors
from pyrt.errors import NativeError
from pyrt.native._fuzzy import c_default_params
from pyrt.native._lib import ffi, lib

ROOT = Path(__file__).resolve().parent.parent
NAN = math.nan


def _header_codes() -> dict[str, int]:
    """Every status code csrc/pyrt_native.h defines, by name."""
    text = (ROOT / "csrc" / "pyrt_native.h").read_text()
    return {m[1]: int(m[2]) for m in re.finditer(r"#define\s+PYRT_(OK|E[A-Z]+)\s+(\d+)", text)}


def _entry_points() -> set[str]:
    """Every function the compiled module exposes (its cdef is the public headers)."""
    return {name for name in dir(lib) if callable(getattr(lib, name))}


def test_every_header_code_maps_into_the_family():
    """Each status code of the header is a Status member; OK raises nothing, every other code
    raises its own NativeError subclass."""
    codes = _header_codes()
    assert "OK" in codes and len(codes) >= 6
    assert {s.name: int(s) for s in nat.Status} == codes
    errors.raise_for_status(codes["OK"], "ok")
    classes = set()
    for name, value in codes.items():
        assert getattr(lib, f"PYRT_{name}") == value
        if name == "OK":
            continue
        with pytest.raises(NativeError) as info:
            errors.raise_for_status(value, "probe")
        cls = type(info.value)
        assert cls is not NativeError and cls.status == value
        assert str(info.value).startswith("probe: ")
        classes.add(cls)
    assert len(classes) == len(codes) - 1


def test_unknown_code_is_still_a_native_error():
    """A code the header does not define (a kernel out of step) is a plain NativeError."""
    unknown = max(_header_codes().values()) + 1
    with pytest.raises(NativeError, match="unknown status"):
        errors.raise_for_status(unknown, "probe")


def test_converged_tells_iteration_limit_from_failure():
    """converged: OK is True, ENOCONVERGE False, any other code raises from the family."""
    assert errors.converged(lib.PYRT_OK, "probe") is True
    assert errors.converged(lib.PYRT_ENOCONVERGE, "probe") is False
    with pytest.raises(nat.DegenerateGeometryError):
        errors.converged(lib.PYRT_EDEGENERATE, "probe")


def test_every_entry_point_returns_a_status_code():
    """Every public C function returns int (a status code) and nothing else."""
    points = _entry_points()
    assert len(points) >= 19
    for name in sorted(points):
        assert ffi.typeof(getattr(lib, name)).result is ffi.typeof("int"), name


def test_no_wrapper_inspects_a_raw_code():
    """Outside _errors, no module of pyrt.native compares a status code or names a PYRT_E code."""
    pattern = re.compile(r"\brc\s*(==|!=)|\bif\s+(not\s+)?rc\b|PYRT_E[A-Z]+|PYRT_OK|Status\.E")
    for path in sorted((ROOT / "pyrt" / "native").glob("*.py")):
        if path.name == "_errors.py":
            continue
        hits = [line for line in path.read_text().splitlines() if pattern.search(line)]
        assert not hits, f"{path.name}: {hits}"


# ---------------------------------------------------- each entry point's error path

_TOPS = np.array([[0.0, 0.0, 1299.0], [60.0, 0.0, 1299.0], [-60.0, 0.0, 1299.0]])
_BOTTOMS = np.array([[NAN, NAN, NAN], [545.44, 0.0, -250.0], [-545.44, 0.0, -250.0]])
_RING = ((0.0, 0.0, 595.8), (0.0, 0.0, 1.0), 72.5)


def _finder():
    return nat.PositionFinder(_TOPS, _BOTTOMS)


def _batch(**bad):
    b = nat.FuzzyBatch(nat.FuzzyParams(), 3)
    b.inputs[:, nat.FuzzyInput.TENSION_HIGH] = 100.0
    for name, value in bad.items():
        b.inputs[0, nat.FuzzyInput[name]] = value
    return b


def _control(**changes):
    kw = dict(tops=_TOPS.tolist(), bottoms=[None, *_BOTTOMS[1:].tolist()],
              offsets=[(0.0, 0.0, 0.0)] * 3, stretch=[2e-5] * 3, dead=[50.0] * 3,
              ring=nat.NeckRing(*_RING), axis_point=(0.0, 0.0), weight_air=50.0,
              weight_liquid=40.0, liquid_level=None, offside_tension=10.0,
              near_end_cm=10.0, position=(0.0, 0.0, 100.0))
    return nat.PolyControl(_finder(), _batch(), **dict(kw, **changes))


def _statics():
    return nat.StaticsSolver(_TOPS.tolist(), [None, *_BOTTOMS[1:].tolist()], None, [50.0] * 3,
                             [2e-5] * 3, [1200.0] * 3, ring=_RING)


def _finder_solve():
    f = _finder()
    f.solve(np.array([600.0, NAN, 1100.0]), np.zeros(3))


def _statics_solve():
    s = _statics()
    s.set_payout(1, 0.0)
    s.solve()


def _puma():
    from pyrt.native._puma import PumaKernel

    return PumaKernel((0.672, 0.4318, 0.0203, 0.15005, 0.4318), np.eye(4), np.eye(4),
                      np.zeros(6), np.full(6, -np.inf), np.full(6, np.inf))


def _chain(**bad):
    kw = dict(kinds=["revolute"], origins=[np.eye(4)], axes=[[0.0, 0.0, 1.0]], offsets=[0.0],
              base=np.eye(4), tool=np.eye(4), lower=[-1.0], upper=[1.0], masses=[1.0],
              coms=[[0.1, 0.0, 0.0]], inertias=[np.eye(3)])
    return nat.ChainKernels(**dict(kw, **bad))


def _arm(**bad):
    params = dict(armature=[0.1], damping=[0.0], friction=[0.0], stop_lo=[-2.0],
                  stop_hi=[2.0], stop_k=[1e3], stop_c=[10.0], nm_per_count=[1e-3],
                  amps_per_count=[1e-4], effort=[30.0], counts=[1000.0])
    params.update(bad)
    return nat.ArmKernel(_chain(), params, max_step=1e-3, friction_velocity=0.005,
                         gravity=(0.0, 0.0, -9.81), tip=(0.0, 0.0, 0.0), table_stiffness=5e4,
                         table_damping=500.0, table_friction=0.3, ft_scale=[1e3] * 6,
                         ft_offsets=[0.0] * 6, ft_sigma=[0.0] * 6)


def _servo_board_nan() -> None:
    servo = nat.Servo(1, 1e-3)
    servo.tick_board(NAN, nat.ServoBoard(servo, [1.0], [0], [1.0], 1), [0])


def _arm_nan_state():
    a = _arm()
    a.q[0] = NAN
    a.publish()


def _drive_nan(run: bool):
    """A drive whose counts per unit the caller turned to NaN in its own array."""
    d = nat.DriveKernel(1, 1e-3, counts=[1e3], nm_per_count=[1e-3], arm=_arm() if run else None)
    d.params[0, 0] = NAN
    d.run(0.01) if run else d.tick()


#: Public C entry point -> a wrapper call with input only C refuses.
THROUGH_WRAPPERS = {
    "pyrt_findpos_solve": lambda: nat.find_position(_TOPS, _BOTTOMS, [600.0, NAN, 1100.0],
                                                    (0.0, 0.0, 0.0)),
    "pyrt_findpos_freeze_mask": lambda: nat.freeze_mask([[1.0, NAN, 0.0]]),
    "pyrt_rope_lengths": lambda: nat.rope_lengths(_TOPS[1], _TOPS, _BOTTOMS),
    "pyrt_fuzzy_check_params": lambda: nat.FuzzyParams(len_full=0.0),
    "pyrt_fuzzy_step": lambda: nat.fuzzy_step(nat.FuzzyParams(), [[NAN] * 11]),
    "pyrt_fuzzy_run": lambda: _batch(FREE=2.0).step(),
    "pyrt_neck_init": lambda: nat.NeckRing((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 10.0),
    "pyrt_neck_check": lambda: _control(ring=(0.0,) * 12 + (1.0,)),   # no frame
    "pyrt_neck_contact": lambda: nat.NeckRing(*_RING).contact((NAN, 0.0, 0.0), (0.0, 0.0, 0.0)),
    "pyrt_neck_rope_path": lambda: nat.NeckRing(*_RING).rope_path(
        _TOPS[1], (1.0, NAN, 0.0), (0.0, 0.0, 0.0), nat.NECK_UPPER),
    "pyrt_polyctl_measure": lambda: _control().measure([NAN] * 3, [600.0] * 3, [0.0] * 3),
    "pyrt_polyctl_drive": lambda: _control().drive((0.0, 0.0, NAN), [0.0] * 3, 20.0,
                                                   [0.0] * 3, [0.0] * 3, [0.0] * 3, [0.0] * 3),
    "pyrt_statics_solve": _statics_solve,
    "pyrt_statics_evaluate": lambda: _statics().evaluate(_TOPS[1]),
    "pyrt_puma_inverse": lambda: _puma().inverse(np.full((4, 4), NAN), 0),
    "pyrt_kin_check": lambda: _chain(axes=[[0.0, 0.0, 2.0]]),
    "pyrt_kin_call": lambda: _chain().fk([NAN]),
    "pyrt_kin_frames": lambda: _chain().frames([NAN]),
    "pyrt_kin_ik": lambda: _chain().ik(np.full((4, 4), NAN), [0.0]),
    "pyrt_kin_rnea": lambda: _chain().rnea([NAN], None, None),
    "pyrt_kin_mass_matrix": lambda: _chain().mass_matrix([NAN]),
    "pyrt_kin_forward_dynamics": lambda: _chain(masses=[0.0], inertias=[np.zeros((3, 3))]).
    forward_dynamics([0.0], None, [1.0]),
    "pyrt_servo_reset": lambda: nat.Servo(1, 1e-3).reset([NAN]),
    "pyrt_servo_load": lambda: nat.Servo(1, 1e-3).segment(0.01, [NAN], [0.0], [0.0], [0.0]),
    "pyrt_servo_tick": lambda: nat.Servo(1, 1e-3).tick([NAN]),
    "pyrt_servo_load_at": lambda: nat.Servo(1, 1e-3).segment(0.01, [0.0], [0.0], [0.0], [0.0],
                                                             start=NAN),
    "pyrt_servo_tick_at": lambda: nat.Servo(1, 1e-3).tick([0.0], now=NAN),
    "pyrt_servo_tick_board": lambda: _servo_board_nan(),
    "pyrt_arm_check": lambda: _arm(damping=[-1.0]),
    "pyrt_arm_step": lambda: _arm().step(NAN),
    "pyrt_arm_step_dac": lambda: _arm().step_dac(NAN, [0]),
    "pyrt_arm_publish": _arm_nan_state,
    "pyrt_drive_tick": lambda: _drive_nan(False),
    "pyrt_drive_run": lambda: _drive_nan(True),
    "pyrt_image_hand_over": lambda: _hand_over_bad_state(),
    "pyrt_journal_init": lambda: nat.TickEncoder(1, 1, 0),
    "pyrt_journal_encode": lambda: nat.TickEncoder(1, 1, 1000).encode(
        struct.pack("=5q", 0, 0, 0, -1, 0), 0, 1),   # missed < 0
}

def _hand_over_bad_state():
    """A tick hand-over whose count of ticks handed over went negative: C refuses it."""
    hand = nat.TickHandOver(bytearray(8 * 4), 1, 0, 1000)
    hand.state.put = -1
    hand(0)


#: Entry points whose only failure is a NULL pointer or a struct the wrapper
#: always fills correctly: their error path is called straight, and its code
#: goes through the same mapping.
ONLY_RAW = {
    "pyrt_excess128": lambda: lib.pyrt_excess128(1, ffi.NULL),
    "pyrt_from_excess128": lambda: lib.pyrt_from_excess128(1, ffi.NULL),
    "pyrt_excess128_many": lambda: lib.pyrt_excess128_many(ffi.NULL, ffi.NULL, -1),
    "pyrt_fuzzy_default_params": lambda: lib.pyrt_fuzzy_default_params(ffi.NULL),
    "pyrt_rq_check": lambda: lib.pyrt_rq_check(ffi.NULL),
    "pyrt_rq_check_wide": lambda: lib.pyrt_rq_check_wide(ffi.NULL),
    "pyrt_kin_workspace_size": lambda: lib.pyrt_kin_workspace_size(0, ffi.NULL),
    "pyrt_arm_work_size": lambda: lib.pyrt_arm_work_size(0, ffi.NULL),
    "pyrt_servo_encoders": lambda: lib.pyrt_servo_encoders(ffi.NULL, 1, ffi.NULL),
    "pyrt_kin_fk": lambda: lib.pyrt_kin_fk(ffi.NULL, ffi.NULL, ffi.NULL, ffi.NULL),
    "pyrt_kin_jacobian": lambda: lib.pyrt_kin_jacobian(ffi.NULL, ffi.NULL, ffi.NULL, ffi.NULL,
                                                       ffi.NULL),
    "pyrt_journal_record_bound": lambda: lib.pyrt_journal_record_bound(ffi.NULL, 0, ffi.NULL),
    "pyrt_image_gather": lambda: lib.pyrt_image_gather(ffi.NULL, 1, ffi.NULL, 0),
    "pyrt_image_row": lambda: lib.pyrt_image_row(ffi.NULL, 1, 0, 0, 0, 0, 0, ffi.NULL, 0),
    "pyrt_image_changes": lambda: lib.pyrt_image_changes(ffi.NULL, ffi.NULL, 1, 0, ffi.NULL,
                                                         ffi.NULL),
}


def test_every_entry_point_has_an_error_path_test():
    """The two tables below cover exactly the public C entry points."""
    assert set(THROUGH_WRAPPERS) | set(ONLY_RAW) == _entry_points()
    assert not set(THROUGH_WRAPPERS) & set(ONLY_RAW)


@pytest.mark.parametrize("name", sorted(THROUGH_WRAPPERS))
def test_error_path_through_the_wrapper(name, monkeypatch):
    """Bad input that only C refuses comes back as a NativeError subclass, raised from the
    status code the entry point returned, through the one mapping."""
    seen = []
    original = errors._raise

    def spy(rc, what, detail):
        seen.append(rc)
        original(rc, what, detail)

    monkeypatch.setattr(errors, "_raise", spy)
    with pytest.raises(NativeError) as info:
        THROUGH_WRAPPERS[name]()
    assert seen and seen[-1] in set(_header_codes().values()) - {0}
    assert type(info.value) is not NativeError and info.value.status == seen[-1]


@pytest.mark.parametrize("name", sorted(ONLY_RAW))
def test_error_path_straight_into_c(name):
    """A NULL pointer is refused with a header code that maps into the family."""
    rc = ONLY_RAW[name]()
    assert rc == lib.PYRT_EINVAL
    with pytest.raises(nat.NativeInputError):
        errors.raise_for_status(rc, name)


def test_c_defaults_struct_matches_the_header_constants():
    """pyrt_fuzzy_default_params fills exactly the header's PYRT_FUZZY_DEFAULT_* values."""
    for name, value in c_default_params().items():
        assert value == getattr(lib, f"PYRT_FUZZY_DEFAULT_{name.upper()}")
