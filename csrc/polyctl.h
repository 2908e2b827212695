/*
 * The PolyAxis control poll as two batch kernels (000, section 5).
 *
 * pyrt_polyctl_measure (steps 1-3 of the poll): every rope's stretch-
 * corrected length from its encoder length and tension; where a segment of
 * a rope bears on the neck ring at the current estimate (neck.h, Newton on
 * the rim angle from last poll's angle; the segments in ring_segments),
 * the rim contact becomes its effective top (upper segment) or effective
 * bottom (lower segment) and the piece beyond the contact leaves the length
 * the finder sees; the prepared position finder (findpos.h) is solved; the
 * residual net force on the source at the new estimate (measured tensions
 * along the ropes toward the effective tops and bottoms, plus the net
 * weight).
 *
 * pyrt_polyctl_drive (step 4, after the motion has set the hare): the error
 * signals (off-side ropes toward offside_tension, the others free, unless
 * the caller set desired_tension and is_free itself: errorSignalAll), each
 * rope's length at the hare over the ring (neck.h), the length and tension errors,
 * their rates, the NEAR_END truth, the fuzzy input rows, and one batched
 * fuzzy step (fuzzy.h) giving every axis's velocity change.
 *
 * The caller owns every array; nothing is allocated and nothing is global.
 * Arrays are n doubles unless noted (n x 3 row-major for points).  The
 * per-poll inputs and outputs are pointers so that a caller may lay them
 * out in one block and exchange each call's data in one copy each way.  A bottom
 * row of NaN means the rope has no bottom attachment.  A rim angle of NaN
 * means the rope ran free of the ring at the last poll.
 */
#ifndef PYRT_POLYCTL_H
#define PYRT_POLYCTL_H

#include "pyrt_native.h"
#include "findpos.h"
#include "neck.h"
#include "fuzzy.h"

/* Ropes per manipulator: 1 .. PYRT_POLYCTL_MAX_ROPES. */
#define PYRT_POLYCTL_MAX_ROPES 16

/*
 * The segments the controller lets bear on the neck ring by default: both,
 * as the world does (statics.h PYRT_STATICS_RING_SEGMENTS), one geometry in
 * two roles.  A controller that deliberately knows less sets ring_segments
 * to a smaller mask (PYRT_NECK_UPPER: the lower segment always straight).
 */
#define PYRT_POLYCTL_RING_SEGMENTS (PYRT_NECK_UPPER | PYRT_NECK_LOWER)

typedef struct {
    int32_t n;
    /* geometry, bound once */
    const double *tops;         /* n x 3 top pulleys, cm */
    const double *bottoms;      /* n x 3 bottom attachments; NaN rows: none */
    const double *offsets;      /* n x 3 carriage offsets from the source */
    const double *stretch;      /* per newton */
    const double *dead;         /* dead lengths, cm */
    pyrt_neck_ring ring;        /* pyrt_neck_init (radius <= 0: none) */
    int32_t ring_segments;      /* the segments the controller lets bear on the
                                   ring (a mask of PYRT_NECK_UPPER/LOWER) */
    double axis_point[2];       /* (x, y) of the central axis: the off side */
    double weight_air;          /* N: the source's weight */
    double weight_liquid;       /* N: its net weight below liquid_level */
    double liquid_level;        /* z of the liquid surface (-inf: in air) */
    double offside_tension;     /* N */
    double near_end_cm;         /* NEAR_END falls from 1 to 0 over this distance */
    /* the prepared finder and fuzzy batch, and writable views of their inputs */
    pyrt_findpos_problem *finder;
    double *finder_tops;        /* n x 3: the finder's top points */
    double *finder_bottoms;     /* n x 3: the finder's bottom points (NaN rows kept) */
    double *finder_lengths;     /* n: the lengths the finder solves for */
    const pyrt_fuzzy_batch *fuzzy;
    double *fuzzy_inputs;       /* n x PYRT_FUZZY_NINPUTS: the batch's input rows */
    /* per-poll inputs */
    double *tension;            /* measured tensions, N */
    double *encoder_length;     /* encoder lengths (dead length included), cm */
    double *velocity;           /* each motor's present velocity, cm/s */
    double *position;           /* 3: the estimate (measure's result) */
    int32_t use_start;          /* 1: the solve starts from position (then cleared) */
    double *hare;               /* 3: the point the source is driven after */
    double endpoint[3];
    int32_t has_endpoint;       /* 0: NEAR_END is 0 */
    double rate_scale;          /* 1 / dt for the error rates, 1/s */
    int32_t signal_all;         /* 1: desired_tension and is_free were set by the caller */
    /* state carried between polls */
    double *phi;                /* upper segment's rim angle at the estimate (NaN: free) */
    double *phi_lower;          /* lower segment's rim angle at the estimate (NaN: free) */
    double *hare_phi;           /* upper segment's rim angle at the hare (NaN: free) */
    double *hare_phi_lower;     /* lower segment's rim angle at the hare (NaN: free) */
    double *prev_error_length;
    double *prev_error_tension;
    int32_t have_prev;          /* 0: the error rates are 0 at this poll */
    double *last_dv;            /* last poll's velocity changes, cm/s (drive's result) */
    /* outputs */
    double *length;             /* corrected length beyond the top pulley, cm */
    double *desired_tension;    /* N */
    double *is_free;            /* 1: free, 0: driven toward desired_tension */
    double *error_length;       /* corrected length - length at the hare, cm */
    double *error_tension;      /* tension - desired (0 when free), N */
    double *result;             /* 5: distErr (the solve's RMS residual, cm), the
                                   net force x, y, z and its magnitude, N */
} pyrt_polyctl;

/*
 * Steps 1-3 (see above).  PYRT_EINVAL for a NULL pointer, n out of range,
 * a ring pyrt_neck_check refuses or a finder of another size;
 * PYRT_ENONFINITE for a NaN or infinite tension or encoder length;
 * PYRT_EDEGENERATE when a rope's carriage pulley is on the rim; otherwise
 * the finder's status (position and the outputs but length are left as
 * they were when it fails).
 */
int pyrt_polyctl_measure(pyrt_polyctl *c);

/*
 * Step 4 (see above); the velocity changes are in the fuzzy batch's dv.
 * PYRT_EINVAL / PYRT_ENONFINITE for bad input, PYRT_EDEGENERATE for a
 * hare that puts a carriage pulley on a pulley, an attachment or the rim,
 * else the fuzzy status.
 */
int pyrt_polyctl_drive(pyrt_polyctl *c);

#endif /* PYRT_POLYCTL_H */
