/*
 * The neck ring and the ropes that bear on it; see neck.h for the model.
 */
#include "neck.h"

#include <math.h>
#include <stddef.h>

static double dot3(const double *a, const double *b)
{
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

static int finite3(const double *v)
{
    return isfinite(v[0]) && isfinite(v[1]) && isfinite(v[2]);
}

/* The rim at angle phi and the two pieces of the path f -> c -> q. */
typedef struct {
    double u[3];    /* unit radius toward c */
    double c[3];    /* the rim point */
    double cp[3];   /* dc/dphi */
    double a[3];    /* c - f */
    double b[3];    /* c - q */
    double da, db;  /* |a|, |b| */
} rim_point;

static void at_angle(const pyrt_neck_ring *ring, const double *f, const double *q, double phi,
                     rim_point *e)
{
    const double rad = ring->radius;
    double cs = cos(phi), sn = sin(phi);
    int k;
    for (k = 0; k < 3; ++k) {
        e->u[k] = cs * ring->e1[k] + sn * ring->e2[k];
        e->cp[k] = rad * (-sn * ring->e1[k] + cs * ring->e2[k]);
        e->c[k] = ring->centre[k] + rad * e->u[k];
        e->a[k] = e->c[k] - f[k];
        e->b[k] = e->c[k] - q[k];
    }
    e->da = sqrt(dot3(e->a, e->a));
    e->db = sqrt(dot3(e->b, e->b));
}

/* d(da + db)/dphi in *f1 and d2(da + db)/dphi2 (c'' = -(c - centre)) in *f2. */
static void slope(const pyrt_neck_ring *ring, const rim_point *e, double *f1, double *f2)
{
    const double rad = ring->radius;
    double ia = 1.0 / e->da, ib = 1.0 / e->db;
    double pa = dot3(e->a, e->cp) * ia;
    double pb = dot3(e->b, e->cp) * ib;
    *f1 = pa + pb;
    *f2 = (rad * rad - pa * pa - rad * dot3(e->u, e->a)) * ia
          + (rad * rad - pb * pb - rad * dot3(e->u, e->b)) * ib;
}

/*
 * 1 when the straight line f -> q crosses the ring plane outside the ring,
 * with r the crossing point's radius vector in the plane; else 0.
 */
static int crosses_outside(const pyrt_neck_ring *ring, const double *f, const double *q,
                           double *r)
{
    const double *cen = ring->centre, *ax = ring->axis;
    double fc[3], qc[3], hf, hq, s, xr;
    int k;
    if (!(ring->radius > 0.0))
        return 0;
    for (k = 0; k < 3; ++k) {
        fc[k] = f[k] - cen[k];
        qc[k] = q[k] - cen[k];
    }
    hf = dot3(fc, ax);
    hq = dot3(qc, ax);
    if (!((hf > 0.0 && hq < 0.0) || (hf < 0.0 && hq > 0.0)))
        return 0;
    s = hf / (hf - hq);
    for (k = 0; k < 3; ++k)
        r[k] = fc[k] + s * (qc[k] - fc[k]);
    xr = dot3(r, ax);
    for (k = 0; k < 3; ++k)
        r[k] -= xr * ax[k];
    return dot3(r, r) > ring->radius * ring->radius;
}

/* The segment q -> f over the rim at the angle found (e evaluated at phi). */
static int over_rim(const pyrt_neck_ring *ring, const rim_point *e, double phi,
                    pyrt_neck_segment *out)
{
    double f1, f2;
    int k;
    out->bears = 1;
    out->phi = phi;
    out->head = e->da;
    out->tail = e->db;
    for (k = 0; k < 3; ++k) {
        out->point[k] = e->c[k];
        out->tangent[k] = e->cp[k];
        out->dir[k] = 0.0;
    }
    out->curvature = 0.0;
    if (e->da < PYRT_MIN_SEGMENT_CM || e->db < PYRT_MIN_SEGMENT_CM)
        return PYRT_EDEGENERATE;
    for (k = 0; k < 3; ++k)
        out->dir[k] = e->b[k] * (1.0 / e->db);
    slope(ring, e, &f1, &f2);
    out->curvature = f2;
    return PYRT_OK;
}

/* The segment q -> f, over the ring when may_bear and it crosses outside. */
static int segment(const pyrt_neck_ring *ring, const double *f, const double *q, int may_bear,
                   double hint, pyrt_neck_segment *out)
{
    double r[3], d[3], dist;
    int k;

    if (may_bear && crosses_outside(ring, f, q, r)) {
        rim_point e;
        double phi, f1, f2, step;
        if (isnan(hint))
            phi = atan2(dot3(r, ring->e2), dot3(r, ring->e1));
        else
            phi = hint;
        for (k = 0; k < PYRT_NECK_MAX_ITER; ++k) {
            at_angle(ring, f, q, phi, &e);
            if (e.da < PYRT_MIN_SEGMENT_CM || e.db < PYRT_MIN_SEGMENT_CM)
                return over_rim(ring, &e, phi, out);
            slope(ring, &e, &f1, &f2);
            if (f2 > 0.0)
                step = -f1 / f2;
            else if (fabs(f1) <= PYRT_NECK_TIE * ring->radius)
                step = PYRT_NECK_FALLBACK_STEP;  /* a tie: either way is a contact */
            else
                step = f1 > 0.0 ? -PYRT_NECK_FALLBACK_STEP : PYRT_NECK_FALLBACK_STEP;
            if (step > PYRT_NECK_MAX_STEP)
                step = PYRT_NECK_MAX_STEP;
            else if (step < -PYRT_NECK_MAX_STEP)
                step = -PYRT_NECK_MAX_STEP;
            phi += step;
            if (fabs(step) < PYRT_NECK_STEP_TOL)
                break;
        }
        at_angle(ring, f, q, phi, &e);
        return over_rim(ring, &e, phi, out);
    }
    for (k = 0; k < 3; ++k)
        d[k] = f[k] - q[k];
    dist = sqrt(dot3(d, d));
    out->bears = 0;
    out->phi = NAN;
    out->head = 0.0;
    out->tail = dist;
    out->curvature = 0.0;
    for (k = 0; k < 3; ++k) {
        out->point[k] = f[k];
        out->tangent[k] = 0.0;
        out->dir[k] = 0.0;
    }
    if (dist < PYRT_MIN_SEGMENT_CM)
        return PYRT_EDEGENERATE;
    dist = 1.0 / dist;
    for (k = 0; k < 3; ++k)
        out->dir[k] = d[k] * dist;
    return PYRT_OK;
}

static void no_segment(pyrt_neck_segment *out)
{
    int k;
    out->bears = 0;
    out->phi = 0.0;
    out->head = 0.0;
    out->tail = 0.0;
    out->curvature = 0.0;
    for (k = 0; k < 3; ++k) {
        out->point[k] = 0.0;
        out->dir[k] = 0.0;
        out->tangent[k] = 0.0;
    }
}

int pyrt_neck_init(pyrt_neck_ring *ring, const double *centre, const double *axis, double radius)
{
    double n, a[3], h[3], e1[3], d, m;
    int k;
    if (ring == NULL || centre == NULL || axis == NULL)
        return PYRT_EINVAL;
    if (!finite3(centre) || !finite3(axis) || !isfinite(radius))
        return PYRT_ENONFINITE;
    n = sqrt(dot3(axis, axis));
    if (!(n > 0.0) || !isfinite(n))
        return PYRT_EINVAL;
    for (k = 0; k < 3; ++k)
        a[k] = axis[k] / n;
    /* any unit vector perpendicular to the axis, then e2 = axis x e1 */
    h[0] = fabs(a[0]) < 0.9 ? 1.0 : 0.0;
    h[1] = 1.0 - h[0];
    h[2] = 0.0;
    d = dot3(h, a);
    for (k = 0; k < 3; ++k)
        e1[k] = h[k] - d * a[k];
    m = sqrt(dot3(e1, e1));
    for (k = 0; k < 3; ++k) {
        ring->centre[k] = centre[k];
        ring->axis[k] = a[k];
        ring->e1[k] = e1[k] / m;
    }
    ring->e2[0] = a[1] * ring->e1[2] - a[2] * ring->e1[1];
    ring->e2[1] = a[2] * ring->e1[0] - a[0] * ring->e1[2];
    ring->e2[2] = a[0] * ring->e1[1] - a[1] * ring->e1[0];
    ring->radius = radius;
    return PYRT_OK;
}

int pyrt_neck_check(const pyrt_neck_ring *ring)
{
    const double tol = 1e-6;
    if (ring == NULL)
        return PYRT_EINVAL;
    if (!isfinite(ring->radius))
        return PYRT_ENONFINITE;
    if (!(ring->radius > 0.0))
        return PYRT_OK;
    if (!finite3(ring->centre) || !finite3(ring->axis) || !finite3(ring->e1)
        || !finite3(ring->e2))
        return PYRT_ENONFINITE;
    if (fabs(dot3(ring->axis, ring->axis) - 1.0) > tol || fabs(dot3(ring->e1, ring->e1) - 1.0) > tol
        || fabs(dot3(ring->e2, ring->e2) - 1.0) > tol || fabs(dot3(ring->axis, ring->e1)) > tol
        || fabs(dot3(ring->axis, ring->e2)) > tol || fabs(dot3(ring->e1, ring->e2)) > tol)
        return PYRT_EINVAL;
    return PYRT_OK;
}

int pyrt_neck_contact(const pyrt_neck_ring *ring, const double *far, const double *q,
                      double hint, pyrt_neck_segment *out)
{
    if (ring == NULL || far == NULL || q == NULL || out == NULL)
        return PYRT_EINVAL;
    if (!finite3(far) || !finite3(q) || isinf(hint))
        return PYRT_ENONFINITE;
    return segment(ring, far, q, 1, hint, out);
}

int pyrt_neck_rope_path(const pyrt_neck_ring *ring, int32_t segments, const double *top,
                        const double *bottom, const double *q, const double *hint,
                        pyrt_neck_rope *out)
{
    double h0 = NAN, h1 = NAN;
    int nans, rc;
    if (ring == NULL || top == NULL || bottom == NULL || q == NULL || out == NULL)
        return PYRT_EINVAL;
    nans = isnan(bottom[0]) + isnan(bottom[1]) + isnan(bottom[2]);
    if (nans != 0 && nans != 3)
        return PYRT_EINVAL;
    if (!finite3(top) || !finite3(q) || (nans == 0 && !finite3(bottom)))
        return PYRT_ENONFINITE;
    if (hint != NULL) {
        h0 = hint[0];
        h1 = hint[1];
        if (isinf(h0) || isinf(h1))
            return PYRT_ENONFINITE;
    }
    rc = segment(ring, top, q, (segments & PYRT_NECK_UPPER) != 0, h0, &out->upper);
    if (rc != PYRT_OK)
        return rc;
    if (nans == 3) {
        no_segment(&out->lower);
    } else {
        rc = segment(ring, bottom, q, (segments & PYRT_NECK_LOWER) != 0, h1, &out->lower);
        if (rc != PYRT_OK)
            return rc;
    }
    out->length = out->upper.head + out->upper.tail + out->lower.head + out->lower.tail;
    return PYRT_OK;
}
