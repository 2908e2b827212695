"""The generic joint servo (csrc/servo.c): every joint of a robot in one call.

:class:`Servo` holds the C state and every array it works on, allocated
once: per tick the caller writes the measured joints into :attr:`Servo.q`
(or passes them to :meth:`Servo.tick`) and reads the outputs from
:attr:`Servo.tau` (N m, or N for a prismatic joint).  The trajectory loads
one segment at a time (:meth:`Servo.segment`: knots A and B, quintic with
accelerations, cubic without); see ``csrc/servo.h`` for the law, the
interpolation and the following-error trip.

Time: :meth:`Servo.tick` with ``now`` (s, the loop's clock) runs on the time
that really passed (a late tick evaluates the trajectory at its own time,
the velocity estimate and the integral use its dt, the integral's bounded
at :data:`MAX_DT_PERIODS` periods: :attr:`Servo.stalls` counts the ticks
beyond); without ``now`` the servo clocks itself, one period per tick.  A
segment starts at the next tick, or at ``start`` on that clock (a
trajectory continuing its segments gives :attr:`Servo.end`).

Gains are plain arrays (:attr:`Servo.gains`, one row per :data:`GAINS`
name, one column per joint; ``servo.kp`` etc. are views of the rows) that
the caller may change between ticks.  Their safe ranges depend on the
joint's inertia, its effort limit and the servo period
(:func:`gain_ranges`); :meth:`Servo.set_gain` refuses a value outside them
with the reason and changes nothing, :func:`check_gains` gives the reason
for a whole set.  :func:`tuned_gains` places each joint's closed loop at a
triple real pole.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from pyrt.native._arrays import F64, as_f64
from pyrt.native._errors import NativeInputError, raise_for_status
from pyrt.native._lib import ffi, lib

__all__ = [
    "GAINS",
    "GAIN_UNITS",
    "MAX_DT_PERIODS",
    "MAX_JOINTS",
    "Servo",
    "ServoBoard",
    "ServoTrip",
    "check_gains",
    "gain_ranges",
    "tuned_gains",
]

MAX_JOINTS: int = lib.PYRT_SERVO_MAX_JOINTS
NGAINS: int = lib.PYRT_SERVO_NGAINS
NSTATE: int = lib.PYRT_SERVO_NSTATE
NKNOTS: int = lib.PYRT_SERVO_NKNOTS
#: The integral's dt is bounded at this many periods (a longer stall is counted).
MAX_DT_PERIODS: int = lib.PYRT_SERVO_MAX_DT_PERIODS
_QUINTIC: int = lib.PYRT_SERVO_QUINTIC
_CUBIC: int = lib.PYRT_SERVO_CUBIC

#: The gain rows, in the order of csrc/servo.h.
GAINS: tuple[str, ...] = ("kp", "ki", "kd", "kv", "ka", "kff", "ilim", "tmax", "felim", "velhz")
_ROWS = {name: getattr(lib, f"PYRT_SERVO_{name.upper()}") for name in GAINS}
if sorted(_ROWS.values()) != list(range(NGAINS)):  # pragma: no cover - header out of step
    raise ImportError("csrc/servo.h's gain rows differ from pyrt.native's")

#: Each gain's unit (revolute joints; a prismatic joint has N and m for N m and rad).
GAIN_UNITS: dict[str, str] = {
    "kp": "N m/rad", "ki": "N m/(rad s)", "kd": "N m s/rad", "kv": "N m s/rad",
    "ka": "kg m^2", "kff": "", "ilim": "N m", "tmax": "N m", "felim": "rad", "velhz": "Hz",
}

#: The fastest closed loop the ranges allow, as a fraction of the servo rate.
BANDWIDTH_FRACTION = 1.0 / 20.0
#: The largest following-error limit allowed (rad): a trip must still mean something.
MAX_FELIM = 0.5


@dataclass(frozen=True)
class ServoTrip:
    """A following-error trip: ``joint`` (index) and its ``name``, the
    following ``error`` and the ``limit`` it went beyond (rad or m)."""

    joint: int
    name: str
    error: float
    limit: float

    def __str__(self) -> str:
        return (f"joint {self.name}: following error {math.degrees(self.error):.3f} deg "
                f"beyond its limit {math.degrees(self.limit):.3f} deg")


def _vector(name: str, value: ArrayLike, n: int) -> np.ndarray:
    v = as_f64(name, value, (n,))
    return v


def gain_ranges(inertia: ArrayLike, effort: ArrayLike, period: float
                ) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Safe ranges (low, high), per joint, of every gain for joints of the
    given ``inertia`` (kg m^2: the largest diagonal of the mass matrix over
    the workspace, rotor inertia included) and ``effort`` limit (N m), at a
    servo ``period`` (s).

    The stiffest loop allowed is the triple pole of :func:`tuned_gains` at
    ``BANDWIDTH_FRACTION`` of the servo rate (50 Hz at 1 kHz): beyond it the
    sampled loop loses its margin.  Feed-forwards are bounded by what the
    effort can give; the output clamp by the effort itself; the velocity
    filter by the Nyquist rate.
    """
    inertia_a = np.asarray(inertia, dtype=float)
    effort_a = np.asarray(effort, dtype=float)
    if inertia_a.ndim != 1 or inertia_a.shape != effort_a.shape:
        raise NativeInputError("gain_ranges: inertia and effort are two vectors of one length")
    if not (np.isfinite(inertia_a).all() and (inertia_a > 0).all()):
        raise NativeInputError("gain_ranges: every inertia must be a finite number > 0 kg m^2")
    if not (np.isfinite(effort_a).all() and (effort_a > 0).all()):
        raise NativeInputError("gain_ranges: every effort must be a finite number > 0 N m")
    if not (isinstance(period, (int, float)) and math.isfinite(period) and period > 0):
        raise NativeInputError(f"gain_ranges: period must be > 0 s, got {period!r}")
    hi = tuned_gains(inertia_a, effort_a, period, BANDWIDTH_FRACTION / period)
    zero = np.zeros_like(inertia_a)
    return {
        "kp": (zero, hi["kp"]),
        "ki": (zero, hi["ki"]),
        "kd": (zero, hi["kd"]),
        "kv": (zero, effort_a / 0.1),            # the effort at 0.1 rad/s
        "ka": (zero, 10.0 * inertia_a),
        "kff": (zero, np.ones_like(inertia_a)),
        "ilim": (zero, effort_a.copy()),
        "tmax": (np.full_like(inertia_a, 1e-9), effort_a.copy()),
        "felim": (np.full_like(inertia_a, 1e-6), np.full_like(inertia_a, MAX_FELIM)),
        "velhz": (np.full_like(inertia_a, 1.0), np.full_like(inertia_a, 0.5 / period)),
    }


def tuned_gains(inertia: ArrayLike, effort: ArrayLike, period: float, bandwidth_hz: float,
                felim: float = 0.05) -> dict[str, np.ndarray]:
    """Gains that place each joint's loop (inertia I) at a triple real pole
    at ``w = 2 pi bandwidth_hz``: ``kp = 3 I w^2``, ``kd = 3 I w``,
    ``ki = I w^3``; the integrator may give half the effort, the output is
    clamped at the effort, the velocity filter at 5 bandwidths (within
    Nyquist), feed-forwards: all of the dynamics, none of the rest."""
    i = np.asarray(inertia, dtype=float)
    eff = np.asarray(effort, dtype=float)
    w = 2.0 * math.pi * bandwidth_hz
    return {
        "kp": 3.0 * i * w * w, "ki": i * w ** 3, "kd": 3.0 * i * w,
        "kv": np.zeros_like(i), "ka": np.zeros_like(i), "kff": np.ones_like(i),
        "ilim": 0.5 * eff, "tmax": eff.copy(), "felim": np.full_like(i, felim),
        "velhz": np.full_like(i, min(5.0 * bandwidth_hz, 0.4 / period)),
    }


def check_gains(gains: ArrayLike, ranges: dict[str, tuple[np.ndarray, np.ndarray]],
                names: Sequence[str] | None = None) -> str | None:
    """Why a gain set (``NGAINS x n``, rows in :data:`GAINS` order) is not
    within ``ranges`` (the first gain out, named with its joint, value,
    range and unit), or None when every gain is within."""
    g = np.asarray(gains, dtype=float)
    n = g.shape[1] if g.ndim == 2 else -1
    if g.shape != (NGAINS, n):
        return f"expected gains of shape ({NGAINS}, n), got {g.shape}"
    for row, name in enumerate(GAINS):
        lo, hi = ranges[name]
        for j in range(n):
            why = _out_of_range(name, j, float(g[row, j]), float(lo[j]), float(hi[j]), names)
            if why:
                return why
    return None


def _out_of_range(name: str, j: int, value: float, lo: float, hi: float,
                  names: Sequence[str] | None) -> str | None:
    if math.isfinite(value) and lo <= value <= hi:
        return None
    joint = names[j] if names is not None else str(j)
    unit = GAIN_UNITS[name]
    return (f"{name} of joint {joint}: {value:.6g} {unit} is outside its safe range "
            f"{lo:.6g} .. {hi:.6g} {unit}").replace("  ", " ")


class Servo:
    """One robot's servo: ``n`` joints at ``period`` seconds (see the module text).

    ``names`` name the joints in a trip (default ``"1"`` .. ``"n"``);
    ``gains`` (a mapping name -> n values; missing ones are zero, except
    ``kff`` 1, ``tmax`` 1e9 and ``felim`` 0.1 rad and ``velhz`` 0.2/period)
    and ``ranges`` (of :func:`gain_ranges`: without them only the C
    kernel's basic ranges hold).  The servo starts holding at zero: call
    :meth:`reset` with the measured joints to close the loop there.
    """

    def __init__(self, n: int, period: float, *, names: Sequence[str] | None = None,
                 gains: dict[str, ArrayLike] | None = None,
                 ranges: dict[str, tuple[np.ndarray, np.ndarray]] | None = None):
        if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= MAX_JOINTS:
            raise NativeInputError(f"a servo has 1 to {MAX_JOINTS} joints, got {n!r}")
        if not (isinstance(period, (int, float)) and math.isfinite(period) and period > 0):
            raise NativeInputError(f"period must be a number of seconds > 0, got {period!r}")
        self.n = n
        self.period = float(period)
        self.names = tuple(str(x) for x in names) if names is not None else tuple(
            str(j + 1) for j in range(n))
        if len(self.names) != n:
            raise NativeInputError(f"names: expected {n}, got {len(self.names)}")
        self.ranges = ranges
        self.gains = np.zeros((NGAINS, n), F64)
        self.gains[_ROWS["kff"]] = 1.0
        self.gains[_ROWS["tmax"]] = 1e9
        self.gains[_ROWS["felim"]] = 0.1
        self.gains[_ROWS["velhz"]] = 0.2 / self.period
        if gains:
            self.set_gains(gains)
        self.state = np.zeros((NSTATE, n), F64)
        self.knots = np.zeros((NKNOTS, n), F64)
        #: This tick's measured joints (written by the caller, or by tick(q)).
        self.q = np.zeros(n, F64)
        #: This tick's outputs.
        self.tau = np.zeros(n, F64)
        self._keep = [ffi.from_buffer(a) for a in (self.gains, self.state, self.q, self.tau,
                                                   self.knots)]
        c = ffi.new("pyrt_servo *")
        c.n = n
        c.period = self.period
        c.gains, c.state, c.q, c.tau = (ffi.cast("double *", b) for b in self._keep[:4])
        self._knots_p = ffi.cast("double *", self._keep[4])
        self._c = c
        self._tick = lib.pyrt_servo_tick
        self._tick_at = lib.pyrt_servo_tick_at
        self._tick_board = lib.pyrt_servo_tick_board
        self._load_at = lib.pyrt_servo_load_at
        self._ff_buf = np.zeros(n, F64)
        self.reset(np.zeros(n))

    # ------------------------------------------------------------ gains

    def __getattr__(self, name: str) -> np.ndarray:
        row = _ROWS.get(name)
        if row is None:
            raise AttributeError(name)
        return self.__dict__["gains"][row]  # type: ignore[no-any-return]

    def set_gain(self, name: str, joint: int, value: float) -> None:
        """Set one gain of one joint, refused (NativeInputError, nothing
        changed) when outside its range."""
        row = _ROWS.get(name)
        if row is None:
            raise NativeInputError(f"unknown gain {name!r}; gains: {' '.join(GAINS)}")
        if isinstance(joint, bool) or not isinstance(joint, int) or not 0 <= joint < self.n:
            raise NativeInputError(f"joint must be 0..{self.n - 1}, got {joint!r}")
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise NativeInputError(f"{name}: not a number: {value!r}") from None
        trial = self.gains.copy()
        trial[row, joint] = v
        why = self._why(trial)
        if why:
            raise NativeInputError(why)
        self.gains[row, joint] = v

    def set_gains(self, gains: dict[str, ArrayLike]) -> None:
        """Set whole rows (name -> n values) at once; refused together."""
        trial = self.gains.copy()
        for name, values in gains.items():
            row = _ROWS.get(name)
            if row is None:
                raise NativeInputError(f"unknown gain {name!r}; gains: {' '.join(GAINS)}")
            trial[row] = _vector(name, values, self.n)
        why = self._why(trial)
        if why:
            raise NativeInputError(why)
        self.gains[...] = trial

    def _why(self, g: np.ndarray) -> str | None:
        basic = {
            "kp": (0.0, math.inf), "ki": (0.0, math.inf), "kd": (0.0, math.inf),
            "kv": (0.0, math.inf), "ka": (0.0, math.inf), "kff": (0.0, 1.0),
            "ilim": (0.0, math.inf), "tmax": (1e-300, math.inf), "felim": (1e-300, math.inf),
            "velhz": (1e-300, math.inf),
        }
        for row, name in enumerate(GAINS):
            for j in range(self.n):
                lo, hi = basic[name]
                if self.ranges is not None:
                    lo, hi = float(self.ranges[name][0][j]), float(self.ranges[name][1][j])
                why = _out_of_range(name, j, float(g[row, j]), lo, hi, self.names)
                if why:
                    return why
        return None

    # ------------------------------------------------------------ the loop

    def reset(self, q: ArrayLike, ff: ArrayLike | None = None, now: float | None = None) -> None:
        """Close the loop at the measured ``q``: hold there (with the
        feed-forward ``ff``, e.g. the gravity torque there), integrators and
        velocity estimate cleared, a trip cleared, outputs zero; ``now`` (s):
        the servo's clock is set there (the next tick's dt counts from it)."""
        qv = _vector("q", q, self.n)
        if now is not None:
            self._c.last = _time("now", now)
        ffp = ffi.NULL
        if ff is not None:
            self._ff_buf[...] = _vector("ff", ff, self.n)
            ffp = ffi.cast("double *", ffi.from_buffer(self._ff_buf))
        raise_for_status(lib.pyrt_servo_reset(self._c, ffi.cast("double *", ffi.from_buffer(qv)),
                                              ffp), "servo reset")

    def segment(self, duration: float, qa: ArrayLike, qda: ArrayLike, qb: ArrayLike,
                qdb: ArrayLike, qdda: ArrayLike | None = None, qddb: ArrayLike | None = None,
                ffa: ArrayLike | None = None, ffb: ArrayLike | None = None,
                start: float | None = None) -> None:
        """Load the next segment, ``duration`` seconds from knot A to knot B:
        quintic when both accelerations are given, cubic when neither is;
        ``ffa``/``ffb`` the dynamics feed-forward at the knots (None: zero);
        ``start`` as :meth:`load`.  Refused (NativeInputError) and nothing
        changed on a bad value."""
        if (qdda is None) != (qddb is None):
            raise NativeInputError("segment: give both accelerations (quintic) or neither (cubic)")
        k = self.knots
        k[...] = 0.0
        for row, name, value in ((0, "qa", qa), (1, "qda", qda), (2, "qdda", qdda),
                                 (3, "qb", qb), (4, "qdb", qdb), (5, "qddb", qddb),
                                 (6, "ffa", ffa), (7, "ffb", ffb)):
            if value is not None:
                k[row] = _vector(name, value, self.n)
        self.load(duration, quintic=qdda is not None, start=start)

    def load(self, duration: float, quintic: bool = True, start: float | None = None) -> None:
        """Load the segment already written into :attr:`knots`
        (``NKNOTS x n``, rows qa qda qdda qb qdb qddb ffa ffb), starting at
        ``start`` (s, the servo's clock: e.g. :attr:`end`, the last
        segment's end) or, by default, at the next self-clocked tick."""
        if duration.__class__ is not float and (
                not isinstance(duration, (int, float)) or isinstance(duration, bool)):
            raise NativeInputError(f"duration: expected seconds, got {duration!r}")
        order = _QUINTIC if quintic else _CUBIC
        if start is None:
            rc = lib.pyrt_servo_load(self._c, self._knots_p, float(duration), order)
        else:
            if start.__class__ is not float:
                start = _time("start", start, finite=False)
            rc = self._load_at(self._c, self._knots_p, float(duration), order, start)
        # (no duration in the words: a float's repr every segment cost more than the load)
        raise_for_status(rc, "servo segment", _load_why)

    def tick(self, q: ArrayLike | None = None, now: float | None = None) -> ServoTrip | None:
        """One servo tick on the measured joints ``q`` (None: :attr:`q` as
        the caller wrote it) at ``now`` (s, the servo's clock: the time that
        really passed since the last tick counts; None: one period later);
        the outputs are in :attr:`tau`.  Returns the trip when this tick's
        following error stopped the robot (every output zero), else None
        (while tripped, every output stays zero; :attr:`trip` says why).
        Bad input (a ``now`` before the last tick's included) raises and
        zeroes the outputs."""
        if q is not None:
            self.q[...] = q
        c = self._c
        was = c.tripped
        rc = self._tick(c) if now is None else self._tick_at(c, now)
        raise_for_status(rc, "servo tick", _tick_why)
        if c.tripped and not was:
            return self.trip
        return None

    def tick_board(self, now: float, board: ServoBoard, counts: Sequence[int]) -> ServoTrip | None:
        """A passive board's servo task in one call: the encoders ``counts``
        (unwrapped into :attr:`q`), :meth:`tick` at ``now``, then (unless
        tripped) the bounds of the measured joints and the outputs as DAC counts
        (:class:`ServoBoard`: ``board.beyond``, ``board.changed``, ``board.dac``).
        Returns the trip this tick made, or None."""
        if len(counts) != self.n or board.q is not self.q:
            raise NativeInputError(f"tick_board: {self.n} counts of this servo's board, "
                                   f"got {len(counts)}")
        c = self._c
        was = c.tripped
        raise_for_status(self._tick_board(c, now, board.c, counts), "servo tick", _tick_why)
        if c.tripped and not was:
            return self.trip
        return None

    def board_ticker(self, board: ServoBoard) -> Callable[[float, Sequence[int]], int]:
        """:meth:`tick_board` on ``board`` bound once, for a servo task's every
        tick: ``tick(now, counts)`` returns the bits of the joints whose DAC
        count changed (``board.changed``), or -1 when the tick did more than
        change DACs -- the servo tripped in it (:attr:`trip`), its dt was a
        stall (:attr:`dt`), a joint is beyond its bounds (``board.beyond``;
        ``board.changed`` says which DACs changed before it): the caller
        looks then.  Raises as :meth:`tick_board` on a refused tick."""
        if board.q is not self.q:
            raise NativeInputError("board_ticker: a board of another servo")
        n, fn, c, bc = self.n, self._tick_board, self._c, board.c

        def tick(now: float, counts: Sequence[int]) -> int:
            if len(counts) != n:
                raise NativeInputError(f"tick_board: {n} counts of this servo's board, "
                                       f"got {len(counts)}")
            raise_for_status(fn(c, now, bc, counts), "servo tick", _tick_why)
            return bc.outcome  # type: ignore[no-any-return]

        return tick

    @property
    def now(self) -> float:
        """The servo's clock: the time of the last tick (s)."""
        return float(self._c.last)

    @property
    def end(self) -> float:
        """The time (s, the servo's clock) the loaded segment ends at: where a
        trajectory's next segment starts."""
        c = self._c
        return float(c.start + c.duration)

    @property
    def dt(self) -> float:
        """The last tick's dt (s): the time that passed since the tick before."""
        return float(self._c.dt)

    @property
    def stalls(self) -> int:
        """Ticks that came more than :data:`MAX_DT_PERIODS` periods after the one
        before (their integral step bounded there)."""
        return int(self._c.stalls)

    @property
    def longest_stall(self) -> float:
        """The longest dt among :attr:`stalls` (s), 0 without any."""
        return float(self._c.stall_max)

    @property
    def trip(self) -> ServoTrip | None:
        """The trip that stopped the servo (until :meth:`reset`), or None."""
        c = self._c
        if not c.tripped:
            return None
        j = c.trip_joint
        return ServoTrip(j, self.names[j], c.trip_error, float(self.gains[_ROWS["felim"], j]))

    @property
    def tripped(self) -> bool:
        """Whether a following error stopped the servo (outputs zero until reset)."""
        return bool(self._c.tripped)

    @property
    def late(self) -> int:
        """Ticks the reference has held at the last knot B (the next segment late)."""
        return int(self._c.late)

    def _row(self, name: str) -> np.ndarray:
        return self.state[getattr(lib, f"PYRT_SERVO_{name}")]

    @property
    def q_ref(self) -> np.ndarray:
        """This tick's reference positions (a view)."""
        return self._row("QREF")

    @property
    def qd_ref(self) -> np.ndarray:
        """This tick's reference velocities (a view)."""
        return self._row("QDREF")

    @property
    def qdd_ref(self) -> np.ndarray:
        """This tick's reference accelerations (a view)."""
        return self._row("QDDREF")

    @property
    def error(self) -> np.ndarray:
        """This tick's following errors ``q_ref - q`` (a view)."""
        return self._row("ERR")

    @property
    def velocity(self) -> np.ndarray:
        """The filtered velocity estimate (a view)."""
        return self._row("VEL")

    @property
    def integral(self) -> np.ndarray:
        """The integrators, N m (a view)."""
        return self._row("INTEG")

    @property
    def feed_forward(self) -> np.ndarray:
        """This tick's interpolated dynamics feed-forward, N m (a view)."""
        return self._row("FF")

    def __repr__(self) -> str:
        return f"Servo({self.n} joints, {self.period * 1e3:g} ms)"


class ServoBoard:
    """A passive board's side of ``servo`` (:meth:`Servo.tick_board`): its
    encoders in (``counts_per_unit`` per joint radian or metre, ``counts``
    the counters as read now; a 32-bit counter wraps) and its DACs out
    (``dac_per_unit`` DAC counts per N m or N, ``full`` the full scale).
    :attr:`lo`/:attr:`hi` bound the measured joints (beyond one: the
    caller's fault; write them in place).  After a tick: the servo's ``q``
    the measured joints, :attr:`dac` the counts, :attr:`changed` a bit per
    joint whose count changed, :attr:`beyond` the first joint beyond its
    bounds or -1."""

    def __init__(self, servo: Servo, counts_per_unit: ArrayLike, counts: Sequence[int],
                 dac_per_unit: ArrayLike, full: int) -> None:
        n = servo.n
        if isinstance(full, bool) or not isinstance(full, int) or full <= 0:
            raise NativeInputError(f"full: expected a DAC full scale > 0, got {full!r}")
        cpu = _vector("counts_per_unit", counts_per_unit, n)
        per = _vector("dac_per_unit", dac_per_unit, n)
        if not (np.isfinite(cpu).all() and (cpu > 0).all() and np.isfinite(per).all()):
            raise NativeInputError("counts_per_unit (> 0) and dac_per_unit must be finite")
        if len(counts) != n:
            raise NativeInputError(f"counts: expected {n}, got {len(counts)}")
        self.counts_per_unit = cpu.copy()
        self.dac_per_unit = per.copy()
        #: The counters as last read, and their unwrapped totals.
        self.last = np.array([int(c) for c in counts], np.int64)
        self.total = self.last.copy()
        self.q = servo.q
        self.q[:] = (self.total + 0.5) / self.counts_per_unit
        self.lo = np.full(n, -np.inf)
        self.hi = np.full(n, np.inf)
        #: The DAC counts last written (this tick's after a tick).
        self.dac = np.zeros(n, np.int32)
        self.n = n
        self._keep = [ffi.from_buffer(a) for a in (self.counts_per_unit, self.q, self.lo,
                                                   self.hi, self.dac_per_unit, self.last,
                                                   self.total, self.dac)]
        c = ffi.new("pyrt_servo_board *")
        c.counts_per_unit, c.q, c.lo, c.hi, c.dac_per_unit = (
            ffi.cast("double *", b) for b in self._keep[:5])
        c.last, c.total = (ffi.cast("int64_t *", b) for b in self._keep[5:7])
        c.dac = ffi.cast("int32_t *", self._keep[7])
        c.dac_full = full
        c.beyond = -1
        #: The C struct (its ``changed`` and ``beyond`` are read after a tick).
        self.c = c
        self._encoders = lib.pyrt_servo_encoders

    def encoders(self, counts: Sequence[int]) -> None:
        """Only the encoders: ``counts`` unwrapped into the servo's ``q`` (no tick)."""
        if len(counts) != self.n:
            raise NativeInputError(f"encoders: expected {self.n} counts, got {len(counts)}")
        raise_for_status(self._encoders(self.c, self.n, counts), "servo encoders")

    @property
    def changed(self) -> int:
        """Bit j set: joint j's DAC count changed this tick."""
        return int(self.c.changed)

    @property
    def beyond(self) -> int:
        """The first joint beyond its bounds this tick, or -1."""
        return int(self.c.beyond)


def _time(name: str, value: Any, finite: bool = True) -> float:
    """A time in seconds (a number; finite unless the kernel checks it)."""
    if (isinstance(value, bool) or not isinstance(value, (int, float))
            or (finite and not math.isfinite(value))):
        raise NativeInputError(f"{name}: expected a finite time in seconds, got {value!r}")
    return float(value)


def _load_why(exc: Any) -> str:
    return ("a knot or the start is NaN or infinite, the duration is not a number of "
            "seconds > 0, or the order is neither quintic nor cubic")


def _tick_why(exc: Any) -> str:
    return ("NaN or infinity in the measured joints, a gain or the time, the time before the "
            "last tick's, or a gain outside its basic range (negative; kff outside 0..1; "
            "tmax, felim, velhz not > 0): outputs zeroed")
