/*
 * Rope-and-source statics: damped Newton on the potential energy with an
 * analytic gradient and Hessian.  See statics.h for the model.
 */
#include "statics.h"

#include <math.h>
#include <stddef.h>

static double dot3(const double *a, const double *b)
{
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

static double norm3(const double *a)
{
    return sqrt(dot3(a, a));
}

/* h += w * (I - u u^T) */
static void add_projector(double *h, const double *u, double w)
{
    int r, c;
    for (r = 0; r < 3; ++r) {
        for (c = 0; c < 3; ++c) {
            h[3 * r + c] += w * ((r == c ? 1.0 : 0.0) - u[r] * u[c]);
        }
    }
}

/* h += w * a b^T */
static void add_outer(double *h, const double *a, const double *b, double w)
{
    int r, c;
    for (r = 0; r < 3; ++r) {
        for (c = 0; c < 3; ++c) {
            h[3 * r + c] += w * a[r] * b[c];
        }
    }
}

/*
 * h += d2(length)/dq2 of one segment (neck.h): the straight piece from the
 * carriage pulley, and where the segment bears on the ring the envelope
 * correction (the contact point moves with q).
 */
static void add_segment_hessian(double *h, const pyrt_neck_segment *s)
{
    int k;
    add_projector(h, s->dir, 1.0 / s->tail);
    if (s->bears && s->curvature > 1e-12) {
        double v[3];
        double uc = dot3(s->dir, s->tangent);
        for (k = 0; k < 3; ++k) {
            v[k] = (s->tangent[k] - uc * s->dir[k]) / s->tail;
        }
        add_outer(h, v, v, -1.0 / s->curvature);
    }
}

/*
 * Geometry of rope i with the source at x: g (length beyond the top
 * pulley), grad = dg/dx, and (hg != NULL, zeroed by the caller) d2g/dx2.
 */
static int rope_geometry(const pyrt_statics_problem *p, int32_t i, const double *x,
                         double *g, double *grad, double *hg, int32_t *wrap)
{
    const double *b = p->bottoms + 3 * i;
    pyrt_neck_rope path;
    double q[3];
    int k, st;

    for (k = 0; k < 3; ++k) {
        q[k] = x[k] + (p->offsets != NULL ? p->offsets[3 * i + k] : 0.0);
    }
    st = pyrt_neck_rope_path(&p->ring, PYRT_STATICS_RING_SEGMENTS, p->tops + 3 * i, b, q, NULL,
                             &path);
    if (st != PYRT_OK) {
        return st;
    }
    *g = path.length;
    for (k = 0; k < 3; ++k) {
        grad[k] = -path.upper.dir[k] - path.lower.dir[k];
    }
    if (hg != NULL) {
        add_segment_hessian(hg, &path.upper);
        if (!isnan(b[0])) {
            add_segment_hessian(hg, &path.lower);
        }
    }
    *wrap = path.upper.bears || path.lower.bears;
    return PYRT_OK;
}

/*
 * Energy, gradient and (H != NULL) Hessian at x; tensions and wrap flags
 * written when the pointers are not NULL.
 */
static int assemble(const pyrt_statics_problem *p, const double *x, double *E, double *G,
                    double *H, double *tension, int32_t *wrapped, double *glen)
{
    int32_t i;
    int k;
    *E = p->weight * x[2];
    G[0] = 0.0;
    G[1] = 0.0;
    G[2] = p->weight;
    if (H != NULL) {
        for (k = 0; k < 9; ++k) {
            H[k] = 0.0;
        }
    }
    for (i = 0; i < p->n; ++i) {
        double g, grad[3], hg[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0};
        int32_t wrap = 0;
        double s, kk, T = 0.0;
        int st = rope_geometry(p, i, x, &g, grad, H != NULL ? hg : NULL, &wrap);
        if (st != PYRT_OK) {
            return st;
        }
        if (glen != NULL) {
            glen[i] = g;
        }
        if (wrapped != NULL) {
            wrapped[i] = wrap;
        }
        s = p->dead[i] + g - p->payout[i];
        if (p->intact[i] != 0 && s > 0.0) {
            kk = 1.0 / (p->compliance[i] * p->payout[i]);
            T = kk * s;
            *E += 0.5 * kk * s * s;
            for (k = 0; k < 3; ++k) {
                G[k] += T * grad[k];
            }
            if (H != NULL) {
                add_outer(H, grad, grad, kk);
                for (k = 0; k < 9; ++k) {
                    H[k] += T * hg[k];
                }
            }
        }
        if (tension != NULL) {
            tension[i] = T;
        }
    }
    return PYRT_OK;
}

/* Solve (A + mu I) x = b by Cholesky; 0 on success, 1 if not positive definite. */
static int chol_solve(const double *A, double mu, const double *b, double *x)
{
    double l00, l10, l11, l20, l21, l22, y0, y1, y2, d;
    d = A[0] + mu;
    if (!(d > 0.0)) {
        return 1;
    }
    l00 = sqrt(d);
    l10 = A[3] / l00;
    l20 = A[6] / l00;
    d = A[4] + mu - l10 * l10;
    if (!(d > 0.0)) {
        return 1;
    }
    l11 = sqrt(d);
    l21 = (A[7] - l20 * l10) / l11;
    d = A[8] + mu - l20 * l20 - l21 * l21;
    if (!(d > 0.0)) {
        return 1;
    }
    l22 = sqrt(d);
    y0 = b[0] / l00;
    y1 = (b[1] - l10 * y0) / l11;
    y2 = (b[2] - l20 * y0 - l21 * y1) / l22;
    x[2] = y2 / l22;
    x[1] = (y1 - l21 * x[2]) / l11;
    x[0] = (y0 - l10 * x[1] - l20 * x[2]) / l00;
    if (!(isfinite(x[0]) && isfinite(x[1]) && isfinite(x[2]))) {
        return 1;
    }
    /* reject a solve that lost all accuracy to cancellation */
    if (mu == 0.0 && (l11 < 1e-7 * l00 || l22 < 1e-7 * l00)) {
        return 1;
    }
    return 0;
}

static int validate(const pyrt_statics_problem *p)
{
    int32_t i;
    int k, st;
    if (p == NULL || p->tops == NULL || p->bottoms == NULL || p->payout == NULL ||
        p->dead == NULL || p->compliance == NULL || p->intact == NULL ||
        p->position == NULL || p->tension == NULL || p->wrapped == NULL) {
        return PYRT_EINVAL;
    }
    if (p->n < 1 || p->n > PYRT_STATICS_MAX_ROPES || p->max_iter < 1) {
        return PYRT_EINVAL;
    }
    if (!(p->tol > 0.0) || !(p->max_step > 0.0)) {
        return PYRT_EINVAL;
    }
    if (!isfinite(p->tol) || !isfinite(p->max_step) || !isfinite(p->weight) ||
        !isfinite(p->floor_z)) {
        return PYRT_ENONFINITE;
    }
    st = pyrt_neck_check(&p->ring);
    if (st != PYRT_OK) {
        return st;
    }
    for (k = 0; k < 3; ++k) {
        if (!isfinite(p->position[k])) {
            return PYRT_ENONFINITE;
        }
    }
    for (i = 0; i < p->n; ++i) {
        const double *b = p->bottoms + 3 * i;
        int nans = isnan(b[0]) + isnan(b[1]) + isnan(b[2]);
        for (k = 0; k < 3; ++k) {
            if (!isfinite(p->tops[3 * i + k]) ||
                (p->offsets != NULL && !isfinite(p->offsets[3 * i + k]))) {
                return PYRT_ENONFINITE;
            }
        }
        if (nans != 0 && nans != 3) {
            return PYRT_EINVAL;
        }
        if (nans == 0 && !(isfinite(b[0]) && isfinite(b[1]) && isfinite(b[2]))) {
            return PYRT_ENONFINITE;
        }
        if (!isfinite(p->payout[i]) || !isfinite(p->dead[i]) || !isfinite(p->compliance[i])) {
            return PYRT_ENONFINITE;
        }
        if (!(p->payout[i] > 0.0) || !(p->dead[i] >= 0.0) || !(p->compliance[i] > 0.0)) {
            return PYRT_EINVAL;
        }
    }
    return PYRT_OK;
}

int pyrt_statics_evaluate(const pyrt_statics_problem *p, const double *position,
                          double *g, double *tension, int32_t *wrapped)
{
    double E, G[3];
    int st;
    if (position == NULL || tension == NULL) {
        return PYRT_EINVAL;
    }
    st = validate(p);
    if (st != PYRT_OK) {
        return st;
    }
    if (!(isfinite(position[0]) && isfinite(position[1]) && isfinite(position[2]))) {
        return PYRT_ENONFINITE;
    }
    return assemble(p, position, &E, G, NULL, tension, wrapped, g);
}

int pyrt_statics_solve(pyrt_statics_problem *p)
{
    double x[3], E, G[3], H[9];
    double tension[PYRT_STATICS_MAX_ROPES];
    int32_t wrapped[PYRT_STATICS_MAX_ROPES];
    int32_t it, i;
    int st, k, converged = 0, floored;

    st = validate(p);
    if (st != PYRT_OK) {
        return st;
    }
    for (k = 0; k < 3; ++k) {
        x[k] = p->position[k];
    }
    if (x[2] < p->floor_z) {
        x[2] = p->floor_z;
    }
    st = assemble(p, x, &E, G, H, tension, wrapped, NULL);
    if (st != PYRT_OK) {
        return st;
    }
    for (it = 0; it < p->max_iter; ++it) {
        double A[9], b[3], dx[3], xn[3], En, Gn[3], len, mu, alpha, step;
        int tries;
        floored = x[2] <= p->floor_z && G[2] > 0.0;
        for (k = 0; k < 9; ++k) {
            A[k] = H[k];
        }
        for (k = 0; k < 3; ++k) {
            b[k] = -G[k];
        }
        if (floored) {
            /* the floor carries the source: only x and y are free */
            A[2] = A[5] = A[6] = A[7] = 0.0;
            A[8] = 1.0;
            b[2] = 0.0;
        }
        mu = 0.0;
        for (tries = 0; chol_solve(A, mu, b, dx) != 0; ++tries) {
            if (tries >= 30) {
                return PYRT_ENOCONVERGE;
            }
            mu = mu == 0.0 ? 1e-9 * (fabs(A[0]) + fabs(A[4]) + fabs(A[8])) + 1e-6 : mu * 100.0;
        }
        len = norm3(dx);
        if (len > p->max_step) {
            for (k = 0; k < 3; ++k) {
                dx[k] *= p->max_step / len;
            }
        }
        alpha = 1.0;
        for (tries = 0;; ++tries) {
            double descent;
            for (k = 0; k < 3; ++k) {
                xn[k] = x[k] + alpha * dx[k];
            }
            if (xn[2] < p->floor_z) {
                xn[2] = p->floor_z;
            }
            st = assemble(p, xn, &En, Gn, NULL, NULL, NULL, NULL);
            if (st != PYRT_OK) {
                return st;
            }
            descent = G[0] * (xn[0] - x[0]) + G[1] * (xn[1] - x[1]) + G[2] * (xn[2] - x[2]);
            if (En <= E + 1e-4 * descent + 1e-13 * fabs(E) || tries >= 40) {
                break;
            }
            alpha *= 0.5;
        }
        step = sqrt((xn[0] - x[0]) * (xn[0] - x[0]) + (xn[1] - x[1]) * (xn[1] - x[1]) +
                    (xn[2] - x[2]) * (xn[2] - x[2]));
        for (k = 0; k < 3; ++k) {
            x[k] = xn[k];
        }
        st = assemble(p, x, &E, G, H, tension, wrapped, NULL);
        if (st != PYRT_OK) {
            return st;
        }
        if (step < p->tol) {
            converged = 1;
            ++it;
            break;
        }
    }
    floored = x[2] <= p->floor_z && G[2] > 0.0;
    for (k = 0; k < 3; ++k) {
        p->position[k] = x[k];
    }
    for (i = 0; i < p->n; ++i) {
        p->tension[i] = tension[i];
        p->wrapped[i] = wrapped[i];
    }
    p->iterations = it;
    p->residual = sqrt(G[0] * G[0] + G[1] * G[1] + (floored ? 0.0 : G[2] * G[2]));
    return converged ? PYRT_OK : PYRT_ENOCONVERGE;
}
