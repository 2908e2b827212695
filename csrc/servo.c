/*
 * The generic joint servo (servo.h).
 */
#include "servo.h"

#include <math.h>
#include <stddef.h>

#define TWO_PI 6.283185307179586

static int valid(const pyrt_servo *s)
{
    return s != NULL && s->n >= 1 && s->n <= PYRT_SERVO_MAX_JOINTS && s->gains != NULL
        && s->state != NULL && s->tau != NULL && isfinite(s->period) && s->period > 0.0;
}

static void zero_out(const pyrt_servo *s)
{
    for (int32_t j = 0; j < s->n; j++) {
        s->tau[j] = 0.0;
    }
}

/* The basic ranges of the gains: finite, >= 0, KFF within 0..1, and the
 * clamp, the following-error limit and the cut-off > 0. */
static int check_gains(const double *g, int32_t n)
{
    for (int32_t k = 0; k < PYRT_SERVO_NGAINS * n; k++) {
        if (!isfinite(g[k])) {
            return PYRT_ENONFINITE;
        }
        if (g[k] < 0.0) {
            return PYRT_EINVAL;
        }
    }
    for (int32_t j = 0; j < n; j++) {
        if (g[PYRT_SERVO_KFF * n + j] > 1.0 || g[PYRT_SERVO_TMAX * n + j] <= 0.0
            || g[PYRT_SERVO_FELIM * n + j] <= 0.0 || g[PYRT_SERVO_VELHZ * n + j] <= 0.0) {
            return PYRT_EINVAL;
        }
    }
    return PYRT_OK;
}

int pyrt_servo_reset(pyrt_servo *s, const double *q, const double *ff)
{
    if (!valid(s) || q == NULL) {
        if (s != NULL && s->tau != NULL && s->n >= 1 && s->n <= PYRT_SERVO_MAX_JOINTS) {
            zero_out(s);
        }
        return PYRT_EINVAL;
    }
    const int32_t n = s->n;
    zero_out(s);
    for (int32_t j = 0; j < n; j++) {
        if (!isfinite(q[j]) || (ff != NULL && !isfinite(ff[j]))) {
            return PYRT_ENONFINITE;
        }
    }
    double *st = s->state;
    for (int32_t j = 0; j < n; j++) {
        const double f = ff != NULL ? ff[j] : 0.0;
        st[PYRT_SERVO_C0 * n + j] = q[j];
        for (int r = 1; r < 6; r++) {
            st[(PYRT_SERVO_C0 + r) * n + j] = 0.0;
        }
        st[PYRT_SERVO_SFFA * n + j] = f;
        st[PYRT_SERVO_SFFB * n + j] = f;
        st[PYRT_SERVO_INTEG * n + j] = 0.0;
        st[PYRT_SERVO_QLAST * n + j] = q[j];
        st[PYRT_SERVO_VEL * n + j] = 0.0;
        st[PYRT_SERVO_QREF * n + j] = q[j];
        st[PYRT_SERVO_QDREF * n + j] = 0.0;
        st[PYRT_SERVO_QDDREF * n + j] = 0.0;
        st[PYRT_SERVO_ERR * n + j] = 0.0;
        st[PYRT_SERVO_FF * n + j] = f;
    }
    s->order = PYRT_SERVO_HOLD;
    s->duration = 0.0;
    s->ticks = 0;
    s->late = 0;
    s->tripped = 0;
    s->trip_joint = -1;
    s->trip_error = 0.0;
    return PYRT_OK;
}

int pyrt_servo_load(pyrt_servo *s, const double *knots, double duration, int32_t order)
{
    if (!valid(s)) {
        return PYRT_EINVAL;
    }
    return pyrt_servo_load_at(s, knots, duration, order, s->last + s->period);
}

int pyrt_servo_load_at(pyrt_servo *s, const double *knots, double duration, int32_t order,
                       double start)
{
    if (!valid(s) || knots == NULL
        || (order != PYRT_SERVO_QUINTIC && order != PYRT_SERVO_CUBIC)) {
        return PYRT_EINVAL;
    }
    if (!isfinite(duration) || !isfinite(start)) {
        return PYRT_ENONFINITE;
    }
    if (duration <= 0.0) {
        return PYRT_EINVAL;
    }
    const int32_t n = s->n;
    for (int r = 0; r < PYRT_SERVO_NKNOTS; r++) {
        if (order == PYRT_SERVO_CUBIC && (r == PYRT_SERVO_QDDA || r == PYRT_SERVO_QDDB)) {
            continue;
        }
        for (int32_t j = 0; j < n; j++) {
            if (!isfinite(knots[r * n + j])) {
                return PYRT_ENONFINITE;
            }
        }
    }
    const double T = duration, T2 = T * T, T3 = T2 * T;
    double *st = s->state;
    for (int32_t j = 0; j < n; j++) {
        const double qa = knots[PYRT_SERVO_QA * n + j], va = knots[PYRT_SERVO_QDA * n + j];
        const double qb = knots[PYRT_SERVO_QB * n + j], vb = knots[PYRT_SERVO_QDB * n + j];
        const double h = qb - qa;
        double c[6] = {qa, va, 0.0, 0.0, 0.0, 0.0};
        if (order == PYRT_SERVO_QUINTIC) {
            const double aa = knots[PYRT_SERVO_QDDA * n + j];
            const double ab = knots[PYRT_SERVO_QDDB * n + j];
            c[2] = 0.5 * aa;
            c[3] = (20.0 * h - (8.0 * vb + 12.0 * va) * T - (3.0 * aa - ab) * T2) / (2.0 * T3);
            c[4] = (-30.0 * h + (14.0 * vb + 16.0 * va) * T + (3.0 * aa - 2.0 * ab) * T2)
                   / (2.0 * T3 * T);
            c[5] = (12.0 * h - 6.0 * (vb + va) * T + (ab - aa) * T2) / (2.0 * T3 * T2);
        } else {
            c[2] = (3.0 * h - (2.0 * va + vb) * T) / T2;
            c[3] = (-2.0 * h + (va + vb) * T) / T3;
        }
        for (int r = 0; r < 6; r++) {
            st[(PYRT_SERVO_C0 + r) * n + j] = c[r];
        }
        st[PYRT_SERVO_SFFA * n + j] = knots[PYRT_SERVO_FFA * n + j];
        st[PYRT_SERVO_SFFB * n + j] = knots[PYRT_SERVO_FFB * n + j];
    }
    s->order = order;
    s->duration = duration;
    s->start = start;
    s->ticks = 0;
    s->late = 0;
    return PYRT_OK;
}

int pyrt_servo_tick(pyrt_servo *s)
{
    if (!valid(s)) {
        if (s != NULL && s->tau != NULL && s->n >= 1 && s->n <= PYRT_SERVO_MAX_JOINTS) {
            zero_out(s);
        }
        return PYRT_EINVAL;
    }
    return pyrt_servo_tick_at(s, s->last + s->period);
}

int pyrt_servo_tick_at(pyrt_servo *s, double now)
{
    if (!valid(s) || s->q == NULL) {
        if (s != NULL && s->tau != NULL && s->n >= 1 && s->n <= PYRT_SERVO_MAX_JOINTS) {
            zero_out(s);
        }
        return PYRT_EINVAL;
    }
    const int32_t n = s->n;
    const double *q = s->q, *g = s->gains;
    double *st = s->state, *tau = s->tau;
    for (int32_t j = 0; j < n; j++) {
        if (!isfinite(q[j])) {
            zero_out(s);
            return PYRT_ENONFINITE;
        }
    }
    const int rc = check_gains(g, n);
    if (rc != PYRT_OK) {
        zero_out(s);
        return rc;
    }
    /* the time that passed: the velocity estimate over it, the integral over it
     * within its bound */
    const double dt = now - s->last;
    if (!isfinite(now) || !isfinite(dt)) {
        zero_out(s);
        return PYRT_ENONFINITE;
    }
    if (dt < 0.0) {
        zero_out(s);
        return PYRT_EINVAL;
    }
    s->last = now;
    s->dt = dt;
    const double bound = PYRT_SERVO_MAX_DT_PERIODS * s->period;
    double dt_i = dt;
    if (dt > bound) {
        dt_i = bound;
        if (s->stalls < INT32_MAX) {
            s->stalls += 1;
        }
        if (dt > s->stall_max) {
            s->stall_max = dt;
        }
    }

    /* the velocity estimate (no time passed: unchanged) */
    for (int32_t j = 0; j < n && dt > 0.0; j++) {
        const double alpha = 1.0 - exp(-TWO_PI * g[PYRT_SERVO_VELHZ * n + j] * dt);
        const double raw = (q[j] - st[PYRT_SERVO_QLAST * n + j]) / dt;
        double *v = &st[PYRT_SERVO_VEL * n + j];
        *v += alpha * (raw - *v);
        st[PYRT_SERVO_QLAST * n + j] = q[j];
    }
    if (s->tripped) {
        zero_out(s);
        return PYRT_OK;
    }

    /* the segment clock and the reference */
    double t, frac;
    int held;
    if (s->order == PYRT_SERVO_HOLD) {
        t = 0.0;
        frac = 1.0;
        held = 1;
    } else {
        const double half = 0.5 * s->period;
        t = now - s->start;
        if (t < 0.0) {
            t = 0.0; /* the segment starts later: knot A until then */
        }
        if (t < s->duration + half) {
            s->ticks += 1;
        }
        held = t > s->duration + half;
        if (held) {
            if (s->late < INT32_MAX) {
                s->late += 1;
            }
        }
        if (t >= s->duration) {
            t = s->duration;
        }
        frac = t / s->duration;
    }
    for (int32_t j = 0; j < n; j++) {
        const double c0 = st[PYRT_SERVO_C0 * n + j], c1 = st[(PYRT_SERVO_C0 + 1) * n + j];
        const double c2 = st[(PYRT_SERVO_C0 + 2) * n + j], c3 = st[(PYRT_SERVO_C0 + 3) * n + j];
        const double c4 = st[(PYRT_SERVO_C0 + 4) * n + j], c5 = st[(PYRT_SERVO_C0 + 5) * n + j];
        st[PYRT_SERVO_QREF * n + j] = c0 + t * (c1 + t * (c2 + t * (c3 + t * (c4 + t * c5))));
        if (held) {
            st[PYRT_SERVO_QDREF * n + j] = 0.0;
            st[PYRT_SERVO_QDDREF * n + j] = 0.0;
        } else {
            st[PYRT_SERVO_QDREF * n + j] =
                c1 + t * (2.0 * c2 + t * (3.0 * c3 + t * (4.0 * c4 + t * 5.0 * c5)));
            st[PYRT_SERVO_QDDREF * n + j] =
                2.0 * c2 + t * (6.0 * c3 + t * (12.0 * c4 + t * 20.0 * c5));
        }
        const double fa = st[PYRT_SERVO_SFFA * n + j];
        st[PYRT_SERVO_FF * n + j] = fa + (st[PYRT_SERVO_SFFB * n + j] - fa) * frac;
        st[PYRT_SERVO_ERR * n + j] = st[PYRT_SERVO_QREF * n + j] - q[j];
    }

    /* the following error: the joint furthest beyond its limit trips the robot */
    int32_t worst = -1;
    double ratio = 1.0;
    for (int32_t j = 0; j < n; j++) {
        const double r = fabs(st[PYRT_SERVO_ERR * n + j]) / g[PYRT_SERVO_FELIM * n + j];
        if (r > ratio) {
            ratio = r;
            worst = j;
        }
    }
    if (worst >= 0) {
        s->tripped = 1;
        s->trip_joint = worst;
        s->trip_error = st[PYRT_SERVO_ERR * n + worst];
        for (int32_t j = 0; j < n; j++) {
            st[PYRT_SERVO_INTEG * n + j] = 0.0;
        }
        zero_out(s);
        return PYRT_OK;
    }

    /* the law */
    for (int32_t j = 0; j < n; j++) {
        const double e = st[PYRT_SERVO_ERR * n + j];
        const double pd = g[PYRT_SERVO_KP * n + j] * e
            + g[PYRT_SERVO_KD * n + j] * (st[PYRT_SERVO_QDREF * n + j] - st[PYRT_SERVO_VEL * n + j])
            + g[PYRT_SERVO_KV * n + j] * st[PYRT_SERVO_QDREF * n + j]
            + g[PYRT_SERVO_KA * n + j] * st[PYRT_SERVO_QDDREF * n + j]
            + g[PYRT_SERVO_KFF * n + j] * st[PYRT_SERVO_FF * n + j];
        const double ilim = g[PYRT_SERVO_ILIM * n + j], tmax = g[PYRT_SERVO_TMAX * n + j];
        const double old = st[PYRT_SERVO_INTEG * n + j];
        double integ = old + g[PYRT_SERVO_KI * n + j] * e * dt_i;
        integ = integ > ilim ? ilim : (integ < -ilim ? -ilim : integ);
        double u = pd + integ;
        if ((u > tmax && e > 0.0) || (u < -tmax && e < 0.0)) {
            integ = old > ilim ? ilim : (old < -ilim ? -ilim : old);
            u = pd + integ;
        }
        st[PYRT_SERVO_INTEG * n + j] = integ;
        tau[j] = u > tmax ? tmax : (u < -tmax ? -tmax : u);
    }
    return PYRT_OK;
}

int pyrt_servo_encoders(pyrt_servo_board *b, int32_t n, const int64_t *counts)
{
    if (b == NULL || counts == NULL || b->counts_per_unit == NULL || b->last == NULL
        || b->total == NULL || b->q == NULL || n < 1 || n > PYRT_SERVO_MAX_JOINTS) {
        return PYRT_EINVAL;
    }
    const int64_t two31 = (int64_t)1 << 31, two32 = (int64_t)1 << 32;
    for (int32_t j = 0; j < n; j++) {
        if (counts[j] == b->last[j]) {
            continue;
        }
        int64_t d = counts[j] - b->last[j];
        if (d < -two31 || d >= two31) {
            d = (d + two31) % two32;
            d = (d < 0 ? d + two32 : d) - two31;
        }
        b->total[j] += d;
        b->last[j] = counts[j];
        b->q[j] = ((double)b->total[j] + 0.5) / b->counts_per_unit[j];
    }
    return PYRT_OK;
}

int pyrt_servo_tick_board(pyrt_servo *s, double now, pyrt_servo_board *b,
                          const int64_t *counts)
{
    const int ok = valid(s);
    if (b == NULL) {
        if (ok) {
            zero_out(s);
        }
        return PYRT_EINVAL;
    }
    b->changed = 0;
    b->beyond = -1;
    b->outcome = -1;
    if (!ok || b->lo == NULL || b->hi == NULL || b->dac_per_unit == NULL || b->dac == NULL
        || b->dac_full <= 0 || b->q != s->q) {
        if (ok) {
            zero_out(s);
        }
        return PYRT_EINVAL;
    }
    int rc = pyrt_servo_encoders(b, s->n, counts);
    if (rc != PYRT_OK) {
        zero_out(s);
        return rc;
    }
    const int32_t was_tripped = s->tripped, stalls = s->stalls;
    rc = pyrt_servo_tick_at(s, now);
    if (rc != PYRT_OK) {
        return rc;
    }
    if (s->tripped) {
        b->outcome = (!was_tripped || s->stalls != stalls) ? -1 : 0;
        return PYRT_OK;
    }
    const int32_t n = s->n;
    const double full = (double)b->dac_full;
    uint64_t changed = 0;
    for (int32_t j = 0; j < n; j++) {
        const double q = s->q[j];
        if (q < b->lo[j] || q > b->hi[j]) {
            b->beyond = j;
            break;
        }
        double c = rint(s->tau[j] * b->dac_per_unit[j]);
        if (!(c <= full)) {
            c = isnan(c) ? 0.0 : full;
        }
        if (c < -full) {
            c = -full;
        }
        const int32_t v = (int32_t)c;
        if (v != b->dac[j]) {
            b->dac[j] = v;
            changed |= (uint64_t)1 << j;
        }
    }
    b->changed = changed;
    b->outcome = (b->beyond >= 0 || s->stalls != stalls) ? -1 : (int64_t)changed;
    return PYRT_OK;
}
