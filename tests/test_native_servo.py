"""The generic servo (csrc/servo.c through pyrt.native.Servo) against its Python reference."""

from __future__ import annotations

import math
import textwrap

import numpy as np
import pytest
from _ref_servo import GAINS, RefServo, dacs, unwrap
from _sanitize import PRELUDE, assert_clean, run_under_asan
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pyrt.native import (
    NativeInputError,
    NonFiniteError,
    Servo,
    ServoBoard,
    ServoTrip,
    check_gains,
    gain_ranges,
    tuned_gains,
)
from pyrt.native._servo import MAX_DT_PERIODS

PERIOD = 1e-3
PUMA_INERTIA = np.array([3.6, 4.9, 0.95, 0.19, 0.17, 0.19])
PUMA_EFFORT = np.array([97.6, 186.4, 89.4, 24.2, 20.1, 21.3])

finite = st.floats(-2.0, 2.0, allow_nan=False)


@st.composite
def servo_case(draw):
    """Random gains, segments and measured joints for a few ticks."""
    n = draw(st.integers(1, 7))
    gains = {
        "kp": [draw(st.floats(0, 5e3)) for _ in range(n)],
        "ki": [draw(st.floats(0, 5e4)) for _ in range(n)],
        "kd": [draw(st.floats(0, 200)) for _ in range(n)],
        "kv": [draw(st.floats(0, 50)) for _ in range(n)],
        "ka": [draw(st.floats(0, 5)) for _ in range(n)],
        "kff": [draw(st.floats(0, 1)) for _ in range(n)],
        "ilim": [draw(st.floats(0, 50)) for _ in range(n)],
        "tmax": [draw(st.floats(0.1, 100)) for _ in range(n)],
        "felim": [draw(st.floats(0.02, 1.0)) for _ in range(n)],
        "velhz": [draw(st.floats(1, 400)) for _ in range(n)],
    }
    q0 = [draw(finite) for _ in range(n)]
    segments = []
    for _ in range(draw(st.integers(1, 3))):
        quintic = draw(st.booleans())
        ticks = draw(st.integers(1, 12))
        dur = ticks * PERIOD * draw(st.sampled_from([1.0, 0.73, 1.31]))
        knots = {k: [draw(finite) for _ in range(n)] for k in ("qda", "qdb", "ffa", "ffb")}
        for k in ("qa", "qb"):  # near the joints, so that most ticks run the law, some trip
            knots[k] = [q0[j] + draw(st.floats(-0.1, 0.1)) for j in range(n)]
        if quintic:
            knots["qdda"] = [draw(st.floats(-50, 50)) for _ in range(n)]
            knots["qddb"] = [draw(st.floats(-50, 50)) for _ in range(n)]
        measured = [[q0[j] + draw(st.floats(-0.05, 0.05)) for j in range(n)]
                    for _ in range(draw(st.integers(1, 15)))]
        segments.append((dur, knots, measured))
    return n, gains, q0, segments


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(servo_case())
def test_c_matches_reference(case):
    """Over random gains, quintic and cubic segments and measured joints, every tick's outputs,
    references, errors, integrators, trips and late counts of C equal the reference's."""
    n, gains, q0, segments = case
    servo = Servo(n, PERIOD, gains={k: np.array(v) for k, v in gains.items()})
    ref = RefServo(n, PERIOD, gains)
    servo.reset(q0, ff=[0.5] * n)
    ref.reset(q0, ff=[0.5] * n)
    # the output carries the references' rounding (their tolerances below) through the gains
    tau_tol = 1e-9 + 1e-5 * max(gains["ka"]) + 1e-7 * (max(gains["kv"]) + max(gains["kd"]))
    for dur, knots, measured in segments:
        servo.segment(dur, **knots)
        ref.load(dur, **knots)
        for q in measured:
            trip = servo.tick(q)
            ref_trip = ref.tick(q)
            assert (trip.joint if trip else None) == ref_trip
            np.testing.assert_allclose(servo.tau, ref.tau, rtol=1e-9, atol=tau_tol)
            assert servo.tripped == ref.tripped and servo.late == ref.late
            if not ref.tripped:
                np.testing.assert_allclose(servo.q_ref, ref.qref, rtol=1e-9, atol=1e-9)
                np.testing.assert_allclose(servo.qd_ref, ref.qdref, rtol=1e-9, atol=1e-7)
                np.testing.assert_allclose(servo.qdd_ref, ref.qddref, rtol=1e-9, atol=1e-5)
                np.testing.assert_allclose(servo.error, ref.err, rtol=1e-9, atol=1e-9)
            np.testing.assert_allclose(servo.integral, ref.integ, rtol=1e-9, atol=1e-9)
            np.testing.assert_allclose(servo.velocity, ref.vel, rtol=1e-9, atol=1e-9)


@settings(max_examples=100, deadline=None)
@given(st.integers(1, 30), st.lists(finite, min_size=6, max_size=6),
       st.lists(st.floats(-20, 20), min_size=2, max_size=2))
def test_interpolation_lands_on_the_knots(ticks, vals, acc):
    """A tick evaluates the segment at its clock: the first tick of a segment gives knot A, and
    the tick after its k ticks (when no next segment came) knot B's position, velocity and
    acceleration for a quintic, position and velocity for a cubic."""
    qa, va, qb, vb = vals[:4]
    servo = Servo(1, PERIOD, gains={"felim": [10.0]})
    dur = ticks * PERIOD
    servo.reset([qa])
    servo.segment(dur, [qa], [va], [qb], [vb], [acc[0]], [acc[1]])
    servo.tick([qa])
    assert servo.q_ref[0] == qa and servo.qd_ref[0] == va
    assert servo.qdd_ref[0] == pytest.approx(acc[0], abs=1e-12)
    for _ in range(ticks):
        servo.tick([qa])
    assert servo.q_ref[0] == pytest.approx(qb, abs=1e-9)
    assert servo.qd_ref[0] == pytest.approx(vb, abs=1e-6)
    assert servo.qdd_ref[0] == pytest.approx(acc[1], abs=1e-3)
    servo.reset([qa])
    servo.segment(dur, [qa], [va], [qb], [vb])
    for _ in range(ticks + 1):
        servo.tick([qa])
    assert servo.q_ref[0] == pytest.approx(qb, abs=1e-9)
    assert servo.qd_ref[0] == pytest.approx(vb, abs=1e-6)


def test_a_late_segment_holds_its_end_at_rest():
    """Past the segment's end the reference holds knot B with zero velocity and acceleration,
    and the late counter counts the ticks (never an extrapolation)."""
    servo = Servo(2, PERIOD, gains={"felim": [5.0, 5.0]})
    servo.reset([0.0, 0.0])
    servo.segment(0.005, [0, 0], [0, 0], [0.1, -0.1], [1.0, -1.0], [0, 0], [0, 0])
    for _ in range(6):
        servo.tick([0.0, 0.0])
    assert servo.late == 0 and servo.qd_ref.tolist() == pytest.approx([1.0, -1.0])
    for k in range(3):
        servo.tick([0.0, 0.0])
        assert servo.late == k + 1
        assert servo.q_ref.tolist() == pytest.approx([0.1, -0.1])
        assert servo.qd_ref.tolist() == [0.0, 0.0] and servo.qdd_ref.tolist() == [0.0, 0.0]


@st.composite
def timed_case(draw):
    """A servo case on a clock that jitters, stalls and stands still, segments joined in time."""
    n, gains, q0, segments = draw(servo_case())
    gaps = st.sampled_from([0.0, 0.4e-3, 1e-3, 1.6e-3, 0.015, 0.03, 1.0])
    timed = [(dur, knots, [(q, draw(gaps)) for q in measured], draw(st.booleans()))
             for dur, knots, measured in segments]
    return n, gains, q0, timed


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(timed_case())
def test_c_matches_reference_on_the_time_that_passed(case):
    """On a clock whose ticks jitter, stall (15 ms, 30 ms, 1 s) or stand still, segments
    started at the next tick or where the last ended, every tick's outputs, references,
    velocity estimate, integrators, trips, late and stall counts of C equal the reference's."""
    n, gains, q0, segments = case
    servo = Servo(n, PERIOD, gains={k: np.array(v) for k, v in gains.items()})
    ref = RefServo(n, PERIOD, gains)
    servo.reset(q0, ff=[0.5] * n, now=2.0)
    ref.last = 2.0
    ref.reset(q0, ff=[0.5] * n)
    for dur, knots, measured, joined in segments:
        start = servo.end if joined and servo.end > 2.0 else None
        servo.segment(dur, **knots, start=start)
        ref.load(dur, **knots, start=start)
        for q, gap in measured:
            now = servo.now + gap
            trip = servo.tick(q, now=now)
            ref_trip = ref.tick(q, now=now)
            assert (trip.joint if trip else None) == ref_trip
            np.testing.assert_allclose(servo.tau, ref.tau, rtol=1e-9, atol=1e-9)
            assert servo.tripped == ref.tripped and servo.late == ref.late
            assert servo.stalls == ref.stalls and servo.longest_stall == ref.stall_max
            if not ref.tripped:
                np.testing.assert_allclose(servo.q_ref, ref.qref, rtol=1e-9, atol=1e-9)
                np.testing.assert_allclose(servo.qd_ref, ref.qdref, rtol=1e-9, atol=1e-7)
                np.testing.assert_allclose(servo.error, ref.err, rtol=1e-9, atol=1e-9)
            np.testing.assert_allclose(servo.integral, ref.integ, rtol=1e-9, atol=1e-9)
            np.testing.assert_allclose(servo.velocity, ref.vel, rtol=1e-9, atol=1e-9)


def test_a_late_tick_evaluates_the_trajectory_at_its_own_time():
    """A tick that comes 15 ms late gives the segment's point (position and velocity) at the
    time that passed, not one period on; past the segment's end it gives knot B."""
    servo = Servo(1, PERIOD, gains={"felim": [5.0]})
    servo.reset([0.0], now=0.0)
    servo.segment(0.04, [0.0], [1.0], [0.04], [1.0], [0.0], [0.0], start=0.001)
    servo.tick([0.0], now=0.001)
    servo.tick([0.0], now=0.002)
    servo.tick([0.015], now=0.017)  # 15 ms late
    assert servo.q_ref[0] == pytest.approx(0.016, abs=1e-12)
    assert servo.qd_ref[0] == pytest.approx(1.0, abs=1e-9)
    assert servo.error[0] == pytest.approx(0.001, abs=1e-12)
    servo.tick([0.04], now=0.05)
    assert servo.q_ref[0] == pytest.approx(0.04, abs=1e-12) and servo.late == 1
    servo.segment(0.02, [0.04], [1.0], [0.06], [1.0], [0.0], [0.0], start=servo.end)
    servo.tick([0.05], now=0.051)  # the next segment joined in time: 10 ms into it
    assert servo.q_ref[0] == pytest.approx(0.05, abs=1e-12) and servo.late == 0


def test_a_long_stall_bounds_the_integral_step_and_is_counted():
    """A tick 2 s after the last: the integral grows by at most MAX_DT_PERIODS periods of
    KI e, the velocity estimate is the mean speed over the stall (no kick), the stall is
    counted with its length; a time before the last tick is refused, outputs zero."""
    servo = Servo(1, PERIOD, gains={"ki": [100.0], "ilim": [1e6], "felim": [1.0]})
    servo.reset([0.0], now=10.0)
    servo.tick([0.0], now=10.001)
    servo.tick([-0.1], now=12.001)
    assert servo.integral[0] == pytest.approx(100.0 * 0.1 * MAX_DT_PERIODS * PERIOD)
    assert servo.velocity[0] == pytest.approx(-0.1 / 2.0)
    assert servo.stalls == 1 and servo.longest_stall == pytest.approx(2.0)
    assert servo.dt == pytest.approx(2.0)
    servo.tick([-0.1], now=12.001)  # no time passed: the estimate and the integral stay
    assert servo.velocity[0] == pytest.approx(-0.05)
    assert servo.integral[0] == pytest.approx(100.0 * 0.1 * MAX_DT_PERIODS * PERIOD)
    with pytest.raises(NativeInputError):
        servo.tick([0.0], now=11.0)
    assert servo.tau[0] == 0.0
    with pytest.raises(NativeInputError):
        servo.tick([0.0], now=math.nan)
    with pytest.raises(NativeInputError):
        servo.segment(0.01, [0.0], [0.0], [0.0], [0.0], start=math.inf)


@st.composite
def board_case(draw):
    """A servo case read through a board: counters that wrap, bounds, DAC scales."""
    n, gains, q0, segments = draw(servo_case())
    for _dur, knots, _m in segments:  # the knots about zero: the test puts them at the joints
        for k in ("qa", "qb"):
            knots[k] = [v - q0[j] for j, v in enumerate(knots[k])]
    cpu = [draw(st.floats(1e3, 1e5)) for _ in range(n)]
    first = [draw(st.integers(0, (1 << 32) - 1)) for _ in range(n)]
    steps = draw(st.lists(st.lists(st.integers(-3000, 3000), min_size=n, max_size=n),
                          min_size=1, max_size=12))
    per = [draw(st.floats(10.0, 1e4)) for _ in range(n)]
    bound = draw(st.floats(0.01, 0.2))
    return n, gains, cpu, first, steps, per, bound, segments[0]


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(board_case())
def test_the_board_tick_matches_encoders_law_bounds_and_dacs_of_the_reference(case):
    """tick_board against the reference: 32-bit counters unwrapped (across the wrap), the law
    at the loop's time, the first joint beyond its bounds ending the walk, and each DAC count
    rint(tau * scale) within the full scale, a bit per count that changed."""
    n, gains, cpu, first, steps, per, bound, (dur, knots, _measured) = case
    full = 2000
    servo = Servo(n, PERIOD, gains={k: np.array(v) for k, v in gains.items()})
    board = ServoBoard(servo, cpu, first, per, full)
    last, total = list(first), list(first)
    q = [(t + 0.5) / c for t, c in zip(total, cpu, strict=True)]
    assert servo.q.tolist() == q
    ref = RefServo(n, PERIOD, gains)
    servo.reset(q, now=1.0)
    ref.last = 1.0
    ref.reset(q)
    board.lo[:] = np.array(q) - bound
    board.hi[:] = np.array(q) + bound
    lo, hi = board.lo.tolist(), board.hi.tolist()
    knots = {k: [v + q[j] if k in ("qa", "qb") else v for j, v in enumerate(vals)]
             for k, vals in knots.items()}
    servo.segment(dur, **knots)
    ref.load(dur, **knots)
    dac = [0] * n
    counts = list(first)
    for i, step in enumerate(steps):
        counts = [(c + d) % (1 << 32) for c, d in zip(counts, step, strict=True)]
        now = 1.0 + (i + 1) * PERIOD
        unwrap(last, total, counts)
        q = [(t + 0.5) / c for t, c in zip(total, cpu, strict=True)]
        trip = servo.tick_board(now, board, counts)
        ref_trip = ref.tick(q, now=now)
        assert (trip.joint if trip else None) == ref_trip
        assert servo.q.tolist() == q and board.total.tolist() == total
        np.testing.assert_allclose(servo.tau, ref.tau, rtol=1e-9, atol=1e-9)
        if ref.tripped:
            assert board.changed == 0 and board.beyond == -1
            continue
        changed, beyond = dacs(servo.tau.tolist(), q, lo, hi, per, full, dac)
        assert (board.changed, board.beyond) == (changed, beyond)
        assert board.dac.tolist() == dac


def test_the_board_tick_refuses_bad_input_with_every_output_zero():
    """A board whose q is not the servo's, NaN in the time, or a bad scale: refused, every
    servo output zero, no DAC marked changed."""
    servo = Servo(2, PERIOD, gains={"kp": [100.0, 100.0], "felim": [1.0, 1.0]})
    board = ServoBoard(servo, [1e3, 1e3], [0, 0], [1e3, 1e3], 100)
    servo.reset(servo.q.copy(), now=0.0)
    servo.tick_board(0.001, board, [50, -50])
    assert board.changed == 3 and servo.tau.any()
    with pytest.raises(NativeInputError):
        servo.tick_board(math.nan, board, [60, -60])
    assert not servo.tau.any() and board.changed == 0
    other = Servo(2, PERIOD)
    with pytest.raises(NativeInputError):
        other.tick_board(0.001, board, [0, 0])
    for bad in ({"counts_per_unit": [0.0, 1.0]}, {"dac_per_unit": [math.inf, 1.0]},
                {"full": 0}, {"counts": [0]}):
        kw = {"counts_per_unit": [1.0, 1.0], "counts": [0, 0], "dac_per_unit": [1.0, 1.0],
              "full": 10, **bad}
        with pytest.raises(NativeInputError):
            ServoBoard(servo, **kw)


def test_following_error_trips_every_joint_in_the_same_tick():
    """One joint beyond its following-error limit: that tick's outputs are all zero, the trip
    names the joint furthest beyond, and the servo stays stopped until reset."""
    names = ("waist", "shoulder", "elbow")
    servo = Servo(3, PERIOD, names=names, gains={"kp": [100.0] * 3, "felim": [0.1, 0.05, 0.1]})
    servo.reset([0.0, 0.0, 0.0], ff=[5.0, 5.0, 5.0])
    servo.tick([0.01, 0.0, -0.01])
    assert (servo.tau != 0).all()
    trip = servo.tick([0.09, 0.06, 0.0])     # joint 1 at 0.9 of its limit, joint 2 at 1.2
    assert isinstance(trip, ServoTrip) and trip.joint == 1 and trip.name == "shoulder"
    assert trip.error == pytest.approx(-0.06) and trip.limit == 0.05
    assert "shoulder" in str(trip) and "beyond its limit" in str(trip)
    assert servo.tau.tolist() == [0.0, 0.0, 0.0] and servo.integral.tolist() == [0.0] * 3
    assert servo.tick([0.0, 0.0, 0.0]) is None       # reported once ...
    assert servo.tripped and servo.tau.tolist() == [0.0] * 3  # ... and held
    servo.reset([0.0, 0.0, 0.0])
    assert not servo.tripped and servo.trip is None
    servo.tick([0.001, 0.0, 0.0])
    assert servo.tau[0] != 0


def test_integrator_does_not_wind_up_at_the_clamp():
    """While the output is clamped in the direction of the error the integrator does not grow;
    it is bounded by its limit."""
    servo = Servo(1, PERIOD, gains={"kp": [1000.0], "ki": [1e5], "tmax": [10.0],
                                    "ilim": [8.0], "felim": [1.0]})
    servo.reset([0.0])
    servo.segment(0.001, [0.0], [0.0], [0.5], [0.0])
    for _ in range(200):
        servo.tick([0.0])
    assert servo.tau[0] == 10.0
    assert servo.integral[0] == 0.0  # kp e alone saturates: the integrator never started
    servo2 = Servo(1, PERIOD, gains={"kp": [1.0], "ki": [1e4], "tmax": [10.0], "ilim": [8.0],
                                     "felim": [1.0]})
    servo2.reset([0.0])
    servo2.segment(0.001, [0.0], [0.0], [0.5], [0.0])
    for _ in range(500):
        servo2.tick([0.0])
    assert servo2.integral[0] == 8.0 and servo2.tau[0] == pytest.approx(8.5)


def test_bad_input_zeroes_the_outputs_and_raises():
    """NaN in the measured joints, or a gain written out of its basic range, raises from the
    status code and leaves every output zero."""
    servo = Servo(2, PERIOD, gains={"kp": [100.0, 100.0], "felim": [1.0, 1.0]})
    servo.reset([0.0, 0.0])
    servo.tick([0.01, 0.01])
    assert (servo.tau != 0).all()
    with pytest.raises(NonFiniteError):
        servo.tick([math.nan, 0.0])
    assert servo.tau.tolist() == [0.0, 0.0]
    servo.tick([0.01, 0.01])
    servo.kp[1] = -1.0
    with pytest.raises(NativeInputError, match="basic range"):
        servo.tick([0.01, 0.01])
    assert servo.tau.tolist() == [0.0, 0.0]
    with pytest.raises(NativeInputError):
        servo.segment(-0.01, [0, 0], [0, 0], [0, 0], [0, 0])
    with pytest.raises(NativeInputError, match="both accelerations"):
        servo.segment(0.01, [0, 0], [0, 0], [0, 0], [0, 0], qdda=[0, 0])


def test_gains_out_of_their_safe_range_are_refused_with_the_reason():
    """set_gain and set_gains refuse a value outside the safe ranges, naming gain, joint, value
    and range, and change nothing; a value within is taken."""
    ranges = gain_ranges(PUMA_INERTIA, PUMA_EFFORT, PERIOD)
    gains = tuned_gains(PUMA_INERTIA, PUMA_EFFORT, PERIOD, 10.0)
    servo = Servo(6, PERIOD, names=[f"q{j + 1}" for j in range(6)], gains=gains, ranges=ranges)
    before = servo.gains.copy()
    with pytest.raises(NativeInputError, match=r"kp of joint q2: .* outside its safe range"):
        servo.set_gain("kp", 1, 1e7)
    with pytest.raises(NativeInputError, match=r"tmax of joint q1: 200 N m .*97.6 N m"):
        servo.set_gain("tmax", 0, 200.0)
    with pytest.raises(NativeInputError, match="kff"):
        servo.set_gains({"kff": [1.5] * 6})
    with pytest.raises(NativeInputError, match="unknown gain"):
        servo.set_gain("kq", 0, 1.0)
    assert np.array_equal(servo.gains, before)
    servo.set_gain("kp", 1, 1000.0)
    assert servo.kp[1] == 1000.0


def test_ranges_allow_loops_up_to_a_twentieth_of_the_servo_rate():
    """Tuned gains at 50 Hz on a 1 kHz servo are within the ranges; at 60 Hz they are refused."""
    ranges = gain_ranges(PUMA_INERTIA, PUMA_EFFORT, PERIOD)
    ok = tuned_gains(PUMA_INERTIA, PUMA_EFFORT, PERIOD, 49.9)
    bad = tuned_gains(PUMA_INERTIA, PUMA_EFFORT, PERIOD, 60.0)
    as_rows = lambda g: np.array([g[k] for k in GAINS])  # noqa: E731
    assert check_gains(as_rows(ok), ranges) is None
    assert "kp of joint 0" in check_gains(as_rows(bad), ranges)
    with pytest.raises(NativeInputError):
        gain_ranges([1.0, -1.0], [1.0, 1.0], PERIOD)


SANITIZE_DRIVER = textwrap.dedent(
    """
    import math
    import numpy as np
    from pyrt.native import Servo, ServoBoard
    from pyrt.errors import NativeError

    ffi, lib = native.ffi, native.lib
    import pyrt.native._lib as bound
    assert bound.lib is lib, "pyrt.native is not using the sanitized build"
    rng = np.random.default_rng(1)
    for n in (1, 6, lib.PYRT_SERVO_MAX_JOINTS):
        s = Servo(n, 1e-3, gains={"kp": rng.uniform(0, 100, n), "ki": rng.uniform(0, 10, n),
                                  "felim": np.full(n, 0.3)})
        s.reset(rng.uniform(-1, 1, n), ff=rng.uniform(-1, 1, n))
        now = 0.0
        for k in range(40):
            if k % 10 == 0:
                a = rng.uniform(-1, 1, (6, n))
                s.segment(0.0097, *a[:4], a[4], a[5]) if k % 20 else s.segment(
                    0.01, *a[:4], start=s.end)
            if k % 2:
                s.tick(rng.uniform(-1, 1, n))
            else:
                now = s.now + float(rng.choice([0.0, 1e-3, 0.023, 2.0]))
                s.tick(rng.uniform(-1, 1, n), now=now)
        for bad, when in (([math.nan] * n, None), ([0.0] * n, s.now - 1.0),
                          ([0.0] * n, math.inf)):
            try:
                s.tick(bad, now=when)
            except NativeError:
                pass
        s.reset(np.zeros(n), now=s.now)
        b = ServoBoard(s, rng.uniform(1e3, 1e4, n), [int(v) for v in rng.integers(0, 2**32, n)],
                       rng.uniform(1, 1e3, n), 32767)
        b.lo[:], b.hi[:] = s.q - 0.5, s.q + 0.5
        counts = b.last.tolist()
        for k in range(30):
            counts = [(v + int(d)) % 2**32 for v, d in zip(counts, rng.integers(-999, 999, n))]
            try:
                s.tick_board(s.now + 1e-3, b, counts)
            except NativeError:
                pass
    c = ffi.new("pyrt_servo *")
    assert lib.pyrt_servo_tick(ffi.NULL) == lib.PYRT_EINVAL
    assert lib.pyrt_servo_tick(c) == lib.PYRT_EINVAL
    assert lib.pyrt_servo_reset(ffi.NULL, ffi.NULL, ffi.NULL) == lib.PYRT_EINVAL
    assert lib.pyrt_servo_reset(c, ffi.NULL, ffi.NULL) == lib.PYRT_EINVAL
    assert lib.pyrt_servo_load(ffi.NULL, ffi.NULL, 1.0, 5) == lib.PYRT_EINVAL
    assert lib.pyrt_servo_load_at(ffi.NULL, ffi.NULL, 1.0, 5, 0.0) == lib.PYRT_EINVAL
    assert lib.pyrt_servo_tick_at(ffi.NULL, 0.0) == lib.PYRT_EINVAL
    assert lib.pyrt_servo_tick_at(c, math.nan) == lib.PYRT_EINVAL
    assert lib.pyrt_servo_tick_board(ffi.NULL, 0.0, ffi.NULL, ffi.NULL) == lib.PYRT_EINVAL
    assert lib.pyrt_servo_encoders(ffi.NULL, 1, ffi.NULL) == lib.PYRT_EINVAL
    b = ffi.new("pyrt_servo_board *")
    assert lib.pyrt_servo_tick_board(c, 0.0, b, ffi.NULL) == lib.PYRT_EINVAL
    c.n = lib.PYRT_SERVO_MAX_JOINTS + 1
    assert lib.pyrt_servo_tick(c) == lib.PYRT_EINVAL
    print("SANITIZE-DRIVER-OK")
    """
)


@pytest.mark.sanitize
def test_servo_kernel_is_clean_under_the_sanitizers(tmp_path):
    """Every servo entry point, good input and bad, runs without an ASan or UBSan report."""
    assert_clean(run_under_asan(PRELUDE + SANITIZE_DRIVER, tmp_path))
