/*
 * The ten fuzzy rules of the 000 Axis controller (VELOCITY_MODE).  See
 * fuzzy.h for the rule table; the defaults and their reasons are here.
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
    /*
     * Tension guards (rules 0, 1), offsets inward from the bounds.  LowT is
     * full 1 N above the lower bound and gone 5 N above it, so with a bound
     * of a few newtons it stays silent at the 10 N off-side target and
     * takes over well before LOW_TENSION_STOP.  HighT starts 15 N below the
     * upper bound (a quarter of the 60 N working range) and is full 2 N
     * below it.  dv_tension 0.4 cm/s per poll is the document's "increase
     * tension = -0.4 cm/s"; it is the strongest rule, below DV_LIMIT 0.5.
     */
    p->low_t_full = 1.0;
    p->low_t_zero = 5.0;
    p->high_t_zero = 15.0;
    p->high_t_full = 2.0;
    p->dv_tension = 0.4;
    /*
     * Length (rules 2, 3): linear from no error to 1 cm, no dead band, so
     * that near the target the rules act as the proportional term of a PD
     * loop and the velocity integrator cannot drift inside a dead band.
     * With the 50 ms poll, 0.1 cm/s per poll at 1 cm is an acceleration of
     * 2 cm/s^2 per cm of error: omega = sqrt(0.1 / (1 cm * 0.05 s)) =
     * 1.4 rad/s, a 4.4 s natural period; the hare's 20 cm ramps to
     * 2 cm/s ask for 0.1 cm/s^2, which this loop follows 0.05 cm behind.
     */
    p->len_zero = 0.0;
    p->len_full = 1.0;
    p->dv_length = 0.1;
    /*
     * Length-error rate damping (rule 7): linear up to 2 cm/s (the hare's
     * top speed), 0.25 cm/s per poll at full: 0.25 / (2 * 0.05) = 2.5 /s =
     * 2 zeta omega, zeta = 0.9 with the length rules above.  With the
     * length rules saturated (errors over 1 cm) the two balance at a
     * closing speed of 0.1 / 0.125 = 0.8 cm/s, so a large error is taken up
     * steadily instead of with a lunge.
     */
    p->len_rate_zero = 0.0;
    p->len_rate_full = 2.0;
    p->dv_len_rate = 0.25;
    /*
     * Relative tension (rules 4, 5) for a rope with a target (the off-side
     * rope at 10 N): a 0.5 N dead band for loadcell noise and offset (the
     * document found tension errors stopping the source near the end), full
     * at 5 N.  0.2 cm/s per poll at 5 N (0.04 per N) beats the length rules
     * (0.1 per cm) for any rope stiffer than 2.5 N/cm of paid-out length,
     * which every tensioned rope is (a 1000 cm rope of compliance 1e-4 per
     * N is 10 N/cm), so the off-side rope behaves as an idler as the
     * document intends.  Near the end 75 % of the rule is
     * relaxed ("only partially relaxed").
     */
    p->rel_zero = 0.5;
    p->rel_full = 5.0;
    p->dv_rel_tension = 0.2;
    p->near_end_relax = 0.75;
    /*
     * Tension-error rate damping (rule 8): stops two side ropes trading
     * tension in an oscillation (the document's common scenario).  Full at
     * 40 N/s (a rope of ~40 N/cm moving at 1 cm/s), 0.25 cm/s per poll:
     * 0.25 / 40 / 0.05 = 0.125 cm/s^2 of velocity change per N/s.
     *
     * The whole set was checked in closed loop on the prototype statics
     * (5.3 kg source, dead length 453 cm, rope compliance 5e-6 to 1e-4 per
     * N, loadcell noise 0.5 N, 20 and 50 ms polls): every target the
     * tension bounds allow ends within 0.1 cm in plane with the tensions
     * between 8 and 58 N; a target that needs a rope below its bound is
     * held off by the guards instead of being reached.
     */
    p->t_rate_zero = 0.0;
    p->t_rate_full = 40.0;
    p->dv_t_rate = 0.25;
    /*
     * Velocity high (rule 6): a soft speed limit between 5 cm/s and the
     * motor's 7.0 cm/s cruise maximum; the hare never asks for more than
     * 2 cm/s of source speed, so this only catches a run-away.
     */
    p->vel_zero = 5.0;
    p->vel_full = 7.0;
    p->dv_velocity = 0.3;
    /*
     * dv high (rule 9, the document's deltaDV(dv, ...)): above 0.1 cm/s per
     * poll the next change is cut by up to half of the last one, full at
     * DV_LIMIT 0.5, so bursts of velocity change (the ones that stall a
     * stepper) are smoothed over several polls.
     */
    p->dv_zero = 0.1;
    p->dv_full = 0.5;
    p->dv_damping = 0.5;
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
