"""Pure-Python reference of the ten fuzzy rules (csrc/fuzzy.c), operation for operation.

Used by tests/test_native_fuzzy.py (C must equal it to 1e-12) and by
bench/bench_native.py.  ``params`` is any object with the FuzzyParams fields;
``row`` is a sequence of the 11 input columns in FuzzyInput order.
"""

from __future__ import annotations

import math

TENSION, DESIRED, FREE, LENGTH_ERROR, VELOCITY, ELV, ETV, LAST_DV, NEAR_END, T_LOW, T_HIGH = range(11)


def up(x: float, zero: float, full: float) -> float:
    """Rising shoulder: 0 at or below zero, 1 at or above full."""
    if x <= zero:
        return 0.0
    if x >= full:
        return 1.0
    return (x - zero) / (full - zero)


def down(x: float, full: float, zero: float) -> float:
    """Falling shoulder: 1 at or below full, 0 at or above zero."""
    if x <= full:
        return 1.0
    if x >= zero:
        return 0.0
    return (zero - x) / (zero - full)


def sgn(x: float) -> float:
    return 1.0 if x > 0.0 else (-1.0 if x < 0.0 else 0.0)


def axis_rules(p, row) -> tuple[float, list[float]]:
    """(dv, ten rule outputs) for one axis."""
    t = row[TENSION]
    te = t - row[DESIRED]
    bound = 1.0 - row[FREE]
    e = row[LENGTH_ERROR]
    v = row[VELOCITY]
    elv = row[ELV]
    etv = row[ETV]
    dvl = row[LAST_DV]
    t_low, t_high = row[T_LOW], row[T_HIGH]
    gate = bound * (1.0 - p.near_end_relax * row[NEAR_END])
    r = [
        down(t, t_low + p.low_t_full, t_low + p.low_t_zero) * -p.dv_tension,
        up(t, t_high - p.high_t_zero, t_high - p.high_t_full) * p.dv_tension,
        up(-e, p.len_zero, p.len_full) * p.dv_length,
        up(e, p.len_zero, p.len_full) * -p.dv_length,
        gate * up(-te, p.rel_zero, p.rel_full) * -p.dv_rel_tension,
        gate * up(te, p.rel_zero, p.rel_full) * p.dv_rel_tension,
        up(math.fabs(v), p.vel_zero, p.vel_full) * (-sgn(v) * p.dv_velocity),
        up(math.fabs(elv), p.len_rate_zero, p.len_rate_full) * (-sgn(elv) * p.dv_len_rate),
        bound * up(math.fabs(etv), p.t_rate_zero, p.t_rate_full) * (sgn(etv) * p.dv_t_rate),
        up(math.fabs(dvl), p.dv_zero, p.dv_full) * (-p.dv_damping * dvl),
    ]
    dv = 0.0
    for x in r:
        dv += x
    return dv, r


def fuzzy_step(params, rows) -> tuple[list[float], list[list[float]]]:
    """Every axis: *params* is one parameter object or one per row."""
    each = params if isinstance(params, (list, tuple)) else [params] * len(rows)
    dvs, rules = [], []
    for p, row in zip(each, rows, strict=True):
        dv, r = axis_rules(p, row)
        dvs.append(dv)
        rules.append(r)
    return dvs, rules
