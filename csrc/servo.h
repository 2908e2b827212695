/*
 * A generic joint servo: every joint of one robot in one call, at the servo
 * rate (004's passive boards, hardware (b)).
 *
 * Time.  The servo runs on the time that really passed, not on a count of
 * ticks: pyrt_servo_tick_at(s, now) is a tick at the caller's clock `now`
 * (s; the loop's time), dt = now - last (the previous tick's time).  A loop
 * that stalls (a long tick, skipped deadlines) gives a late tick a larger dt
 * and the servo follows: the reference is the trajectory's point at that
 * time, the velocity estimate and the integral use that dt.  The integral's
 * dt is bounded at PYRT_SERVO_MAX_DT_PERIODS periods (a long stall must not
 * kick the output through a huge integral step); a tick beyond that bound
 * counts in `stalls` and `stall_max` keeps the longest dt.  pyrt_servo_tick
 * is the self-clocked tick, at last + period (a board's own servo, whose
 * ticks are its clock).
 *
 * Interpolation.  The trajectory hands the servo one segment at a time, from
 * knot A to knot B: position, velocity and acceleration at both ends give a
 * quintic per joint, position and velocity alone a cubic.  The segment
 * starts at a time on the servo's clock: pyrt_servo_load_at(..., start)
 * says when (a trajectory that continues its last segment gives that
 * segment's end, so the segments join in time as in space), pyrt_servo_load
 * starts it at the next self-clocked tick (last + period).  A tick evaluates
 * the polynomial at t = now - start, within 0 .. duration: the reference is
 * where the joint should be at the instant it is measured, so the ticks of a
 * segment of k periods evaluate 0/k .. (k-1)/k of it and the next segment's
 * first tick is knot B (its knot A); a tick that comes late evaluates the
 * segment at its own time, never at the count of ticks.  A tick at the end
 * evaluates knot B; more than half a period past it (the trajectory did not
 * bring the next segment in time) the reference holds knot B's position with
 * zero velocity and acceleration and the late counter counts the ticks: a
 * reference is never extrapolated.
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
 *     I   += KI e dt, within +-ILIM; not grown while the output is
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

/* The integral's dt is bounded at this many periods (a stall beyond: counted). */
#define PYRT_SERVO_MAX_DT_PERIODS 10

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
 *   last        s: the servo's clock, the time of the last tick (in/out: a
 *               timed caller sets it where it closes the loop, e.g. at reset)
 *   gains       PYRT_SERVO_NGAINS x n
 *   state       PYRT_SERVO_NSTATE x n
 *   q           n: this tick's measured positions (in)
 *   tau         n: this tick's outputs (out)
 *   order       the loaded segment's order (out)
 *   duration    the loaded segment's duration, s (out)
 *   start       the loaded segment's start on the servo's clock, s (out)
 *   dt          the last tick's dt, s (out)
 *   ticks       ticks into the segment (out)
 *   late        ticks past its end, the reference held at knot B (out)
 *   tripped     1 after a following-error trip, until reset (out)
 *   trip_joint  the joint that tripped it, or -1 (out)
 *   trip_error  its following error then (out)
 *   stalls      ticks whose dt was beyond PYRT_SERVO_MAX_DT_PERIODS periods (out)
 *   stall_max   the longest such dt, s (out)
 */
typedef struct {
    int32_t n;
    double period;
    double *gains;
    double *state;
    const double *q;
    double *tau;
    double last;
    int32_t order;
    double duration;
    double start;
    double dt;
    int32_t ticks;
    int32_t late;
    int32_t tripped;
    int32_t trip_joint;
    double trip_error;
    int32_t stalls;
    double stall_max;
} pyrt_servo;

/* Close the loop at the measured q (n): hold there with feed-forward ff (n,
 * or NULL: none), integrators and velocity estimate cleared, a trip
 * cleared, outputs zero; the servo's clock (last) and its stall count are
 * kept. */
int pyrt_servo_reset(pyrt_servo *s, const double *q, const double *ff);

/* Load the next segment: knots (PYRT_SERVO_NKNOTS x n), duration (s, > 0),
 * order PYRT_SERVO_QUINTIC or PYRT_SERVO_CUBIC (the acceleration rows are
 * then not read).  The integrators and the velocity estimate carry on. */
int pyrt_servo_load(pyrt_servo *s, const double *knots, double duration, int32_t order);

/* pyrt_servo_load with the segment starting at `start` (s, the servo's
 * clock; finite) instead of the next self-clocked tick. */
int pyrt_servo_load_at(pyrt_servo *s, const double *knots, double duration, int32_t order,
                       double start);

/* One tick at `now` (s, the servo's clock: finite, not before last): reads
 * s->q, writes s->tau and the state (see the header text). */
int pyrt_servo_tick_at(pyrt_servo *s, double now);

/* One self-clocked tick, at last + period. */
int pyrt_servo_tick(pyrt_servo *s);

/*
 * A passive board's servo task in one call (pyrt_servo_tick_board): its
 * encoders in, the law, the bounds of the measured joints and its DAC
 * counts out.  The caller fills the pointers, counts_per_unit and dac_full
 * once; the kernel keeps last and total and writes dac, changed and beyond.
 *
 *   counts_per_unit n: encoder counts per joint radian (or metre), finite > 0
 *   last, total     n: the counters as last read and their unwrapped totals
 *   q               n: the measured joints, (total + 0.5) / counts_per_unit
 *                   (the middle of the count): the servo's q (out)
 *   lo, hi          n: where each measured joint may go (beyond: the fault)
 *   dac_per_unit    n: DAC counts per N m (or N) of output, finite
 *   dac_full        the DAC's full scale, > 0: a count is within +-dac_full
 *   dac             n: the values last written (in); this tick's (out)
 *   changed         bit j set: dac[j] differs from the value last written (out)
 *   beyond          the first joint (by index) beyond lo .. hi, or -1 (out)
 *   outcome         changed, or -1 when the tick did more than change DACs: the
 *                   servo tripped in it, its dt was a stall (beyond
 *                   PYRT_SERVO_MAX_DT_PERIODS periods), a joint is beyond its
 *                   bounds, or the tick was refused (out): the caller's one test
 */
typedef struct {
    const double *counts_per_unit;
    int64_t *last;
    int64_t *total;
    double *q;
    const double *lo;
    const double *hi;
    const double *dac_per_unit;
    int32_t dac_full;
    int32_t *dac;
    uint64_t changed;
    int32_t beyond;
    int64_t outcome;
} pyrt_servo_board;

/* The encoders: each of the n counters' step since the last read
 * (counts[j] - last[j]) taken modulo 2^32 into -2^31 .. 2^31 - 1 (a 32-bit
 * counter wraps) is added to its total; q as above. */
int pyrt_servo_encoders(pyrt_servo_board *b, int32_t n, const int64_t *counts);

/* pyrt_servo_encoders (b->q must be s->q), pyrt_servo_tick_at(s, now), then,
 * unless the servo is tripped, the bounds and the DACs joint by joint: the
 * first joint beyond its bounds ends the walk (beyond; its DAC and those
 * after it unchanged); every other joint's count is rint(tau * dac_per_unit)
 * (ties to even) within +-dac_full.  A refused tick or pointer: status code,
 * changed 0, beyond -1 (the servo's outputs zero as pyrt_servo_tick_at's). */
int pyrt_servo_tick_board(pyrt_servo *s, double now, pyrt_servo_board *b,
                          const int64_t *counts);

#endif /* PYRT_SERVO_H */
