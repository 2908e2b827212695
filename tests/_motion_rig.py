"""Shared arms and helpers of the pyrt.motion tests."""

from __future__ import annotations

import math

import numpy as np

from pyrt.frames import PositionEquation, Transform
from pyrt.kinematics import Chain, DHRow
from pyrt.kinematics.puma import puma560
from pyrt.motion import Evaluator, Limits

PUMA = puma560()
PUMA_LIMITS = Limits(vmax=[1.5] * 6, amax=[5.0] * 6, v_cart=0.5, w_cart=1.5, a_cart=2.0,
                     alpha_cart=6.0)

#: A 7-joint arm (a KUKA iiwa-like standard DH table), no closed form.
ARM7 = Chain.from_dh([
    DHRow(d=0.34, alpha=-math.pi / 2, lower=-2.9, upper=2.9),
    DHRow(alpha=math.pi / 2, lower=-2.0, upper=2.0),
    DHRow(d=0.40, alpha=math.pi / 2, lower=-2.9, upper=2.9),
    DHRow(alpha=-math.pi / 2, lower=-2.0, upper=2.0),
    DHRow(d=0.40, alpha=-math.pi / 2, lower=-2.9, upper=2.9),
    DHRow(alpha=math.pi / 2, lower=-2.0, upper=2.0),
    DHRow(d=0.126, lower=-3.0, upper=3.0),
], name="arm7")
ARM7_LIMITS = Limits(vmax=[1.5] * 7, amax=[5.0] * 7)

#: Joint values around which the random tests draw (away from singularities).
PUMA_HOME = np.array([0.1, 0.8, -3.0, 0.2, 0.8, 0.1])
ARM7_HOME = np.array([0.1, 0.6, 0.2, -1.2, 0.3, 0.9, 0.2])

TOOL_OFFSET = np.eye(4)
TOOL_OFFSET[2, 3] = 0.05  # a 50 mm tool along the flange's z


def equation(pose, name="P", tool=TOOL_OFFSET, coord=None):
    """``T6 . TOOL = [COORD .] POS`` with POS at ``pose`` (the tool frame's target)."""
    t6 = Transform.varb("T6")
    tl = Transform.const("TOOL", tool)
    pos = Transform.varb("POS", pose)
    rhs = [pos] if coord is None else [coord, pos]
    return PositionEquation(name, [t6, tl], rhs)


def tool_pose(chain, q, tool=TOOL_OFFSET):
    return chain.fk(q) @ tool


def run(ev, limit=5000, until=None, wrench=None):
    """Tick until the evaluator is idle (or ``until(knot)``); the knots."""
    knots = []
    for _ in range(limit):
        k = ev.tick(wrench(knots[-1]) if wrench is not None and knots else None)
        knots.append(k)
        if until is not None and until(k):
            break
        if until is None and ev.idle and float(np.max(np.abs(k.qd))) < 1e-9 and len(knots) > 3:
            break
    return knots


def dist_to_segment(p, a, b):
    ab = b - a
    L2 = float(ab @ ab)
    s = 0.0 if L2 == 0 else min(max(float((p - a) @ ab) / L2, 0.0), 1.0)
    return float(np.linalg.norm(p - (a + s * ab)))


def angle(ra, rb):
    r = ra[:3, :3].T @ rb[:3, :3]
    return math.acos(max(-1.0, min(1.0, (np.trace(r) - 1) / 2)))


def make(chain=PUMA, limits=PUMA_LIMITS, q0=None, **kw):
    q0 = (PUMA_HOME if chain is PUMA else ARM7_HOME) if q0 is None else q0
    return Evaluator(chain, limits, q0, **kw)


def conveyor(speed=0.05, period=0.01, origin=None, name="CONV"):
    """A functional COORD translating along the world's y at ``speed`` m/s."""
    base = np.eye(4) if origin is None else np.array(origin)

    def at(sample):
        t = base.copy()
        t[1, 3] += speed * sample * period
        return t

    return Transform.functional(name, at, base)
