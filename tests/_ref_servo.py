"""A pure-Python reference of csrc/servo.c: the same law, interpolation, time and
trip, written plainly from csrc/servo.h's description, one joint at a time."""

from __future__ import annotations

import math

MAX_DT_PERIODS = 10
GAINS = ("kp", "ki", "kd", "kv", "ka", "kff", "ilim", "tmax", "felim", "velhz")


def quintic(qa, va, aa, qb, vb, ab, T):
    """Coefficients c0..c5 of the quintic through (qa, va, aa) at 0 and (qb, vb, ab) at T."""
    h = qb - qa
    return [qa, va, aa / 2.0,
            (20 * h - (8 * vb + 12 * va) * T - (3 * aa - ab) * T * T) / (2 * T ** 3),
            (-30 * h + (14 * vb + 16 * va) * T + (3 * aa - 2 * ab) * T * T) / (2 * T ** 4),
            (12 * h - 6 * (vb + va) * T + (ab - aa) * T * T) / (2 * T ** 5)]


def cubic(qa, va, qb, vb, T):
    """Coefficients c0..c5 (c4 = c5 = 0) of the cubic through (qa, va) and (qb, vb)."""
    h = qb - qa
    return [qa, va, (3 * h - (2 * va + vb) * T) / T ** 2, (-2 * h + (va + vb) * T) / T ** 3,
            0.0, 0.0]


def poly(c, t):
    """Position, velocity and acceleration of coefficients c at t."""
    p = sum(ck * t ** k for k, ck in enumerate(c))
    v = sum(k * ck * t ** (k - 1) for k, ck in enumerate(c) if k >= 1)
    a = sum(k * (k - 1) * ck * t ** (k - 2) for k, ck in enumerate(c) if k >= 2)
    return p, v, a


class RefServo:
    """The servo of csrc/servo.h for n joints: gains a dict name -> list."""

    def __init__(self, n, period, gains):
        self.n, self.period = n, period
        self.gains = {k: list(v) for k, v in gains.items()}
        self.last, self.start, self.stalls, self.stall_max = 0.0, 0.0, 0, 0.0
        self.reset([0.0] * n)

    def reset(self, q, ff=None):
        n = self.n
        ff = list(ff) if ff is not None else [0.0] * n
        self.coef = [[q[j], 0, 0, 0, 0, 0] for j in range(n)]
        self.ffa, self.ffb = list(ff), list(ff)
        self.integ = [0.0] * n
        self.qlast = list(q)
        self.vel = [0.0] * n
        self.order, self.duration, self.ticks, self.late = 0, 0.0, 0, 0
        self.tripped, self.trip_joint, self.trip_error = False, -1, 0.0
        self.tau = [0.0] * n
        self.qref, self.qdref, self.qddref = list(q), [0.0] * n, [0.0] * n
        self.err, self.ff = [0.0] * n, list(ff)

    def load(self, T, qa, qda, qb, qdb, qdda=None, qddb=None, ffa=None, ffb=None, start=None):
        n = self.n
        self.start = self.last + self.period if start is None else start
        if qdda is None:
            self.coef = [cubic(qa[j], qda[j], qb[j], qdb[j], T) for j in range(n)]
            self.order = 3
        else:
            self.coef = [quintic(qa[j], qda[j], qdda[j], qb[j], qdb[j], qddb[j], T)
                         for j in range(n)]
            self.order = 5
        self.ffa = list(ffa) if ffa is not None else [0.0] * n
        self.ffb = list(ffb) if ffb is not None else [0.0] * n
        self.duration, self.ticks, self.late = T, 0, 0

    def tick(self, q, now=None):
        """One tick at ``now`` (None: one period after the last); returns the joint
        index of a trip made by this tick, or None."""
        n, g = self.n, self.gains
        now = self.last + self.period if now is None else now
        dt = now - self.last
        self.last = now
        dt_i = min(dt, MAX_DT_PERIODS * self.period)  # the integral's step, bounded
        if dt > MAX_DT_PERIODS * self.period:
            self.stalls += 1
            self.stall_max = max(self.stall_max, dt)
        for j in range(n):
            if dt == 0:
                break  # no time passed: the estimate stays
            alpha = 1.0 - math.exp(-2 * math.pi * g["velhz"][j] * dt)
            raw = (q[j] - self.qlast[j]) / dt
            self.vel[j] += alpha * (raw - self.vel[j])
            self.qlast[j] = q[j]
        if self.tripped:
            self.tau = [0.0] * n
            return None
        if self.order == 0:
            t, frac, held = 0.0, 1.0, True
        else:
            half = 0.5 * self.period
            t = max(now - self.start, 0.0)
            if t < self.duration + half:
                self.ticks += 1
            held = t > self.duration + half
            if held:
                self.late += 1
            t = min(t, self.duration)
            frac = t / self.duration
        for j in range(n):
            p, v, a = poly(self.coef[j], t)
            self.qref[j] = p
            self.qdref[j], self.qddref[j] = (0.0, 0.0) if held else (v, a)
            self.ff[j] = self.ffa[j] + (self.ffb[j] - self.ffa[j]) * frac
            self.err[j] = p - q[j]
        ratios = [abs(self.err[j]) / g["felim"][j] for j in range(n)]
        worst = max(range(n), key=lambda j: ratios[j])
        if ratios[worst] > 1.0:
            self.tripped, self.trip_joint, self.trip_error = True, worst, self.err[worst]
            self.integ = [0.0] * n
            self.tau = [0.0] * n
            return worst
        for j in range(n):
            e = self.err[j]
            pd = (g["kp"][j] * e + g["kd"][j] * (self.qdref[j] - self.vel[j])
                  + g["kv"][j] * self.qdref[j] + g["ka"][j] * self.qddref[j]
                  + g["kff"][j] * self.ff[j])
            ilim, tmax = g["ilim"][j], g["tmax"][j]
            integ = min(max(self.integ[j] + g["ki"][j] * e * dt_i, -ilim), ilim)
            u = pd + integ
            if (u > tmax and e > 0) or (u < -tmax and e < 0):
                integ = min(max(self.integ[j], -ilim), ilim)
                u = pd + integ
            self.integ[j] = integ
            self.tau[j] = min(max(u, -tmax), tmax)
        return None


def unwrap(last, total, counts):
    """The encoders of csrc/servo.h: each step modulo 2^32 into -2^31 .. 2^31 - 1."""
    for j, c in enumerate(counts):
        d = c - last[j]
        if not -(1 << 31) <= d < (1 << 31):
            d = ((d + (1 << 31)) % (1 << 32)) - (1 << 31)
        total[j] += d
        last[j] = c


def dacs(tau, q, lo, hi, per_unit, full, dac):
    """The bounds and the DAC counts of pyrt_servo_tick_board: (changed mask, beyond)."""
    changed = 0
    for j in range(len(tau)):
        if q[j] < lo[j] or q[j] > hi[j]:
            return changed, j
        c = round(tau[j] * per_unit[j])
        c = full if c > full else (-full if c < -full else c)
        if c != dac[j]:
            dac[j] = c
            changed |= 1 << j
    return changed, -1
