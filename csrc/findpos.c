/*
 * The iterated-linear position finder of 000 (section 5, Eq. 1-2) and the
 * forward rope geometry.  See findpos.h for the conventions.
 */
#include "findpos.h"

#include <math.h>
#include <stddef.h>

#define MIN_SEGMENT_CM (PYRT_FINDPOS_MIN_SEGMENT_UM * 1.0e-4)
/* A pivot below this fraction of the largest diagonal term is singular. */
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
 * negative number when the points are closer than MIN_SEGMENT_CM.
 */
static double toward(const double *p, const double *q, double *u)
{
    double d0 = q[0] - p[0], d1 = q[1] - p[1], d2 = q[2] - p[2];
    double len = sqrt(d0 * d0 + d1 * d1 + d2 * d2);
    if (!(len >= MIN_SEGMENT_CM))
        return -1.0;
    u[0] = d0 / len;
    u[1] = d1 / len;
    u[2] = d2 / len;
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
 * Solve m d = -g for the unfrozen components by Cholesky (m is symmetric
 * positive semi-definite); frozen components of d are zero.
 */
static int solve_normal(double m[3][3], const double g[3], const int32_t freeze[3], double d[3])
{
    double l[3][3] = {{0.0, 0.0, 0.0}, {0.0, 0.0, 0.0}, {0.0, 0.0, 0.0}};
    double y[3] = {0.0, 0.0, 0.0};
    double scale = 0.0;
    int idx[3];
    int k = 0, i, j, r;

    for (i = 0; i < 3; i++) {
        d[i] = 0.0;
        if (!freeze[i]) {
            idx[k++] = i;
            if (m[i][i] > scale)
                scale = m[i][i];
        }
    }
    if (k == 0 || !(scale > 0.0))
        return PYRT_ESINGULAR;
    for (i = 0; i < k; i++) {
        for (j = 0; j <= i; j++) {
            double s = m[idx[i]][idx[j]];
            for (r = 0; r < j; r++)
                s -= l[i][r] * l[j][r];
            if (i == j) {
                if (!(s > SINGULAR_RATIO * scale))
                    return PYRT_ESINGULAR;
                l[i][i] = sqrt(s);
            } else {
                l[i][j] = s / l[j][j];
            }
        }
    }
    for (i = 0; i < k; i++) {          /* L y = -g */
        double s = -g[idx[i]];
        for (r = 0; r < i; r++)
            s -= l[i][r] * y[r];
        y[i] = s / l[i][i];
    }
    for (i = k - 1; i >= 0; i--) {     /* L^T d = y */
        double s = y[i];
        for (r = i + 1; r < k; r++)
            s -= l[r][i] * d[idx[r]];
        d[idx[i]] = s / l[i][i];
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
        double m[3][3] = {{0.0, 0.0, 0.0}, {0.0, 0.0, 0.0}, {0.0, 0.0, 0.0}};
        double g[3] = {0.0, 0.0, 0.0}, d[3];
        double step2;
        for (i = 0; i < n; i++) {
            double a[3], pred, r;
            int j, k;
            rc = rope_at(p->tops + 3 * i, p->bottoms + 3 * i,
                         p->offsets != NULL ? p->offsets + 3 * i : NULL, x, &pred, a);
            if (rc != PYRT_OK)
                return rc;
            /* r(x + d) = r(x) + a . d with the directions held fixed (Eq. 2). */
            r = p->lengths[i] - pred;
            for (j = 0; j < 3; j++) {
                g[j] += a[j] * r;
                for (k = 0; k < 3; k++)
                    m[j][k] += a[j] * a[k];
            }
        }
        rc = solve_normal(m, g, p->freeze, d);
        if (rc != PYRT_OK)
            return rc;
        x[0] += d[0];
        x[1] += d[1];
        x[2] += d[2];
        if (!all_finite(x, 3))
            return PYRT_ENOCONVERGE;
        step2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
        if (step2 < p->tol * p->tol)
            break;
    }
    if (it > p->max_iter)
        return PYRT_ENOCONVERGE;

    for (i = 0; i < n; i++) {
        double a[3], pred;
        rc = rope_at(p->tops + 3 * i, p->bottoms + 3 * i,
                     p->offsets != NULL ? p->offsets + 3 * i : NULL, x, &pred, a);
        if (rc != PYRT_OK)
            return rc;
        res[i] = p->lengths[i] - pred;
        ss += res[i] * res[i];
    }
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
