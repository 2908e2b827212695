/* Paul's closed-form inverse of the PUMA 560; see puma.h. */
#include "puma.h"

#include <math.h>
#include <stddef.h>

#define PUMA_PI 3.14159265358979323846
#define PUMA_TWO_PI 6.28318530717958647692
#define PUMA_LIMIT_TOL 1e-9

/* out (3x4 of a rigid transform) = a . b, both rigid 4x4 row-major. */
static void rigid_mul(const double *a, const double *b, double *out)
{
    int i, j;
    for (i = 0; i < 3; i++) {
        for (j = 0; j < 4; j++) {
            out[4 * i + j] = a[4 * i] * b[j] + a[4 * i + 1] * b[4 + j] + a[4 * i + 2] * b[8 + j];
        }
        out[4 * i + 3] += a[4 * i + 3];
    }
}

static double clamp1(double x)
{
    return x > 1.0 ? 1.0 : (x < -1.0 ? -1.0 : x);
}

/* A joint value within [lo, hi] a whole number of turns from v, the nearest
 * to v; returns 0 when there is none. */
static int into_limits(double v, double lo, double hi, double *out)
{
    int k, found = 0;
    double best = v;
    if (v >= lo - PUMA_LIMIT_TOL && v <= hi + PUMA_LIMIT_TOL) {
        best = v;
        found = 1;
    } else {
        for (k = -2; k <= 2; k++) {
            double c = v + k * PUMA_TWO_PI;
            if (c >= lo - PUMA_LIMIT_TOL && c <= hi + PUMA_LIMIT_TOL
                && (!found || fabs(c - v) < fabs(best - v))) {
                best = c;
                found = 1;
            }
        }
    }
    if (!found)
        return 0;
    *out = best < lo ? lo : (best > hi ? hi : best);
    return 1;
}

int pyrt_puma_inverse(const pyrt_puma *arm, const double *pose, int32_t config,
                      const double *seed, double *q, int32_t *why, double *detail)
{
    double m1[12], t[12], th[6], out[6];
    double px, py, pz, r, phi, off, th1, c1, s1, x, y, rho, len2, k, psi, beta;
    double th2, c2, s2, th23, c23, s23, r03[9], w[9], s5, th4, th5, th6;
    double c4, s4, c5, s5f, a0, a1;
    int i, j, lefty, up;

    if (arm == NULL || pose == NULL || q == NULL || why == NULL || detail == NULL)
        return PYRT_EINVAL;
    for (i = 0; i < 16; i++)
        if (!isfinite(pose[i]))
            return PYRT_ENONFINITE;
    if (seed != NULL)
        for (i = 0; i < 6; i++)
            if (!isfinite(seed[i]))
                return PYRT_ENONFINITE;
    *why = PYRT_PUMA_REACHED;
    detail[0] = 0.0;

    /* the flange in the DH base frame */
    rigid_mul(arm->base_inv, pose, m1);
    {
        double full[16];
        for (i = 0; i < 12; i++)
            full[i] = m1[i];
        full[12] = full[13] = full[14] = 0.0;
        full[15] = 1.0;
        rigid_mul(full, arm->tool_inv, t);
    }
    px = t[3];
    py = t[7];
    pz = t[11] - arm->d1;
    lefty = (config & PYRT_PUMA_LEFTY) != 0;

    /* joint 1: px s1 - py c1 = d3 */
    r = hypot(px, py);
    if (r < fabs(arm->d3) * (1.0 - 1e-12) && !(config & PYRT_PUMA_NEAREST)) {
        *why = PYRT_PUMA_INSIDE_OFFSET;
        detail[0] = r;
        return PYRT_OK;
    }
    phi = atan2(py, px);
    off = r > 0.0 ? asin(clamp1(arm->d3 / r)) : 0.0;
    th1 = lefty ? phi + PUMA_PI - off : phi + off;
    c1 = cos(th1);
    s1 = sin(th1);
    x = px * c1 + py * s1;
    y = pz;

    /* joints 2 and 3: (x, y) = a2 (c2, s2) + Rot(th2 + th3) (a3, d4) */
    rho = hypot(x, y);
    len2 = arm->a3 * arm->a3 + arm->d4 * arm->d4;
    k = (x * x + y * y + arm->a2 * arm->a2 - len2) / (2.0 * arm->a2);
    if (rho == 0.0 || (fabs(k) > rho * (1.0 + 1e-12) && !(config & PYRT_PUMA_NEAREST))) {
        *why = rho >= arm->a2 + sqrt(len2) ? PYRT_PUMA_TOO_FAR : PYRT_PUMA_TOO_NEAR;
        detail[0] = rho;
        return PYRT_OK;
    }
    psi = acos(clamp1(k / rho));
    if ((config & PYRT_PUMA_NEAREST) && fabs(k) >= rho && psi < 0.02)
        psi = 0.02; /* off the stretched arm, on the configuration's side */
    beta = atan2(y, x);
    up = ((config & PYRT_PUMA_BELOW) == 0) == !lefty;
    th2 = up ? beta + psi : beta - psi;
    c2 = cos(th2);
    s2 = sin(th2);
    th23 = atan2(y - arm->a2 * s2, x - arm->a2 * c2) - atan2(arm->d4, arm->a3);

    /* the wrist: R36 = R03^T R = Rz(th4) Ry(-th5) Rz(th6) */
    c23 = cos(th23);
    s23 = sin(th23);
    r03[0] = c1 * c23; r03[1] = -s1; r03[2] = -c1 * s23;
    r03[3] = s1 * c23; r03[4] = c1;  r03[5] = -s1 * s23;
    r03[6] = s23;      r03[7] = 0.0; r03[8] = c23;
    for (i = 0; i < 3; i++)
        for (j = 0; j < 3; j++)
            w[3 * i + j] = r03[i] * t[j] + r03[3 + i] * t[4 + j] + r03[6 + i] * t[8 + j];
    s5 = hypot(w[2], w[5]);
    th5 = atan2(s5, w[8]);
    if (s5 > PYRT_PUMA_SINGULAR) {
        th4 = atan2(-w[5], -w[2]); /* q5 > 0 here: flipped */
        if (!(config & PYRT_PUMA_FLIP)) {
            th4 += PUMA_PI;
            th5 = -th5;
        }
    } else {
        th4 = seed != NULL ? seed[3] + arm->offsets[3] : 0.0;
    }
    c4 = cos(th4);
    s4 = sin(th4);
    c5 = cos(th5);
    s5f = sin(th5);
    /* Rz(th6) = (Rz(th4) Ry(-th5))^T w: its first column */
    a0 = c4 * c5 * w[0] + s4 * c5 * w[3] + s5f * w[6];
    a1 = -s4 * w[0] + c4 * w[3];
    th6 = atan2(a1, a0);

    th[0] = th1;
    th[1] = th2;
    th[2] = th23 - th2;
    th[3] = th4;
    th[4] = th5;
    th[5] = th6;
    for (i = 0; i < 6; i++) {
        double v = remainder(th[i] - arm->offsets[i], PUMA_TWO_PI);
        if (seed != NULL)
            v += PUMA_TWO_PI * floor((seed[i] - v) / PUMA_TWO_PI + 0.5);
        if (!(config & PYRT_PUMA_NO_LIMITS)) {
            double placed;
            if (!into_limits(v, arm->lower[i], arm->upper[i], &placed)) {
                *why = PYRT_PUMA_LIMIT + i;
                detail[0] = v;
                return PYRT_OK;
            }
            v = placed;
        }
        out[i] = v;
    }
    for (i = 0; i < 6; i++)
        q[i] = out[i];
    return PYRT_OK;
}
