/*
 * The neck ring and the ropes that bear on it (000, section 5,
 * neckIntersection()): one model for the simulated world (statics.c) and
 * the controller (polyctl.c), and through pyrt.native for Python.
 *
 * A straight rope segment runs from the carriage pulley q to its far end f
 * (the top pulley, or the bottom attachment).  When f and q lie on opposite
 * sides of the ring plane and the straight line would cross the plane
 * outside the ring, the segment bears on the ring instead: the ring is
 * frictionless (the document's assumption), so the rope takes the shortest
 * path f -> c -> q over a point c of the rim and lies in a plane through a
 * ring radius.  With c(phi) = centre + radius (cos phi e1 + sin phi e2), c is
 * found by Newton's method on phi, from a hint (the angle found for the same
 * rope at the last call) or else from the radius through the straight
 * line's crossing point; from the hint it converges in one or two steps
 * instead of four to six.
 *
 * Which segments of a rope may bear on the ring is a parameter (segments,
 * a mask of PYRT_NECK_UPPER and PYRT_NECK_LOWER) of the one model: the world
 * lets both bear (statics.h PYRT_STATICS_RING_SEGMENTS), the controller
 * only the upper one (polyctl.h PYRT_POLYCTL_RING_SEGMENTS).
 *
 * Units: centimetres, radians.  Plain C99: no globals, no allocation,
 * status codes from pyrt_native.h.
 */
#ifndef PYRT_NECK_H
#define PYRT_NECK_H

#include "pyrt_native.h"

/* Segments of a rope (the segments mask). */
#define PYRT_NECK_UPPER 1   /* top pulley to carriage pulley */
#define PYRT_NECK_LOWER 2   /* carriage pulley to bottom attachment */

/* Newton on the rim angle: at most this many steps ... */
#define PYRT_NECK_MAX_ITER 12
/* ... stopping after a step shorter than this (rad) ... */
#define PYRT_NECK_STEP_TOL 1e-10
/* ... each step at most this long (rad) ... */
#define PYRT_NECK_MAX_STEP 0.5
/* ... and this long, downhill, where the length is not convex in phi (rad); */
#define PYRT_NECK_FALLBACK_STEP 0.1
/* where the slope is within this many cm per radian of the radius of zero there
 * (the start is the symmetric point between two equal contacts: a rope from a
 * point on the axis), the step is +FALLBACK_STEP: rounding does not choose. */
#define PYRT_NECK_TIE 1e-12

/*
 * The ring: centre, unit axis pointing out of the vessel, and two unit
 * vectors spanning its plane (e2 = axis x e1), interior radius.  Made by
 * pyrt_neck_init; a radius <= 0 means there is no ring (nothing bears).
 */
typedef struct {
    double centre[3];
    double axis[3];
    double e1[3];
    double e2[3];
    double radius;
} pyrt_neck_ring;

/*
 * One segment, carriage pulley q to far end f.  When bears is 1 it runs over
 * the rim point c; when 0 it runs straight and c is f (phi NaN, head 0,
 * tangent and curvature 0).
 *
 *   point      c
 *   phi        c's rim angle
 *   head       |f - c|: the piece beyond the contact
 *   tail       |c - q|
 *   dir        (c - q) / tail: the pull on the carriage per newton
 *   tangent    dc/dphi
 *   curvature  d2(head + tail)/dphi2 at phi (> 0 at the shortest path)
 */
typedef struct {
    int32_t bears;
    double point[3];
    double phi;
    double head;
    double tail;
    double dir[3];
    double tangent[3];
    double curvature;
} pyrt_neck_segment;

/*
 * A rope with the carriage pulley at q: its length beyond the top pulley
 * (upper.head + upper.tail + lower.head + lower.tail) and both segments;
 * a rope with no bottom attachment has a lower segment of all zeros.
 */
typedef struct {
    double length;
    pyrt_neck_segment upper;
    pyrt_neck_segment lower;
} pyrt_neck_rope;

/*
 * Make a ring from its centre (3), axis (3, any length > 0, pointing out of
 * the vessel) and radius: the axis normalised, e1 the unit vector nearest
 * x (or y when the axis is nearly x) in the ring plane, e2 = axis x e1.
 * PYRT_EINVAL (NULL, zero axis), PYRT_ENONFINITE.
 */
int pyrt_neck_init(pyrt_neck_ring *ring, const double *centre, const double *axis, double radius);

/*
 * PYRT_OK when *ring is usable: no ring (radius <= 0), or every number
 * finite with axis, e1 and e2 orthonormal (to 1e-6).  PYRT_EINVAL (NULL,
 * not orthonormal), PYRT_ENONFINITE.  The kernels check their ring once per
 * call with this; pyrt_neck_contact and pyrt_neck_rope_path trust theirs.
 */
int pyrt_neck_check(const pyrt_neck_ring *ring);

/*
 * The segment from q to the far end f (3 each), over the ring where it bears
 * on it; hint: the rim angle to start Newton from (NaN: from the crossing).
 * PYRT_EINVAL (NULL), PYRT_ENONFINITE (f, q or an infinite hint),
 * PYRT_EDEGENERATE (a piece shorter than PYRT_MIN_SEGMENT_CM; *out then
 * holds the point reached).
 */
int pyrt_neck_contact(const pyrt_neck_ring *ring, const double *far, const double *q,
                      double hint, pyrt_neck_segment *out);

/*
 * The rope from top (3) over the carriage pulley q (3) to bottom (3; all
 * NaN: no bottom attachment), the segments in the mask `segments' bearing
 * on the ring where they cross it outside, the others straight.  hint: the
 * rim angles to start from for the upper and the lower segment (2; NaN:
 * none), or NULL.  Status codes as pyrt_neck_contact's; PYRT_EINVAL also
 * for a bottom row partly NaN.
 */
int pyrt_neck_rope_path(const pyrt_neck_ring *ring, int32_t segments, const double *top,
                        const double *bottom, const double *q, const double *hint,
                        pyrt_neck_rope *out);

#endif /* PYRT_NECK_H */
