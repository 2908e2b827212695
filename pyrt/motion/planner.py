"""Planning a motion record when it is queued (outside the loop).

:class:`Planner` holds the arm (a :class:`~pyrt.kinematics.Chain`) and its
limits; :meth:`Planner.plan` turns one :class:`~pyrt.motion.MotionSpec` into
the pieces that follow the plan already queued (:mod:`pyrt.motion._pieces`),
and checks them by sampling at the trajectory period before anything runs:

* the segment's time is the least that keeps every joint velocity, the
  Cartesian velocities (translation and rotation), the record's ``speed``
  and ``max_diff`` within their limits, or the record's ``segment_time``;
* each transition's half-time ``tau`` is the least that keeps the
  accelerations (joint, or Cartesian for a Cartesian transition) within
  the limits, or the record's ``transition``;
* the sampled joint velocities and accelerations are checked (a joint path
  of a Cartesian line curves): a segment or a transition that exceeds them
  is slowed and sampled again;
* a Cartesian segment that would pass a singularity (the Jacobian's
  smallest singular value under ``Limits.singular``), leave the reach or
  cross a joint limit is refused, naming where (the fraction of the
  segment, the tool position, the joint).

The sampling, the limits' checks and the refusals are :mod:`pyrt.motion._checks`.

Transitions (001, Paul): the space of a transition is the new segment's:
joint -> joint and Cartesian -> joint in joint space (the joint values at A
extrapolated with their velocity, 001's cart -> joint), joint -> Cartesian
and Cartesian -> Cartesian in the new equation's drive space (T6 at A
extrapolated along its drive parameters, 001's joint -> cart).  With a
moving frame on either side the transition is made when it starts, from the
last samples expressed in the new equation's frames: the frames' extra
velocity is then part of the start velocity, which is 001's third-order
polynomial added to the quartic (see ``docs/arm-motion.md``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from pyrt.errors import ConfigError
from pyrt.kinematics import Chain, JointSets
from pyrt.motion._checks import (
    Refused,
    Slow,
    check_segment,
    end_of,
    kept_joint_time,
    tool_travel,
)
from pyrt.motion._geom import drive_of, pose_of
from pyrt.motion._inverse import PreparedInverse
from pyrt.motion._pieces import (
    CART,
    JOINT,
    Frames,
    FrameTracker,
    Piece,
    line_coeffs,
    norm,
    transition_coeffs,
)
from pyrt.motion.record import BufferMode, Mode, MotionSpec, Move, RecordError

__all__ = ["Limits", "Planner", "Segment"]

Matrix = npt.NDArray[np.float64]
Vector = npt.NDArray[np.float64]

#: Plan-time finite-difference step (s) for a state's velocity.
_H = 1e-4
#: How many times a plan is slowed and sampled again before it is refused.
_TRIES = 20


#: The share of the acceleration limits a transition is planned for: its half-time
#: makes Paul's quartic peak there.  A sampled second difference is a weighted mean
#: of the acceleration over two periods, never above that peak, so a joint
#: transition keeps the sampled check's 0.995 ``amax`` by construction (and is
#: planned once, not slowed and sampled again).
A_PLAN = 0.99


def _joint_rates(chain: Chain, frames: Frames, dv: Vector, q: Vector) -> Vector:
    """The joint velocities of a drive-space velocity ``dv`` at ``q``: the tool's twist
    in the world through the Jacobian's pseudo-inverse (for a square Jacobian that is
    not singular its inverse: one solve, not a decomposition)."""
    pre = frames.parts(None)[0][:3, :3]
    t6 = chain.fk(q)
    tool = frames.tool(t6, None)
    w = pre @ dv[3:]
    (wx, wy, wz), (rx, ry, rz) = w.tolist(), (tool[:3, 3] - t6[:3, 3]).tolist()
    v = pre @ dv[:3] - np.array([wy * rz - wz * ry, wz * rx - wx * rz,
                                 wx * ry - wy * rx])  # w x r, on floats
    jac, twist = chain.jacobian(q), np.concatenate([v, w])
    if jac.shape[0] == jac.shape[1]:
        try:
            return np.asarray(np.linalg.solve(jac, twist), dtype=float)
        except np.linalg.LinAlgError:
            pass
    return np.asarray(np.linalg.pinv(jac) @ twist, dtype=float)


@dataclass(frozen=True)
class Limits:
    """The arm's limits: joint velocity ``vmax`` and acceleration ``amax``
    (n,), the tool's Cartesian velocity ``v_cart`` (m/s) and ``w_cart``
    (rad/s) and acceleration ``a_cart`` (m/s^2) and ``alpha_cart``
    (rad/s^2); ``singular``: the smallest singular value of the Jacobian a
    Cartesian segment may pass; ``payload``: the largest mass a record may
    carry (kg)."""

    vmax: tuple[float, ...]
    amax: tuple[float, ...]
    v_cart: float = 0.5
    w_cart: float = 1.5
    a_cart: float = 2.0
    alpha_cart: float = 6.0
    singular: float = 0.02
    payload: float = math.inf

    def __post_init__(self) -> None:
        v = np.asarray(self.vmax, dtype=float)
        a = np.asarray(self.amax, dtype=float)
        if v.shape != a.shape or v.ndim != 1 or (v <= 0).any() or (a <= 0).any() or not (
                np.isfinite(v).all() and np.isfinite(a).all()):
            raise ValueError("Limits: vmax and amax are one finite value > 0 per joint")
        for name in ("v_cart", "w_cart", "a_cart", "alpha_cart"):
            x = getattr(self, name)
            if not (math.isfinite(x) and x > 0):
                raise ValueError(f"Limits: {name} must be finite and > 0, got {x!r}")
        object.__setattr__(self, "vmax", tuple(float(x) for x in v))
        object.__setattr__(self, "amax", tuple(float(x) for x in a))


@dataclass
class Segment:
    """A planned record: its pieces and the times that matter."""

    move: Move
    kind: str
    frames: Frames
    config: str | None
    period: float
    #: When the straight line passes its start point and its end point.
    t_c: float
    t_e: float
    tau_in: float
    tau_out: float
    start: Any
    end: Any
    velocity: Vector
    r_c: Matrix | None
    p_c: Vector | None
    pieces: list[Piece] = field(default_factory=list)
    #: When the first piece begins and when the record counts as reached.
    t_begin: float = 0.0
    t_reached: float = 0.0
    q_end: Vector | None = None
    t6_end: Matrix | None = None
    #: True when the record ended with a rest (buffered, or a blend refused).
    rested: bool = True
    #: The tool position at the start corner and the largest blend error there (m).
    blend_error: float = 0.0
    tracking: bool = False
    #: The buffer mode the segment was planned with (a blend that could not be
    #: made within the limits and the tolerance is buffered), and why not.
    how: BufferMode = BufferMode.BUFFERED
    #: The line's start in its space, and the start state A when not at rest.
    x0: Any = None
    state_a: Any = None
    refusals: list[str] = field(default_factory=list)


@dataclass
class Tail:
    """What a new record starts from: the plan queued so far, seen at ``now``."""

    now: float
    sample: int
    period: float
    q: Vector
    t6: Matrix
    pieces: list[Piece]
    last: Segment | None
    equation: Any = None
    config: str | None = None


class Planner:
    """Plans records for one chain (see the module doc)."""

    def __init__(self, chain: Chain, limits: Limits, tracker: FrameTracker,
                 sets: JointSets | None = None) -> None:
        if len(limits.vmax) != chain.n:
            raise ValueError(f"Limits give {len(limits.vmax)} joints; chain {chain.name!r} "
                             f"has {chain.n}")
        if sets is not None and sets.joint_names != chain.joint_names:
            raise ValueError(f"joint sets {sets!r}: joints {list(sets.joint_names)} are not "
                             f"chain {chain.name!r}'s {list(chain.joint_names)}")
        #: The arm's joint sets: a record naming some moves only their joints.
        self.sets = sets
        self.chain = chain
        self.limits = limits
        self.vmax = np.array(limits.vmax)
        #: The velocities planned for: just under the limits (the sampled check
        #: keeps a reserve for rounding).
        self.vplan = 0.998 * self.vmax
        self.amax = np.array(limits.amax)
        self.aplan = A_PLAN * self.amax  # the accelerations planned for
        self.tracker = tracker
        self.closed = chain.closed_form
        #: The closed form's prepared inverse for this planner's thread (or None).
        self._fast = PreparedInverse.of(self.closed)
        self._jt_last: tuple[tuple[Any, ...], float] | None = None  # (see kept_joint_time)

    # -- the inverse ------------------------------------------------------------------
    def solve(self, t6: Matrix, seed: Vector, config: str | None) -> Vector | None:
        """Joint values of ``t6`` nearest ``seed`` (the closed form in
        ``config`` when the chain has one), or None."""
        if (fast := self._fast) is not None and config is not None and fast.here():
            return fast(t6, seed, config)
        if self.closed is not None and config is not None:
            try:
                q = self.closed.solve(t6, config, seed)  # type: ignore[call-arg]
            except TypeError:  # a closed form that takes no seed
                q = self.closed.solve(t6, config)
            return None if q is None else np.asarray(q, dtype=float)
        r = self.chain.ik(t6, seed)
        if not r.ok:
            return None
        return r.q.copy()

    def why(self, t6: Matrix, seed: Vector, config: str | None) -> str:
        if self.closed is not None and config is not None and hasattr(self.closed, "reason"):
            reason = self.closed.reason(t6, config)
            if reason:
                return str(reason)
        r = self.chain.ik(t6, seed)
        return f"no inverse (residual {r.residual:.3g} after {r.iterations} iterations)"

    def config_of(self, q: Vector) -> str | None:
        return None if self.closed is None else self.closed.config_of(q)

    # -- joint sets ------------------------------------------------------------------
    def moved_joints(self, spec: MotionSpec) -> list[int] | None:
        """The joint indices a record naming joint sets moves (None: every
        joint); RecordError for sets the arm does not have, or a record that
        cannot move only some joints."""
        if spec.sets is None:
            return None
        if self.sets is None:
            raise RecordError(f"sets: refused: chain {self.chain.name!r} declares no joint sets "
                              f"(a record naming {', '.join(spec.sets)} cannot be planned)")
        try:
            idx = list(self.sets.indices(spec.sets))
        except ConfigError as exc:
            raise RecordError(f"sets: {exc}") from None
        if spec.target is None:
            raise RecordError("sets: a record naming joint sets moves to a joint target "
                              "(target=, the named sets' joint values)")
        if len(spec.target) != len(idx):
            raise RecordError(f"target: {len(spec.target)} joint values; joint set(s) "
                              f"{', '.join(spec.sets)} have {len(idx)}")
        return idx

    # -- evaluating pieces at plan time -------------------------------------------------
    def sample_of(self, tail: Tail, t: float) -> float:
        """The (fractional) sample number of trajectory time ``t``, for a moving
        frame's predicted value."""
        return tail.sample + (t - tail.now) / tail.period

    def q_of(self, piece: Piece, t: float, seed: Vector, sample: float) -> Vector | None:
        if piece.space == JOINT:
            return piece.x(t)
        if piece.space == CART:
            assert piece.frames is not None
            pos = piece.pose(t)
            return self.solve(piece.frames.t6(pos, sample), seed, piece.config)
        assert piece.fn is not None
        return np.asarray(piece.fn(t - piece.origin), dtype=float)

    @staticmethod
    def piece_at(pieces: list[Piece], t: float) -> Piece | None:
        for p in pieces:
            if p.t0 - 1e-9 <= t < p.t1:
                return p
        return pieces[-1] if pieces and t >= pieces[-1].t0 else None

    def _state(self, piece: Piece, t: float, seed: Vector, tail: Tail, space: str,
               frames: Frames, ref: tuple[Matrix, Vector] | None) -> tuple[Vector, Vector, Vector]:
        """(x, v, q) of ``piece`` (extrapolated if ``t`` is past it) at ``t``, in
        ``space`` (drive coordinates about ``ref`` through ``frames``)."""
        xs = []
        q0 = seed
        for dt in (-_H, 0.0, _H):
            n = self.sample_of(tail, t + dt)
            q = self.q_of(piece, t + dt, q0, n)
            if q is None:
                raise Refused(f"the motion queued before cannot be followed at {t:.3f} s")
            if space == JOINT:
                xs.append(q)
            else:
                assert ref is not None
                pos = frames.pos(self.chain.fk(q), n)
                xs.append(drive_of(pos, ref[0], ref[1]))
            if dt == 0.0:
                q0 = q
        return xs[1], (xs[2] - xs[0]) / (2 * _H), q0

    # -- the plan ---------------------------------------------------------------------
    def plan(self, spec: MotionSpec, tail: Tail, move: Move, *,
             force_sensor: bool) -> Segment:
        """The segment of ``spec`` after ``tail``; RecordError names what is refused."""
        try:
            return self._plan(spec, tail, move, force_sensor)
        except Refused as exc:
            raise RecordError(f"{spec.name or 'record'}: refused: {exc}") from None

    def _plan(self, spec: MotionSpec, tail: Tail, move: Move, force_sensor: bool) -> Segment:
        chain = self.chain
        if spec.force_limits is not None and not force_sensor:
            raise RecordError("force_limits: refused: this arm's evaluator has no force sensor "
                              "(a guarded move needs one)")
        if spec.comply is not None and not force_sensor:
            raise RecordError("comply: refused: this arm's evaluator has no force sensor "
                              "(holding a force needs one)")
        if spec.mass > self.limits.payload:
            raise RecordError(f"mass: {spec.mass:g} kg is more than the arm's payload "
                              f"{self.limits.payload:g} kg")
        eq = spec.equation if spec.equation is not None else tail.equation
        mode = spec.mode
        if mode is Mode.CART and eq is None:
            raise RecordError("equation: a Cartesian record needs a position equation (none "
                              "given and none queued before)")
        moved = self.moved_joints(spec)
        if spec.target is not None and moved is None and len(spec.target) != chain.n:
            raise RecordError(f"target: {len(spec.target)} joint values; the arm has {chain.n}")
        if spec.update is not None:
            spec.update_transform()
        # (a joint target still moves the tool of the last equation: blends and
        # max_diff are measured at that tool)
        frames = Frames(eq, self.tracker)
        period = 1.0 / spec.sample_rate if spec.sample_rate else tail.period
        config = tail.config
        if spec.config is not None:
            if self.closed is None:
                raise RecordError(f"config: refused: chain {chain.name!r} has no closed-form "
                                  "inverse with named configurations")
            try:
                from pyrt.kinematics.puma import parse_config

                config = parse_config(spec.config)
            except ValueError as exc:
                raise RecordError(f"config: {exc}") from None
            if config not in self.closed.configurations:
                raise RecordError(f"config: {spec.config!r} is not one of "
                                  f"{', '.join(self.closed.configurations)}")
        # The target POS (equation mode), with the distance modifier.
        target_pos: Matrix | None = None
        if spec.target is None:
            assert eq is not None
            target_pos = np.array(eq.values(eq.pos)[1])
            if spec.distance is not None:
                from pyrt.kinematics import transform

                d = spec.distance
                # in the tool frame (POS is where the tool frame goes)
                target_pos = target_pos @ transform(d[:3], d[3:])
        # Where the new segment starts, and how.
        last = tail.last
        buffer = BufferMode(spec.buffer)
        moving = last is not None and not last.rested and tail.pieces and not (
            last.pieces and last.pieces[-1].t1 <= tail.now)
        if not moving or last is None:
            buffer = BufferMode.BUFFERED
        elif last.tracking:
            # following a moving frame: the new motion starts from that motion (001's
            # extrapolation), as an aborting record does
            buffer = BufferMode.ABORTING
        kind = CART if mode is Mode.CART else JOINT
        attempts: list[str] = []
        buffer = BufferMode(buffer)
        for how in ([buffer, BufferMode.BUFFERED] if buffer is BufferMode.BLENDING
                    else [buffer]):
            try:
                seg = self._segment(spec, tail, move, kind, frames, config, period,
                                    target_pos, how)
            except Slow as exc:
                attempts.append(exc.what)
                continue
            if how is not buffer:
                seg.blend_error = 0.0
            seg.how = how
            seg.refusals = attempts
            return seg
        raise Refused("; ".join(attempts))

    def _segment(self, spec: MotionSpec, tail: Tail, move: Move, kind: str, frames: Frames,
                 config: str | None, period: float, target_pos: Matrix | None,
                 how: BufferMode) -> Segment:
        chain, lim = self.chain, self.limits
        last = tail.last
        speed = spec.speed
        slow = 1.0
        tau_scale_in = tau_scale_out = 1.0
        t_guess = 0.0
        tau_guess = 0.0
        last_slow: Slow | None = None
        for _attempt in range(_TRIES):
            # -- the start state --------------------------------------------------------
            if how is BufferMode.BUFFERED:
                t_rest = tail.now
                if last is not None and tail.pieces:
                    t_rest = max(t_rest, tail.pieces[-1].t0 if last.tracking
                                 else tail.pieces[-1].t1)
                q_s, t6_s = end_of(tail)
                x_a = None
            elif how is BufferMode.BLENDING:
                assert last is not None
                assert last.q_end is not None and last.t6_end is not None
                q_s, t6_s = last.q_end, last.t6_end
            else:  # aborting: from the state a few samples ahead
                t_a = tail.now + 2 * tail.period
                p = self.piece_at(tail.pieces, t_a)
                assert p is not None
                q_at = self.q_of(p, t_a, tail.q, self.sample_of(tail, t_a))
                if q_at is None:
                    raise Refused("the running motion cannot be followed to the abort point")
                q_s = q_at
                t6_s = chain.fk(q_s)
            # -- the target ---------------------------------------------------------------
            # in a moving frame, where the target will be when the segment ends (001)
            n_end_guess = self.sample_of(tail, tail.now + t_guess)
            held: list[int] | None = None  # the joints a record naming joint sets holds
            if kind == JOINT:
                moved = self.moved_joints(spec)
                if moved is not None:
                    # only the named sets' joints move; the others hold where the
                    # queue leaves them (still moving: where they come to rest)
                    assert spec.target is not None
                    q_e = np.array(q_s, dtype=float)
                    q_e[moved] = spec.target
                    held = [i for i in range(chain.n) if i not in moved]
                elif spec.target is not None:
                    q_e = np.array(spec.target)
                else:
                    assert target_pos is not None
                    t6_e = frames.t6(target_pos, n_end_guess)
                    q_e_opt = self.solve(t6_e, q_s, config)
                    if q_e_opt is None:
                        raise Refused("the target cannot be reached: "
                                      + self.why(t6_e, q_s, config))
                    q_e = q_e_opt
                why = chain.limit_violation(q_e)
                if why:
                    raise Refused(f"the target is outside the joint limits ({why})")
            # -- the line in its space ----------------------------------------------------
            # The start state A in the new segment's space, when the segment does not
            # start from rest in it: aborting (the running motion at t_a), or from rest
            # in the world while the new equation's frame moves.
            r_c = p_c = None
            x_a = v_a = None
            if how is BufferMode.ABORTING:
                t_a = tail.now + 2 * tail.period
                prior = self.piece_at(tail.pieces, t_a)
            elif how is BufferMode.BUFFERED and frames.moving:
                t_a = t_rest
                prior = Piece(JOINT, -math.inf, math.inf, 0.0,
                              line_coeffs(q_s, np.zeros_like(q_s)), None)
            else:
                prior = None
            if kind == JOINT:
                if prior is not None:
                    x_a, v_a, _ = self._state(prior, t_a, q_s, tail, JOINT, frames, None)
                    # 001's extrapolation: the line starts where the motion would be
                    # tau later at its present velocity
                    x_s = x_a + v_a * tau_guess
                    if held:
                        q_e[held] = x_s[held]
                else:
                    x_s = np.array(q_s, dtype=float)
                start = x_s
                delta = q_e - x_s
                t_need = float(np.max(np.abs(delta) / (speed * slow * self.vplan)))
                end: Any = q_e
                v_line_dir = delta
            else:
                if prior is not None:
                    n_a = self.sample_of(tail, t_a)
                    pos_a = frames.pos(t6_s, n_a)
                    r_c, p_c = pos_a[:3, :3].copy(), pos_a[:3, 3].copy()
                    x_a, v_a, _ = self._state(prior, t_a, q_s, tail, CART, frames, (r_c, p_c))
                    x_s = x_a + v_a * tau_guess
                    pos_s = pose_of(x_s, r_c, p_c)
                else:
                    t_ref = last.t_e if how is BufferMode.BLENDING and last is not None \
                        else t_rest + tau_guess
                    pos_s = frames.pos(t6_s, self.sample_of(tail, t_ref))
                    r_c, p_c = pos_s[:3, :3].copy(), pos_s[:3, 3].copy()
                    x_s = np.zeros(6)
                assert target_pos is not None
                v_line_dir = drive_of(target_pos, r_c, p_c) - x_s
                dp, phi = norm(v_line_dir[:3]), norm(v_line_dir[3:])
                t_need = max(dp / (speed * slow * lim.v_cart), phi / (speed * slow * lim.w_cart))
                n_c = self.sample_of(tail, tail.now + tau_guess)
                t_need = max(t_need, kept_joint_time(self, frames, r_c, p_c, v_line_dir, x_s,
                                                     q_s, config, n_c, speed * slow))
                start = pos_s
                end = target_pos
            if spec.max_diff is not None:
                if kind == CART:
                    dp, phi = norm(v_line_dir[:3]), norm(v_line_dir[3:])
                else:
                    dp, phi = tool_travel(self, q_s, q_e, frames)
                t_need = max(t_need, dp * period / spec.max_diff[0],
                             phi * period / spec.max_diff[1])
            t_seg = max(t_need, 1e-3)
            if spec.segment_time is not None:
                if spec.segment_time + 1e-12 < t_need:
                    raise RecordError(f"segment_time: {spec.segment_time:g} s is shorter than "
                                      f"the {t_need:.3g} s the limits need")
                t_seg = spec.segment_time / slow
            # -- the transitions' half-times -------------------------------------------------
            for _ in range(4):
                v_line = v_line_dir / t_seg
                if v_a is not None:
                    v_in = v_a
                elif how is BufferMode.BLENDING:
                    assert last is not None
                    v_in = self._incoming(last, kind, frames, r_c, p_c, tail)
                else:
                    v_in = np.zeros_like(v_line)
                q_end_guess = q_e if kind == JOINT else None
                tau_in = self._tau(kind, v_line - v_in, q_s, frames) * tau_scale_in
                tau_out = self._tau(kind, v_line, q_end_guess if q_end_guess is not None
                                    else q_s, frames) * tau_scale_out
                if spec.transition is not None:
                    need = max(tau_in, tau_out)
                    if spec.transition + 1e-12 < need / max(tau_scale_in, tau_scale_out):
                        raise RecordError(f"transition: {spec.transition:g} s is shorter than "
                                          f"the {need:.3g} s the acceleration limits need")
                    tau_in = max(tau_in, spec.transition)
                    tau_out = max(tau_out, spec.transition)
                if x_a is not None and v_a is not None:
                    # the line starts where the motion at A would be tau_in later
                    # (001's extrapolation), so the transition meets it exactly
                    target_x = x_s + v_line_dir
                    x_s = x_a + v_a * tau_in
                    if held:  # the held joints' transition brakes them to rest on the line
                        target_x[held] = q_e[held] = x_s[held]
                    v_line_dir = target_x - x_s
                    v_line = v_line_dir / t_seg
                if t_seg >= tau_in + tau_out:
                    break
                t_seg = tau_in + tau_out
            # -- the corner's time -----------------------------------------------------------
            if how is BufferMode.BUFFERED:
                t_c = t_rest + tau_in
                if prior is not None:
                    t_c = t_a + tau_in
            elif how is BufferMode.BLENDING:
                assert last is not None
                t_c = last.t_e
                begin = t_c - tau_in
                if len(last.pieces) < 3 or last.tracking or begin < last.t_c + last.tau_in \
                        or min(begin, last.t_e - last.tau_out) < tail.now + 2 * tail.period:
                    raise Slow("blend", "no room to blend into the motion before")
            else:
                t_c = tail.now + 2 * tail.period + tau_in
            again = False
            if kind == JOINT and frames.moving and abs(
                    t_c + t_seg + tau_out - tail.now - t_guess) > 1e-3:
                t_guess = t_c + t_seg + tau_out - tail.now
                again = True
            if prior is not None and abs(tau_in - tau_guess) > 0.05 * tau_in:
                tau_guess = tau_in  # the line's joint time estimated from a nearer start
                again = True
            if again and _attempt < _TRIES - 1:
                continue
            seg = Segment(move, kind, frames, config, period, t_c, t_c + t_seg, tau_in, tau_out,
                          start, end, v_line, r_c, p_c)
            seg.x0 = x_s
            seg.state_a = None if x_a is None else (x_a, v_a)
            seg.rested = False
            seg.tracking = frames.moving and kind == CART
            self._pieces(seg, tail, how, v_in)
            try:
                check_segment(self, seg, spec, tail, how)
            except Slow as exc:
                last_slow = exc
                # a transition's joint acceleration is its own (1/tau) plus the
                # curvature of the joints' path (1/T^2): stretch both
                stretch = kind == CART and spec.segment_time is None
                if exc.where == "in":
                    tau_scale_in *= max(exc.ratio, 1.1)
                    slow /= math.sqrt(exc.ratio) if stretch else 1.0
                elif exc.where == "out":
                    tau_scale_out *= max(exc.ratio, 1.1)
                    slow /= math.sqrt(exc.ratio) if stretch else 1.0
                elif exc.where == "blend":
                    # a slower new segment changes the velocity less at the corner
                    if how is not BufferMode.BLENDING or slow < 0.3:
                        raise
                    slow *= 0.7
                else:
                    slow /= exc.ratio
                continue
            return seg
        why = f": {last_slow.what}" if last_slow is not None else ""
        raise Refused(f"cannot keep within the limits after slowing {_TRIES} times{why}")

    # -- helpers --------------------------------------------------------------------------
    def _tau(self, kind: str, dv: Vector, q: Vector, frames: Frames) -> float:
        """The least transition half-time for a velocity change ``dv`` (Paul's
        quartic peaks at ``3 |dv| / (4 tau)``): in joint space the joint limits; in
        drive space the Cartesian ones and the joints' (``dv`` mapped through the
        Jacobian's pseudo-inverse at ``q``)."""
        if kind == JOINT:
            tau = float(np.max(0.75 * np.abs(dv) / self.aplan))
        else:
            tau = max(0.75 * norm(dv[:3]) / self.limits.a_cart,
                      0.75 * norm(dv[3:]) / self.limits.alpha_cart)
            qd = _joint_rates(self.chain, frames, dv, q)
            tau = max(tau, 1.1 * float(np.max(0.75 * np.abs(qd) / self.aplan)))
        return max(tau, 2e-3)

    def _incoming(self, last: Segment, kind: str, frames: Frames, r_c: Matrix | None,
                  p_c: Vector | None, tail: Tail) -> Vector:
        """The previous line's velocity at its end, in the new segment's space."""
        line = last.pieces[1]
        assert last.q_end is not None
        if kind == JOINT and last.kind == JOINT:
            return last.velocity.copy()
        ref = None if kind == JOINT else (r_c, p_c)
        _, v, _ = self._state(line, last.t_e, last.q_end, tail, kind, frames, ref)  # type: ignore[arg-type]
        return v

    def _pieces(self, seg: Segment, tail: Tail, how: BufferMode, v_in: Vector) -> None:
        """Make the segment's pieces: the transition in, the line, the way to rest."""
        kw: dict[str, Any] = {}
        if seg.kind == CART:
            kw = {"frames": seg.frames, "r_c": seg.r_c, "p_c": seg.p_c, "config": seg.config}
        x_s = np.asarray(seg.x0, dtype=float)
        v = seg.velocity
        t_c, t_e, ti, to = seg.t_c, seg.t_e, seg.tau_in, seg.tau_out
        x_e = x_s + v * (t_e - t_c)
        pieces: list[Piece] = []
        runtime = None
        last = tail.last
        if seg.state_a is not None:
            xa, va = seg.state_a
            c_in = transition_coeffs(xa, va, x_s + v * ti, v, ti)
            if seg.frames.moving or (last is not None and last.frames.moving):
                runtime = (seg.kind, x_s + v * ti, v, ti)
        elif how is BufferMode.BUFFERED:
            c_in = transition_coeffs(x_s, np.zeros_like(v), x_s + v * ti, v, ti)
        else:
            assert last is not None
            piece = last.pieces[1]
            ref = None if seg.kind == JOINT else (seg.r_c, seg.p_c)
            assert last.q_end is not None
            xa, va, _ = self._state(piece, t_c - ti, last.q_end, tail, seg.kind, seg.frames,
                                    ref)  # type: ignore[arg-type]
            c_in = transition_coeffs(xa, va, x_s + v * ti, v, ti)
            if (last.frames.moving or seg.frames.moving) and last.frames.eq is not seg.frames.eq:
                runtime = (seg.kind, x_s + v * ti, v, ti)
        p_in = Piece(seg.kind, t_c - ti, t_c + ti, t_c - ti, c_in, seg, **kw)
        p_in.runtime = runtime
        pieces.append(p_in)
        if t_e - to > t_c + ti:
            pieces.append(Piece(seg.kind, t_c + ti, t_e - to, t_c, line_coeffs(x_s, v), seg,
                                **kw))
        c_out = transition_coeffs(x_e - v * to, v, x_e, np.zeros_like(v), to)
        t_end = t_e + to
        pieces.append(Piece(seg.kind, t_e - to, t_end, t_e - to, c_out, seg, **kw))
        if seg.tracking:
            # at rest in a moving frame: the tool keeps following it
            pieces.append(Piece(seg.kind, t_end, math.inf, t_end, line_coeffs(x_e, 0 * v), seg,
                                **kw))
        comply = seg.move.spec.comply
        if comply is not None and comply.dwell > 0.0:
            # at rest on the path, the force loop holds on before the record is reached
            pieces.append(Piece(seg.kind, t_end, t_end + comply.dwell, t_end,
                                line_coeffs(x_e, 0 * v), seg, **kw))
            t_end += comply.dwell
        seg.pieces = pieces
        seg.t_begin = pieces[0].t0
        seg.t_reached = t_end
