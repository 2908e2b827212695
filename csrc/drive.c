/*
 * The on-board servo of a motion-control board, hardware (a) (drive.h).
 */
#include "drive.h"

#include <math.h>
#include <stddef.h>

#define TWO31 2147483648.0
#define TWO32 4294967296.0

static int valid(const pyrt_drive *d)
{
    return d != NULL && d->n >= 1 && d->n <= PYRT_DRIVE_MAX_JOINTS && d->params != NULL
        && d->setpoint != NULL && d->velocity != NULL && d->torque != NULL
        && d->felim != NULL && d->count != NULL && d->dac != NULL && d->amp != NULL
        && d->ferr != NULL && d->work != NULL && d->servo.n == d->n
        && d->servo.gains != NULL && d->servo.state != NULL && isfinite(d->period)
        && d->period > 0.0 && d->servo.period == d->period;
}

static void outputs_off(pyrt_drive *d)
{
    for (int32_t j = 0; j < d->n; j++) {
        d->dac[j] = 0;
        d->amp[j] = 0;
    }
}

/* The step from b to a modulo 2^32, as a signed 32-bit difference. */
static double wrapped(double a, double b)
{
    double s = a - b;
    if (s >= TWO31) {
        s -= TWO32;
    } else if (s < -TWO31) {
        s += TWO32;
    }
    return s;
}

static int32_t to_int32(double v)
{
    const double r = rint(v);
    if (r > 2147483647.0) {
        return INT32_MAX;
    }
    if (r < -2147483648.0) {
        return INT32_MIN;
    }
    return (int32_t)r;
}

int pyrt_drive_tick(pyrt_drive *d)
{
    if (d == NULL) {
        return PYRT_EINVAL;
    }
    if (!valid(d)) {
        if (d->dac != NULL && d->amp != NULL && d->n >= 1 && d->n <= PYRT_DRIVE_MAX_JOINTS) {
            outputs_off(d);
        }
        return PYRT_EINVAL;
    }
    const int32_t n = d->n;
    const double *cpu = d->params + PYRT_DRIVE_COUNTS * n;
    const double *npc = d->params + PYRT_DRIVE_NM_PER_COUNT * n;
    for (int32_t j = 0; j < n; j++) {
        if (!isfinite(cpu[j]) || !isfinite(npc[j])) {
            outputs_off(d);
            return PYRT_ENONFINITE;
        }
        if (cpu[j] <= 0.0 || npc[j] <= 0.0) {
            outputs_off(d);
            return PYRT_EINVAL;
        }
    }
    double *w = d->work;
    double *last = w + PYRT_DRIVE_W_LAST * n, *total = w + PYRT_DRIVE_W_TOTAL * n;
    double *q = w + PYRT_DRIVE_W_Q * n, *tau = w + PYRT_DRIVE_W_TAU * n;
    double *k = w + PYRT_DRIVE_W_KNOTS * n;
    d->servo.q = q;
    d->servo.tau = tau;

    /* 1. the encoders */
    for (int32_t j = 0; j < n; j++) {
        const double c = (double)d->count[j];
        if (!d->primed) {
            last[j] = c;
            total[j] = c;
        } else {
            total[j] += wrapped(c, last[j]);
            last[j] = c;
        }
        q[j] = (total[j] + 0.5) / cpu[j];
    }
    d->primed = 1;

    /* 2. the power stage */
    int32_t status = 0;
    if (!d->enable) {
        d->on = 0;
        d->faulted = 0;
        d->fault_joint = 0;
    } else if (!d->faulted && !d->on) {
        int ready = d->period_us > 0;
        for (int32_t j = 0; j < n; j++) {
            ready = ready && d->felim[j] > 0;
        }
        if (!ready) {
            status |= PYRT_DRIVE_REFUSED;
        } else {
            for (int32_t j = 0; j < n; j++) {
                k[PYRT_SERVO_QB * n + j] = q[j];
                k[PYRT_SERVO_QDB * n + j] = 0.0;
                k[PYRT_SERVO_QDDB * n + j] = 0.0;
                k[PYRT_SERVO_FFB * n + j] = d->torque[j] * npc[j];
            }
            const int rc = pyrt_servo_reset(&d->servo, q, k + PYRT_SERVO_FFB * n);
            if (rc != PYRT_OK) {
                outputs_off(d);
                return rc;
            }
            d->on = 1;
            d->sync_seen = d->sync;
        }
    }
    if (!d->on) {
        outputs_off(d);
        for (int32_t j = 0; j < n && !d->faulted; j++) {
            d->ferr[j] = 0; /* faulted: the errors of the trip are kept */
        }
        if (d->faulted) {
            status |= PYRT_DRIVE_FAULT | (d->fault_joint << PYRT_DRIVE_JOINT_SHIFT);
        }
        d->status = status;
        return PYRT_OK;
    }

    /* 3. the limits and the next segment (a limit or the period written 0 while on
     * is the board's fault, joint 0) */
    int ready = d->period_us > 0;
    for (int32_t j = 0; j < n; j++) {
        ready = ready && d->felim[j] > 0;
    }
    if (!ready) {
        d->on = 0;
        d->faulted = 1;
        d->fault_joint = 0;
        outputs_off(d);
        for (int32_t j = 0; j < n; j++) {
            d->ferr[j] = 0;
        }
        d->status = PYRT_DRIVE_FAULT;
        return PYRT_OK;
    }
    double *felim = d->servo.gains + PYRT_SERVO_FELIM * n;
    for (int32_t j = 0; j < n; j++) {
        felim[j] = d->felim[j] / cpu[j];
    }
    if (d->sync != d->sync_seen) {
        d->sync_seen = d->sync;
        const double T = d->period_us * 1e-6;
        for (int32_t j = 0; j < n; j++) {
            k[PYRT_SERVO_QA * n + j] = k[PYRT_SERVO_QB * n + j];
            k[PYRT_SERVO_QDA * n + j] = k[PYRT_SERVO_QDB * n + j];
            k[PYRT_SERVO_FFA * n + j] = k[PYRT_SERVO_FFB * n + j];
            const double s = total[j] + wrapped((double)d->setpoint[j], last[j]);
            k[PYRT_SERVO_QB * n + j] = (s + 0.5) / cpu[j];
            k[PYRT_SERVO_QDB * n + j] = d->velocity[j] / cpu[j];
            k[PYRT_SERVO_FFB * n + j] = d->torque[j] * npc[j];
        }
        const int rc = pyrt_servo_load(&d->servo, k, T, PYRT_SERVO_CUBIC);
        if (rc != PYRT_OK) {
            outputs_off(d);
            return rc;
        }
    }

    /* 4. the servo */
    const int rc = pyrt_servo_tick(&d->servo);
    if (rc != PYRT_OK) {
        outputs_off(d);
        return rc;
    }
    const double *err = d->servo.state + PYRT_SERVO_ERR * n;
    if (d->servo.tripped) {
        d->on = 0;
        d->faulted = 1;
        d->fault_joint = d->servo.trip_joint + 1;
        outputs_off(d);
        status |= PYRT_DRIVE_FAULT | (d->fault_joint << PYRT_DRIVE_JOINT_SHIFT);
    } else {
        for (int32_t j = 0; j < n; j++) {
            double c = rint(tau[j] / npc[j]);
            c = c > PYRT_DRIVE_DAC_FULL ? PYRT_DRIVE_DAC_FULL
                                        : (c < -PYRT_DRIVE_DAC_FULL ? -PYRT_DRIVE_DAC_FULL : c);
            d->dac[j] = (int32_t)c;
            d->amp[j] = 1;
        }
        status |= PYRT_DRIVE_ENABLED;
        if (d->servo.late > 0) {
            status |= PYRT_DRIVE_LATE;
        }
    }

    /* 5. the inputs */
    for (int32_t j = 0; j < n; j++) {
        d->ferr[j] = to_int32(err[j] * cpu[j]);
    }
    d->status = status;
    return PYRT_OK;
}

int pyrt_drive_run(pyrt_drive *d, pyrt_arm *a, double dt)
{
    if (d == NULL || a == NULL || !valid(d) || a->n != d->n || a->dac != d->dac
        || a->enable != d->amp || a->count != d->count) {
        if (d != NULL && valid(d)) {
            outputs_off(d);
        }
        return PYRT_EINVAL;
    }
    if (!isfinite(dt)) {
        return PYRT_ENONFINITE;
    }
    if (dt < 0.0) {
        return PYRT_EINVAL;
    }
    const double period = d->period, eps = 1e-9 * period;
    double left = dt;
    if (!d->primed) {
        d->since = period;
    }
    while (left > eps) {
        if (d->since >= period - eps) {
            const int rc = pyrt_drive_tick(d);
            if (rc != PYRT_OK) {
                return rc;
            }
            d->since = 0.0;
        }
        double h = period - d->since;
        if (h > left) {
            h = left;
        }
        const int rc = pyrt_arm_step(a, h);
        if (rc != PYRT_OK) {
            return rc;
        }
        d->since += h;
        left -= h;
    }
    d->since += left;
    return PYRT_OK;
}
