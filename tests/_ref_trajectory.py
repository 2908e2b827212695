"""Pure-Python reference of pyrt.robots.trajectory.plan: plain floats, no numpy.

Written from Paul's formulation: around via point B, with A the point where
the transition begins on the incoming line and C the corresponding point on
the outgoing line, ``h = u`` running 0..1 over the transition of 2 tau, the
path is ``A + 2 tau (v_in u + (v_out - v_in) (u**3 - u**4 / 2))``.
"""

from __future__ import annotations

TAU_MIN = 1e-6


class RefPlan:
    """A plan as lists of floats: points, the time each is passed, taus, line velocities."""

    def __init__(self, start, vias, vmax, amax, durations=None, speeds=None):
        n = len(start)
        points = [[float(x) for x in start]] + [[float(x) for x in v] for v in vias]
        m = len(points) - 1
        durations = durations if isinstance(durations, list) else [durations] * m
        speeds = speeds if isinstance(speeds, list) else [speeds] * m
        tau_a = TAU_MIN
        for j in range(n):
            tau_a = max(tau_a, 1.5 * vmax[j] / amax[j])
        lines = [[0.0] * n]
        seg_times = []
        for i in range(m):
            f = speeds[i] if speeds[i] is not None else 1.0
            t = 2.0 * tau_a
            for j in range(n):
                t = max(t, abs(points[i + 1][j] - points[i][j]) / (f * vmax[j]))
            if durations[i] is not None:
                t = max(t, durations[i])
            seg_times.append(t)
            lines.append([(points[i + 1][j] - points[i][j]) / t for j in range(n)])
        lines.append([0.0] * n)
        taus = []
        for i in range(m + 1):
            tau = 0.0
            for j in range(n):
                tau = max(tau, 0.75 * abs(lines[i + 1][j] - lines[i][j]) / amax[j])
            taus.append(0.0 if tau == 0.0 else max(tau, TAU_MIN))
        times = [taus[0]]
        for t in seg_times:
            times.append(times[-1] + t)
        self.n = n
        self.points = points
        self.lines = lines
        self.taus = taus
        self.times = times
        self.duration = times[-1] + taus[-1]

    def sample(self, t):
        """(q, qd, qdd) as lists of floats at time t."""
        n = self.n
        if t <= 0.0:
            return list(self.points[0]), [0.0] * n, [0.0] * n
        if t >= self.duration:
            return list(self.points[-1]), [0.0] * n, [0.0] * n
        for i, b in enumerate(self.points):
            tau, tb = self.taus[i], self.times[i]
            vin, vout = self.lines[i], self.lines[i + 1]
            if tau > 0.0 and tb - tau <= t <= tb + tau:
                u = (t - (tb - tau)) / (2.0 * tau)
                q, qd, qdd = [], [], []
                for j in range(n):
                    a = b[j] - vin[j] * tau
                    dv = vout[j] - vin[j]
                    q.append(a + 2.0 * tau * (vin[j] * u + dv * (u ** 3 - u ** 4 / 2.0)))
                    qd.append(vin[j] + dv * (3.0 * u ** 2 - 2.0 * u ** 3))
                    qdd.append(3.0 * dv * u * (1.0 - u) / tau)
                return q, qd, qdd
            if i + 1 < len(self.points) and tb + tau <= t <= self.times[i + 1] - self.taus[i + 1]:
                return ([b[j] + vout[j] * (t - tb) for j in range(n)], list(vout), [0.0] * n)
        raise AssertionError(f"t={t} falls in no piece")
