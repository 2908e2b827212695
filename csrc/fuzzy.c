/*
 * The ten fuzzy rules of the 000 Axis controller (VELOCITY_MODE).  See
 * fuzzy.h for the rule table, the defaults and their reasons.
 */
#include "fuzzy.h"

#include <math.h>
#include <stddef.h>

/* Rising shoulder: 0 at or below zero, 1 at or above full, linear between. */
static double up(double x, double zero, double full)
{
    if (x <= zero)
        return 0.0;
    if (x >= full)
        return 1.0;
    return (x - zero) / (full - zero);
}

/* Falling shoulder: 1 at or below full, 0 at or above zero, linear between. */
static double down(double x, double full, double zero)
{
    if (x <= full)
        return 1.0;
    if (x >= zero)
        return 0.0;
    return (zero - x) / (zero - full);
}

static double sgn(double x)
{
    return x > 0.0 ? 1.0 : (x < 0.0 ? -1.0 : 0.0);
}

int pyrt_fuzzy_default_params(pyrt_fuzzy_params *p)
{
    if (p == NULL)
        return PYRT_EINVAL;
    p->low_t_full = PYRT_FUZZY_DEFAULT_LOW_T_FULL;
    p->low_t_zero = PYRT_FUZZY_DEFAULT_LOW_T_ZERO;
    p->high_t_zero = PYRT_FUZZY_DEFAULT_HIGH_T_ZERO;
    p->high_t_full = PYRT_FUZZY_DEFAULT_HIGH_T_FULL;
    p->len_zero = PYRT_FUZZY_DEFAULT_LEN_ZERO;
    p->len_full = PYRT_FUZZY_DEFAULT_LEN_FULL;
    p->rel_zero = PYRT_FUZZY_DEFAULT_REL_ZERO;
    p->rel_full = PYRT_FUZZY_DEFAULT_REL_FULL;
    p->near_end_relax = PYRT_FUZZY_DEFAULT_NEAR_END_RELAX;
    p->vel_zero = PYRT_FUZZY_DEFAULT_VEL_ZERO;
    p->vel_full = PYRT_FUZZY_DEFAULT_VEL_FULL;
    p->len_rate_zero = PYRT_FUZZY_DEFAULT_LEN_RATE_ZERO;
    p->len_rate_full = PYRT_FUZZY_DEFAULT_LEN_RATE_FULL;
    p->t_rate_zero = PYRT_FUZZY_DEFAULT_T_RATE_ZERO;
    p->t_rate_full = PYRT_FUZZY_DEFAULT_T_RATE_FULL;
    p->dv_zero = PYRT_FUZZY_DEFAULT_DV_ZERO;
    p->dv_full = PYRT_FUZZY_DEFAULT_DV_FULL;
    p->dv_tension = PYRT_FUZZY_DEFAULT_DV_TENSION;
    p->dv_length = PYRT_FUZZY_DEFAULT_DV_LENGTH;
    p->dv_rel_tension = PYRT_FUZZY_DEFAULT_DV_REL_TENSION;
    p->dv_velocity = PYRT_FUZZY_DEFAULT_DV_VELOCITY;
    p->dv_len_rate = PYRT_FUZZY_DEFAULT_DV_LEN_RATE;
    p->dv_t_rate = PYRT_FUZZY_DEFAULT_DV_T_RATE;
    p->dv_damping = PYRT_FUZZY_DEFAULT_DV_DAMPING;
    return PYRT_OK;
}

int pyrt_fuzzy_check_params(const pyrt_fuzzy_params *p)
{
    const double *v;
    size_t i;
    if (p == NULL)
        return PYRT_EINVAL;
    v = (const double *)p;
    for (i = 0; i < sizeof(*p) / sizeof(double); i++)
        if (!isfinite(v[i]))
            return PYRT_ENONFINITE;
    if (!(p->low_t_full < p->low_t_zero) || !(p->high_t_full < p->high_t_zero))
        return PYRT_EINVAL;
    if (!(p->len_zero >= 0.0 && p->len_zero < p->len_full))
        return PYRT_EINVAL;
    if (!(p->rel_zero >= 0.0 && p->rel_zero < p->rel_full))
        return PYRT_EINVAL;
    if (!(p->vel_zero >= 0.0 && p->vel_zero < p->vel_full))
        return PYRT_EINVAL;
    if (!(p->len_rate_zero >= 0.0 && p->len_rate_zero < p->len_rate_full))
        return PYRT_EINVAL;
    if (!(p->t_rate_zero >= 0.0 && p->t_rate_zero < p->t_rate_full))
        return PYRT_EINVAL;
    if (!(p->dv_zero >= 0.0 && p->dv_zero < p->dv_full))
        return PYRT_EINVAL;
    if (p->dv_tension < 0.0 || p->dv_length < 0.0 || p->dv_rel_tension < 0.0
        || p->dv_velocity < 0.0 || p->dv_len_rate < 0.0 || p->dv_t_rate < 0.0)
        return PYRT_EINVAL;
    if (!(p->dv_damping >= 0.0 && p->dv_damping <= 1.0))
        return PYRT_EINVAL;
    if (!(p->near_end_relax >= 0.0 && p->near_end_relax <= 1.0))
        return PYRT_EINVAL;
    return PYRT_OK;
}

static int check_row(const double *in)
{
    int j;
    for (j = 0; j < PYRT_FUZZY_NINPUTS; j++)
        if (!isfinite(in[j]))
            return PYRT_ENONFINITE;
    if (!(in[PYRT_FUZZY_IN_FREE] >= 0.0 && in[PYRT_FUZZY_IN_FREE] <= 1.0))
        return PYRT_EINVAL;
    if (!(in[PYRT_FUZZY_IN_NEAR_END] >= 0.0 && in[PYRT_FUZZY_IN_NEAR_END] <= 1.0))
        return PYRT_EINVAL;
    if (!(in[PYRT_FUZZY_IN_TENSION_LOW] < in[PYRT_FUZZY_IN_TENSION_HIGH]))
        return PYRT_EINVAL;
    return PYRT_OK;
}

static double axis_rules(const pyrt_fuzzy_params *p, const double *in, double *r)
{
    double t = in[PYRT_FUZZY_IN_TENSION];
    double te = t - in[PYRT_FUZZY_IN_DESIRED_TENSION];
    double bound = in[PYRT_FUZZY_IN_FREE];
    double e = in[PYRT_FUZZY_IN_LENGTH_ERROR];
    double v = in[PYRT_FUZZY_IN_VELOCITY];
    double elv = in[PYRT_FUZZY_IN_LENGTH_ERROR_RATE];
    double etv = in[PYRT_FUZZY_IN_TENSION_ERROR_RATE];
    double dvl = in[PYRT_FUZZY_IN_LAST_DV];
    double t_low = in[PYRT_FUZZY_IN_TENSION_LOW];
    double t_high = in[PYRT_FUZZY_IN_TENSION_HIGH];
    double gate, dv;
    int k;

    bound = 1.0 - bound;                                /* NOT free */
    gate = bound * (1.0 - p->near_end_relax * in[PYRT_FUZZY_IN_NEAR_END]);

    r[0] = down(t, t_low + p->low_t_full, t_low + p->low_t_zero) * -p->dv_tension;
    r[1] = up(t, t_high - p->high_t_zero, t_high - p->high_t_full) * p->dv_tension;
    r[2] = up(-e, p->len_zero, p->len_full) * p->dv_length;
    r[3] = up(e, p->len_zero, p->len_full) * -p->dv_length;
    r[4] = gate * up(-te, p->rel_zero, p->rel_full) * -p->dv_rel_tension;
    r[5] = gate * up(te, p->rel_zero, p->rel_full) * p->dv_rel_tension;
    r[6] = up(fabs(v), p->vel_zero, p->vel_full) * (-sgn(v) * p->dv_velocity);
    r[7] = up(fabs(elv), p->len_rate_zero, p->len_rate_full) * (-sgn(elv) * p->dv_len_rate);
    r[8] = bound * up(fabs(etv), p->t_rate_zero, p->t_rate_full) * (sgn(etv) * p->dv_t_rate);
    r[9] = up(fabs(dvl), p->dv_zero, p->dv_full) * (-p->dv_damping * dvl);

    dv = 0.0;
    for (k = 0; k < PYRT_FUZZY_NRULES; k++)
        dv += r[k];
    return dv;
}

int pyrt_fuzzy_step(int32_t n, const pyrt_fuzzy_params *params, int32_t nparams,
                    const double *inputs, double *dv, double *rules)
{
    double r[PYRT_FUZZY_NRULES];
    int32_t i;
    int rc, k;

    if (n < 1 || n > PYRT_FUZZY_MAX_AXES || params == NULL || inputs == NULL || dv == NULL)
        return PYRT_EINVAL;
    if (nparams != 1 && nparams != n)
        return PYRT_EINVAL;
    for (i = 0; i < nparams; i++) {
        rc = pyrt_fuzzy_check_params(params + i);
        if (rc != PYRT_OK)
            return rc;
    }
    for (i = 0; i < n; i++) {
        rc = check_row(inputs + (size_t)i * PYRT_FUZZY_NINPUTS);
        if (rc != PYRT_OK)
            return rc;
    }
    for (i = 0; i < n; i++) {
        const pyrt_fuzzy_params *p = params + (nparams == 1 ? 0 : i);
        dv[i] = axis_rules(p, inputs + (size_t)i * PYRT_FUZZY_NINPUTS, r);
        if (rules != NULL)
            for (k = 0; k < PYRT_FUZZY_NRULES; k++)
                rules[(size_t)i * PYRT_FUZZY_NRULES + k] = r[k];
    }
    return PYRT_OK;
}

int pyrt_fuzzy_run(const pyrt_fuzzy_batch *b)
{
    if (b == NULL)
        return PYRT_EINVAL;
    return pyrt_fuzzy_step(b->n, b->params, b->nparams, b->inputs, b->dv, b->rules);
}
