/* Small dense linear algebra shared by the kernels (kinematics.c, armworld.c).
 * Internal: no kernel's public header includes it, so cffi never sees it; the
 * functions are static inline, compiled into each kernel that uses them.  No
 * allocation, no globals. */
#ifndef PYRT_LINALG_H
#define PYRT_LINALG_H

#include <math.h>

/* Cholesky of the n x n SPD matrix a (row-major, lower triangle) in place;
 * 0 when it is not positive definite. */
static inline int cholesky(double *a, int n)
{
    for (int j = 0; j < n; j++) {
        double d = a[j * n + j];
        for (int k = 0; k < j; k++) {
            d -= a[j * n + k] * a[j * n + k];
        }
        if (!(d > 0.0) || !isfinite(d)) {
            return 0;
        }
        d = sqrt(d);
        a[j * n + j] = d;
        for (int i = j + 1; i < n; i++) {
            double s = a[i * n + j];
            for (int k = 0; k < j; k++) {
                s -= a[i * n + k] * a[j * n + k];
            }
            a[i * n + j] = s / d;
        }
    }
    return 1;
}

/* Solve L L^T x = b in place (x = b on entry). */
static inline void chol_solve(const double *l, int n, double *x)
{
    for (int i = 0; i < n; i++) {
        double s = x[i];
        for (int k = 0; k < i; k++) {
            s -= l[i * n + k] * x[k];
        }
        x[i] = s / l[i * n + i];
    }
    for (int i = n - 1; i >= 0; i--) {
        double s = x[i];
        for (int k = i + 1; k < n; k++) {
            s -= l[k * n + i] * x[k];
        }
        x[i] = s / l[i * n + i];
    }
}

#endif /* PYRT_LINALG_H */
