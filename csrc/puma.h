/*
 * Paul's closed-form inverse of the PUMA 560 (Paul, Shimano & Mayer 1981),
 * for the standard DH table of pyrt.kinematics.puma: alpha = (90, 0, -90,
 * 90, -90, 0) degrees, a = (0, a2, a3, 0, 0, 0), d = (d1, 0, d3, d4, 0, 0).
 *
 * The pose solved for is base . A1(q1 + o1) ... A6(q6 + o6) . tool; the
 * description carries the inverses of base and tool, the offsets and the
 * limits.  4x4 transforms are 16 doubles, row-major.  The configuration is
 * RCCL's, as bits: lefty (else righty), below (else above), flip (else
 * noflip); two more bits ask for the nearest posture to a wrist centre just
 * out of reach (a seed for a numerical inverse) and for no joint limits.
 *
 * An answer that is not a solution is not an error: the entry point
 * returns PYRT_OK and says why in *why (PYRT_PUMA_REACHED when q holds the
 * answer), with the number that decided it in detail[0] (the wrist
 * centre's distance from joint 1's axis or from the shoulder, m; or the
 * joint's angle, rad).  PYRT_EINVAL for NULL, PYRT_ENONFINITE for NaN or
 * infinity in the pose or the seed.
 *
 * Plain C99: no globals, no allocation.
 */
#ifndef PYRT_PUMA_H
#define PYRT_PUMA_H

#include "pyrt_native.h"

/* Configuration bits (all clear: righty, above, noflip). */
#define PYRT_PUMA_LEFTY 1
#define PYRT_PUMA_BELOW 2
#define PYRT_PUMA_FLIP 4
/* Option bits. */
#define PYRT_PUMA_NEAREST 8
#define PYRT_PUMA_NO_LIMITS 16

/* *why. */
#define PYRT_PUMA_REACHED 0
#define PYRT_PUMA_INSIDE_OFFSET 1   /* wrist centre nearer joint 1's axis than d3 */
#define PYRT_PUMA_TOO_FAR 2         /* beyond the arm's reach */
#define PYRT_PUMA_TOO_NEAR 3        /* nearer the shoulder than |a2 - |(a3, d4)|| */
#define PYRT_PUMA_LIMIT 10          /* PYRT_PUMA_LIMIT + i: joint i beyond its limits */

/* |sin q5| at or below which the wrist is at its singularity. */
#define PYRT_PUMA_SINGULAR 1e-12

/*
 * The arm: its DH lengths (m), the inverses of its base and tool, joint
 * offsets (added to q before the table) and limits (rad; may be +-inf).
 */
typedef struct {
    double d1, a2, a3, d3, d4;
    double base_inv[16];
    double tool_inv[16];
    double offsets[6];
    double lower[6];
    double upper[6];
} pyrt_puma;

/*
 * q (6) = the joint values putting the tool at pose in configuration
 * config; with seed (6, or NULL), each joint is the turn of its angle
 * nearest the seed's (else the one in (-pi, pi]), then within the limits
 * when a turn brings it there.  At the wrist's singularity joint 4 keeps
 * the seed's value (0 without a seed).  q is written only when *why is
 * PYRT_PUMA_REACHED.
 */
int pyrt_puma_inverse(const pyrt_puma *arm, const double *pose, int32_t config,
                      const double *seed, double *q, int32_t *why, double *detail);

#endif /* PYRT_PUMA_H */
