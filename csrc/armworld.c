/*
 * The simulated arm's integration step (armworld.h).
 *
 * Work layout (doubles), n joints:
 *   A     n n    the step's matrix, then its Cholesky factor
 *   RHS   n      A qd + h f, then the new qd
 *   BIAS  n      rnea(q, qd, 0, g)
 *   F     n      the generalised forces
 *   Q     n      q being integrated (committed at the end)
 *   QD    n      qd being integrated
 *   TAU   n      the motors' torque
 *   CUR   n      the motors' current
 *   CNT   n      the encoder counts to publish
 *   JAC   6 n    the tool's Jacobian
 *   JT    3 n    the tip's linear Jacobian
 *   POSE  16     the tool pose
 *   CON   3      the contact force to publish
 *   WR    6      the wrench to publish
 *   FT    6      the sensor counts to publish
 */
#include "armworld.h"
#include "_linalg.h"

#include <math.h>
#include <stddef.h>
#include <string.h>

#define W_A(n) 0
#define W_RHS(n) ((n) * (n))
#define W_BIAS(n) (W_RHS(n) + (n))
#define W_F(n) (W_BIAS(n) + (n))
#define W_Q(n) (W_F(n) + (n))
#define W_QD(n) (W_Q(n) + (n))
#define W_TAU(n) (W_QD(n) + (n))
#define W_CUR(n) (W_TAU(n) + (n))
#define W_CNT(n) (W_CUR(n) + (n))
#define W_JAC(n) (W_CNT(n) + (n))
#define W_JT(n) (W_JAC(n) + 6 * (n))
#define W_POSE(n) (W_JT(n) + 3 * (n))
#define W_CON(n) (W_POSE(n) + 16)
#define W_WR(n) (W_CON(n) + 3)
#define W_FT(n) (W_WR(n) + 6)
#define W_SIZE(n) (W_FT(n) + 6)

#define TWO_PI 6.283185307179586
#define TWO32 4294967296.0
#define TWO31 2147483648.0

int pyrt_arm_work_size(int32_t n, int32_t *size)
{
    if (size == NULL || n < 1 || n > PYRT_ARM_MAX_JOINTS) {
        return PYRT_EINVAL;
    }
    *size = W_SIZE(n);
    return PYRT_OK;
}

/* ------------------------------------------------------------------ checks */

static int finite_all(const double *v, int n)
{
    for (int i = 0; i < n; i++) {
        if (!isfinite(v[i])) {
            return 0;
        }
    }
    return 1;
}

static int positive(double v)
{
    return isfinite(v) && v > 0.0;
}

static int check(const pyrt_arm *a)
{
    if (a == NULL || a->chain == NULL || a->ws == NULL || a->params == NULL ||
        a->dac == NULL || a->enable == NULL || a->count == NULL || a->ft == NULL ||
        a->q == NULL || a->qd == NULL || a->torque == NULL || a->current == NULL ||
        a->contact == NULL || a->wrench == NULL || a->work == NULL) {
        return PYRT_EINVAL;
    }
    const int n = a->n;
    if (n < 1 || n > PYRT_ARM_MAX_JOINTS || n != a->chain->n) {
        return PYRT_EINVAL;
    }
    if (!finite_all(a->gravity, 3) || !finite_all(a->tip, 3) || !finite_all(a->ft_offsets, 6) ||
        !finite_all(a->q, n) || !finite_all(a->qd, n) || !isfinite(a->max_step) ||
        !isfinite(a->friction_vs) || !isfinite(a->table_k) || !isfinite(a->table_c) ||
        !isfinite(a->table_mu) || !isfinite(a->payload) || (a->table && !isfinite(a->table_z))) {
        return PYRT_ENONFINITE;
    }
    if (!positive(a->max_step) || !positive(a->friction_vs) || !positive(a->table_k) ||
        a->table_c < 0.0 || a->table_mu < 0.0 || a->payload < 0.0 ||
        (a->table != 0 && a->table != 1)) {
        return PYRT_EINVAL;
    }
    for (int k = 0; k < 6; k++) {
        if (!isfinite(a->ft_scale[k]) || !isfinite(a->ft_sigma[k])) {
            return PYRT_ENONFINITE;
        }
        if (!(a->ft_scale[k] > 0.0) || a->ft_sigma[k] < 0.0) {
            return PYRT_EINVAL;
        }
    }
    const double *p = a->params;
    for (int r = 0; r < PYRT_ARM_NROWS; r++) {
        for (int j = 0; j < n; j++) {
            const double v = p[r * n + j];
            if (isnan(v) || (isinf(v) && r != PYRT_ARM_STOP_LO && r != PYRT_ARM_STOP_HI)) {
                return PYRT_ENONFINITE;
            }
            switch (r) {
            case PYRT_ARM_NM_PER_COUNT:
            case PYRT_ARM_AMPS_PER_COUNT:
            case PYRT_ARM_EFFORT:
            case PYRT_ARM_COUNTS:
                if (!(v > 0.0)) {
                    return PYRT_EINVAL;
                }
                break;
            case PYRT_ARM_STOP_LO:
                if (!(v <= p[PYRT_ARM_STOP_HI * n + j])) {
                    return PYRT_EINVAL;
                }
                break;
            case PYRT_ARM_STOP_HI:
                break;
            default:
                if (v < 0.0) {
                    return PYRT_EINVAL;
                }
            }
        }
    }
    return PYRT_OK;
}

int pyrt_arm_check(const pyrt_arm *a)
{
    return check(a);
}

/* ------------------------------------------------------------------ algebra */

/* ------------------------------------------------------------------ noise */

static uint64_t splitmix64(uint64_t *state)
{
    uint64_t z = (*state += UINT64_C(0x9E3779B97F4A7C15));
    z = (z ^ (z >> 30)) * UINT64_C(0xBF58476D1CE4E5B9);
    z = (z ^ (z >> 27)) * UINT64_C(0x94D049BB133111EB);
    return z ^ (z >> 31);
}

/* Six standard normals (three Box-Muller pairs). */
static void normals6(uint64_t *state, double *z)
{
    for (int p = 0; p < 3; p++) {
        const double u1 = (double)(splitmix64(state) >> 11) * 0x1.0p-53;
        const double u2 = (double)(splitmix64(state) >> 11) * 0x1.0p-53;
        const double r = sqrt(-2.0 * log(1.0 - u1));
        z[2 * p] = r * cos(TWO_PI * u2);
        z[2 * p + 1] = r * sin(TWO_PI * u2);
    }
}

/* ------------------------------------------------------------------ physics */

/* The motors' torque and current from the DACs and enables. */
static void drives(const pyrt_arm *a, double *tau, double *cur)
{
    const int n = a->n;
    const double *npc = a->params + PYRT_ARM_NM_PER_COUNT * n;
    const double *apc = a->params + PYRT_ARM_AMPS_PER_COUNT * n;
    const double *eff = a->params + PYRT_ARM_EFFORT * n;
    for (int j = 0; j < n; j++) {
        const double d = a->enable[j] ? (double)a->dac[j] : 0.0;
        const double t = d * npc[j];
        cur[j] = d * apc[j];
        tau[j] = t < -eff[j] ? -eff[j] : (t > eff[j] ? eff[j] : t);
    }
}

/*
 * The table's force on the tip at (q, qd) into con (3, world) and the
 * sensor's wrench into wr (6, tool frame).  When the tip presses on the
 * table, jt (3 x n) holds the tip's linear Jacobian, *ct the friction's
 * damping coefficient, and the result is 1; else 0 (or a negative status).
 */
static int contact_force(const pyrt_arm *a, double *w, const double *q, const double *qd,
                         double *con, double *wr, double *ct)
{
    const int n = a->n;
    double *pose = w + W_POSE(n);
    int rc = pyrt_kin_fk(a->chain, a->ws, q, pose);
    if (rc != PYRT_OK) {
        return -rc;
    }
    const double *t = a->tip;
    const double r[3] = {
        pose[0] * t[0] + pose[1] * t[1] + pose[2] * t[2],
        pose[4] * t[0] + pose[5] * t[1] + pose[6] * t[2],
        pose[8] * t[0] + pose[9] * t[1] + pose[10] * t[2],
    };
    const double pz = pose[11] + r[2];
    int pressing = 0;
    con[0] = con[1] = con[2] = 0.0;
    if (a->table && pz < a->table_z) {
        double *jac = w + W_JAC(n);
        double *jt = w + W_JT(n);
        rc = pyrt_kin_jacobian(a->chain, a->ws, q, jac, NULL);
        if (rc != PYRT_OK) {
            return -rc;
        }
        const double *jv0 = jac, *jv1 = jac + n, *jv2 = jac + 2 * n;
        const double *jw0 = jac + 3 * n, *jw1 = jac + 4 * n, *jw2 = jac + 5 * n;
        double v[3] = {0.0, 0.0, 0.0};
        for (int i = 0; i < n; i++) {
            /* v_tip = v + w x r = v - r x w */
            jt[i] = jv0[i] - (r[1] * jw2[i] - r[2] * jw1[i]);
            jt[n + i] = jv1[i] - (r[2] * jw0[i] - r[0] * jw2[i]);
            jt[2 * n + i] = jv2[i] - (r[0] * jw1[i] - r[1] * jw0[i]);
            v[0] += jt[i] * qd[i];
            v[1] += jt[n + i] * qd[i];
            v[2] += jt[2 * n + i] * qd[i];
        }
        const double fn = a->table_k * (a->table_z - pz) - a->table_c * v[2];
        if (fn > 0.0) {
            const double vt = hypot(v[0], v[1]);
            const double vs = PYRT_ARM_TABLE_VS;
            *ct = a->table_mu * fn * (vt > 1e-12 ? tanh(vt / vs) / vt : 1.0 / vs);
            con[0] = -*ct * v[0];
            con[1] = -*ct * v[1];
            con[2] = fn;
            pressing = 1;
        }
    }
    /* the wrist: contact and the payload's weight at the tip, in the tool frame */
    const double fw[3] = {con[0] + a->payload * a->gravity[0],
                          con[1] + a->payload * a->gravity[1],
                          con[2] + a->payload * a->gravity[2]};
    const double fx = pose[0] * fw[0] + pose[4] * fw[1] + pose[8] * fw[2];
    const double fy = pose[1] * fw[0] + pose[5] * fw[1] + pose[9] * fw[2];
    const double fz = pose[2] * fw[0] + pose[6] * fw[1] + pose[10] * fw[2];
    wr[0] = fx;
    wr[1] = fy;
    wr[2] = fz;
    wr[3] = t[1] * fz - t[2] * fy;
    wr[4] = t[2] * fx - t[0] * fz;
    wr[5] = t[0] * fy - t[1] * fx;
    return pressing;
}

/* One internal step of h seconds on w's Q and QD. */
static int substep(const pyrt_arm *a, double *w, double h)
{
    const int n = a->n;
    const double *p = a->params;
    double *m = w + W_A(n);
    double *rhs = w + W_RHS(n);
    double *bias = w + W_BIAS(n);
    double *f = w + W_F(n);
    double *q = w + W_Q(n);
    double *qd = w + W_QD(n);
    const double *tau = w + W_TAU(n);
    int rc = pyrt_kin_mass_matrix(a->chain, a->ws, q, m);
    if (rc != PYRT_OK) {
        return rc;
    }
    rc = pyrt_kin_rnea(a->chain, a->ws, q, qd, NULL, a->gravity, bias);
    if (rc != PYRT_OK) {
        return rc;
    }
    const double *arm = p + PYRT_ARM_ARMATURE * n;
    const double *damp = p + PYRT_ARM_DAMPING * n;
    const double *fc = p + PYRT_ARM_FRICTION * n;
    const double *brake = p + PYRT_ARM_BRAKE * n;
    const double *lo = p + PYRT_ARM_STOP_LO * n;
    const double *hi = p + PYRT_ARM_STOP_HI * n;
    const double *ks = p + PYRT_ARM_STOP_K * n;
    const double *cs = p + PYRT_ARM_STOP_C * n;
    const double inv_vs = 1.0 / a->friction_vs;
    for (int i = 0; i < n; i++) {
        m[i * n + i] += arm[i];
    }
    for (int i = 0; i < n; i++) {
        /* A qd, the momentum the implicit step starts from */
        double s = 0.0;
        for (int k = 0; k < n; k++) {
            s += m[i * n + k] * qd[k];
        }
        rhs[i] = s;
    }
    for (int i = 0; i < n; i++) {
        double fi = tau[i] - bias[i];
        double di = h * damp[i];
        if (fc[i] != 0.0) {
            /* smoothed Coulomb friction, its slope in the matrix */
            const double th = tanh(qd[i] * inv_vs);
            const double dfr = fc[i] / a->friction_vs * (1.0 - th * th);
            fi += dfr * qd[i] - fc[i] * th;
            di += h * dfr;
        }
        if (a->release != NULL && !a->release[i]) {
            /* the engaged brake: a stiff viscous lock, wholly in the matrix */
            di += h * brake[i] / PYRT_ARM_BRAKE_VS;
        }
        /* an end stop pushes while its spring-damper pushes */
        const double d_lo = lo[i] - q[i];
        const double d_hi = q[i] - hi[i];
        if (d_lo > 0.0 && ks[i] * d_lo - cs[i] * qd[i] > 0.0) {
            fi += ks[i] * d_lo;
            di += h * cs[i] + h * h * ks[i];
        } else if (d_hi > 0.0 && ks[i] * d_hi + cs[i] * qd[i] > 0.0) {
            fi -= ks[i] * d_hi;
            di += h * cs[i] + h * h * ks[i];
        }
        f[i] = fi;
        m[i * n + i] += di;
    }
    if (a->table) {
        double ct = 0.0;
        const int pressing = contact_force(a, w, q, qd, w + W_CON(n), w + W_WR(n), &ct);
        if (pressing < 0) {
            return -pressing;
        }
        if (pressing) {
            const double *jt = w + W_JT(n);
            const double *jx = jt, *jy = jt + n, *jz = jt + 2 * n;
            const double *con = w + W_CON(n);
            double sx = 0.0, sy = 0.0, sz = 0.0;
            for (int k = 0; k < n; k++) {
                sx += jx[k] * qd[k];
                sy += jy[k] * qd[k];
                sz += jz[k] * qd[k];
            }
            const double cn = a->table_c;
            const double kz = h * cn + h * h * a->table_k;
            const double kt = h * ct;
            for (int i = 0; i < n; i++) {
                f[i] += jx[i] * con[0] + jy[i] * con[1] + jz[i] * con[2] + cn * jz[i] * sz;
                if (ct > 0.0) {
                    f[i] += ct * (jx[i] * sx + jy[i] * sy);
                }
                for (int k = 0; k < n; k++) {
                    m[i * n + k] += kz * jz[i] * jz[k];
                    if (ct > 0.0) {
                        m[i * n + k] += kt * (jx[i] * jx[k] + jy[i] * jy[k]);
                    }
                }
            }
        }
    }
    for (int i = 0; i < n; i++) {
        rhs[i] += h * f[i];
    }
    if (!cholesky(m, n)) {
        return PYRT_ESINGULAR;
    }
    chol_solve(m, n, rhs);
    if (!finite_all(rhs, n)) {
        return PYRT_ENONFINITE;
    }
    for (int i = 0; i < n; i++) {
        qd[i] = rhs[i];
        q[i] += h * rhs[i];
    }
    return finite_all(q, n) ? PYRT_OK : PYRT_ENONFINITE;
}

/* What publishing at (q, qd) gives, into w's CNT, CON, WR and FT; *rng advanced. */
static int publish_into(const pyrt_arm *a, double *w, const double *q, const double *qd,
                        uint64_t *rng)
{
    const int n = a->n;
    const double *cpu = a->params + PYRT_ARM_COUNTS * n;
    double *cnt = w + W_CNT(n);
    double *con = w + W_CON(n);
    double *wr = w + W_WR(n);
    double *ft = w + W_FT(n);
    for (int j = 0; j < n; j++) {
        /* the counter wraps as a 32-bit register (fmod is exact) */
        const double c = floor(q[j] * cpu[j]);
        if (!isfinite(c)) {
            return PYRT_ENONFINITE;
        }
        double m = fmod(c, TWO32);
        if (m < 0.0) {
            m += TWO32;
        }
        cnt[j] = m >= TWO31 ? m - TWO32 : m;
    }
    if (a->table || a->payload > 0.0) {
        double ct = 0.0;
        const int rc = contact_force(a, w, q, qd, con, wr, &ct);
        if (rc < 0) {
            return -rc;
        }
    } else {
        memset(con, 0, 3 * sizeof(double));
        memset(wr, 0, 6 * sizeof(double));
    }
    double z[6];
    normals6(rng, z);
    for (int k = 0; k < 6; k++) {
        double v = rint((wr[k] + z[k] * a->ft_sigma[k]) * a->ft_scale[k]) + a->ft_offsets[k];
        if (isnan(v)) {
            return PYRT_ENONFINITE;
        }
        ft[k] = v < -TWO31 ? -TWO31 : (v > TWO31 - 1.0 ? TWO31 - 1.0 : v);
    }
    return PYRT_OK;
}

static void commit_inputs(pyrt_arm *a, const double *w, uint64_t rng)
{
    const int n = a->n;
    for (int j = 0; j < n; j++) {
        a->count[j] = (int32_t)w[W_CNT(n) + j];
    }
    for (int k = 0; k < 6; k++) {
        a->ft[k] = (int32_t)w[W_FT(n) + k];
    }
    memcpy(a->contact, w + W_CON(n), 3 * sizeof(double));
    memcpy(a->wrench, w + W_WR(n), 6 * sizeof(double));
    a->rng = rng;
}

static int step_checked(pyrt_arm *a, double dt);

int pyrt_arm_step(pyrt_arm *a, double dt)
{
    const int rc = check(a);
    if (rc != PYRT_OK) {
        return rc;
    }
    return step_checked(a, dt);
}

int pyrt_arm_step_dac(pyrt_arm *a, double dt, const int32_t *dac)
{
    if (dac == NULL) {
        return PYRT_EINVAL;
    }
    int rc = check(a);
    if (rc != PYRT_OK) {
        return rc;
    }
    const int n = a->n;
    int32_t old[PYRT_ARM_MAX_JOINTS];
    memcpy(old, a->dac, (size_t)n * sizeof(int32_t));
    memcpy(a->dac, dac, (size_t)n * sizeof(int32_t));
    rc = step_checked(a, dt);
    if (rc != PYRT_OK) {
        memcpy(a->dac, old, (size_t)n * sizeof(int32_t));
    }
    return rc;
}

/* pyrt_arm_step after check(a). */
static int step_checked(pyrt_arm *a, double dt)
{
    int rc;
    if (!isfinite(dt)) {
        return PYRT_ENONFINITE;
    }
    if (dt < 0.0) {
        return PYRT_EINVAL;
    }
    if (dt == 0.0) {
        return PYRT_OK;
    }
    double k = ceil(dt / a->max_step - 1e-9);
    if (k < 1.0) {
        k = 1.0;
    }
    if (k > PYRT_ARM_MAX_SUBSTEPS) {
        return PYRT_EINVAL;
    }
    const int n = a->n;
    double *w = a->work;
    const double h = dt / k;
    memcpy(w + W_Q(n), a->q, (size_t)n * sizeof(double));
    memcpy(w + W_QD(n), a->qd, (size_t)n * sizeof(double));
    drives(a, w + W_TAU(n), w + W_CUR(n));
    for (long s = 0; s < (long)k; s++) {
        rc = substep(a, w, h);
        if (rc != PYRT_OK) {
            return rc;
        }
    }
    uint64_t rng = a->rng;
    rc = publish_into(a, w, w + W_Q(n), w + W_QD(n), &rng);
    if (rc != PYRT_OK) {
        return rc;
    }
    memcpy(a->q, w + W_Q(n), (size_t)n * sizeof(double));
    memcpy(a->qd, w + W_QD(n), (size_t)n * sizeof(double));
    memcpy(a->torque, w + W_TAU(n), (size_t)n * sizeof(double));
    memcpy(a->current, w + W_CUR(n), (size_t)n * sizeof(double));
    commit_inputs(a, w, rng);
    return PYRT_OK;
}

int pyrt_arm_publish(pyrt_arm *a)
{
    const int rc0 = check(a);
    if (rc0 != PYRT_OK) {
        return rc0;
    }
    uint64_t rng = a->rng;
    const int rc = publish_into(a, a->work, a->q, a->qd, &rng);
    if (rc != PYRT_OK) {
        return rc;
    }
    commit_inputs(a, a->work, rng);
    return PYRT_OK;
}
