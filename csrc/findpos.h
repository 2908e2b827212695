/*
 * Rope manipulator geometry: the iterated-linear position finder and the
 * forward rope lengths (000, section 5, Eq. 1-2 and the freeze mask).
 *
 * Units are centimetres throughout.  Arrays of points are row-major n x 3
 * doubles (x, y, z of rope 0, then rope 1, ...).  A rope whose bottom row is
 * all NaN is a central rope: it runs from its top pulley straight to the
 * carriage pulley and has no bottom segment.  Any other NaN or infinity in
 * an input is PYRT_ENONFINITE.
 *
 * Rope model (Eq. 1): the carriage pulley of rope i sits at xs + offset_i;
 * the predicted length is |top_i - xs - offset_i| (top segment) plus
 * |bottom_i - xs - offset_i| (bottom segment, side ropes only).
 *
 * Residual sign: residual_i = measured length - predicted length.  A
 * positive residual means more rope is paid out than the estimated source
 * position accounts for.  (000 defines its lengthResidual with the opposite
 * sign to errorLength; pyrt fixes measured - predicted everywhere.)
 *
 * Plain C99: no globals, no allocation, every function returns a status code
 * from pyrt_native.h.
 */
#ifndef PYRT_FINDPOS_H
#define PYRT_FINDPOS_H

#include "pyrt_native.h"

/* Ropes per problem: 1 .. PYRT_FINDPOS_MAX_ROPES (3 in-plane, 5 out-of-plane). */
#define PYRT_FINDPOS_MAX_ROPES 16

/*
 * The freeze rule of 000: a direction whose sum of |bottom attachment|
 * components over the side ropes is below this many centimetres is held at
 * its start value, so that in-plane motion cannot wander out of plane.
 */
#define PYRT_FINDPOS_FREEZE_CM 1

/* Defaults of the solver: 000's 0.1 cm step tolerance, and an iteration limit. */
#define PYRT_FINDPOS_DEFAULT_TOL 0.1
#define PYRT_FINDPOS_DEFAULT_MAX_ITER 50

/*
 * One position-finding problem.  Pointers are borrowed (the caller owns the
 * memory and keeps it alive); the prepared Python form binds them once and
 * then only calls pyrt_findpos_solve.
 *
 *   n          ropes, 1 .. PYRT_FINDPOS_MAX_ROPES
 *   tops       n x 3 top pulley points (where the rope leaves the pulley;
 *              the caller may move them between calls, e.g. for rope
 *              contact with the neck ring)
 *   bottoms    n x 3 bottom attachment points; an all-NaN row = central rope
 *   offsets    n x 3 carriage pulley offsets (Delta of Eq. 1), or NULL for
 *              all zero
 *   lengths    n measured (stretch-corrected) rope lengths
 *   freeze     3 flags: nonzero holds that direction at its start value
 *   tol        stop when the step of an iteration is shorter than tol (cm;
 *              000 uses 0.1: PYRT_FINDPOS_DEFAULT_TOL); finite and > 0
 *   max_iter   iteration limit, >= 1
 *   position   3 doubles: the start on entry, the solution on exit
 *   residuals  n doubles: measured - predicted at the solution
 *   rms        out: sqrt(sum(residual^2) / n), the document's distErr
 *   iterations out: linear solves performed
 *
 * position, residuals, rms and iterations are written only when the status
 * is PYRT_OK; on any error they keep their previous contents.
 */
typedef struct {
    int32_t n;
    const double *tops;
    const double *bottoms;
    const double *offsets;
    const double *lengths;
    int32_t freeze[3];
    double tol;
    int32_t max_iter;
    double *position;
    double *residuals;
    double rms;
    int32_t iterations;
} pyrt_findpos_problem;

/*
 * Minimise sum(residual_i^2) over the unfrozen components of the source
 * position by the iterated linear method of 000 (Eq. 2): each iteration
 * holds the rope directions fixed at the current estimate, solves the 3x3
 * normal equations for the step (frozen rows and columns removed), and
 * stops when the step is shorter than tol.
 *
 * Returns PYRT_OK; PYRT_EINVAL (NULL pointer, n out of range, tol or
 * max_iter out of range, every direction frozen, a bottom row partly NaN);
 * PYRT_ENONFINITE (NaN or infinity in tops, offsets, lengths, start or a
 * bottom); PYRT_EDEGENERATE (a segment shorter than
 * PYRT_MIN_SEGMENT_CM during the iteration); PYRT_ESINGULAR (the
 * ropes do not fix the unfrozen directions); PYRT_ENOCONVERGE (max_iter
 * reached, or the iteration ran away to a non-finite point).
 */
int pyrt_findpos_solve(pyrt_findpos_problem *p);

/*
 * The freeze mask of 000 for a set of bottom attachments: freeze[j] = 1 when
 * the sum over side ropes of |bottom[j]| is below PYRT_FINDPOS_FREEZE_CM,
 * else 0.  Central rows (all NaN) are skipped.  PYRT_EINVAL or
 * PYRT_ENONFINITE as for pyrt_findpos_solve.
 */
int pyrt_findpos_freeze_mask(int32_t n, const double *bottoms, int32_t *freeze);

/*
 * Forward geometry for a source at position (3): for each rope the length
 * of the top segment, of the bottom segment (0 for a central rope), their
 * sum, and the unit vectors from the carriage pulley toward the top pulley
 * and toward the bottom attachment (zero for a central rope) -- the
 * directions in which the rope pulls the source.  offsets may be NULL (all
 * zero); top_len, bottom_len, top_dir and bottom_dir may each be NULL when
 * not wanted; total (n) is required.
 *
 * PYRT_EINVAL, PYRT_ENONFINITE as above; PYRT_EDEGENERATE when a segment is
 * shorter than PYRT_MIN_SEGMENT_CM (the source at a pulley).
 */
int pyrt_rope_lengths(int32_t n, const double *tops, const double *bottoms,
                      const double *offsets, const double *position,
                      double *total, double *top_len, double *bottom_len,
                      double *top_dir, double *bottom_dir);

#endif /* PYRT_FINDPOS_H */
