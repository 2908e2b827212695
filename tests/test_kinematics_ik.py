"""The numerical inverse: fk(ik(T)) = T over random reachable poses of a
6-joint (PUMA 560) and a 7-joint (Panda) arm, within the limits, nearest
the seed; unreachable poses and bad options."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pyrt.kinematics import Chain, DHRow
from pyrt.native import NativeInputError

PI = math.pi
#: The PUMA 560 as the Robotics Toolbox gives it (standard DH, m, rad).
PUMA = Chain.from_dh([
    DHRow(a=0.0, alpha=PI / 2, d=0.672, lower=-2.79, upper=2.79),
    DHRow(a=0.4318, alpha=0.0, d=0.0, lower=-0.79, upper=3.93),
    DHRow(a=0.0203, alpha=-PI / 2, d=0.15005, lower=-3.93, upper=0.79),
    DHRow(a=0.0, alpha=PI / 2, d=0.4318, lower=-1.92, upper=2.97),
    DHRow(a=0.0, alpha=-PI / 2, d=0.0, lower=-1.75, upper=1.75),
    DHRow(a=0.0, alpha=0.0, d=0.0, lower=-4.64, upper=4.64),
], name="puma560")
#: The Franka Panda (Craig's modified DH), a redundant 7-joint arm, with its flange.
PANDA = Chain.from_dh([
    DHRow(a=0.0, alpha=0.0, d=0.333, lower=-2.8973, upper=2.8973),
    DHRow(a=0.0, alpha=-PI / 2, d=0.0, lower=-1.7628, upper=1.7628),
    DHRow(a=0.0, alpha=PI / 2, d=0.316, lower=-2.8973, upper=2.8973),
    DHRow(a=0.0825, alpha=PI / 2, d=0.0, lower=-3.0718, upper=-0.0698),
    DHRow(a=-0.0825, alpha=-PI / 2, d=0.384, lower=-2.8973, upper=2.8973),
    DHRow(a=0.0, alpha=PI / 2, d=0.0, lower=-0.0175, upper=3.7525),
    DHRow(a=0.088, alpha=PI / 2, d=0.0, lower=-2.8973, upper=2.8973),
], modified=True, name="panda", tool=np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0.107],
                                                [0, 0, 0, 1.0]]))

SEEDS = st.integers(0, 2**32 - 1)


def reachable(chain: Chain, rng: np.random.Generator, margin: float = 0.3
              ) -> tuple[np.ndarray, np.ndarray]:
    """Joint values within the limits (less a margin) and their tool pose."""
    q = rng.uniform(chain.lower + margin, chain.upper - margin)
    return q, chain.fk(q)


@pytest.mark.parametrize("chain", [PUMA, PANDA], ids=["6 joints", "7 joints"])
@settings(max_examples=80, deadline=None)
@given(seed=SEEDS)
def test_ik_reaches_random_reachable_poses(chain, seed):
    """From a seed near a reachable pose's joints, ik converges: fk(ik(T)) = T to 1e-9, within the limits."""
    rng = np.random.default_rng(seed)
    q, target = reachable(chain, rng)
    seed_q = np.clip(q + rng.uniform(-0.25, 0.25, chain.n), chain.lower, chain.upper)
    r = chain.ik(target, seed_q)
    assert r.ok, (r.iterations, r.residual)
    assert r.residual <= 1e-9
    np.testing.assert_allclose(chain.fk(r.q), target, rtol=0, atol=1e-9)
    assert chain.limit_violation(r.q) is None


@settings(max_examples=60, deadline=None)
@given(seed=SEEDS)
def test_redundant_ik_minimises_joint_motion(seed):
    """For the 7-joint arm the answer is no farther from the seed than the joints the pose came from, and (away from singularities) no self-motion brings it nearer."""
    rng = np.random.default_rng(seed)
    q, target = reachable(PANDA, rng, margin=0.4)
    seed_q = q + rng.uniform(-0.15, 0.15, 7)
    r = PANDA.ik(target, seed_q)
    assert r.ok
    assert np.linalg.norm(r.q - seed_q) <= np.linalg.norm(q - seed_q) + 1e-9
    # the way along the self-motion converges linearly (slowly where the
    # manifold bends hard): the stationarity is asserted with more iterations
    r = PANDA.ik(target, seed_q, max_iter=2000)
    assert r.ok
    jac = PANDA.jacobian(r.q)
    if np.linalg.svd(jac, compute_uv=False).min() > 1e-2:
        # away from a singularity the answer is a stationary point of the
        # distance on the self-motion manifold (near one the manifold's
        # tangent is ill-conditioned and only the distance is asserted)
        d = r.q - seed_q
        along_self_motion = d - np.linalg.pinv(jac) @ (jac @ d)
        assert np.linalg.norm(along_self_motion) < 1e-6


def test_ik_at_the_solution_takes_no_step():
    """A seed whose pose is already the target is the answer, after zero iterations."""
    q = np.array([0.1, 0.7, -1.2, 0.3, 0.4, 0.5])
    r = PUMA.ik(PUMA.fk(q), q)
    assert r.ok and r.iterations == 0
    np.testing.assert_array_equal(r.q, q)


def test_ik_seed_and_target_may_be_any_real_arrays():
    """Lists work as target and seed; out= receives the answer."""
    q = [0.1, 0.7, -1.2, 0.3, 0.4, 0.5]
    out = np.empty(6)
    r = PUMA.ik(PUMA.fk(q).tolist(), [0.0, 0.6, -1.0, 0.2, 0.3, 0.4], out=out)
    assert r.ok and r.q is out


def test_unreachable_pose_is_not_ok_and_stays_within_limits():
    """A pose 10 m away ends with ok False, the best point met, its residual, within the limits."""
    target = PUMA.fk(np.zeros(6))
    target[:3, 3] += 10.0
    r = PUMA.ik(target, np.zeros(6), max_iter=50)
    assert not r.ok
    assert r.iterations == 50
    assert r.residual > 9.0
    assert PUMA.limit_violation(r.q) is None
    assert abs(np.linalg.norm(target[:3, 3] - PUMA.fk(r.q)[:3, 3]) - r.residual) < 1.0


def test_ik_respects_joint_limits_when_the_seed_is_outside():
    """A seed beyond a limit is clamped to it: the answer is within the limits."""
    q = np.array([0.1, 0.7, -1.2, 0.3, 0.4, 0.5])
    seed = q.copy()
    seed[1] = 5.0
    r = PUMA.ik(PUMA.fk(q), seed)
    assert PUMA.limit_violation(r.q) is None


def test_ik_half_turn_orientation_error():
    """A target turned half a turn from the seed's pose (the rotation vector's hard case) is reached."""
    q = np.array([0.2, 0.9, -1.0, 0.1, 0.6, 0.3])
    seed = q.copy()
    seed[5] += PI - 1e-9
    r = PUMA.ik(PUMA.fk(q), seed)
    assert r.ok
    np.testing.assert_allclose(PUMA.fk(r.q), PUMA.fk(q), atol=1e-9)


@pytest.mark.parametrize("kw", [dict(tol=0.0), dict(tol=math.nan), dict(max_iter=0),
                                dict(max_iter=1.5), dict(null_tol=-1.0)])
def test_ik_options_are_checked(kw):
    """A tolerance <= 0 or NaN, or an iteration limit < 1 or not an integer, is refused."""
    with pytest.raises(NativeInputError):
        PUMA.ik(np.eye(4), np.zeros(6), **kw)


def test_two_threads_on_one_chain_get_each_their_own_answers():
    """A planner's thread and the loop's thread calling one chain at once (fk, Jacobian, ik, rnea, aba) get exactly what each would alone."""
    import threading

    from pyrt.kinematics.puma import puma560

    chain = puma560()
    rng = np.random.default_rng(7)
    qs = [rng.uniform(chain.lower, chain.upper) for _ in range(60)]
    poses = [chain.fk(q) for q in qs]

    def work(q: np.ndarray, pose: np.ndarray) -> tuple[np.ndarray, ...]:
        ik = chain.ik(pose, q + 0.05)
        cf = chain.closed_form.solve(pose, "righty-above-noflip")
        return (chain.fk(q), chain.jacobian(q), ik.q, chain.rnea(q, q, q), chain.aba(q, q, q),
                np.zeros(6) if cf is None else cf)

    alone = [work(q, p) for q, p in zip(qs, poses, strict=True)]
    seen: dict[int, list[tuple[np.ndarray, ...]]] = {}
    start = threading.Barrier(3)

    def run(k: int) -> None:
        start.wait()
        seen[k] = [work(q, p) for _ in range(5) for q, p in zip(qs, poses, strict=True)]

    threads = [threading.Thread(target=run, args=(k,)) for k in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    assert sorted(seen) == [0, 1, 2]
    for got in seen.values():
        for i, row in enumerate(got):
            for a, b in zip(row, alone[i % len(alone)], strict=True):
                assert np.array_equal(a, b)
