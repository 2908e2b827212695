/*
 * Rope-and-source statics: where the source carriage hangs for given
 * payed-out rope lengths (000, sections 5-6 and 17; the physics behind the
 * simulated manipulator boards).
 *
 * Units: centimetres, newtons.  Arrays of points are row-major n x 3
 * doubles.  As in findpos.h, a rope whose bottom row is all NaN is a central
 * rope (top pulley straight to the carriage); any other NaN or infinity is
 * PYRT_ENONFINITE.
 *
 * Model.  The carriage pulley of rope i sits at x + offset_i.  A side rope
 * runs from its top pulley down to the carriage pulley and back up to its
 * bottom attachment, one tension along its whole length; a central rope
 * ends at the carriage.  The rope geometry beyond the top pulley is g_i(x);
 * the rope also spans dead_i from the spindle to the top pulley.  A rope is
 * elastic with a stretch proportional to tension and to its unstretched
 * length u_i (payout_i, dead section included):
 *
 *     tension_i = max(0, dead_i + g_i(x) - u_i) / (compliance_i * u_i)
 *
 * so a slack rope carries nothing and never pushes.  The rope's path over
 * the neck ring is the one model of neck.h: a straight segment (top pulley
 * to carriage, or carriage to bottom attachment with the source up in the
 * neck) that would cross the neck-ring plane outside the ring bears on the
 * ring instead, both segments of a rope may (PYRT_STATICS_RING_SEGMENTS).
 * The carriage itself cannot pass through the ring's rim; the rope length
 * jumps there, at positions no source can reach.
 *
 * The equilibrium minimises the potential energy
 *
 *     E(x) = weight * z + sum_i (1/2) k_i s_i^2,   k_i = 1/(compliance_i u_i)
 *
 * (weight: net downward force, gravity less buoyancy) by damped Newton
 * iterations on the analytic gradient and Hessian, warm-started from the
 * position passed in, with the source kept above floor_z (the vessel
 * bottom, which carries it when every rope is slack).
 *
 * Plain C99: no globals, no allocation, status codes from pyrt_native.h.
 */
#ifndef PYRT_STATICS_H
#define PYRT_STATICS_H

#include "pyrt_native.h"
#include "neck.h"

/* Ropes per problem: 1 .. PYRT_STATICS_MAX_ROPES. */
#define PYRT_STATICS_MAX_ROPES 16

/* The world lets both segments of a rope bear on the neck ring. */
#define PYRT_STATICS_RING_SEGMENTS (PYRT_NECK_UPPER | PYRT_NECK_LOWER)

/* Defaults of the solver: step tolerance (cm), longest step (cm), iterations. */
#define PYRT_STATICS_DEFAULT_TOL 1e-7
#define PYRT_STATICS_DEFAULT_MAX_STEP 10.0
#define PYRT_STATICS_DEFAULT_MAX_ITER 50

/*
 * One statics problem.  Pointers are borrowed; the Python side binds them
 * once and then only rewrites payout (and intact) between calls.
 *
 *   n           ropes, 1 .. PYRT_STATICS_MAX_ROPES
 *   tops        n x 3 top pulley points
 *   bottoms     n x 3 bottom attachments; an all-NaN row = central rope
 *   offsets     n x 3 carriage pulley offsets, or NULL for all zero
 *   payout      n unstretched rope lengths from the spindle (> 0)
 *   dead        n spindle-to-top-pulley lengths (>= 0)
 *   compliance  n strains per newton (> 0)
 *   intact      n flags: 0 = broken rope (carries nothing)
 *   ring        the neck ring (pyrt_neck_init; radius <= 0: no ring)
 *   weight      net downward force on the source, N (may be negative)
 *   floor_z     lowest z the source may take
 *   tol         stop when a step is shorter than tol (cm), > 0
 *   max_step    longest step of one iteration (cm), > 0
 *   max_iter    iteration limit, >= 1
 *   position    3: the warm start on entry, the equilibrium on exit
 *   tension     n out: rope tensions at the equilibrium
 *   wrapped     n out: 1 when the rope (either segment) bears on the neck ring
 *   iterations  out: Newton steps taken
 *   residual    out: magnitude of the net force on the source (N), the
 *               floor's reaction excluded
 *
 * Outputs are written on PYRT_OK and on PYRT_ENOCONVERGE (then they hold the
 * best point reached, which a caller stepping in time may continue from);
 * on any other status they keep their previous contents.
 */
typedef struct {
    int32_t n;
    const double *tops;
    const double *bottoms;
    const double *offsets;
    const double *payout;
    const double *dead;
    const double *compliance;
    const int32_t *intact;
    pyrt_neck_ring ring;
    double weight;
    double floor_z;
    double tol;
    double max_step;
    int32_t max_iter;
    double *position;
    double *tension;
    int32_t *wrapped;
    int32_t iterations;
    double residual;
} pyrt_statics_problem;

/*
 * Solve for the static equilibrium.  Returns PYRT_OK; PYRT_EINVAL (NULL
 * pointer, n, tol, max_step, max_iter, payout, compliance or dead out of
 * range, a bottom row partly NaN, a ring pyrt_neck_check refuses);
 * PYRT_ENONFINITE; PYRT_EDEGENERATE (the carriage pulley on a top pulley or
 * bottom attachment); PYRT_ENOCONVERGE (max_iter reached).
 */
int pyrt_statics_solve(pyrt_statics_problem *p);

/*
 * Rope geometry and tensions at a given position (no solving): g (n),
 * tension (n) and wrapped (n) as defined above; g and wrapped may be NULL.
 * Same status codes as pyrt_statics_solve but never PYRT_ENOCONVERGE.
 */
int pyrt_statics_evaluate(const pyrt_statics_problem *p, const double *position,
                          double *g, double *tension, int32_t *wrapped);

#endif /* PYRT_STATICS_H */
