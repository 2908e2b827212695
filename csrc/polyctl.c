/*
 * The PolyAxis control poll kernels; see polyctl.h.  The arithmetic follows
 * the Python forms it replaced operation for operation (pyrt/robots/_neck.py
 * for the ring contact, PolyAxis.measure / error_signal / _drive), so the
 * results agree to rounding; tests/_ref_polyctl.py is the reference.
 */
#include "polyctl.h"

#include <math.h>
#include <stddef.h>

static double dist3(const double *a, const double *b)
{
    double dx = a[0] - b[0], dy = a[1] - b[1], dz = a[2] - b[2];
    return sqrt(dx * dx + dy * dy + dz * dz);
}

/* 1 and the rim point/angle when the rope t -> q bears on the ring, else 0. */
static int contact(const double *ring, const double *t, const double *q, double hint,
                   double *cp, double *phi_out)
{
    const double rad = ring[12];
    const double cx0 = ring[0], cy0 = ring[1], cz0 = ring[2];
    const double ax0 = ring[3], ax1 = ring[4], ax2 = ring[5];
    const double e1x = ring[6], e1y = ring[7], e1z = ring[8];
    const double e2x = ring[9], e2y = ring[10], e2z = ring[11];
    double tcx, tcy, tcz, ht, qcx, qcy, qcz, hq, s, rx, ry, rz, xr, phi, cs, sn;
    int k;

    if (!(rad > 0.0))
        return 0;
    tcx = t[0] - cx0;
    tcy = t[1] - cy0;
    tcz = t[2] - cz0;
    ht = tcx * ax0 + tcy * ax1 + tcz * ax2;
    if (!(ht > 0.0))
        return 0;
    qcx = q[0] - cx0;
    qcy = q[1] - cy0;
    qcz = q[2] - cz0;
    hq = qcx * ax0 + qcy * ax1 + qcz * ax2;
    if (!(hq < 0.0))
        return 0;
    s = ht / (ht - hq);
    rx = tcx + s * (qcx - tcx);
    ry = tcy + s * (qcy - tcy);
    rz = tcz + s * (qcz - tcz);
    xr = rx * ax0 + ry * ax1 + rz * ax2;
    rx = rx - xr * ax0;
    ry = ry - xr * ax1;
    rz = rz - xr * ax2;
    if (rx * rx + ry * ry + rz * rz <= rad * rad)
        return 0;
    if (isnan(hint))
        phi = atan2(rx * e2x + ry * e2y + rz * e2z, rx * e1x + ry * e1y + rz * e1z);
    else
        phi = hint;
    for (k = 0; k < PYRT_POLYCTL_RING_ITER; k++) {
        double ux, uy, uz, px, py, pz, cx, cy, cz, ax_, ay_, az_, bx, by, bz;
        double da, db, pa, pb, f1, f2, step;
        cs = cos(phi);
        sn = sin(phi);
        ux = cs * e1x + sn * e2x;
        uy = cs * e1y + sn * e2y;
        uz = cs * e1z + sn * e2z;
        px = -sn * e1x + cs * e2x;
        py = -sn * e1y + cs * e2y;
        pz = -sn * e1z + cs * e2z;
        cx = cx0 + rad * ux;
        cy = cy0 + rad * uy;
        cz = cz0 + rad * uz;
        ax_ = cx - t[0];
        ay_ = cy - t[1];
        az_ = cz - t[2];
        bx = cx - q[0];
        by = cy - q[1];
        bz = cz - q[2];
        da = sqrt(ax_ * ax_ + ay_ * ay_ + az_ * az_);
        db = sqrt(bx * bx + by * by + bz * bz);
        if (da < 1e-9 || db < 1e-9)
            break;
        pa = rad * (ax_ * px + ay_ * py + az_ * pz) / da;
        pb = rad * (bx * px + by * py + bz * pz) / db;
        f1 = pa + pb;
        f2 = (rad * rad - pa * pa) / da + (rad * rad - pb * pb) / db;
        f2 -= rad * (ux * (ax_ / da + bx / db) + uy * (ay_ / da + by / db)
                     + uz * (az_ / da + bz / db));
        step = f2 > 0.0 ? -f1 / f2 : (f1 > 0.0 ? -0.1 : 0.1);
        step = step < -0.5 ? -0.5 : (step > 0.5 ? 0.5 : step);
        phi += step;
        if (-1e-10 < step && step < 1e-10)
            break;
    }
    cs = cos(phi);
    sn = sin(phi);
    cp[0] = cx0 + rad * (cs * e1x + sn * e2x);
    cp[1] = cy0 + rad * (cs * e1y + sn * e2y);
    cp[2] = cz0 + rad * (cs * e1z + sn * e2z);
    *phi_out = phi;
    return 1;
}

int pyrt_ring_contact(const double *ring, const double *t, const double *q, double hint,
                      double *cp, double *phi, int32_t *bears)
{
    if (ring == NULL || t == NULL || q == NULL || cp == NULL || phi == NULL || bears == NULL)
        return PYRT_EINVAL;
    if (contact(ring, t, q, hint, cp, phi)) {
        *bears = 1;
    } else {
        *bears = 0;
        cp[0] = t[0];
        cp[1] = t[1];
        cp[2] = t[2];
        *phi = NAN;
    }
    return PYRT_OK;
}

static int check_common(const pyrt_polyctl *c)
{
    if (c == NULL)
        return PYRT_EINVAL;
    if (c->n < 1 || c->n > PYRT_POLYCTL_MAX_ROPES)
        return PYRT_EINVAL;
    if (c->tops == NULL || c->bottoms == NULL || c->offsets == NULL || c->tension == NULL
        || c->length == NULL || c->phi == NULL || c->position == NULL)
        return PYRT_EINVAL;
    return PYRT_OK;
}

int pyrt_polyctl_measure(pyrt_polyctl *c)
{
    int32_t i, n;
    const double *x;
    double fx, fy, fz;
    int rc = check_common(c);

    if (rc != PYRT_OK)
        return rc;
    n = c->n;
    if (c->stretch == NULL || c->dead == NULL || c->encoder_length == NULL
        || c->finder == NULL || c->finder_tops == NULL || c->finder_lengths == NULL
        || c->finder->n != n || c->finder->position == NULL || c->result == NULL)
        return PYRT_EINVAL;
    for (i = 0; i < n; i++)
        if (!isfinite(c->tension[i]) || !isfinite(c->encoder_length[i]))
            return PYRT_ENONFINITE;
    x = c->position;
    for (i = 0; i < n; i++) {
        const double *t0 = c->tops + 3 * i, *o = c->offsets + 3 * i;
        double t = c->tension[i], cp[3], phi, q[3];
        double len = c->encoder_length[i] * (1.0 + c->stretch[i] * (t > 0.0 ? t : 0.0))
                     - c->dead[i];
        c->length[i] = len;
        q[0] = x[0] + o[0];
        q[1] = x[1] + o[1];
        q[2] = x[2] + o[2];
        if (contact(c->ring, t0, q, c->phi[i], cp, &phi)) {
            c->phi[i] = phi;
            c->finder_tops[3 * i] = cp[0];
            c->finder_tops[3 * i + 1] = cp[1];
            c->finder_tops[3 * i + 2] = cp[2];
            c->finder_lengths[i] = len - dist3(t0, cp);
        } else {
            c->phi[i] = NAN;
            c->finder_tops[3 * i] = t0[0];
            c->finder_tops[3 * i + 1] = t0[1];
            c->finder_tops[3 * i + 2] = t0[2];
            c->finder_lengths[i] = len;
        }
    }
    if (c->use_start) {
        c->finder->position[0] = x[0];
        c->finder->position[1] = x[1];
        c->finder->position[2] = x[2];
    }
    rc = pyrt_findpos_solve(c->finder);
    if (rc != PYRT_OK)
        return rc;
    c->use_start = 0;
    c->position[0] = c->finder->position[0];
    c->position[1] = c->finder->position[1];
    c->position[2] = c->finder->position[2];
    c->result[0] = c->finder->rms;
    /* the net force at the new estimate, along this poll's effective tops */
    x = c->position;
    fx = 0.0;
    fy = 0.0;
    fz = -(x[2] < c->liquid_level ? c->weight_liquid : c->weight_air);
    for (i = 0; i < n; i++) {
        const double *o = c->offsets + 3 * i, *tt = c->finder_tops + 3 * i;
        const double *b = c->bottoms + 3 * i;
        double qx = x[0] + o[0], qy = x[1] + o[1], qz = x[2] + o[2];
        double dx = tt[0] - qx, dy = tt[1] - qy, dz = tt[2] - qz;
        double d = sqrt(dx * dx + dy * dy + dz * dz);
        double k = c->tension[i] / (d != 0.0 ? d : 1e-12);
        fx += k * dx;
        fy += k * dy;
        fz += k * dz;
        if (!isnan(b[0])) {
            dx = b[0] - qx;
            dy = b[1] - qy;
            dz = b[2] - qz;
            d = sqrt(dx * dx + dy * dy + dz * dz);
            k = c->tension[i] / (d != 0.0 ? d : 1e-12);
            fx += k * dx;
            fy += k * dy;
            fz += k * dz;
        }
    }
    c->result[1] = fx;
    c->result[2] = fy;
    c->result[3] = fz;
    c->result[4] = sqrt(fx * fx + fy * fy + fz * fz);
    return PYRT_OK;
}

int pyrt_polyctl_drive(pyrt_polyctl *c)
{
    int32_t i, n;
    const double *x, *res;
    double hx, hy, near, k;
    int rc = check_common(c);

    if (rc != PYRT_OK)
        return rc;
    n = c->n;
    if (c->velocity == NULL || c->hare_phi == NULL || c->prev_error_length == NULL
        || c->prev_error_tension == NULL || c->last_dv == NULL || c->desired_tension == NULL
        || c->is_free == NULL || c->error_length == NULL || c->error_tension == NULL
        || c->finder == NULL || c->finder->residuals == NULL || c->finder->n != n
        || c->fuzzy == NULL || c->fuzzy->n != n || c->fuzzy->dv == NULL
        || c->fuzzy_inputs == NULL || c->hare == NULL)
        return PYRT_EINVAL;
    for (i = 0; i < 3; i++)
        if (!isfinite(c->hare[i]) || (c->has_endpoint && !isfinite(c->endpoint[i])))
            return PYRT_ENONFINITE;
    if (!isfinite(c->rate_scale))
        return PYRT_ENONFINITE;
    for (i = 0; i < n; i++)
        if (!isfinite(c->velocity[i]))
            return PYRT_ENONFINITE;
    x = c->position;
    res = c->finder->residuals;
    hx = x[0] - c->axis_point[0];
    hy = x[1] - c->axis_point[1];
    for (i = 0; i < n; i++) {
        const double *t = c->tops + 3 * i, *o = c->offsets + 3 * i, *b = c->bottoms + 3 * i;
        double q[3], cp[3], phi, dx, dy, dz, head = 0.0, want;
        const double *top = t;
        if (!c->signal_all) {
            /* off side: the bottom on the far side of the central axis (or level) */
            int off = !isnan(b[0])
                      && (b[0] - c->axis_point[0]) * hx + (b[1] - c->axis_point[1]) * hy <= 0.0;
            c->desired_tension[i] = off ? c->offside_tension : 0.0;
            c->is_free[i] = off ? 0.0 : 1.0;
        }
        q[0] = c->hare[0] + o[0];
        q[1] = c->hare[1] + o[1];
        q[2] = c->hare[2] + o[2];
        if (contact(c->ring, t, q, c->hare_phi[i], cp, &phi)) {
            c->hare_phi[i] = phi;
            head = dist3(t, cp);
            top = cp;
        } else {
            c->hare_phi[i] = NAN;
        }
        dx = top[0] - q[0];
        dy = top[1] - q[1];
        dz = top[2] - q[2];
        want = head + sqrt(dx * dx + dy * dy + dz * dz);
        if (!isnan(b[0])) {
            dx = b[0] - q[0];
            dy = b[1] - q[1];
            dz = b[2] - q[2];
            want += sqrt(dx * dx + dy * dy + dz * dz);
        }
        c->error_length[i] = (c->length[i] - res[i]) - want;
        c->error_tension[i] = c->is_free[i] != 0.0 ? 0.0
                              : c->tension[i] - c->desired_tension[i];
    }
    near = 0.0;
    if (c->has_endpoint) {
        near = 1.0 - dist3(x, c->endpoint) / c->near_end_cm;
        if (near < 0.0)
            near = 0.0;
    }
    k = c->rate_scale;
    for (i = 0; i < n; i++) {
        double *row = c->fuzzy_inputs + (size_t)i * PYRT_FUZZY_NINPUTS;
        double e = c->error_length[i], te = c->error_tension[i];
        row[PYRT_FUZZY_IN_TENSION] = c->tension[i];
        row[PYRT_FUZZY_IN_DESIRED_TENSION] = c->desired_tension[i];
        row[PYRT_FUZZY_IN_FREE] = c->is_free[i];
        row[PYRT_FUZZY_IN_LENGTH_ERROR] = e;
        row[PYRT_FUZZY_IN_VELOCITY] = c->velocity[i];
        row[PYRT_FUZZY_IN_LENGTH_ERROR_RATE] =
            c->have_prev ? (e - c->prev_error_length[i]) * k : 0.0;
        row[PYRT_FUZZY_IN_TENSION_ERROR_RATE] =
            c->have_prev ? (te - c->prev_error_tension[i]) * k : 0.0;
        row[PYRT_FUZZY_IN_LAST_DV] = c->last_dv[i];
        row[PYRT_FUZZY_IN_NEAR_END] = near;
        c->prev_error_length[i] = e;
        c->prev_error_tension[i] = te;
    }
    c->have_prev = 1;
    rc = pyrt_fuzzy_run(c->fuzzy);
    if (rc != PYRT_OK)
        return rc;
    for (i = 0; i < n; i++)
        c->last_dv[i] = c->fuzzy->dv[i];
    return PYRT_OK;
}
