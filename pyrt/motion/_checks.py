"""The planner's checks: the sampled refusals and the limits a plan must keep.

The functions here take the :class:`~pyrt.motion.planner.Planner` whose arm
and limits they judge:

* :func:`joint_time` samples a Cartesian line's joint path before its pieces
  are made: the least time that keeps the joint velocities (and the path's
  curvature) within the limits, refusing a line that passes a singularity or
  leaves the reach, naming where;
* :func:`tool_travel` is the tool's path length and turn along a joint line
  (for ``max_diff``);
* :func:`check_segment` samples a planned segment at its period: reach,
  joint limits, singularities (refused, :class:`Refused`), joint velocities
  and accelerations, ``max_diff`` and a blend's tolerance (to be slowed,
  :class:`Slow`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from pyrt.motion._geom import log_rot, pose_of, poses_of
from pyrt.motion._pieces import CART, JOINT, Frames, Piece, line_coeffs, norm
from pyrt.motion.record import BufferMode, MotionSpec

if TYPE_CHECKING:
    from pyrt.kinematics import Chain
    from pyrt.motion.planner import Planner, Segment, Tail

Matrix = npt.NDArray[np.float64]
Vector = npt.NDArray[np.float64]


class Refused(Exception):
    """A record the arm cannot do; the message names where and why."""


class Slow(Exception):
    """A plan over a limit at ``where`` (``in``, ``line``, ``out``, ``blend``):
    slow it by ``ratio`` and sample it again."""

    def __init__(self, where: str, what: str, ratio: float = 1.25) -> None:
        super().__init__(what)
        self.where = where
        self.what = what
        self.ratio = max(ratio, 1.05)


def end_of(tail: Tail) -> tuple[Vector, Matrix]:
    """Where the plan queued in ``tail`` ends (joints, T6), or where the arm is."""
    last = tail.last
    if last is None or last.q_end is None or last.rested is None:
        return tail.q, tail.t6
    if not tail.pieces or tail.pieces[-1].t1 <= tail.now or last.tracking:
        return tail.q, tail.t6
    assert last.t6_end is not None
    return last.q_end, last.t6_end


def joint_time(planner: Planner, frames: Frames, r_c: Matrix, p_c: Vector, delta: Vector,
               x_s: Vector, q_s: Vector, config: str | None, sample: float,
               speed: float) -> float:
    """The least time of a Cartesian line that keeps the joint velocities
    within the limits (the joints' path sampled)."""
    k = 24
    pose = np.eye(4)
    q0 = planner.solve(frames.t6(pose_of(x_s, r_c, p_c, pose), sample), q_s, config)
    q = prev = q_s if q0 is None else q0
    # each sample's inverse (seeded at the one before) up to the first out of reach, the
    # singular values where each is judged (batched), then the samples in order
    xs = x_s + delta * (np.arange(1, k + 1)[:, None] / k)  # x_s + delta * (i / k), each
    all_t6 = frames.t6_many(poses_of(xs, r_c, p_c), [sample] * k)  # each kept for a refusal
    rows, whole = solve_rows(planner, all_t6, q, config)
    gots: list[Vector | None] = [*rows] if whole else [*rows, None]
    t6s = list(all_t6[:len(gots)])
    # the joints each sample's singular values are taken at (the one before, out of reach)
    at = rows if whole else np.concatenate(
        [rows, rows[-1:] if len(rows) else np.asarray(q, dtype=float)[None, :]])
    svs = smallest_singular(_jacobians(planner.chain, at), planner.limits.singular).tolist()
    q = prev
    for i, (t6, got, sv) in enumerate(zip(t6s, gots, svs, strict=True), start=1):
        if sv < planner.limits.singular or got is None:
            tool = frames.tool(t6, sample)[:3, 3] * 1e3
            where = f"{100 * i / k:.0f}% of the segment (tool at {tool.round(1).tolist()} mm)"
            if sv < planner.limits.singular:
                raise Refused(f"the line passes a singularity at {where}: smallest singular "
                              f"value {sv:.2g}, q = {np.degrees(q).round(1).tolist()} deg")
            raise Refused(f"the line leaves the arm's reach at {where}: "
                          f"{planner.why(t6, q, config)}")
        q = got
    # every sample reached: the joints' steps keep their velocities within the limits, and
    # the path's curvature (its acceleration at constant speed along the line, d2q/dr2 /
    # T^2) to half the acceleration limits, the other half for the transitions
    steps = np.diff(np.concatenate([np.asarray(prev, dtype=float)[None, :], rows]), axis=0)
    need = max(0.0, float(np.max(np.abs(steps) * k / (speed * planner.vplan))))
    if len(steps) > 1:
        curv = np.abs(np.diff(steps, axis=0)) * k * k
        need = max(need, math.sqrt(float(np.max(curv / (0.5 * planner.amax)))))
    return need


def solve_rows(planner: Planner, t6s: Matrix, seed: Vector,
               config: str | None) -> tuple[Matrix, bool]:
    """The planner's inverse of each T6 of ``t6s`` (m, 4, 4) in order, each seeded at
    the one before (the first at ``seed``), up to the first without one: (the rows
    solved (k, n), in order; whether they are all m) -- the closed form's batch when
    it has one (:meth:`~pyrt.kinematics.puma.PaulInverse.solve_many`)."""
    many = getattr(planner.closed, "solve_many", None)
    if many is not None and config is not None:
        rows, why = many(t6s, config, seed)
        return rows, why is None
    out: list[Vector] = []
    q = seed
    for t6 in t6s:
        got = planner.solve(t6, q, config)
        if got is None:
            break
        out.append(got)
        q = got
    return (np.array(out) if out else np.empty((0, planner.chain.n))), len(out) == len(t6s)


def kept_joint_time(planner: Planner, frames: Frames, r_c: Matrix, p_c: Vector,
                    delta: Vector, x_s: Vector, q_s: Vector, config: str | None,
                    sample: float, speed: float) -> float:
    """:func:`joint_time`, kept on the planner for the last line asked: a blend that
    cannot be made is planned again as a stop on the same line from the same joints
    (in frames that do not move the sample does not matter)."""
    key = (frames, config, speed, sample if frames.moving else None,
           *(np.asarray(v, dtype=float).tobytes() for v in (r_c, p_c, delta, x_s, q_s)))
    hit = planner._jt_last
    if hit is not None and hit[0] == key:
        return hit[1]
    need = joint_time(planner, frames, r_c, p_c, delta, x_s, q_s, config, sample, speed)
    planner._jt_last = (key, need)
    return need


def tool_travel(planner: Planner, q_s: Vector, q_e: Vector,
                frames: Frames) -> tuple[float, float]:
    """The tool's path length (m) and turn (rad) along the joint line ``q_s`` -> ``q_e``."""
    k = 24
    length = angle = 0.0
    prev = frames.tool(planner.chain.fk(q_s), None)
    for i in range(1, k + 1):
        cur = frames.tool(planner.chain.fk(q_s + (q_e - q_s) * i / k), None)
        length += norm(cur[:3, 3] - prev[:3, 3])
        angle += norm(log_rot(prev[:3, :3].T @ cur[:3, :3]))
        prev = cur
    return length, angle


def check_segment(planner: Planner, seg: Segment, spec: MotionSpec, tail: Tail,
                  how: BufferMode) -> None:
    """Sample the segment at its period: reach, limits, singularities,
    velocities, accelerations, max_diff, the blend's tolerance."""
    chain = planner.chain
    dt = seg.period
    # on the loop's own sample times, from the first one in the segment
    t0 = tail.now + math.ceil((seg.t_begin - tail.now) / dt - 1e-9) * dt
    t_end = seg.t_reached
    prior: Piece | None
    if how is BufferMode.BLENDING and tail.last is not None:
        prior = tail.last.pieces[-2]  # the line, run on to the transition
    elif how is BufferMode.ABORTING:
        prior = planner.piece_at(tail.pieces, t0 - dt)
    else:
        prior = None
    q_prev2 = q_prev = None
    seed = end_of(tail)[0] if how is BufferMode.BUFFERED else tail.q
    if prior is not None:
        qa = planner.q_of(prior, t0 - 2 * dt, tail.q, planner.sample_of(tail, t0 - 2 * dt))
        qb = planner.q_of(prior, t0 - dt, tail.q if qa is None else qa,
                       planner.sample_of(tail, t0 - dt))
        if qa is not None and qb is not None:
            q_prev2, q_prev, seed = qa, qb, qb
    elif how is BufferMode.BUFFERED:
        q_prev2 = q_prev = seed
    n_steps = max(math.ceil((t_end - t0) / dt), 1)
    blend_pts: list[Vector] = []
    q_end = None
    # the samples' joints first, each inverse seeded at the sample before, up to the first
    # out of reach; then each check over all of them at once; then the samples in order,
    # each refused or slowed by the first check it fails, as one by one
    times = [min(t0 + i * dt, t_end) for i in range(n_steps + 1)]
    pieces: list[Piece] = []
    for t in times:
        piece = planner.piece_at(seg.pieces, t)
        assert piece is not None
        pieces.append(piece)
    samples = [planner.sample_of(tail, t) for t in times]
    # piece by piece, all at once: a joint piece's values, a Cartesian piece's T6 and
    # their inverses (each seeded at the sample before, as one by one)
    chunks: list[Matrix] = []
    lost = False
    for start, end, piece in _runs(pieces):
        if piece.space == JOINT:
            rows = piece.values(times[start:end])
            whole = True
        elif piece.space == CART:
            assert piece.frames is not None
            t6 = piece.frames.t6_many(piece.poses(times[start:end]), samples[start:end])
            rows, whole = solve_rows(planner, t6, seed, piece.config)
        else:
            got: list[Vector] = []
            whole = True
            for t, n in zip(times[start:end], samples[start:end], strict=True):
                q_f = planner.q_of(piece, t, seed, n)
                if q_f is None:
                    whole = False
                    break
                got.append(q_f)
                seed = q_f
            rows = np.array(got) if got else np.empty((0, chain.n))
        if len(rows):
            chunks.append(rows)
            seed = rows[-1]
        if not whole:
            lost = True
            break
    q_all = np.concatenate(chunks) if chunks else np.empty((0, chain.n))
    qs: list[Vector] = [*q_all]
    m = len(qs)
    flags = _sample_flags(planner, q_all, pieces, q_prev2, q_prev, dt)
    # without max_diff a sample no check flags passes: only those are looked at, and in a
    # blend the samples of the transition in (their tool points), in order
    looked: Sequence[int]
    if spec.max_diff is not None:
        looked = range(m)
    else:
        looked = flags.flagged(planner.limits.singular)
        if how is BufferMode.BLENDING:
            t_blend = seg.t_c + seg.tau_in
            head = next((i for i, t in enumerate(times[:m]) if t > t_blend), m)
            looked = sorted({*range(head), *looked})
    for i in looked:
        t, piece, n = times[i], pieces[i], samples[i]
        frac = 100.0 * (t - seg.t_c) / max(seg.t_e - seg.t_c, 1e-9)
        frac = min(max(frac, 0.0), 100.0)
        q = qs[i]
        if flags.outside[i]:
            why = chain.limit_violation(q)
            if why:
                tool = chain.fk(q)[:3, 3] * 1e3
                raise Refused(f"the path crosses a joint limit at {frac:.0f}% of the segment "
                              f"(T6 at {tool.round(1).tolist()} mm): {why}")
        sv = flags.singular.get(i)
        if sv is not None and sv < planner.limits.singular:
            tool = chain.fk(q)[:3, 3] * 1e3
            raise Refused(f"the path passes a singularity at {frac:.0f}% of the "
                          f"segment (T6 at {tool.round(1).tolist()} mm, q = "
                          f"{np.degrees(q).round(1).tolist()} deg; smallest singular "
                          f"value {sv:.2g})")
        q_prev = flags.prev(i, 1)
        if flags.over_v[i] or flags.over_a[i]:
            q_prev2 = flags.prev(i, 2)
            assert q_prev is not None and q_prev2 is not None
            qd = (q - q_prev) / dt
            qdd = (q - 2 * q_prev + q_prev2) / (dt * dt)
            where = _where(seg, t - dt)
            if flags.over_v[i]:
                j = int(np.argmax(np.abs(qd) / planner.vmax))
                if np.abs(q - q_prev)[j] > 0.5:
                    raise Refused(f"the path passes a singularity at {frac:.0f}% of the "
                                  f"segment: joint {chain.joints[j].name} would jump "
                                  f"{math.degrees(abs(q[j] - q_prev[j])):.0f} deg")
                raise Slow(where, f"joint {chain.joints[j].name} over its velocity limit "
                           f"at {frac:.0f}% of the segment",
                           1.02 * float(np.abs(qd)[j] / planner.vmax[j]))
            j = int(np.argmax(np.abs(qdd) / planner.amax))
            ratio = float(np.abs(qdd)[j] / planner.amax[j])
            raise Slow(where, f"joint {chain.joints[j].name} over its acceleration "
                       f"limit at {frac:.0f}% of the segment",
                       1.02 * (ratio if where != "line" else math.sqrt(ratio)))
        if spec.max_diff is not None and q_prev is not None:
            a = seg.frames.tool(chain.fk(q_prev), n)
            b = seg.frames.tool(chain.fk(q), n)
            if norm(b[:3, 3] - a[:3, 3]) > spec.max_diff[0] * 1.001 or norm(
                    log_rot(a[:3, :3].T @ b[:3, :3])) > spec.max_diff[1] * 1.001:
                raise Slow("line", "over the maximum differential motion")
        if how is BufferMode.BLENDING and t <= seg.t_c + seg.tau_in:
            blend_pts.append(_tool_point(planner, seg, q, n))
    if lost:  # out of reach
        t, piece, n = times[m], pieces[m], samples[m]
        frac = min(max(100.0 * (t - seg.t_c) / max(seg.t_e - seg.t_c, 1e-9), 0.0), 100.0)
        assert piece.frames is not None
        t6 = piece.frames.t6(piece.pose(t, np.eye(4)), n)
        tool = t6[:3, 3] * 1e3
        raise Refused(f"the path leaves the arm's reach at {frac:.0f}% of the segment "
                      f"(T6 at {tool.round(1).tolist()} mm): "
                      f"{planner.why(t6, seed, piece.config)}")
    q_end = qs[-1]
    if how is BufferMode.BLENDING:
        corner_tool = _blend_error(planner, seg, tail, blend_pts)
        seg.blend_error = corner_tool
        tol = seg.move.spec.tolerance
        if tol is not None and corner_tool > 0.9 * tol:
            raise Slow("blend", f"the blend would cut the corner by "
                       f"{corner_tool * 1e3:.2f} mm, more than its tolerance "
                       f"{tol * 1e3:.2f} mm")
    # where the segment ends (the last piece before any tracking)
    t_fin = seg.t_reached
    piece = planner.piece_at(seg.pieces, t_fin - 1e-12)
    assert piece is not None
    qf = planner.q_of(piece, t_fin, q_end, planner.sample_of(tail, t_fin))
    seg.q_end = np.array(q_end) if qf is None else qf
    seg.t6_end = chain.fk(seg.q_end)


def _runs(pieces: list[Piece]) -> list[tuple[int, int, Piece]]:
    """The runs of samples on one piece: (first index, end index, piece), in order."""
    out = []
    start = 0
    for end in range(1, len(pieces) + 1):
        if end < len(pieces) and pieces[end] is pieces[start]:
            continue
        out.append((start, end, pieces[start]))
        start = end
    return out


def _where(seg: Segment, t: float) -> str:
    if t < seg.t_c + seg.tau_in:
        return "in"
    if t > seg.t_e - seg.tau_out:
        return "out"
    return "line"


class _Flags:
    """What each sample of a segment fails, found for all the samples at once:
    ``outside`` (maybe beyond a joint limit: the chain says), ``singular`` (sample
    -> smallest singular value, Cartesian samples), ``over_v``/``over_a`` (a joint
    over its velocity / acceleration limit, from the samples' differences)."""

    def __init__(self, hist: list[Vector | None], outside: list[bool],
                 singular: dict[int, float], over_v: list[bool], over_a: list[bool]) -> None:
        self._hist = hist
        self.outside = outside
        self.singular = singular
        self.over_v = over_v
        self.over_a = over_a

    def flagged(self, limit: float) -> list[int]:
        """The samples some check flags (beyond a joint limit maybe, a singular value
        under ``limit``, a velocity or an acceleration over its limit), in order."""
        sing = self.singular
        return [i for i, (out, v, a) in enumerate(zip(self.outside, self.over_v, self.over_a,
                                                       strict=True))
                if out or v or a or sing.get(i, limit) < limit]

    def prev(self, i: int, back: int) -> Vector | None:
        """The joints ``back`` samples before sample ``i`` (None: none)."""
        return self._hist[i + 2 - back]


def _sample_flags(planner: Planner, q: Matrix, pieces: list[Piece],
                  q_prev2: Vector | None, q_prev: Vector | None, dt: float) -> _Flags:
    """The checks of :func:`check_segment` on the joints ``q`` (m, n) of its samples
    (``q_prev2``, ``q_prev`` the two before the first, or None), all at once."""
    m = len(q)
    qs = [*q]
    hist: list[Vector | None] = [q_prev2, q_prev, *qs]
    if m == 0:
        return _Flags(hist, [], {}, [], [])
    chain = planner.chain
    lower, upper = np.asarray(chain.lower), np.asarray(chain.upper)
    inside = np.logical_and(q >= lower, q <= upper).all(axis=1) & np.isfinite(q).all(axis=1)
    outside = [not v for v in np.asarray(inside).tolist()]
    cart = [i for i in range(m) if pieces[i].space == CART]
    singular: dict[int, float] = {}
    if cart:
        sv = smallest_singular(_jacobians(chain, q[cart] if len(cart) < m else q),
                               planner.limits.singular)
        singular = dict(zip(cart, sv.tolist(), strict=True))
    # the samples with two before them: their velocities and accelerations
    first = 0 if q_prev2 is not None and q_prev is not None else (
        1 if q_prev is not None else 2)
    over_v = [False] * m
    over_a = [False] * m
    if first < m:
        # from two samples before `first` on
        full = np.concatenate([np.array(hist[first:2]).reshape(-1, q.shape[1]), q])
        cur, p1, p2 = full[2:], full[1:-1], full[:-2]
        qd = (cur - p1) / dt
        qdd = (cur - 2 * p1 + p2) / (dt * dt)
        over_v[first:] = (np.abs(qd) > planner.vmax * 0.999).any(axis=1).tolist()
        over_a[first:] = (np.abs(qdd) > planner.amax * 0.995).any(axis=1).tolist()
    return _Flags(hist, outside, singular, over_v, over_a)


#: Every how many samples :func:`smallest_singular` decomposes one Jacobian.
_ANCHOR = 6


def smallest_singular(jacs: Matrix, limit: float) -> Vector:
    """For each Jacobian of ``jacs`` (m, 6, n): its smallest singular value, or a
    lower bound of it that is at least ``limit`` (a sample the check passes).

    Weyl's inequality bounds how far a singular value moves between two
    matrices by the 2-norm of their difference (at most its Frobenius norm):
    ``sigma(J) >= sigma(A) - ||J - A||_F``.  So one Jacobian in every
    :data:`_ANCHOR` is decomposed, each other one is bounded from its nearest such
    anchor, and only those whose bound falls under ``limit`` are decomposed too:
    a sample is under ``limit`` exactly when its smallest singular value is."""
    m = len(jacs)
    if m <= 2:
        return np.asarray(np.linalg.svd(jacs, compute_uv=False)[:, -1], dtype=float)
    anchors = np.arange(0, m, _ANCHOR)
    nearest = np.minimum((np.arange(m) + _ANCHOR // 2) // _ANCHOR, len(anchors) - 1)
    at = anchors[nearest]
    sv_anchor = np.linalg.svd(jacs[anchors], compute_uv=False)[:, -1]
    dist = np.sqrt(((jacs - jacs[at]) ** 2).sum(axis=(1, 2)))
    out = sv_anchor[nearest] - dist
    out[anchors] = sv_anchor
    low = np.flatnonzero(out < limit)
    if low.size:
        out[low] = np.linalg.svd(jacs[low], compute_uv=False)[:, -1]
    return np.asarray(out, dtype=float)


def _jacobians(chain: Chain, qs: Sequence[Vector] | Matrix) -> Matrix:
    """The Jacobians (len(qs), 6, n) at joints ``qs``, through one pair of arrays the
    chain's kernel stays bound to."""
    q_buf = np.zeros(chain.n)
    j_buf = np.zeros((6, chain.n))
    out = np.empty((len(qs), 6, chain.n))
    for i, q in enumerate(qs):
        q_buf[...] = q
        out[i] = chain.jacobian(q_buf, out=j_buf)
    return out


def _tool_point(planner: Planner, seg: Segment, q: Vector, n: float) -> Vector:
    return np.asarray(seg.frames.tool(planner.chain.fk(q), n)[:3, 3], dtype=float)


def _blend_error(planner: Planner, seg: Segment, tail: Tail, pts: list[Vector]) -> float:
    """The largest distance of the blended tool path from the unblended
    one (the previous line to its end, then the new line), sampled."""
    last = tail.last
    if last is None or not pts:
        return 0.0
    line = last.pieces[1] if len(last.pieces) > 1 else last.pieces[0]
    chunks: list[Matrix] = []
    k = 60
    assert last.q_end is not None
    q = last.q_end
    t_c, ti = seg.t_c, seg.tau_in
    new_line = Piece(seg.kind, t_c, seg.t_e, t_c, line_coeffs(seg.x0, seg.velocity), seg,
                     frames=seg.frames, r_c=seg.r_c, p_c=seg.p_c, config=seg.config)
    for piece, t_from in ((line, t_c - ti), (new_line, t_c)):
        ts = [t_from + ti * i / k for i in range(k + 1)]
        ns = [planner.sample_of(tail, t) for t in ts]
        if piece.space == CART:
            # a Cartesian line's T6 is its pose through its frames: the tool points
            # without an inverse and the forward kinematics back, all at once
            assert piece.frames is not None
            t6 = piece.frames.t6_many(piece.poses(ts), ns)
            if seg.frames.moving:
                chunks.append(np.array([seg.frames.tool(m, n)[:3, 3]
                                        for m, n in zip(t6, ns, strict=True)], dtype=float))
            else:
                tool = seg.frames.parts(None)[2]
                chunks.append(t6[:, :3, :3] @ tool[:3, 3] + t6[:, :3, 3])
            continue
        points: list[Vector] = []
        for t, n in zip(ts, ns, strict=True):
            got = planner.q_of(piece, t, q, n)
            if got is not None:
                q = got
                points.append(_tool_point(planner, seg, q, n))
        if points:
            chunks.append(np.array(points))
    # each blended point's distance to each reference point, coordinate by coordinate
    # on (points, references) arrays (the same roundings as on the vectors' rows)
    r = np.concatenate(chunks).T
    p = np.array(pts)
    dx, dy, dz = (r[i][None, :] - p[:, i:i + 1] for i in range(3))
    d = np.sqrt(dx * dx + dy * dy + dz * dz)
    return max(0.0, float(d.min(axis=1).max()))
