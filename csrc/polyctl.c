/*
 * The PolyAxis control poll kernels; see polyctl.h.  The arithmetic follows
 * the Python forms it replaced operation for operation (PolyAxis.measure /
 * error_signal / _drive); the neck ring is neck.h's model.
 * tests/_ref_polyctl.py is the reference.
 */
#include "polyctl.h"

#include <math.h>
#include <stddef.h>

static double dist3(const double *a, const double *b)
{
    double dx = a[0] - b[0], dy = a[1] - b[1], dz = a[2] - b[2];
    return sqrt(dx * dx + dy * dy + dz * dz);
}

static int check_common(const pyrt_polyctl *c)
{
    if (c == NULL)
        return PYRT_EINVAL;
    if (c->n < 1 || c->n > PYRT_POLYCTL_MAX_ROPES)
        return PYRT_EINVAL;
    if (c->tops == NULL || c->bottoms == NULL || c->offsets == NULL || c->tension == NULL
        || c->length == NULL || c->phi == NULL || c->phi_lower == NULL || c->position == NULL)
        return PYRT_EINVAL;
    if ((c->ring_segments & ~(PYRT_NECK_UPPER | PYRT_NECK_LOWER)) != 0)
        return PYRT_EINVAL;
    return pyrt_neck_check(&c->ring);
}

/* Rope i's path with the carriage at pos (+ its offset), its rim hints
 * (phi, phi_lower) updated for the next poll: NAN where a segment is clear. */
static int rope_at(const pyrt_polyctl *c, int32_t i, const double *pos, double *phi,
                   double *phi_lower, pyrt_neck_rope *path)
{
    const double *o = c->offsets + 3 * i;
    double q[3], hint[2];
    int rc;

    q[0] = pos[0] + o[0];
    q[1] = pos[1] + o[1];
    q[2] = pos[2] + o[2];
    hint[0] = phi[i];
    hint[1] = phi_lower[i];
    rc = pyrt_neck_rope_path(&c->ring, c->ring_segments, c->tops + 3 * i, c->bottoms + 3 * i,
                             q, hint, path);
    if (rc != PYRT_OK)
        return rc;
    phi[i] = path->upper.bears ? path->upper.phi : NAN;
    phi_lower[i] = path->lower.bears ? path->lower.phi : NAN;
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
        || c->finder_bottoms == NULL
        || c->finder->n != n || c->finder->position == NULL || c->result == NULL)
        return PYRT_EINVAL;
    for (i = 0; i < n; i++)
        if (!isfinite(c->tension[i]) || !isfinite(c->encoder_length[i]))
            return PYRT_ENONFINITE;
    for (i = 0; i < n; i++) {
        double t = c->tension[i];
        c->length[i] = c->encoder_length[i] * (1.0 + c->stretch[i] * (t > 0.0 ? t : 0.0))
                       - c->dead[i];
    }
    x = c->position;
    for (i = 0; i < n; i++) {
        const double *b = c->bottoms + 3 * i;
        pyrt_neck_rope path;
        rc = rope_at(c, i, x, c->phi, c->phi_lower, &path);
        if (rc != PYRT_OK)
            return rc;
        c->finder_tops[3 * i] = path.upper.point[0];
        c->finder_tops[3 * i + 1] = path.upper.point[1];
        c->finder_tops[3 * i + 2] = path.upper.point[2];
        if (!isnan(b[0])) {
            c->finder_bottoms[3 * i] = path.lower.point[0];
            c->finder_bottoms[3 * i + 1] = path.lower.point[1];
            c->finder_bottoms[3 * i + 2] = path.lower.point[2];
        }
        c->finder_lengths[i] = c->length[i] - path.upper.head - path.lower.head;
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
    /* the net force at the new estimate, toward this poll's effective tops and bottoms */
    x = c->position;
    fx = 0.0;
    fy = 0.0;
    fz = -(x[2] < c->liquid_level ? c->weight_liquid : c->weight_air);
    for (i = 0; i < n; i++) {
        const double *o = c->offsets + 3 * i, *tt = c->finder_tops + 3 * i;
        const double *b = c->finder_bottoms + 3 * i;
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
    if (c->velocity == NULL || c->hare_phi == NULL || c->hare_phi_lower == NULL
        || c->prev_error_length == NULL
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
        const double *b = c->bottoms + 3 * i;
        double want;
        pyrt_neck_rope path;
        if (!c->signal_all) {
            /* off side: the bottom on the far side of the central axis (or level) */
            int off = !isnan(b[0])
                      && (b[0] - c->axis_point[0]) * hx + (b[1] - c->axis_point[1]) * hy <= 0.0;
            c->desired_tension[i] = off ? c->offside_tension : 0.0;
            c->is_free[i] = off ? 0.0 : 1.0;
        }
        rc = rope_at(c, i, c->hare, c->hare_phi, c->hare_phi_lower, &path);
        if (rc != PYRT_OK)
            return rc;
        want = path.length;
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
