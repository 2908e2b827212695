"""The hardware (a) board's servo (csrc/drive.c through pyrt.native.DriveKernel) against its Python reference."""

from __future__ import annotations

import math
import textwrap

import numpy as np
import pytest
from _ref_drive import FAULT, JOINT_SHIFT, REFUSED, RefDrive
from _sanitize import PRELUDE, assert_clean, run_under_asan
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pyrt.native import (
    DRIVE_ENABLED,
    DRIVE_FAULT,
    DRIVE_LATE,
    DRIVE_REFUSED,
    DriveKernel,
    NativeInputError,
    tuned_gains,
)

PERIOD = 1e-3
I32 = st.integers(-(1 << 31), (1 << 31) - 1)


@st.composite
def drive_case(draw):
    """A random board (counts, torque scale, gains) and a sequence of ticks: encoder counts
    near a start that may sit at the counter's wrap, register writes now and then."""
    n = draw(st.integers(1, 6))
    counts = [draw(st.floats(100.0, 1e5)) for _ in range(n)]
    nm = [draw(st.floats(1e-4, 1e-2)) for _ in range(n)]
    gains = tuned_gains([draw(st.floats(0.05, 5.0)) for _ in range(n)],
                        [draw(st.floats(5.0, 200.0)) for _ in range(n)], PERIOD,
                        draw(st.floats(2.0, 20.0)))
    start = [draw(st.one_of(I32, st.just((1 << 31) - 5), st.just(-(1 << 31) + 3)))
             for _ in range(n)]
    ticks = []
    for _ in range(draw(st.integers(1, 40))):
        c = [((s + draw(st.integers(-300, 300)) + (1 << 31)) % (1 << 32)) - (1 << 31)
             for s in start]
        regs = None
        if draw(st.integers(0, 3)) == 0:
            regs = {
                "setpoint": [((s + draw(st.integers(-400, 400)) + (1 << 31)) % (1 << 32))
                             - (1 << 31) for s in start],
                "velocity": [draw(st.integers(-20000, 20000)) for _ in range(n)],
                "torque": [draw(st.integers(-32767, 32767)) for _ in range(n)],
                "felim": [draw(st.sampled_from([0, 50, 200, 1000, 100000])) for _ in range(n)],
                "enable": draw(st.sampled_from([0, 1, 1, 1])),
                "sync": draw(st.integers(0, 3)),
                "period_us": draw(st.sampled_from([0, 3000, 10000])),
            }
        ticks.append((c, regs))
    return n, counts, nm, gains, ticks


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(drive_case())
def test_c_matches_reference(case):
    """Over random boards, encoder counts (across the 32-bit wrap) and register writes, every tick's DACs, amplifier enables, status word and following errors equal the Python reference's (a DAC count within 1 of it at a rounding tie)."""
    n, counts, nm, gains, ticks = case
    drive = DriveKernel(n, PERIOD, counts=counts, nm_per_count=nm, gains=gains)
    ref = RefDrive(n, PERIOD, counts, nm, gains)
    for c, regs in ticks:
        if regs is not None:
            for name in ("setpoint", "velocity", "torque", "felim"):
                drive.set_outputs(name, regs[name])
                setattr(ref, name, list(regs[name]))
            drive.set_registers(enable=regs["enable"], sync=regs["sync"],
                                period_us=regs["period_us"])
            ref.enable, ref.sync, ref.period_us = regs["enable"], regs["sync"], regs["period_us"]
        drive.count[:] = c
        drive.tick()
        ref.tick(c)
        assert drive.status == ref.status
        assert drive.amp.tolist() == ref.amp
        assert np.abs(drive.dac - np.array(ref.dac)).max() <= 1
        assert np.abs(drive.ferr - np.array(ref.ferr)).max() <= 1


def _board(n=2, felim=1000):
    drive = DriveKernel(n, PERIOD, counts=[1e4] * n, nm_per_count=[1e-3] * n,
                        gains=tuned_gains([0.5] * n, [30.0] * n, PERIOD, 10.0))
    drive.set_outputs("felim", [felim] * n)
    drive.set_registers(period_us=10_000)
    return drive


def test_enable_closes_the_loop_where_the_arm_is_and_a_setpoint_is_followed_one_period_later():
    """Enabled at counts 500 and -200, the board holds there (status ENABLED, outputs on); a new setpoint with sync changed is reached, interpolated, after one interpolation period (10 ticks), then held with LATE."""
    d = _board()
    d.count[:] = [500, -200]
    d.tick()
    assert d.status == 0 and d.amp.tolist() == [0, 0]
    d.set_registers(enable=1)
    d.tick()
    assert d.status == DRIVE_ENABLED and d.amp.tolist() == [1, 1]
    assert d.ferr.tolist() == [0, 0]
    d.set_outputs("setpoint", [600, -300])
    d.set_registers(sync=1)
    errs = []
    for _ in range(10):
        d.tick()
        errs.append(d.ferr.tolist())
    assert errs[0] == [0, 0]  # the segment starts at the last knot
    assert 0 < errs[5][0] < 100 and -100 < errs[5][1] < 0
    d.tick()
    assert d.ferr.tolist() == [100, -100]  # knot B: the setpoint (the arm did not move)
    assert not d.status & DRIVE_LATE
    d.tick()
    assert d.status == DRIVE_ENABLED | DRIVE_LATE and d.ferr.tolist() == [100, -100]


def test_a_following_error_trips_every_joint_in_the_same_tick_until_enable_is_cleared():
    """An encoder 1001 counts off a limit of 1000: that tick every DAC and enable is 0, the status says FAULT and the joint; enable stays set and the board stays off; enable 0 clears it, enable 1 closes the loop again."""
    d = _board()
    d.set_registers(enable=1)
    d.count[:] = [0, 0]
    d.tick()
    d.count[:] = [0, 1001]
    d.tick()
    assert d.amp.tolist() == [0, 0] and d.dac.tolist() == [0, 0]
    assert d.status == DRIVE_FAULT | (2 << 8) and d.fault_joint == 1
    d.count[:] = [0, 0]
    d.tick()
    assert d.status & DRIVE_FAULT and not d.on and d.amp.tolist() == [0, 0]
    d.set_registers(enable=0)
    d.tick()
    assert d.status == 0
    d.set_registers(enable=1)
    d.tick()
    assert d.status == DRIVE_ENABLED


def test_enable_without_a_following_error_limit_or_a_period_is_refused():
    """A felim of 0 on any joint, or period_us 0: enable is refused (REFUSED, outputs off)."""
    d = _board(felim=0)
    d.set_registers(enable=1)
    d.tick()
    assert d.status == DRIVE_REFUSED == REFUSED and d.amp.tolist() == [0, 0]
    d = _board()
    d.set_registers(enable=1, period_us=0)
    d.tick()
    assert d.status == DRIVE_REFUSED


def test_bad_registers_and_parameters_are_refused():
    """A value beyond 32 bits, a wrong count, counts not > 0: NativeInputError, nothing set."""
    d = _board()
    with pytest.raises(NativeInputError):
        d.set_outputs("setpoint", [1 << 31, 0])
    with pytest.raises(NativeInputError):
        d.set_outputs("setpoint", [0])
    with pytest.raises(NativeInputError):
        d.set_registers(sync=1 << 40)
    assert d.setpoint.tolist() == [0, 0]
    with pytest.raises(NativeInputError):
        DriveKernel(1, PERIOD, counts=[0.0], nm_per_count=[1.0])
    with pytest.raises(NativeInputError):
        DriveKernel(1, PERIOD, counts=[math.nan], nm_per_count=[1.0])


def test_the_status_bits_are_the_headers():
    """The status bits pyrt.native exports are csrc/drive.h's, and the reference's."""
    assert (DRIVE_ENABLED, DRIVE_FAULT, DRIVE_LATE, DRIVE_REFUSED) == (1, 2, 4, 8)
    assert FAULT == DRIVE_FAULT and JOINT_SHIFT == 8


SANITIZE_DRIVER = textwrap.dedent(
    """
    import numpy as np
    from pyrt.native import DriveKernel, tuned_gains

    ffi, lib = native.ffi, native.lib
    import pyrt.native._lib as bound
    assert bound.lib is lib, "pyrt.native is not using the sanitized build"
    rng = np.random.default_rng(2)
    for n in (1, 6, lib.PYRT_DRIVE_MAX_JOINTS):
        d = DriveKernel(n, 1e-3, counts=rng.uniform(1e3, 1e5, n),
                        nm_per_count=rng.uniform(1e-4, 1e-2, n),
                        gains=tuned_gains(np.full(n, 0.5), np.full(n, 30.0), 1e-3, 10.0))
        d.set_outputs("felim", [1000] * n)
        d.set_registers(enable=1, period_us=10000)
        for k in range(60):
            if k % 10 == 0:
                d.set_outputs("setpoint", rng.integers(-2000, 2000, n).tolist())
                d.set_registers(sync=k)
            if k == 45:
                d.set_registers(enable=0)
            d.count[:] = rng.integers(-300, 300, n)
            d.tick()
    c = ffi.new("pyrt_drive *")
    assert lib.pyrt_drive_tick(ffi.NULL) == lib.PYRT_EINVAL
    assert lib.pyrt_drive_tick(c) == lib.PYRT_EINVAL
    assert lib.pyrt_drive_run(ffi.NULL, ffi.NULL, 1.0) == lib.PYRT_EINVAL
    assert lib.pyrt_drive_run(c, ffi.NULL, 1.0) == lib.PYRT_EINVAL
    c.n = lib.PYRT_DRIVE_MAX_JOINTS + 1
    assert lib.pyrt_drive_tick(c) == lib.PYRT_EINVAL
    print("SANITIZE-DRIVER-OK")
    """
)


@pytest.mark.sanitize
def test_drive_kernel_is_clean_under_the_sanitizers(tmp_path):
    """Every drive entry point, good input and bad, runs without an ASan or UBSan report."""
    assert_clean(run_under_asan(PRELUDE + SANITIZE_DRIVER, tmp_path))
