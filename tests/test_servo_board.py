"""A servo task's tick bound once (Servo.board_ticker): the DACs that changed, or -1 to look."""

from __future__ import annotations

import math
import textwrap

import numpy as np
import pytest
from _sanitize import PRELUDE, assert_clean, run_under_asan
from hypothesis import HealthCheck, given, settings
from test_native_servo import PERIOD, board_case

from pyrt.native import NativeInputError, Servo, ServoBoard
from pyrt.native._servo import MAX_DT_PERIODS


def _twins(n, gains, cpu, first, per, bound):
    """Two servos and boards alike: one ticked by tick_board, one by its bound ticker."""
    out = []
    for _ in range(2):
        servo = Servo(n, PERIOD, gains={k: np.array(v) for k, v in gains.items()})
        board = ServoBoard(servo, cpu, first, per, 2000)
        servo.reset(servo.q.copy(), now=1.0)
        board.lo[:] = servo.q - bound
        board.hi[:] = servo.q + bound
        out.append((servo, board))
    return out


@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(board_case())
def test_the_ticker_is_tick_board_and_says_when_to_look(case):
    """Tick for tick the ticker gives tick_board's outputs (joints, torques, DAC counts),
    and returns the bits of the DACs that changed, or -1 exactly when the tick tripped the
    servo or found a joint beyond its bounds."""
    n, gains, cpu, first, steps, per, bound, (dur, knots, _m) = case
    (ref, ref_board), (servo, board) = _twins(n, gains, cpu, first, per, bound)
    for s in (ref, servo):
        q = s.q.copy()
        s.segment(dur, **{k: [v + q[j] if k in ("qa", "qb") else v
                              for j, v in enumerate(vals)] for k, vals in knots.items()})
    tick = servo.board_ticker(board)
    counts = list(first)
    for i, step in enumerate(steps):
        counts = [(c + d) % (1 << 32) for c, d in zip(counts, step, strict=True)]
        now = 1.0 + (i + 1) * PERIOD
        was = ref.tripped
        trip = ref.tick_board(now, ref_board, counts)
        got = tick(now, counts)
        assert servo.q.tolist() == ref.q.tolist() and servo.tau.tolist() == ref.tau.tolist()
        assert board.dac.tolist() == ref_board.dac.tolist()
        assert (board.changed, board.beyond) == (ref_board.changed, ref_board.beyond)
        look = trip is not None or ref_board.beyond >= 0
        assert got == (-1 if look else (0 if was else ref_board.changed))


def test_a_stall_is_a_tick_to_look_at():
    """A tick more than MAX_DT_PERIODS periods after the last (the loop stalled) returns -1
    and is counted; the next on time returns the changed DACs again."""
    servo = Servo(1, PERIOD, gains={"kp": [100.0], "felim": [1.0]})
    board = ServoBoard(servo, [1e3], [0], [1e3], 30000)
    servo.reset([0.0005], now=1.0)
    tick = servo.board_ticker(board)
    assert tick(1.001, [3]) == 1
    assert tick(1.001 + (MAX_DT_PERIODS + 1) * PERIOD, [5]) == -1 and servo.stalls == 1
    assert board.changed == 1 and board.beyond == -1 and servo.trip is None
    assert tick(1.001 + (MAX_DT_PERIODS + 2) * PERIOD, [9]) == 1


def test_the_ticker_refuses_what_tick_board_refuses():
    """A board of another servo, a count of counts that is not the servo's, a NaN time:
    refused (NativeInputError); after the NaN every output is zero."""
    servo = Servo(2, PERIOD, gains={"kp": [100.0, 100.0], "felim": [1.0, 1.0]})
    board = ServoBoard(servo, [1e3, 1e3], [0, 0], [1e3, 1e3], 100)
    with pytest.raises(NativeInputError):
        Servo(2, PERIOD).board_ticker(board)
    servo.reset(servo.q.copy(), now=0.0)
    tick = servo.board_ticker(board)
    assert tick(0.001, [50, -50]) == 3 and servo.tau.any()
    with pytest.raises(NativeInputError):
        tick(0.002, [50])
    with pytest.raises(NativeInputError):
        tick(math.nan, [60, -60])
    assert not servo.tau.any() and board.changed == 0


SANITIZE_DRIVER = textwrap.dedent(
    """
    import numpy as np
    import pyrt.native as nat

    ffi, lib = native.ffi, native.lib
    import pyrt.native._lib as bound
    assert bound.lib is lib, "pyrt.native is not using the sanitized build"
    servo = nat.Servo(3, 1e-3, gains={"kp": [50.0] * 3, "felim": [0.5] * 3})
    board = nat.ServoBoard(servo, [1e3] * 3, [0, 1, 2], [100.0] * 3, 1000)
    servo.reset(servo.q.copy(), now=0.0)
    tick = servo.board_ticker(board)
    rng = np.random.default_rng(3)
    for i in range(200):
        counts = [int(c) for c in rng.integers(-2**31, 2**31, 3)] if i % 50 == 7 \\
            else [int(c) for c in rng.integers(-40, 40, 3)]
        try:
            tick(0.001 * (i + 1) + (0.1 if i % 37 == 5 else 0.0), counts)
        except nat.NativeInputError:
            pass
    assert lib.pyrt_servo_tick_board(servo._c, 1.0, ffi.NULL, [0, 0, 0]) == lib.PYRT_EINVAL
    assert lib.pyrt_servo_tick_board(servo._c, 1.0, board.c, ffi.NULL) == lib.PYRT_EINVAL
    assert board.c.outcome == -1
    print("SANITIZE-DRIVER-OK")
    """
)


@pytest.mark.sanitize
def test_the_board_tick_is_clean_under_the_sanitizers(tmp_path):
    """The board tick and its outcome, good input and bad, without an ASan or UBSan report."""
    assert_clean(run_under_asan(PRELUDE + SANITIZE_DRIVER, tmp_path))
