/*
 * Serial kinematic chains (kinematics.h).
 *
 * Transforms are kept as the top three rows of a row-major 4x4 (12 doubles:
 * m[4r + c] is R[r][c] for c < 3, m[4r + 3] is p[r]), the layout of the
 * chain's 16-double origins, so an origin is used where it lies.
 *
 * Workspace layout (doubles), n joints:
 *   LOC   12 n       joint i's child frame in the previous one
 *   WLD   12 (n+1)   base and the child frames in the world
 *   TIP   12         the tool in the world
 *   JAC   6 n        Jacobian (the inverse's)
 *   IK    4 n + 54   the inverse's vectors and 6 x 6 systems
 *   DYN   15 n       Newton-Euler: w, wd, acc, f, moment per link
 *   MM    n n + 14 n mass matrix, bias, composite bodies (m, h, I)
 */
#include "kinematics.h"
#include "_linalg.h"

#include <math.h>
#include <stddef.h>
#include <string.h>

#define LOC(n) 0
#define WLD(n) (12 * (n))
#define TIP(n) (24 * (n) + 12)
#define JAC(n) (24 * (n) + 24)
#define IKB(n) (30 * (n) + 24)
#define DYN(n) (34 * (n) + 78)
#define MMB(n) (49 * (n) + 78)

int pyrt_kin_workspace_size(int32_t n, int32_t *size)
{
    if (size == NULL || n < 1 || n > PYRT_KIN_MAX_JOINTS) {
        return PYRT_EINVAL;
    }
    *size = MMB(n) + n * n + n + 13 * n;
    return PYRT_OK;
}

/* ------------------------------------------------------------------ algebra */

static void compose(const double *a, const double *b, double *out)
{
    for (int r = 0; r < 3; r++) {
        const double a0 = a[4 * r], a1 = a[4 * r + 1], a2 = a[4 * r + 2];
        out[4 * r] = a0 * b[0] + a1 * b[4] + a2 * b[8];
        out[4 * r + 1] = a0 * b[1] + a1 * b[5] + a2 * b[9];
        out[4 * r + 2] = a0 * b[2] + a1 * b[6] + a2 * b[10];
        out[4 * r + 3] = a0 * b[3] + a1 * b[7] + a2 * b[11] + a[4 * r + 3];
    }
}

/* out = R v, R the rotation of a 3x4 transform. */
static void rot(const double *m, const double *v, double *out)
{
    out[0] = m[0] * v[0] + m[1] * v[1] + m[2] * v[2];
    out[1] = m[4] * v[0] + m[5] * v[1] + m[6] * v[2];
    out[2] = m[8] * v[0] + m[9] * v[1] + m[10] * v[2];
}

/* out = R^T v. */
static void rot_t(const double *m, const double *v, double *out)
{
    out[0] = m[0] * v[0] + m[4] * v[1] + m[8] * v[2];
    out[1] = m[1] * v[0] + m[5] * v[1] + m[9] * v[2];
    out[2] = m[2] * v[0] + m[6] * v[1] + m[10] * v[2];
}

static void cross(const double *a, const double *b, double *out)
{
    const double x = a[1] * b[2] - a[2] * b[1];
    const double y = a[2] * b[0] - a[0] * b[2];
    const double z = a[0] * b[1] - a[1] * b[0];
    out[0] = x;
    out[1] = y;
    out[2] = z;
}

static double dot3(const double *a, const double *b)
{
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

static void to16(const double *m, double *out)
{
    memcpy(out, m, 12 * sizeof(double));
    out[12] = 0.0;
    out[13] = 0.0;
    out[14] = 0.0;
    out[15] = 1.0;
}

static int all_finite(const double *v, int n)
{
    for (int i = 0; i < n; i++) {
        if (!isfinite(v[i])) {
            return 0;
        }
    }
    return 1;
}

/* -------------------------------------------------------------- geometry */

static int args_ok(const pyrt_kin_chain *c, const double *ws)
{
    return c != NULL && ws != NULL && c->n >= 1 && c->n <= PYRT_KIN_MAX_JOINTS &&
           c->kinds != NULL && c->origins != NULL && c->axes != NULL && c->offsets != NULL &&
           c->base != NULL && c->tool != NULL;
}

/* Each joint's child frame in the previous one, at q. */
static void local_frames(const pyrt_kin_chain *c, const double *q, double *loc)
{
    for (int i = 0; i < c->n; i++) {
        const double *o = c->origins + 16 * i;
        const double *a = c->axes + 3 * i;
        double *m = loc + 12 * i;
        const double v = q[i] + c->offsets[i];
        if (c->kinds[i] == PYRT_KIN_REVOLUTE) {
            /* Rodrigues: R = I + s K + (1 - cos) K^2, K = [a]x */
            const double s = sin(v), k = 1.0 - cos(v);
            const double x = a[0], y = a[1], z = a[2];
            const double r[9] = {
                1.0 - k * (y * y + z * z), k * x * y - s * z, k * x * z + s * y,
                k * x * y + s * z, 1.0 - k * (x * x + z * z), k * y * z - s * x,
                k * x * z - s * y, k * y * z + s * x, 1.0 - k * (x * x + y * y),
            };
            for (int row = 0; row < 3; row++) {
                const double o0 = o[4 * row], o1 = o[4 * row + 1], o2 = o[4 * row + 2];
                m[4 * row] = o0 * r[0] + o1 * r[3] + o2 * r[6];
                m[4 * row + 1] = o0 * r[1] + o1 * r[4] + o2 * r[7];
                m[4 * row + 2] = o0 * r[2] + o1 * r[5] + o2 * r[8];
                m[4 * row + 3] = o[4 * row + 3];
            }
        } else {
            memcpy(m, o, 12 * sizeof(double));
            m[3] += v * (o[0] * a[0] + o[1] * a[1] + o[2] * a[2]);
            m[7] += v * (o[4] * a[0] + o[5] * a[1] + o[6] * a[2]);
            m[11] += v * (o[8] * a[0] + o[9] * a[1] + o[10] * a[2]);
        }
    }
}

/* World frames and the tool from the local ones. */
static void world_frames(const pyrt_kin_chain *c, double *ws)
{
    const int n = c->n;
    double *w = ws + WLD(n);
    memcpy(w, c->base, 12 * sizeof(double));
    for (int i = 0; i < n; i++) {
        compose(w + 12 * i, ws + LOC(n) + 12 * i, w + 12 * (i + 1));
    }
    compose(w + 12 * n, c->tool, ws + TIP(n));
}

static void forward(const pyrt_kin_chain *c, double *ws, const double *q)
{
    local_frames(c, q, ws + LOC(c->n));
    world_frames(c, ws);
}

/* Jacobian (6 x n) from the world frames forward() left. */
static void jacobian_from_frames(const pyrt_kin_chain *c, const double *ws, double *jac)
{
    const int n = c->n;
    const double *tip = ws + TIP(n);
    const double pt[3] = {tip[3], tip[7], tip[11]};
    for (int i = 0; i < n; i++) {
        const double *f = ws + WLD(n) + 12 * (i + 1);
        double z[3];
        rot(f, c->axes + 3 * i, z);
        if (c->kinds[i] == PYRT_KIN_REVOLUTE) {
            const double r[3] = {pt[0] - f[3], pt[1] - f[7], pt[2] - f[11]};
            double v[3];
            cross(z, r, v);
            jac[i] = v[0];
            jac[n + i] = v[1];
            jac[2 * n + i] = v[2];
            jac[3 * n + i] = z[0];
            jac[4 * n + i] = z[1];
            jac[5 * n + i] = z[2];
        } else {
            jac[i] = z[0];
            jac[n + i] = z[1];
            jac[2 * n + i] = z[2];
            jac[3 * n + i] = 0.0;
            jac[4 * n + i] = 0.0;
            jac[5 * n + i] = 0.0;
        }
    }
}

int pyrt_kin_check(const pyrt_kin_chain *c)
{
    if (c == NULL || c->n < 1 || c->n > PYRT_KIN_MAX_JOINTS || c->kinds == NULL ||
        c->origins == NULL || c->axes == NULL || c->offsets == NULL || c->base == NULL ||
        c->tool == NULL || c->lower == NULL || c->upper == NULL || c->masses == NULL ||
        c->coms == NULL || c->inertias == NULL) {
        return PYRT_EINVAL;
    }
    const int n = c->n;
    if (!all_finite(c->origins, 16 * n) || !all_finite(c->axes, 3 * n) ||
        !all_finite(c->offsets, n) || !all_finite(c->base, 16) || !all_finite(c->tool, 16) ||
        !all_finite(c->masses, n) || !all_finite(c->coms, 3 * n) ||
        !all_finite(c->inertias, 9 * n)) {
        return PYRT_ENONFINITE;
    }
    for (int i = 0; i < n; i++) {
        if (c->kinds[i] != PYRT_KIN_REVOLUTE && c->kinds[i] != PYRT_KIN_PRISMATIC) {
            return PYRT_EINVAL;
        }
        const double norm = sqrt(dot3(c->axes + 3 * i, c->axes + 3 * i));
        if (fabs(norm - 1.0) > PYRT_KIN_AXIS_TOL) {
            return PYRT_EINVAL;
        }
        if (isnan(c->lower[i]) || isnan(c->upper[i]) || !(c->lower[i] <= c->upper[i])) {
            return PYRT_EINVAL;
        }
        if (c->masses[i] < 0.0) {
            return PYRT_EINVAL;
        }
    }
    return PYRT_OK;
}

int pyrt_kin_fk(const pyrt_kin_chain *c, double *ws, const double *q, double *pose)
{
    if (!args_ok(c, ws) || q == NULL || pose == NULL) {
        return PYRT_EINVAL;
    }
    if (!all_finite(q, c->n)) {
        return PYRT_ENONFINITE;
    }
    forward(c, ws, q);
    to16(ws + TIP(c->n), pose);
    return PYRT_OK;
}

int pyrt_kin_frames(const pyrt_kin_chain *c, double *ws, const double *q, double *frames)
{
    if (!args_ok(c, ws) || q == NULL || frames == NULL) {
        return PYRT_EINVAL;
    }
    if (!all_finite(q, c->n)) {
        return PYRT_ENONFINITE;
    }
    forward(c, ws, q);
    for (int i = 0; i <= c->n; i++) {
        to16(ws + WLD(c->n) + 12 * i, frames + 16 * i);
    }
    return PYRT_OK;
}

int pyrt_kin_jacobian(const pyrt_kin_chain *c, double *ws, const double *q, double *jac,
                      double *pose)
{
    if (!args_ok(c, ws) || q == NULL || jac == NULL) {
        return PYRT_EINVAL;
    }
    if (!all_finite(q, c->n)) {
        return PYRT_ENONFINITE;
    }
    forward(c, ws, q);
    jacobian_from_frames(c, ws, jac);
    if (pose != NULL) {
        to16(ws + TIP(c->n), pose);
    }
    return PYRT_OK;
}

int pyrt_kin_call(const pyrt_kin_call_args *a)
{
    if (a == NULL) {
        return PYRT_EINVAL;
    }
    switch (a->op) {
    case PYRT_KIN_OP_FK:
        return pyrt_kin_fk(a->chain, a->ws, a->q, a->out);
    case PYRT_KIN_OP_JACOBIAN:
        return pyrt_kin_jacobian(a->chain, a->ws, a->q, a->out, NULL);
    default:
        return PYRT_EINVAL;
    }
}

/* ---------------------------------------------------------------- inverse */

/* Position error and rotation vector of target . pose^T, world frame. */
static void pose_error(const double *target, const double *pose, double *e)
{
    e[0] = target[3] - pose[3];
    e[1] = target[7] - pose[7];
    e[2] = target[11] - pose[11];
    /* r = Rt R^T: r[i][j] = sum_k Rt[i][k] R[j][k] */
    double r[9];
    for (int i = 0; i < 3; i++) {
        for (int j = 0; j < 3; j++) {
            r[3 * i + j] = target[4 * i] * pose[4 * j] + target[4 * i + 1] * pose[4 * j + 1] +
                           target[4 * i + 2] * pose[4 * j + 2];
        }
    }
    const double v[3] = {r[7] - r[5], r[2] - r[6], r[3] - r[1]};
    double cs = 0.5 * (r[0] + r[4] + r[8] - 1.0);
    cs = cs > 1.0 ? 1.0 : (cs < -1.0 ? -1.0 : cs);
    const double sn = 0.5 * sqrt(dot3(v, v));
    const double angle = atan2(sn, cs);
    if (cs > -0.99) {
        const double f = sn > 1e-300 ? angle / (2.0 * sn) : 0.5;
        e[3] = f * v[0];
        e[4] = f * v[1];
        e[5] = f * v[2];
        return;
    }
    /* Near a half turn v is small and imprecise: the axis from the
     * symmetric part, (r + r^T)/2 = cos I + (1 - cos) a a^T. */
    int k = 0;
    if (r[4] > r[3 * k + k]) {
        k = 1;
    }
    if (r[8] > r[3 * k + k]) {
        k = 2;
    }
    double a[3];
    const double one_c = 1.0 - cs;
    a[k] = sqrt((r[3 * k + k] - cs) / one_c);
    for (int j = 0; j < 3; j++) {
        if (j != k) {
            a[j] = (r[3 * k + j] + r[3 * j + k]) / (2.0 * one_c * a[k]);
        }
    }
    const double norm = sqrt(dot3(a, a));
    const double sign = dot3(a, v) < 0.0 ? -1.0 : 1.0;
    e[3] = sign * angle * a[0] / norm;
    e[4] = sign * angle * a[1] / norm;
    e[5] = sign * angle * a[2] / norm;
}

/* The inverse's damping: lambda = mu (|e|^2 / 2 + IK_LAMBDA0), mu raised
 * tenfold on a rejected step, lowered tenfold on an accepted one. */
#define IK_LAMBDA0 1e-9
#define IK_MU_MIN 1e-6
#define IK_MU_MAX 1e12
/* The longest null-space step (rad or m). */
#define IK_MAX_NULL 0.2

static double clamp(double v, double lo, double hi)
{
    return v < lo ? lo : (v > hi ? hi : v);
}

/* a = J J^T + lambda I (6 x 6) from jac (6 x n). */
static void jjt(const double *jac, int n, double lambda, double *a)
{
    for (int r = 0; r < 6; r++) {
        for (int s = 0; s <= r; s++) {
            double acc = 0.0;
            for (int k = 0; k < n; k++) {
                acc += jac[r * n + k] * jac[s * n + k];
            }
            a[6 * r + s] = acc;
            a[6 * s + r] = acc;
        }
        a[6 * r + r] += lambda;
    }
}

/* ns = (I - J^T (J J^T)^-1 J) (q - seed): the part of the way back to the
 * seed that leaves the pose alone to first order, at most IK_MAX_NULL long;
 * returns its length (0 when J J^T cannot be factored). */
static double null_step(const double *jac, int n, const double *q, const double *seed,
                        double *d, double *a, double *b, double *ns)
{
    for (int i = 0; i < n; i++) {
        d[i] = q[i] - seed[i];
    }
    for (int r = 0; r < 6; r++) {
        double acc = 0.0;
        for (int k = 0; k < n; k++) {
            acc += jac[r * n + k] * d[k];
        }
        b[r] = acc;
    }
    jjt(jac, n, 1e-12, a);
    if (!cholesky(a, 6)) {
        memset(ns, 0, (size_t)n * sizeof(double));
        return 0.0;
    }
    chol_solve(a, 6, b);
    double norm = 0.0;
    for (int k = 0; k < n; k++) {
        double acc = d[k];
        for (int r = 0; r < 6; r++) {
            acc -= jac[r * n + k] * b[r];
        }
        ns[k] = acc;
        norm += acc * acc;
    }
    norm = sqrt(norm);
    if (norm > IK_MAX_NULL) {
        for (int k = 0; k < n; k++) {
            ns[k] *= IK_MAX_NULL / norm;
        }
    }
    return norm;
}

int pyrt_kin_ik(const pyrt_kin_chain *c, double *ws, const double *target, const double *seed,
                double *q, pyrt_kin_ik_opts *opts)
{
    if (!args_ok(c, ws) || c->lower == NULL || c->upper == NULL || target == NULL ||
        seed == NULL || q == NULL || opts == NULL) {
        return PYRT_EINVAL;
    }
    const int n = c->n;
    if (!(opts->tol > 0.0) || !(opts->null_tol > 0.0) || opts->max_iter < 1) {
        return PYRT_EINVAL;
    }
    if (!all_finite(target, 16) || !all_finite(seed, n) || !isfinite(opts->tol) ||
        !isfinite(opts->null_tol)) {
        return PYRT_ENONFINITE;
    }
    double *jac = ws + JAC(n);
    double *d = ws + IKB(n);
    double *qt = d + n;
    double *ns = qt + n;
    double *best = ns + n;
    double *a = best + n;
    double *e = a + 36;
    double *et = e + 6;
    double *b = et + 6;
    const int redundant = n > 6;
    double mu = 1.0;
    double best_dist = INFINITY; /* redundant: the nearest pose-reaching point so far */
    double gain = 1.0;           /* redundant: the null-space step's length, relative */

    for (int i = 0; i < n; i++) {
        q[i] = clamp(seed[i], c->lower[i], c->upper[i]);
    }
    forward(c, ws, q);
    jacobian_from_frames(c, ws, jac);
    pose_error(target, ws + TIP(n), e);
    double res = sqrt(dot3(e, e) + dot3(e + 3, e + 3));
    int it = 0;
    for (;; it++) {
        if (res <= opts->tol) {
            if (!redundant) {
                break;
            }
            /* the pose is reached.  The nearest point yet is kept and the
             * null-space step toward the seed taken from it; a step that
             * ended farther (the self-motion manifold bends away) is taken
             * again from the nearest point, half as long. */
            double dist = 0.0;
            for (int i = 0; i < n; i++) {
                dist += (q[i] - seed[i]) * (q[i] - seed[i]);
            }
            if (dist < best_dist) {
                best_dist = dist;
                memcpy(best, q, (size_t)n * sizeof(double));
                opts->residual = res;
                gain = gain * 2.0 < 1.0 ? gain * 2.0 : 1.0;
            } else {
                memcpy(q, best, (size_t)n * sizeof(double));
                forward(c, ws, q);
                jacobian_from_frames(c, ws, jac);
                gain *= 0.5;
            }
            const double ns_norm = null_step(jac, n, q, seed, d, a, b, ns);
            if (gain * ns_norm <= opts->null_tol || it >= opts->max_iter) {
                break;
            }
            for (int k = 0; k < n; k++) {
                q[k] = clamp(q[k] - gain * ns[k], c->lower[k], c->upper[k]);
            }
            forward(c, ws, q);
            jacobian_from_frames(c, ws, jac);
            pose_error(target, ws + TIP(n), e);
            res = sqrt(dot3(e, e) + dot3(e + 3, e + 3));
            mu = 1.0;
            continue;
        }
        if (it >= opts->max_iter) {
            break;
        }
        /* the damped minimum-norm step */
        jjt(jac, n, mu * (0.5 * res * res + IK_LAMBDA0), a);
        if (!cholesky(a, 6)) {
            break;
        }
        double y[6];
        memcpy(y, e, sizeof y);
        chol_solve(a, 6, y);
        for (int k = 0; k < n; k++) {
            double acc = 0.0;
            for (int r = 0; r < 6; r++) {
                acc += jac[r * n + k] * y[r];
            }
            qt[k] = clamp(q[k] + acc, c->lower[k], c->upper[k]);
        }
        if (!all_finite(qt, n)) {
            break;
        }
        forward(c, ws, qt);
        pose_error(target, ws + TIP(n), et);
        const double res_t = sqrt(dot3(et, et) + dot3(et + 3, et + 3));
        if (res_t < res) {
            memcpy(q, qt, (size_t)n * sizeof(double));
            memcpy(e, et, 6 * sizeof(double));
            res = res_t;
            jacobian_from_frames(c, ws, jac);
            mu = mu * 0.1 > IK_MU_MIN ? mu * 0.1 : IK_MU_MIN;
        } else {
            mu *= 10.0;
            if (mu > IK_MU_MAX) {
                break;
            }
        }
    }
    opts->iterations = it;
    if (best_dist < INFINITY) {
        memcpy(q, best, (size_t)n * sizeof(double));
        return PYRT_OK;
    }
    opts->residual = res;
    return res <= opts->tol ? PYRT_OK : PYRT_ENOCONVERGE;
}

/* --------------------------------------------------------------- dynamics */

/*
 * Newton-Euler over the local frames forward() left, every vector in its
 * link's own frame.  gb: the gravity in the base frame (NULL: none); qd,
 * qdd NULL: zero.
 */
static void newton_euler(const pyrt_kin_chain *c, double *ws, const double *qd,
                         const double *qdd, const double *gb, double *tau)
{
    const int n = c->n;
    const double *loc = ws + LOC(n);
    double *w = ws + DYN(n);
    double *wd = w + 3 * n;
    double *acc = wd + 3 * n;
    double *f = acc + 3 * n;
    double *mo = f + 3 * n;
    const double zero[3] = {0.0, 0.0, 0.0};
    double a0[3] = {0.0, 0.0, 0.0};
    if (gb != NULL) {
        a0[0] = -gb[0];
        a0[1] = -gb[1];
        a0[2] = -gb[2];
    }
    for (int i = 0; i < n; i++) {
        const double *m = loc + 12 * i;
        const double p[3] = {m[3], m[7], m[11]};
        const double *wp = i ? w + 3 * (i - 1) : zero;
        const double *wdp = i ? wd + 3 * (i - 1) : zero;
        const double *ap = i ? acc + 3 * (i - 1) : a0;
        const double *ax = c->axes + 3 * i;
        const double v = qd != NULL ? qd[i] : 0.0;
        const double dv = qdd != NULL ? qdd[i] : 0.0;
        double t[3], u[3], s[3];
        /* acceleration of this frame's origin as a point of the previous link */
        cross(wdp, p, t);
        cross(wp, p, u);
        cross(wp, u, s);
        const double ao[3] = {ap[0] + t[0] + s[0], ap[1] + t[1] + s[1], ap[2] + t[2] + s[2]};
        double *wi = w + 3 * i, *wdi = wd + 3 * i, *ai = acc + 3 * i;
        rot_t(m, wp, wi);
        rot_t(m, wdp, wdi);
        rot_t(m, ao, ai);
        if (c->kinds[i] == PYRT_KIN_REVOLUTE) {
            cross(wi, ax, t);
            for (int k = 0; k < 3; k++) {
                wdi[k] += ax[k] * dv + t[k] * v;
                wi[k] += ax[k] * v;
            }
        } else {
            cross(wi, ax, t);
            for (int k = 0; k < 3; k++) {
                ai[k] += 2.0 * v * t[k] + ax[k] * dv;
            }
        }
        /* the link's force and moment about its frame's origin */
        const double *cm = c->coms + 3 * i;
        const double *in = c->inertias + 9 * i;
        const double mass = c->masses[i];
        cross(wdi, cm, t);
        cross(wi, cm, u);
        cross(wi, u, s);
        double *fi = f + 3 * i, *mi = mo + 3 * i;
        for (int k = 0; k < 3; k++) {
            fi[k] = mass * (ai[k] + t[k] + s[k]);
        }
        const double iw[3] = {
            in[0] * wi[0] + in[1] * wi[1] + in[2] * wi[2],
            in[3] * wi[0] + in[4] * wi[1] + in[5] * wi[2],
            in[6] * wi[0] + in[7] * wi[1] + in[8] * wi[2],
        };
        cross(wi, iw, t);
        cross(cm, fi, u);
        for (int k = 0; k < 3; k++) {
            mi[k] = in[3 * k] * wdi[0] + in[3 * k + 1] * wdi[1] + in[3 * k + 2] * wdi[2] + t[k] +
                    u[k];
        }
    }
    for (int i = n - 1; i >= 0; i--) {
        double *fi = f + 3 * i, *mi = mo + 3 * i;
        if (i + 1 < n) {
            const double *m = loc + 12 * (i + 1);
            const double p[3] = {m[3], m[7], m[11]};
            double fc[3], mc[3], t[3];
            rot(m, f + 3 * (i + 1), fc);
            rot(m, mo + 3 * (i + 1), mc);
            cross(p, fc, t);
            for (int k = 0; k < 3; k++) {
                fi[k] += fc[k];
                mi[k] += mc[k] + t[k];
            }
        }
        tau[i] = dot3(c->axes + 3 * i, c->kinds[i] == PYRT_KIN_REVOLUTE ? mi : fi);
    }
}

static int dyn_ok(const pyrt_kin_chain *c)
{
    return c->masses != NULL && c->coms != NULL && c->inertias != NULL;
}

/* gravity (world) in the base frame. */
static const double *base_gravity(const pyrt_kin_chain *c, const double *gravity, double *gb)
{
    if (gravity == NULL) {
        return NULL;
    }
    rot_t(c->base, gravity, gb);
    return gb;
}

int pyrt_kin_rnea(const pyrt_kin_chain *c, double *ws, const double *q, const double *qd,
                  const double *qdd, const double *gravity, double *tau)
{
    if (!args_ok(c, ws) || !dyn_ok(c) || q == NULL || tau == NULL) {
        return PYRT_EINVAL;
    }
    const int n = c->n;
    if (!all_finite(q, n) || (qd != NULL && !all_finite(qd, n)) ||
        (qdd != NULL && !all_finite(qdd, n)) || (gravity != NULL && !all_finite(gravity, 3))) {
        return PYRT_ENONFINITE;
    }
    double gb[3];
    local_frames(c, q, ws + LOC(n));
    newton_euler(c, ws, qd, qdd, base_gravity(c, gravity, gb), tau);
    return PYRT_OK;
}

/*
 * Mass matrix into mass (n x n) from the local frames, by the composite
 * rigid body algorithm: each link's subtree (the link and every link after
 * it) as one body -- mass, first moment h = m c and inertia about the
 * link frame's origin, in that frame -- summed tip to base; then column j
 * is the force and moment that accelerate subtree j alone at unit rate
 * about (or along) joint j from rest, carried back to each earlier joint.
 */
static void mass_crba(const pyrt_kin_chain *c, double *ws, double *mass)
{
    const int n = c->n;
    const double *loc = ws + LOC(n);
    double *cm = ws + MMB(n) + n * n + n; /* per link: m, h[3], I[9] */
    for (int i = 0; i < n; i++) {
        double *b = cm + 13 * i;
        const double m = c->masses[i];
        const double *r = c->coms + 3 * i;
        const double *ic = c->inertias + 9 * i;
        const double rr = dot3(r, r);
        b[0] = m;
        for (int k = 0; k < 3; k++) {
            b[1 + k] = m * r[k];
            for (int l = 0; l < 3; l++) {
                b[4 + 3 * k + l] = ic[3 * k + l] + m * ((k == l ? rr : 0.0) - r[k] * r[l]);
            }
        }
    }
    for (int i = n - 1; i > 0; i--) {
        /* add subtree i (frame i) into link i-1 (frame i-1) */
        const double *m = loc + 12 * i;
        const double p[3] = {m[3], m[7], m[11]};
        const double *ch = cm + 13 * i;
        double *pa = cm + 13 * (i - 1);
        const double mass_c = ch[0];
        double h[3], ri[9];
        rot(m, ch + 1, h);
        /* R I R^T */
        for (int k = 0; k < 3; k++) {
            for (int l = 0; l < 3; l++) {
                ri[3 * k + l] = m[4 * k] * ch[4 + l] + m[4 * k + 1] * ch[7 + l] +
                                m[4 * k + 2] * ch[10 + l];
            }
        }
        const double pp = dot3(p, p), ph = dot3(p, h);
        for (int k = 0; k < 3; k++) {
            for (int l = 0; l < 3; l++) {
                const double rir = ri[3 * k] * m[4 * l] + ri[3 * k + 1] * m[4 * l + 1] +
                                   ri[3 * k + 2] * m[4 * l + 2];
                pa[4 + 3 * k + l] += rir + mass_c * ((k == l ? pp : 0.0) - p[k] * p[l]) +
                                     (k == l ? 2.0 * ph : 0.0) - p[k] * h[l] - h[k] * p[l];
            }
        }
        pa[0] += mass_c;
        for (int k = 0; k < 3; k++) {
            pa[1 + k] += h[k] + mass_c * p[k];
        }
    }
    for (int j = 0; j < n; j++) {
        const double *b = cm + 13 * j;
        const double *a = c->axes + 3 * j;
        double f[3], mo[3];
        if (c->kinds[j] == PYRT_KIN_REVOLUTE) {
            cross(a, b + 1, f);
            for (int k = 0; k < 3; k++) {
                mo[k] = b[4 + 3 * k] * a[0] + b[5 + 3 * k] * a[1] + b[6 + 3 * k] * a[2];
            }
        } else {
            for (int k = 0; k < 3; k++) {
                f[k] = b[0] * a[k];
            }
            cross(b + 1, a, mo);
        }
        for (int i = j; i >= 0; i--) {
            if (i < j) {
                /* carry (f, mo) from frame i+1 into frame i */
                const double *m = loc + 12 * (i + 1);
                const double p[3] = {m[3], m[7], m[11]};
                double fr[3], mr[3], t[3];
                rot(m, f, fr);
                rot(m, mo, mr);
                cross(p, fr, t);
                for (int k = 0; k < 3; k++) {
                    f[k] = fr[k];
                    mo[k] = mr[k] + t[k];
                }
            }
            const double v = dot3(c->axes + 3 * i, c->kinds[i] == PYRT_KIN_REVOLUTE ? mo : f);
            mass[i * n + j] = v;
            mass[j * n + i] = v;
        }
    }
}

int pyrt_kin_mass_matrix(const pyrt_kin_chain *c, double *ws, const double *q, double *mass)
{
    if (!args_ok(c, ws) || !dyn_ok(c) || q == NULL || mass == NULL) {
        return PYRT_EINVAL;
    }
    if (!all_finite(q, c->n)) {
        return PYRT_ENONFINITE;
    }
    local_frames(c, q, ws + LOC(c->n));
    mass_crba(c, ws, mass);
    return PYRT_OK;
}

int pyrt_kin_forward_dynamics(const pyrt_kin_chain *c, double *ws, const double *q,
                              const double *qd, const double *tau, const double *gravity,
                              double *qdd)
{
    if (!args_ok(c, ws) || !dyn_ok(c) || q == NULL || tau == NULL || qdd == NULL) {
        return PYRT_EINVAL;
    }
    const int n = c->n;
    if (!all_finite(q, n) || (qd != NULL && !all_finite(qd, n)) || !all_finite(tau, n) ||
        (gravity != NULL && !all_finite(gravity, 3))) {
        return PYRT_ENONFINITE;
    }
    double gb[3];
    double *mass = ws + MMB(n);
    double *bias = mass + n * n;
    local_frames(c, q, ws + LOC(n));
    newton_euler(c, ws, qd, NULL, base_gravity(c, gravity, gb), bias);
    mass_crba(c, ws, mass);
    if (!cholesky(mass, n)) {
        return PYRT_ESINGULAR;
    }
    for (int i = 0; i < n; i++) {
        qdd[i] = tau[i] - bias[i];
    }
    chol_solve(mass, n, qdd);
    return PYRT_OK;
}
