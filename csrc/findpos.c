/*
 * The iterated-linear position finder of 000 (section 5, Eq. 1-2) and the
 * forward rope geometry.  See findpos.h for the conventions.
 */
#include "findpos.h"

#include <math.h>
#include <stddef.h>

/* A normal matrix whose determinant is below this fraction of the product
 * of its diagonal terms is singular. */
#define SINGULAR_RATIO 1.0e-12

static int all_finite(const double *v, int32_t count)
{
    int32_t i;
    for (i = 0; i < count; i++)
        if (!isfinite(v[i]))
            return 0;
    return 1;
}

/*
 * Classify bottom row i: 1 = side rope (finite), 0 = central rope (all NaN),
 * or a negative status for anything else.
 */
static int bottom_kind(const double *b)
{
    if (isnan(b[0]) && isnan(b[1]) && isnan(b[2]))
        return 0;
    if (isfinite(b[0]) && isfinite(b[1]) && isfinite(b[2]))
        return 1;
    if (isnan(b[0]) || isnan(b[1]) || isnan(b[2]))
        return -PYRT_EINVAL;      /* partly NaN: neither central nor side */
    return -PYRT_ENONFINITE;
}

/* Check the geometry shared by the solver and the forward map. */
static int check_geometry(int32_t n, const double *tops, const double *bottoms,
                          const double *offsets)
{
    int32_t i;
    if (n < 1 || n > PYRT_FINDPOS_MAX_ROPES)
        return PYRT_EINVAL;
    if (tops == NULL || bottoms == NULL)
        return PYRT_EINVAL;
    for (i = 0; i < n; i++) {
        int kind = bottom_kind(bottoms + 3 * i);
        if (kind < 0)
            return -kind;
    }
    if (!all_finite(tops, 3 * n))
        return PYRT_ENONFINITE;
    if (offsets != NULL && !all_finite(offsets, 3 * n))
        return PYRT_ENONFINITE;
    return PYRT_OK;
}

/*
 * Unit vector from point p toward point q; returns the distance, or a
 * negative number when the points are closer than PYRT_MIN_SEGMENT_CM.
 */
static double toward(const double *p, const double *q, double *u)
{
    double d0 = q[0] - p[0], d1 = q[1] - p[1], d2 = q[2] - p[2];
    double len = sqrt(d0 * d0 + d1 * d1 + d2 * d2);
    double inv;
    if (!(len >= PYRT_MIN_SEGMENT_CM))
        return -1.0;
    inv = 1.0 / len;
    u[0] = d0 * inv;
    u[1] = d1 * inv;
    u[2] = d2 * inv;
    return len;
}

/*
 * Geometry of rope i for a source at x: predicted length and the gradient
 * direction a = ut + ub (the derivative of the residual with respect to x).
 * Returns PYRT_OK or PYRT_EDEGENERATE.
 */
static int rope_at(const double *top, const double *bottom, const double *offset,
                   const double *x, double *length, double *a)
{
    double p[3], ut[3], ub[3];
    double lt, lb;
    p[0] = x[0];
    p[1] = x[1];
    p[2] = x[2];
    if (offset != NULL) {
        p[0] += offset[0];
        p[1] += offset[1];
        p[2] += offset[2];
    }
    lt = toward(p, top, ut);
    if (lt < 0.0)
        return PYRT_EDEGENERATE;
    a[0] = ut[0];
    a[1] = ut[1];
    a[2] = ut[2];
    *length = lt;
    if (!isnan(bottom[0])) {
        lb = toward(p, bottom, ub);
        if (lb < 0.0)
            return PYRT_EDEGENERATE;
        a[0] += ub[0];
        a[1] += ub[1];
        a[2] += ub[2];
        *length += lb;
    }
    return PYRT_OK;
}

/*
 * Solve m d = -g for the unfrozen components (m symmetric positive
 * semi-definite); frozen components of d are zero.  The reduced system
 * (1x1, 2x2 or 3x3) is solved in closed form with one division.  It is
 * singular when its determinant is below SINGULAR_RATIO times the product
 * of its diagonal (by Hadamard's inequality that ratio lies in 0..1 and
 * measures how close the rope directions are to not spanning).
 */
static int solve_normal(const double m[3][3], const double g[3], const int32_t freeze[3],
                        double d[3])
{
    int idx[3];
    int k = 0, i;

    for (i = 0; i < 3; i++) {
        d[i] = 0.0;
        if (!freeze[i])
            idx[k++] = i;
    }
    if (k == 1) {
        double a = m[idx[0]][idx[0]];
        if (!(a > 0.0))
            return PYRT_ESINGULAR;
        d[idx[0]] = -g[idx[0]] / a;
    } else if (k == 2) {
        int p = idx[0], q = idx[1];
        double a = m[p][p], b = m[p][q], c = m[q][q];
        double det = a * c - b * b, inv;
        if (!(det > SINGULAR_RATIO * a * c) || !(a > 0.0 && c > 0.0))
            return PYRT_ESINGULAR;
        inv = 1.0 / det;
        d[p] = -(c * g[p] - b * g[q]) * inv;
        d[q] = -(a * g[q] - b * g[p]) * inv;
    } else if (k == 3) {
        double c00 = m[1][1] * m[2][2] - m[1][2] * m[1][2];
        double c01 = m[0][2] * m[1][2] - m[0][1] * m[2][2];
        double c02 = m[0][1] * m[1][2] - m[0][2] * m[1][1];
        double c11 = m[0][0] * m[2][2] - m[0][2] * m[0][2];
        double c12 = m[0][1] * m[0][2] - m[0][0] * m[1][2];
        double c22 = m[0][0] * m[1][1] - m[0][1] * m[0][1];
        double det = m[0][0] * c00 + m[0][1] * c01 + m[0][2] * c02, inv;
        if (!(det > SINGULAR_RATIO * m[0][0] * m[1][1] * m[2][2]))
            return PYRT_ESINGULAR;
        inv = 1.0 / det;
        d[0] = -(c00 * g[0] + c01 * g[1] + c02 * g[2]) * inv;
        d[1] = -(c01 * g[0] + c11 * g[1] + c12 * g[2]) * inv;
        d[2] = -(c02 * g[0] + c12 * g[1] + c22 * g[2]) * inv;
    } else {
        return PYRT_ESINGULAR;
    }
    return PYRT_OK;
}

int pyrt_findpos_freeze_mask(int32_t n, const double *bottoms, int32_t *freeze)
{
    double sum[3] = {0.0, 0.0, 0.0};
    int32_t i;
    int j;
    if (n < 1 || n > PYRT_FINDPOS_MAX_ROPES || bottoms == NULL || freeze == NULL)
        return PYRT_EINVAL;
    for (i = 0; i < n; i++) {
        const double *b = bottoms + 3 * i;
        int kind = bottom_kind(b);
        if (kind < 0)
            return -kind;
        if (kind == 1)
            for (j = 0; j < 3; j++)
                sum[j] += fabs(b[j]);
    }
    for (j = 0; j < 3; j++)
        freeze[j] = sum[j] < (double)PYRT_FINDPOS_FREEZE_CM ? 1 : 0;
    return PYRT_OK;
}

/*
 * One linearisation at x (Eq. 2 with the directions held fixed): the normal
 * matrix m (upper triangle: m00 m01 m02 m11 m12 m22) and g = sum a_i r_i,
 * where r_i = measured - predicted and a_i = ut_i + ub_i is the derivative
 * of r_i with respect to x, so that r(x + d) = r(x) + a . d.
 */
static int linearise(const pyrt_findpos_problem *p, const double *x, double m[6], double g[3])
{
    double m00 = 0.0, m01 = 0.0, m02 = 0.0, m11 = 0.0, m12 = 0.0, m22 = 0.0;
    double g0 = 0.0, g1 = 0.0, g2 = 0.0;
    int32_t i;
    for (i = 0; i < p->n; i++) {
        double a[3], pred, r;
        int rc = rope_at(p->tops + 3 * i, p->bottoms + 3 * i,
                         p->offsets != NULL ? p->offsets + 3 * i : NULL, x, &pred, a);
        if (rc != PYRT_OK)
            return rc;
        r = p->lengths[i] - pred;
        g0 += a[0] * r;
        g1 += a[1] * r;
        g2 += a[2] * r;
        m00 += a[0] * a[0];
        m01 += a[0] * a[1];
        m02 += a[0] * a[2];
        m11 += a[1] * a[1];
        m12 += a[1] * a[2];
        m22 += a[2] * a[2];
    }
    m[0] = m00; m[1] = m01; m[2] = m02; m[3] = m11; m[4] = m12; m[5] = m22;
    g[0] = g0; g[1] = g1; g[2] = g2;
    return PYRT_OK;
}

/* Distance from p to q, or a negative number below PYRT_MIN_SEGMENT_CM. */
static double distance(const double *p, const double *q)
{
    double d0 = q[0] - p[0], d1 = q[1] - p[1], d2 = q[2] - p[2];
    double len = sqrt(d0 * d0 + d1 * d1 + d2 * d2);
    return len >= PYRT_MIN_SEGMENT_CM ? len : -1.0;
}

/* Residuals (measured - predicted) at x and their sum of squares. */
static int residuals_at(const pyrt_findpos_problem *p, const double *x, double *res, double *ss)
{
    double sum = 0.0;
    int32_t i;
    for (i = 0; i < p->n; i++) {
        const double *b = p->bottoms + 3 * i;
        double c[3], lt, lb = 0.0;
        c[0] = x[0];
        c[1] = x[1];
        c[2] = x[2];
        if (p->offsets != NULL) {
            c[0] += p->offsets[3 * i];
            c[1] += p->offsets[3 * i + 1];
            c[2] += p->offsets[3 * i + 2];
        }
        lt = distance(c, p->tops + 3 * i);
        if (!isnan(b[0]))
            lb = distance(c, b);
        if (lt < 0.0 || lb < 0.0)
            return PYRT_EDEGENERATE;
        res[i] = p->lengths[i] - (lt + lb);
        sum += res[i] * res[i];
    }
    *ss = sum;
    return PYRT_OK;
}

int pyrt_findpos_solve(pyrt_findpos_problem *p)
{
    double x[3], res[PYRT_FINDPOS_MAX_ROPES];
    double ss = 0.0;
    int32_t n, i, it;
    int rc;

    if (p == NULL)
        return PYRT_EINVAL;
    n = p->n;
    rc = check_geometry(n, p->tops, p->bottoms, p->offsets);
    if (rc != PYRT_OK)
        return rc;
    if (p->lengths == NULL || p->position == NULL || p->residuals == NULL)
        return PYRT_EINVAL;
    if (!(p->tol > 0.0) || !isfinite(p->tol) || p->max_iter < 1)
        return PYRT_EINVAL;
    if (p->freeze[0] && p->freeze[1] && p->freeze[2])
        return PYRT_EINVAL;
    if (!all_finite(p->lengths, n) || !all_finite(p->position, 3))
        return PYRT_ENONFINITE;

    x[0] = p->position[0];
    x[1] = p->position[1];
    x[2] = p->position[2];
    for (it = 1; it <= p->max_iter; it++) {
        double mu[6], m[3][3], g[3], d[3];
        rc = linearise(p, x, mu, g);
        if (rc != PYRT_OK)
            return rc;
        m[0][0] = mu[0]; m[0][1] = mu[1]; m[0][2] = mu[2];
        m[1][0] = mu[1]; m[1][1] = mu[3]; m[1][2] = mu[4];
        m[2][0] = mu[2]; m[2][1] = mu[4]; m[2][2] = mu[5];
        rc = solve_normal(m, g, p->freeze, d);
        if (rc != PYRT_OK)
            return rc;
        x[0] += d[0];
        x[1] += d[1];
        x[2] += d[2];
        if (!all_finite(x, 3))
            return PYRT_ENOCONVERGE;
        if (d[0] * d[0] + d[1] * d[1] + d[2] * d[2] < p->tol * p->tol)
            break;
    }
    if (it > p->max_iter)
        return PYRT_ENOCONVERGE;

    rc = residuals_at(p, x, res, &ss);
    if (rc != PYRT_OK)
        return rc;
    for (i = 0; i < n; i++)
        p->residuals[i] = res[i];
    p->position[0] = x[0];
    p->position[1] = x[1];
    p->position[2] = x[2];
    p->rms = sqrt(ss / (double)n);
    p->iterations = it;
    return PYRT_OK;
}

int pyrt_rope_lengths(int32_t n, const double *tops, const double *bottoms,
                      const double *offsets, const double *position,
                      double *total, double *top_len, double *bottom_len,
                      double *top_dir, double *bottom_dir)
{
    int32_t i;
    int rc = check_geometry(n, tops, bottoms, offsets);
    if (rc != PYRT_OK)
        return rc;
    if (position == NULL || total == NULL)
        return PYRT_EINVAL;
    if (!all_finite(position, 3))
        return PYRT_ENONFINITE;
    /* Check every rope before writing anything. */
    for (i = 0; i < n; i++) {
        double a[3], len;
        rc = rope_at(tops + 3 * i, bottoms + 3 * i, offsets != NULL ? offsets + 3 * i : NULL,
                     position, &len, a);
        if (rc != PYRT_OK)
            return rc;
    }
    for (i = 0; i < n; i++) {
        const double *b = bottoms + 3 * i;
        double p[3], ut[3], ub[3] = {0.0, 0.0, 0.0};
        double lt, lb = 0.0;
        int j;
        for (j = 0; j < 3; j++)
            p[j] = position[j] + (offsets != NULL ? offsets[3 * i + j] : 0.0);
        lt = toward(p, tops + 3 * i, ut);
        if (!isnan(b[0]))
            lb = toward(p, b, ub);
        total[i] = lt + lb;
        if (top_len != NULL)
            top_len[i] = lt;
        if (bottom_len != NULL)
            bottom_len[i] = lb;
        for (j = 0; j < 3; j++) {
            if (top_dir != NULL)
                top_dir[3 * i + j] = ut[j];
            if (bottom_dir != NULL)
                bottom_dir[3 * i + j] = ub[j];
        }
    }
    return PYRT_OK;
}
