"""The trajectory tick: what the trajectory task calls once per period.

:class:`Evaluator` holds one arm's queued motion.  A record is planned
outside the loop: :meth:`Evaluator.snapshot` copies what a plan needs
(bounded), :meth:`Evaluator.plan` plans in the caller's thread with a chain
of its own, and :meth:`Evaluator.commit` (bounded, the loop's side) checks
the snapshot still holds and hands the pieces over (:meth:`Evaluator.queue`
does the three); :meth:`Evaluator.tick` evaluates one sample and returns a
:class:`Knot`: joint position, velocity and acceleration (for the servo's
quintic interpolation), T6, the running record's progress, and the events
of the tick.  A tick's work is bounded: one polynomial, one inverse (seeded
at the last solution; the closed form with the configuration held when the
chain has one), a few vector operations.

Each tick computes the sample one period ahead and hands out the knot
before it, so the knot's velocity and acceleration are the central
differences of three solved samples (exact for joint polynomials to
rounding; for a Cartesian line, the joints' true motion).

**A motion that ends while moving** (a plug-in joint function whose last
sample has velocity, :meth:`Evaluator.queue_function`) is never
extrapolated: the evaluator brakes it to rest within the acceleration
limits (Paul's transition to rest from the last position and velocity); if
that rest would be beyond a joint limit it raises :class:`MotionFault`
instead, which the trajectory task turns into the robot's fault.

**Comply** (a record's :class:`~pyrt.motion.Comply`): while its segment
runs, each tick turns the wrist's force into the tool frame (the
equation's TOOL), low-passes it, and moves an offset of the tool along the
complied axes by the admittance (gain x force error, within the record's
speed and travel); the samples are the planned pose with that offset, in
the tool frame, so the other directions keep the path.  When the segment
ends (or is stopped) the offset stays: the arm holds where the force put
it, and the next record, queued only then, starts from there.

**A moving frame the arm cannot follow**: when a moving frame (a
conveyor) carries the target point beyond the arm's reach, or where a
joint would need more than its velocity limit to follow it, that sample
continues the joints' velocity and the next tick brakes them to rest, the
record ending with a code that says why (elsewhere a sample without an
inverse is a :class:`MotionFault`).

**stop** brakes along the path: the trajectory's time is slowed to a halt
by a smooth step whose length keeps every joint's acceleration within its
limit, so a Cartesian segment's tool stays on its line.  In a moving frame
(the arm following a conveyor) the path itself moves, so there the joints
are braked to rest from their position and velocity (001's extrapolation).
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt

from pyrt.frames import TransformType
from pyrt.kinematics import GRAVITY, Chain, JointSets
from pyrt.motion._comply import ComplyLoop
from pyrt.motion._pieces import CART, FUNC, JOINT, FrameTracker, Piece, transition_coeffs
from pyrt.motion._queueing import Planned, Queueing, QueueSnapshot, StalePlan
from pyrt.motion.planner import Limits, Planner, Segment, Tail
from pyrt.motion.record import BufferMode, MotionSpec, Move, RecordError, Termination

__all__ = ["Evaluator", "Knot", "MotionFault", "Planned", "QueueSnapshot", "StalePlan"]

Matrix = npt.NDArray[np.float64]
Vector = npt.NDArray[np.float64]

#: A joint speed below which a motion counts as at rest (rad/s or m/s).
REST_SPEED = 1e-6


class MotionFault(RuntimeError):
    """The trajectory cannot go on (no inverse at a tick, a rest beyond a
    joint limit): the trajectory task's caller stops the robot."""


class Knot(NamedTuple):
    """One trajectory sample: ``q``, ``qd``, ``qdd`` (n,), ``t6`` (4, 4) at
    time ``t`` (s since the evaluator began) and sample number ``sample``;
    the running record (``move``, None when idle) and its ``progress``;
    ``events``: (word, move) pairs of the tick (``"reached"``, ``"stopped"``,
    ``"aborted"``, a monitor's word, ``"force"``); ``period``: the
    trajectory period from here; ``mass`` carried and ``payload_torque`` (n,),
    the joint torques that hold it against gravity.  Immutable (a named tuple:
    made every trajectory tick, so made cheaply)."""

    sample: int
    t: float
    q: Vector
    qd: Vector
    qdd: Vector
    t6: Matrix
    progress: float
    move: Move | None
    events: tuple[tuple[str, Move], ...]
    period: float
    mass: float
    payload_torque: Vector | None


class Evaluator(Queueing):
    """One arm's queued motion and its trajectory tick (see the module doc).

    ``chain`` and ``limits`` describe the arm, ``q0`` where it rests now,
    ``period`` the trajectory period (s).  ``force_sensor`` says whether
    :meth:`tick` will be given the wrist's wrench (then records may carry
    force limits).  ``sets``: the arm's joint sets (records may name some).
    """

    def __init__(self, chain: Chain, limits: Limits, q0: Sequence[float] | Vector, *,
                 period: float = 0.01, force_sensor: bool = False,
                 sets: JointSets | None = None) -> None:
        if not (math.isfinite(period) and 0.001 <= period <= 0.1):
            raise ValueError(f"period: expected 0.001 .. 0.1 s, got {period!r}")
        self.chain = chain
        self.limits = limits
        self.tracker = FrameTracker(period)
        self.planner = Planner(chain, limits, self.tracker, sets)
        q = np.array(q0, dtype=float)
        why = chain.limit_violation(q)
        if why:
            raise ValueError(f"q0: {why}")
        self.force_sensor = force_sensor
        self._lock = threading.Lock()
        #: Plans made outside the loop use a chain of their own, one plan at a time.
        self._plan_lock = threading.Lock()
        self._side: Planner | None = None
        #: Changes whenever something is queued or stopped (a snapshot's validity).
        self._generation = 0
        self._period = period
        self._pieces: list[Piece] = []
        self._segs: list[Segment] = []
        self._k = 0
        t6 = chain.fk(q)
        # samples n-1, n (the knot handed out next), n+1 (computed ahead)
        self._q = [q.copy(), q.copy()]
        self._t6 = [t6.copy(), t6.copy()]
        self._tp = [0.0, 0.0]  # trajectory (path) time of those samples
        self._h = period  # the time between the two samples held
        self._n = 0
        self._time = 0.0
        self._count = 0
        self._config = self.planner.config_of(q)
        self._equation: Any = None
        self._stop: tuple[str, Move | None] | None = None
        #: While stopping: the rate at which the trajectory's time runs (1 -> 0).
        self._sigma: float | None = None
        self._vp: Vector | None = None
        self._ap: Vector = np.zeros(chain.n)
        self._first_brake = False
        self._events: list[tuple[str, Move]] = []
        self._mass = 0.0
        self._braked = False
        self._watched: list[Any] = []
        #: Comply: the running comply segment, the tool's offset from its path
        #: (tool frame, m) and the filtered force it exerts (tool frame, N).
        self._comply = ComplyLoop()
        self._fk_q = np.zeros(chain.n)
        #: :attr:`wants_wrench`'s last answer and what it was given for.
        self._wants: tuple[tuple[int, ...] | None, bool] = (None, False)

    # -- queueing (the caller's thread) ---------------------------------------------------
    @property
    def period(self) -> float:
        return self._period

    @property
    def sample(self) -> int:
        """The sample number of the knot the next :meth:`tick` hands out (its
        functional transforms are evaluated one sample ahead of it)."""
        return self._n

    @property
    def idle(self) -> bool:
        """True when nothing is queued or running and the arm is at rest."""
        with self._lock:
            return (not self._pieces or self._k >= len(self._pieces)) and self._sigma is None

    @property
    def wants_wrench(self) -> bool:
        """Whether a record queued or running (or a piece still to run) has a force
        limit or a comply spec: without one, :meth:`tick` does the same with or
        without the wrist's wrench (the caller may leave the sensor unread)."""
        with self._lock:
            # what is queued changes only with the generation, the pieces passed and the
            # lists of pieces and records: the answer is kept for those
            key = (self._generation, self._k, len(self._pieces), id(self._pieces),
                   len(self._segs), id(self._segs))
            if key == self._wants[0]:
                return self._wants[1]
            wants = False
            for s in self._segs:
                if s.move.spec.force_limits is not None or s.move.spec.comply is not None:
                    wants = True
                    break
            else:
                for piece in self._pieces[self._k:]:
                    seg = piece.seg
                    if seg is not None and (seg.move.spec.force_limits is not None
                                            or seg.move.spec.comply is not None):
                        wants = True
                        break
            self._wants = (key, wants)
            return wants

    def queue_function(self, fn: Callable[[float], Sequence[float]], duration: float,
                       name: str = "function") -> Move:
        """A plug-in joint motion: ``fn(t)`` gives the joint values for ``0 <= t
        <= duration`` (it should start where the arm is).  Queued after the
        motion before has come to rest; what happens when it ends moving is
        the rule in the module doc."""
        if not (math.isfinite(duration) and duration > 0):
            raise RecordError(f"duration: expected a time > 0 s, got {duration!r}")
        with self._lock:
            tail = self._tail()
            t0 = max(tail.now + 2 * self._period,
                     self._pieces[-1].t1 if self._pieces and tail.last is not None else 0.0)
            q0 = np.asarray(fn(0.0), dtype=float)
            if q0.shape != (self.chain.n,):
                raise RecordError(f"{name}: gives {q0.shape} values; the arm has {self.chain.n}")
            move = Move(MotionSpec(name=name), self._count)
            self._count += 1
            seg = Segment(move, FUNC, _no_frames(self.planner),
                          None, self._period, t0, t0 + duration, 0.0, 0.0, q0, None,
                          np.zeros(self.chain.n), None, None)
            seg.pieces = [Piece(FUNC, t0, t0 + duration, t0, np.zeros((2, self.chain.n)), seg,
                                fn=fn)]
            seg.t_begin, seg.t_reached = t0, t0 + duration
            seg.rested = True
            self._pieces.append(seg.pieces[0])
            self._segs.append(seg)
            self._generation += 1
            return move

    def _splice(self, seg: Segment, tail: Tail) -> None:
        how = seg.how
        t0 = seg.pieces[0].t0
        last = tail.last
        if how is BufferMode.BLENDING and last is not None:
            # the previous line runs on to where the transition begins; its way to
            # rest (not begun: the planner checked) is dropped
            line, rest = last.pieces[-2], last.pieces[-1]
            longer = line.copy_until(t0)
            self._pieces = [longer if p is line else p for p in self._pieces if p is not rest]
            last.pieces = [*last.pieces[:-2], longer]
            last.t_reached = seg.t_c
            last.rested = False
        elif how is BufferMode.ABORTING and last is not None:
            keep: list[Piece] = []
            for p in self._pieces:
                if p.t1 <= t0:
                    keep.append(p)
                elif p.t0 < t0:
                    keep.append(p.copy_until(t0))
            for s in self._segs:
                if s.move.code is None and s.t_reached > t0 + 1e-12:
                    self._events.append(("aborted", s.move))
                    self._finish(s, Termination.ABORTED)
            self._k = min(self._k, len(keep))
            self._pieces = keep
        self._pieces.extend(seg.pieces)
        self._segs.append(seg)
        seg.move.blend_error = seg.blend_error
        seg.move.buffer = seg.how.value
        seg.move.note = "; ".join(seg.refusals)

    # -- stopping ---------------------------------------------------------------------
    def stop(self, code: str = Termination.STOPPED) -> None:
        """Brake to rest (along the path) and drop what is queued."""
        with self._lock:
            self._generation += 1
            if self._stop is None:
                self._stop = (str(code), None)

    # -- the tick ----------------------------------------------------------------------
    def tick(self, wrench: Sequence[float] | Vector | None = None) -> Knot:
        """Evaluate one sample; the knot of the sample before it (module doc)."""
        with self._lock:
            return self._tick(wrench)

    def _tick(self, wrench: Any) -> Knot:
        dt = self._period
        n_next = self._n + 1
        if self._stop is not None and self._sigma is None:
            self._begin_stop()
        if self._k < len(self._pieces):
            seg = self._pieces[self._k].seg
            rate = seg.move.spec.sample_rate if seg is not None else None
            if rate and self._tp[-1] + dt >= self._pieces[self._k].t0 and abs(
                    1.0 / rate - dt) > 1e-12:
                # the record's sample rate, from its first sample on
                dt = self._period = 1.0 / rate
                self.tracker.period = dt
        for tr in self._watched:
            self.tracker.evaluate(tr, n_next)
        if wrench is not None and self._k < len(self._pieces) and self._sigma is None \
                and self._stop is None:
            piece = self._pieces[self._k]
            seg = piece.seg
            if seg is not None and seg.move.spec.comply is not None and piece.frames:
                self._comply.update(seg, piece.frames.parts(n_next)[2], wrench, dt)
        sigma = 1.0
        if self._sigma is not None:
            sigma = self._brake_rate(dt)
        t_next = self._tp[-1] + sigma * dt
        q_next, t6_next = self._sample(t_next, n_next)
        if self._sigma is not None and sigma == 0.0:
            self._end_stop()
        q0, q1 = self._q
        h1, h2 = self._h, dt
        hs = h1 + h2
        # the central differences on plain floats (the same operations, in the same
        # order, as on the arrays: the same roundings), two arrays made of them
        xs, ys, zs = q0.tolist(), q1.tolist(), q_next.tolist()
        both = np.array([(z - x) / hs for x, z in zip(xs, zs, strict=True)]
                        + [2.0 * ((z - y) / h2 - (y - x) / h1) / hs
                           for x, y, z in zip(xs, ys, zs, strict=True)])
        n_q = len(xs)
        qd, qdd = both[:n_q], both[n_q:]
        t_knot = self._tp[1]
        knot_q, knot_t6 = q1, self._t6[1]
        # slide the window
        self._q = [q1, q_next]
        self._t6 = [knot_t6, t6_next]
        self._tp = [t_knot, t_next]
        self._h = dt
        n = self._n
        self._n = n_next
        knot_time = self._time
        self._time += dt
        # events, progress, the running record
        move, progress, seg = self._progress(t_knot, knot_q, knot_t6)
        if self._k > 4:
            # a long run keeps its tick bounded: pieces and records that are over go
            # (the last two pieces stay for a plan that looks back one sample)
            del self._pieces[:self._k - 2]
            self._k = 2
            keep = [s for s in self._segs[:-1] if s.move.code is None or s.tracking]
            self._segs = [*keep, self._segs[-1]] if self._segs else []
        mass = seg.move.spec.mass if seg is not None else self._mass
        self._mass = mass
        tau = None
        if mass > 0.0:
            jac = self.chain.jacobian(knot_q)
            tau = -jac[:3].T @ (mass * np.asarray(GRAVITY))
        events = tuple(self._events)
        self._events.clear()
        if self._sigma is None:
            self._ap = qdd
        knot = Knot(n, knot_time, knot_q, qd, qdd, knot_t6, progress, move, events, dt,
                    mass, tau)
        if seg is not None and self._stop is None:
            spec = seg.move.spec
            if spec.force_limits is not None and wrench is not None:
                w = np.abs(np.asarray(wrench, dtype=float))
                if (w > np.asarray(spec.force_limits)).any():
                    self._stop = (Termination.FORCE, seg.move)
            if spec.monitor is not None and self._stop is None:
                word = spec.monitor(knot)
                if word:
                    self._stop = (str(word), seg.move)
        return knot

    def _sample(self, t: float, n: int) -> tuple[Vector, Matrix]:
        pieces = self._pieces
        while self._k < len(pieces) and t >= pieces[self._k].t1:
            if self._k == len(pieces) - 1 and self._tp[-1] < pieces[self._k].t1:
                # the last piece's end, exactly, before the plan counts as over
                t = pieces[self._k].t1
                break
            self._k += 1
        if self._k >= len(pieces):
            return self._at_end(t, n)
        piece = pieces[self._k]
        if t < piece.t0:
            return self._q[-1], self._t6[-1]
        if piece.runtime is not None:
            self._make_runtime(piece, t, n)
        seed = self._q[-1]
        if piece.space is JOINT or piece.space == JOINT:
            q = piece.x(t)
            fk_q = self._fk_q  # one array the chain's forward kinematics stays bound to
            fk_q[...] = q
            return q, self.chain.fk(fk_q)
        if piece.space == CART:
            frames = piece.frames
            assert frames is not None
            for tr in frames.live:
                self.tracker.evaluate(tr, n)
            t6 = frames.t6(piece.pose(t), n)
            if piece.seg is not None and piece.seg is self._comply.seg:
                t6 = self._comply.apply(t6, frames.parts(n)[2])
            q_opt = self.planner.solve(t6, seed, piece.config)
            if frames.moving and piece.seg is not None and self._stop is None \
                    and self._sigma is None:
                why = self._cannot_follow(q_opt, t6, seed, piece.config)
                if why:
                    # the moving frame carries the point where the arm cannot follow:
                    # this sample goes on at the joints' velocity, the next tick brakes
                    self._stop = (f"stopped: the moving frame carried the tool's point "
                                  f"where the arm cannot follow ({why}); braked to rest",
                                  piece.seg.move)
                    q0, q1 = self._q
                    q_ext = q1 + (q1 - q0) * (self._period / self._h)
                    return q_ext, self.chain.fk(q_ext)
            if q_opt is None:
                raise MotionFault(f"no inverse at t = {t:.3f} s: "
                                  f"{self.planner.why(t6, seed, piece.config)}")
            return q_opt, t6
        assert piece.fn is not None
        q = np.asarray(piece.fn(t - piece.origin), dtype=float)
        return q, self.chain.fk(q)

    def _cannot_follow(self, q: Vector | None, t6: Matrix, seed: Vector,
                       config: str | None) -> str:
        """Why the arm cannot follow a moving frame's sample (no inverse, or a
        joint over its velocity limit to reach it), or ''."""
        if q is None:
            return f"out of reach: {self.planner.why(t6, seed, config)}"
        over = np.abs(q - self._q[1]) / self._period > self.planner.vmax
        if not over.any():
            return ""
        return (f"joint {self.chain.joints[int(np.argmax(over))].name} would go beyond "
                "its velocity limit to follow it")

    @property
    def comply_force(self) -> Vector:
        """The force the tool exerts (N, tool frame; filtered) as the comply loop
        last saw it (zeros before any comply record)."""
        return self._comply.force.copy()

    def _make_runtime(self, piece: Piece, t: float, n: int) -> None:
        """A transition that involves a moving frame: made now, from the last
        two samples in the new segment's space (module doc of the planner)."""
        space, x_b, v_b, tau = piece.runtime
        piece.runtime = None
        dt = self._period
        if space == JOINT:
            xa_1, xa_0 = self._q[-1], self._q[0]
        else:
            frames = piece.frames
            assert frames is not None and piece.r_c is not None and piece.p_c is not None
            from pyrt.motion._geom import drive_of

            xa_1 = drive_of(frames.pos(self._t6[-1], n - 1), piece.r_c, piece.p_c)
            xa_0 = drive_of(frames.pos(self._t6[0], n - 2), piece.r_c, piece.p_c)
        v_a = (xa_1 - xa_0) / dt
        x_a = xa_1 + v_a * (piece.t0 - self._tp[-1])
        piece.c = transition_coeffs(x_a, v_a, x_b, v_b, tau)
        piece.linear = False

    def _at_end(self, t: float, n: int) -> tuple[Vector, Matrix]:
        """The plan has run out: at rest, or brake a motion that ended moving."""
        q1, q0 = self._q[-1], self._q[0]
        v = (q1 - q0) / self._period
        ended = self._pieces[-1] if self._pieces else None
        if ended is None or ended.space != FUNC or float(np.max(np.abs(v))) <= REST_SPEED \
                or self._braked:
            # a planned segment ends at rest exactly where it ends
            self._braked = False
            return q1, self._t6[-1]
        amax = self.planner.amax
        tau = max(float(np.max(0.75 * np.abs(v) / amax)), self._period)
        rest = q1 + v * tau
        why = self.chain.limit_violation(rest)
        if why:
            raise MotionFault(f"the motion ended moving and cannot be brought to rest within "
                              f"the joint limits ({why})")
        t0 = self._tp[-1]
        piece = Piece(JOINT, t0, t0 + 2 * tau, t0, transition_coeffs(q1, v, rest,
                                                                     np.zeros_like(v), tau), None)
        self._pieces.append(piece)
        self._braked = True
        return self._sample(t, n)

    def _begin_stop(self) -> None:
        assert self._stop is not None
        code, by = self._stop
        q0, q1 = self._q
        dt = self._period
        v = (q1 - q0) / dt
        piece = self._pieces[self._k] if self._k < len(self._pieces) else None
        moving_frame = piece is not None and (
            piece.space == FUNC or (piece.frames is not None and piece.frames.moving))
        told = False
        for s in self._segs:
            if s.move.code is None:
                word = code if (by is None or s.move is by) else Termination.STOPPED
                self._events.append((word, s.move))
                self._finish(s, word)
                told = told or s.move is by
        if by is not None and not told:
            # a record that had reached its point and tracked a moving frame: its
            # code stays 'reached', the stop is said all the same
            self._events.append((code, by))
        if piece is None or float(np.max(np.abs(v))) <= REST_SPEED:
            self._pieces, self._k, self._segs = [], 0, []
            self._stop = None
            return
        if moving_frame:
            tau = max(float(np.max(0.75 * np.abs(v) / self.planner.amax)), dt)
            t0 = self._tp[-1]
            brake = Piece(JOINT, t0, t0 + 2 * tau, t0,
                          transition_coeffs(q1, v, q1 + v * tau, np.zeros_like(v), tau), None)
            self._pieces, self._k, self._segs = [brake], 0, []
            self._stop = None
            return
        self._sigma = 1.0
        self._vp = v
        self._first_brake = True

    def _brake_rate(self, dt: float) -> float:
        """The next sample's time rate while stopping: lowered as fast as the
        joints' acceleration limits allow (a fifth in reserve), given the
        path's velocity and acceleration estimated from the last samples."""
        sig = self._sigma
        assert sig is not None
        q0, q1 = self._q
        dtp = self._tp[-1] - self._tp[0]
        amax = self.planner.amax
        vp = self._vp if self._vp is not None else np.zeros_like(q1)
        ap = self._ap
        if dtp > 1e-4 and not self._first_brake:
            v_new = (q1 - q0) / dtp
            ap = np.clip((v_new - vp) / dtp, -amax, amax)
            vp = v_new
        self._first_brake = False
        self._vp, self._ap = vp, ap
        speed = np.abs(vp)
        # the path's own acceleration against the motion uses up part of the limit
        # (it is not counted on when it helps: it may end within the next tick)
        against = np.maximum(-sig * sig * ap * np.sign(vp), 0.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            rate = np.where(speed > 1e-12, (0.8 * amax - against) / speed, np.inf)
        r = max(float(np.min(rate)), 0.0)
        out = max(0.0, sig - r * dt)
        self._sigma = out
        return out

    def _end_stop(self) -> None:
        self._sigma = None
        self._stop = None
        self._pieces, self._k, self._segs = [], 0, []

    def _finish(self, seg: Segment, code: str, q: Vector | None = None,
                t6: Matrix | None = None) -> None:
        q = self._q[-1] if q is None else q
        t6 = self._t6[-1] if t6 is None else t6
        self._end_segment(seg, t6)
        seg.move.finish(code, t6.copy(), q.copy())

    def _end_segment(self, seg: Segment, t6: Matrix) -> None:
        spec = seg.move.spec
        eq = spec.equation
        if eq is None:
            return
        if eq.t6.type in (TransformType.VARB, TransformType.HOLD):
            eq.t6.set(t6)
        target = spec.update_transform()
        if target is not None:
            target.set(eq.solve(target))
        # hold transforms take their next value at the end of the segment (001)
        eq.end_segment()

    def _progress(self, t: float, q: Vector, t6: Matrix
                  ) -> tuple[Move | None, float, Segment | None]:
        running: Segment | None = None
        for s in self._segs:
            if s.move.code is None and t >= s.t_reached - 1e-12:
                self._config = self.planner.config_of(q) if s.kind != FUNC else self._config
                self._events.append((Termination.REACHED.value, s.move))
                self._finish(s, Termination.REACHED, q, t6)
            elif s.move.code is None and running is None and t >= s.t_begin:
                running = s
        if running is None:
            # a record that reached its end but follows a moving frame still runs
            live = [s for s in self._segs if s.tracking]
            if live and self._k < len(self._pieces):
                return live[-1].move, 1.0, live[-1]
            return None, 0.0, None
        span = max(running.t_reached - running.t_begin, 1e-12)
        p = min(max((t - running.t_begin) / span, 0.0), 1.0 - 1e-9)
        running.move.progress = p
        eq = running.move.spec.equation
        if eq is not None:
            eq.progress = p
        return running.move, p, running


def _no_frames(planner: Planner) -> Any:
    from pyrt.motion._pieces import Frames

    return Frames(None, planner.tracker)
