/*
 * A generic joint servo: every joint of one robot in one call, at the servo
 * rate (004's passive boards, hardware (b)).
 *
 * Interpolation.  The trajectory hands the servo one segment at a time, from
 * knot A (now) to knot B (duration later): position, velocity and
 * acceleration at both ends give a quintic per joint, position and velocity
 * alone a cubic.  A tick evaluates the polynomial at the segment's clock,
 * then advances the clock by one period: the reference is where the joint
 * should be at the instant it is measured, so the ticks of a segment of k
 * periods evaluate 0/k .. (k-1)/k of it and the next segment's first tick
 * is knot B (its knot A).  A tick that finds the clock at the end evaluates
 * knot B; past it (the trajectory did not bring the next segment in time)
 * the reference holds knot B's position with zero velocity and
 * acceleration and the late counter counts the ticks: a reference is never
 * extrapolated.
 *
 * Feed-forward.  The rigid-body torque (gravity, inertia, Coriolis: the
 * chain's inverse dynamics) is given with the segment at both knots and
 * interpolated linearly in time; it is computed at the trajectory rate,
 * where the knots are made, not per tick: over one 10 ms segment it moves
 * by a few per cent of its range, and a tick then costs no inverse dynamics.
 *
 * The law, per joint j (angles in rad, or m for a prismatic joint):
 *
 *     e    = q_ref - q
 *     v    = velocity estimate: backward difference of q, first-order
 *            low-pass at VELHZ
 *     I   += KI e period, within +-ILIM; not grown while the output is
 *            clamped in the direction of e (conditional integration)
 *     tau  = KP e + I + KD (qd_ref - v) + KV qd_ref + KA qdd_ref + KFF ff
 *     tau  = clamp(tau, -TMAX, TMAX)                      (the effort limit)
 *
 * Following error.  When any joint's |e| exceeds its FELIM, the tick trips:
 * every output is zero in that same call, the integrators are cleared, and
 * the servo stays tripped (outputs zero) until pyrt_servo_reset; the joint
 * named is the one furthest beyond its limit (largest |e| / FELIM).  A trip
 * is the servo's answer, not an error: the call returns PYRT_OK.
 *
 * Refused input (a NULL pointer, NaN in the measured joints, a gain out of
 * its basic range: negative, KFF outside 0..1, TMAX, FELIM or VELHZ not > 0,
 * not finite) returns a status code and sets every output to zero: a servo
 * that cannot compute its output stops the robot.
 *
 * The caller owns every array (no allocation); gains may be changed between
 * ticks (the upper bounds of their safe ranges are pyrt.native's, not C's).
 * Units: N m (or N), rad (or m), s, Hz.  Plain C99, no globals.
 */
#ifndef PYRT_SERVO_H
#define PYRT_SERVO_H

#include "pyrt_native.h"

/* Joints per servo: 1 .. PYRT_SERVO_MAX_JOINTS. */
#define PYRT_SERVO_MAX_JOINTS 64

/* Rows of the gains (PYRT_SERVO_NGAINS x n, row-major). */
#define PYRT_SERVO_KP 0     /* N m / rad: proportional */
#define PYRT_SERVO_KI 1     /* N m / (rad s): integral */
#define PYRT_SERVO_KD 2     /* N m s / rad: derivative, on qd_ref - v */
#define PYRT_SERVO_KV 3     /* N m s / rad: velocity feed-forward (viscous friction) */
#define PYRT_SERVO_KA 4     /* kg m^2: acceleration feed-forward (rotor inertia) */
#define PYRT_SERVO_KFF 5    /* 0 .. 1: share of the dynamics feed-forward applied */
#define PYRT_SERVO_ILIM 6   /* N m: integrator limit, >= 0 */
#define PYRT_SERVO_TMAX 7   /* N m: output clamp (the effort limit), > 0 */
#define PYRT_SERVO_FELIM 8  /* rad: following-error limit, > 0 */
#define PYRT_SERVO_VELHZ 9  /* Hz: the velocity estimate's low-pass cut-off, > 0 */
#define PYRT_SERVO_NGAINS 10

/* Rows of a segment's knots (PYRT_SERVO_NKNOTS x n). */
#define PYRT_SERVO_QA 0     /* position at A */
#define PYRT_SERVO_QDA 1    /* velocity at A */
#define PYRT_SERVO_QDDA 2   /* acceleration at A (quintic only) */
#define PYRT_SERVO_QB 3
#define PYRT_SERVO_QDB 4
#define PYRT_SERVO_QDDB 5
#define PYRT_SERVO_FFA 6    /* dynamics feed-forward torque at A */
#define PYRT_SERVO_FFB 7    /* ... at B */
#define PYRT_SERVO_NKNOTS 8

/* Rows of the state (PYRT_SERVO_NSTATE x n): the caller allocates it and
 * may read it (the scope's channels); only the kernel writes it. */
#define PYRT_SERVO_C0 0     /* rows 0..5: polynomial coefficients in seconds */
#define PYRT_SERVO_SFFA 6   /* the segment's feed-forward at A and B */
#define PYRT_SERVO_SFFB 7
#define PYRT_SERVO_INTEG 8  /* the integrator, N m */
#define PYRT_SERVO_QLAST 9  /* the last measured position */
#define PYRT_SERVO_VEL 10   /* the velocity estimate */
#define PYRT_SERVO_QREF 11  /* this tick's reference */
#define PYRT_SERVO_QDREF 12
#define PYRT_SERVO_QDDREF 13
#define PYRT_SERVO_ERR 14   /* this tick's following error q_ref - q */
#define PYRT_SERVO_FF 15    /* this tick's interpolated feed-forward */
#define PYRT_SERVO_NSTATE 16

/* Segment orders: a hold (after reset), a cubic, a quintic. */
#define PYRT_SERVO_HOLD 0
#define PYRT_SERVO_CUBIC 3
#define PYRT_SERVO_QUINTIC 5

/*
 * One robot's servo.  The caller fills n, period and the pointers once;
 * the kernel keeps the rest.
 *
 *   n           joints, 1 .. PYRT_SERVO_MAX_JOINTS
 *   period      s, > 0: the servo tick
 *   gains       PYRT_SERVO_NGAINS x n
 *   state       PYRT_SERVO_NSTATE x n
 *   q           n: this tick's measured positions (in)
 *   tau         n: this tick's outputs (out)
 *   order       the loaded segment's order (out)
 *   duration    the loaded segment's duration, s (out)
 *   ticks       ticks into the segment (out)
 *   late        ticks past its end, the reference held at knot B (out)
 *   tripped     1 after a following-error trip, until reset (out)
 *   trip_joint  the joint that tripped it, or -1 (out)
 *   trip_error  its following error then (out)
 */
typedef struct {
    int32_t n;
    double period;
    double *gains;
    double *state;
    const double *q;
    double *tau;
    int32_t order;
    double duration;
    int32_t ticks;
    int32_t late;
    int32_t tripped;
    int32_t trip_joint;
    double trip_error;
} pyrt_servo;

/* Close the loop at the measured q (n): hold there with feed-forward ff (n,
 * or NULL: none), integrators and velocity estimate cleared, a trip
 * cleared, outputs zero. */
int pyrt_servo_reset(pyrt_servo *s, const double *q, const double *ff);

/* Load the next segment: knots (PYRT_SERVO_NKNOTS x n), duration (s, > 0),
 * order PYRT_SERVO_QUINTIC or PYRT_SERVO_CUBIC (the acceleration rows are
 * then not read).  The integrators and the velocity estimate carry on. */
int pyrt_servo_load(pyrt_servo *s, const double *knots, double duration, int32_t order);

/* One tick: reads s->q, writes s->tau and the state (see the header text). */
int pyrt_servo_tick(pyrt_servo *s);

#endif /* PYRT_SERVO_H */
