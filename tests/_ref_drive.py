"""A pure-Python reference of csrc/drive.c (hardware (a)'s on-board servo),
written plainly from csrc/drive.h's description on top of the servo's
reference (tests/_ref_servo.py)."""

from __future__ import annotations

from _ref_servo import RefServo

ENABLED, FAULT, LATE, REFUSED, JOINT_SHIFT = 1, 2, 4, 8, 8
DAC_FULL = 32767


def wrapped(a: int, b: int) -> int:
    """The step from b to a modulo 2^32, signed."""
    return ((a - b + (1 << 31)) % (1 << 32)) - (1 << 31)


class RefDrive:
    """The board of csrc/drive.h: ``counts`` and ``nm`` per joint, the servo's gains
    (``felim`` is the register's)."""

    def __init__(self, n, period, counts, nm, gains):
        self.n, self.period = n, period
        self.counts, self.nm = list(counts), list(nm)
        self.servo = RefServo(n, period, gains)
        self.setpoint = [0] * n
        self.velocity = [0] * n
        self.torque = [0] * n
        self.felim = [0] * n
        self.enable = self.sync = self.period_us = 0
        self.on = self.faulted = False
        self.fault_joint = 0
        self.primed = False
        self.sync_seen = 0
        self.last = [0] * n
        self.total = [0] * n
        self.kb = ([0.0] * n, [0.0] * n, [0.0] * n)  # the last knot: q, qd, ff
        self.dac, self.amp, self.ferr = [0] * n, [0] * n, [0] * n
        self.status = 0

    def _off(self):
        self.dac, self.amp = [0] * self.n, [0] * self.n

    def tick(self, count):
        n, cpu, nm = self.n, self.counts, self.nm
        for j in range(n):
            if not self.primed:
                self.last[j] = self.total[j] = count[j]
            else:
                self.total[j] += wrapped(count[j], self.last[j])
                self.last[j] = count[j]
        self.primed = True
        q = [(self.total[j] + 0.5) / cpu[j] for j in range(n)]
        status = 0
        if not self.enable:
            self.on = self.faulted = False
            self.fault_joint = 0
        elif not self.faulted and not self.on:
            if self.period_us > 0 and all(f > 0 for f in self.felim):
                ff = [self.torque[j] * nm[j] for j in range(n)]
                self.kb = (list(q), [0.0] * n, ff)
                self.servo.reset(q, ff)
                self.on = True
                self.sync_seen = self.sync
            else:
                status |= REFUSED
        if not self.on:
            self._off()
            if not self.faulted:
                self.ferr = [0] * n
            if self.faulted:
                status |= FAULT | (self.fault_joint << JOINT_SHIFT)
            self.status = status
            return
        if self.period_us <= 0 or not all(f > 0 for f in self.felim):
            self.on, self.faulted, self.fault_joint = False, True, 0
            self._off()
            self.ferr = [0] * n
            self.status = FAULT
            return
        self.servo.gains["felim"] = [self.felim[j] / cpu[j] for j in range(n)]
        if self.sync != self.sync_seen:
            self.sync_seen = self.sync
            qa, qda, ffa = self.kb
            qb = [(self.total[j] + wrapped(self.setpoint[j], self.last[j]) + 0.5) / cpu[j]
                  for j in range(n)]
            qdb = [self.velocity[j] / cpu[j] for j in range(n)]
            ffb = [self.torque[j] * nm[j] for j in range(n)]
            self.servo.load(self.period_us * 1e-6, qa, qda, qb, qdb, ffa=ffa, ffb=ffb)
            self.kb = (qb, qdb, ffb)
        tripped = self.servo.tick(q)
        if tripped is not None:
            self.on, self.faulted = False, True
            self.fault_joint = tripped + 1
            self._off()
            status |= FAULT | (self.fault_joint << JOINT_SHIFT)
        else:
            self.dac = [int(max(-DAC_FULL, min(DAC_FULL, round(self.servo.tau[j] / nm[j]))))
                        for j in range(n)]
            self.amp = [1] * n
            status |= ENABLED
            if self.servo.late > 0:
                status |= LATE
        self.ferr = [round(self.servo.err[j] * cpu[j]) for j in range(n)]
        self.status = status
