/*
 * The Axis controller of 000 in VELOCITY_MODE (section 6): ten fuzzy rules
 * that turn an axis's state into a change of motor velocity per poll.
 *
 * Fuzzy AND is the product, NOT is 1 - x; each rule's output is its premise
 * truth times a velocity change, and dv is the sum of the ten outputs (the
 * document's premise-weighted sum).  Positive velocity pays rope out (the
 * rope gets longer), so "increase tension" and "decrease length" are
 * negative velocity changes.  All errors are actual - desired (000).
 *
 * Units: tension N, length cm, velocity and dv cm/s, tension rate N/s.
 * The velocity changes are per poll.  Figure 3 of the document (the fuzzy
 * sets) did not survive; the sets below are pyrt's design, every breakpoint
 * a field of pyrt_fuzzy_params.  Their defaults (pyrt_fuzzy_default_params)
 * and the reasoning for each are in fuzzy.c and in pyrt.native.FuzzyParams;
 * they assume a 50 ms axis poll and the prototype (5.3 kg source, ropes of
 * 10-60 N, motor speeds 0.07-7.0 cm/s, DV_LIMIT 0.5 cm/s per poll applied
 * by the Motor, off-side ropes driven toward 10 N).
 *
 * Membership shapes: up(x, zero, full) is 0 for x <= zero, 1 for x >= full
 * and linear between (a shoulder); down(x, full, zero) is its mirror.
 *
 *   rule  premise                                       velocity change
 *   0     LowT(T)                                       -dv_tension
 *   1     HighT(T)                                      +dv_tension
 *   2     Short(e)        = up(-e, len_zero, len_full)  +dv_length
 *   3     Long(e)         = up(e, len_zero, len_full)   -dv_length
 *   4     G * RelLow(Te)  = up(-Te, rel_zero, rel_full) -dv_rel_tension
 *   5     G * RelHigh(Te) = up(Te, rel_zero, rel_full)  +dv_rel_tension
 *   6     HighV(|v|)                                    -sign(v) dv_velocity
 *   7     HighELV(|de/dt|)                              -sign(de/dt) dv_len_rate
 *   8     (1-free) * HighETV(|dTe/dt|)                  +sign(dTe/dt) dv_t_rate
 *   9     HighDV(|dv_last|)                             -dv_damping * dv_last
 *
 * with LowT(T) = down(T, t_low + low_t_full, t_low + low_t_zero),
 * HighT(T) = up(T, t_high - high_t_zero, t_high - high_t_full),
 * Te = T - desired tension, and the relative-tension gate
 * G = (1 - free) * (1 - near_end_relax * near_end): "not near end", relaxed
 * only partially as the document requires, and zero for a free rope (the
 * document's zero error-tension signal).
 */
#ifndef PYRT_FUZZY_H
#define PYRT_FUZZY_H

#include "pyrt_native.h"

/* Axes per batch call: 1 .. PYRT_FUZZY_MAX_AXES. */
#define PYRT_FUZZY_MAX_AXES 16

/* Rule outputs per axis. */
#define PYRT_FUZZY_NRULES 10

/*
 * Input columns: one row of PYRT_FUZZY_NINPUTS doubles per axis.
 *   TENSION           measured tension, N
 *   DESIRED_TENSION   tension the PolyAxis asks for, N (unused when FREE = 1)
 *   FREE              truth value 0..1; 1 = let the tension float (the
 *                     document's zero error-tension signal)
 *   LENGTH_ERROR      corrected length - desired length, cm
 *   VELOCITY          present motor velocity, cm/s (+ = paying out)
 *   LENGTH_ERROR_RATE d(length error)/dt, cm/s
 *   TENSION_ERROR_RATE d(tension - desired)/dt, N/s
 *   LAST_DV           the velocity change of the previous poll, cm/s
 *   NEAR_END          truth value 0..1 that the move is near its end
 *   TENSION_LOW       lower tension bound, N
 *   TENSION_HIGH      upper tension bound, N (> TENSION_LOW)
 */
#define PYRT_FUZZY_IN_TENSION 0
#define PYRT_FUZZY_IN_DESIRED_TENSION 1
#define PYRT_FUZZY_IN_FREE 2
#define PYRT_FUZZY_IN_LENGTH_ERROR 3
#define PYRT_FUZZY_IN_VELOCITY 4
#define PYRT_FUZZY_IN_LENGTH_ERROR_RATE 5
#define PYRT_FUZZY_IN_TENSION_ERROR_RATE 6
#define PYRT_FUZZY_IN_LAST_DV 7
#define PYRT_FUZZY_IN_NEAR_END 8
#define PYRT_FUZZY_IN_TENSION_LOW 9
#define PYRT_FUZZY_IN_TENSION_HIGH 10
#define PYRT_FUZZY_NINPUTS 11

/*
 * Rule parameters of one axis.  Breakpoints: each set's "zero" and "full"
 * points (zero < full for every set; for the tension guards the offsets are
 * measured inward from the bounds, so low_t_full < low_t_zero and
 * high_t_full < high_t_zero).  Velocity changes are magnitudes (>= 0) in
 * cm/s per poll; the rule fixes the sign.  dv_damping and near_end_relax
 * are fractions in 0..1.
 */
typedef struct {
    double low_t_full;
    double low_t_zero;
    double high_t_zero;
    double high_t_full;
    double len_zero;
    double len_full;
    double rel_zero;
    double rel_full;
    double near_end_relax;
    double vel_zero;
    double vel_full;
    double len_rate_zero;
    double len_rate_full;
    double t_rate_zero;
    double t_rate_full;
    double dv_zero;
    double dv_full;
    double dv_tension;
    double dv_length;
    double dv_rel_tension;
    double dv_velocity;
    double dv_len_rate;
    double dv_t_rate;
    double dv_damping;
} pyrt_fuzzy_params;

/* Fill *p with the documented defaults.  PYRT_EINVAL for NULL. */
int pyrt_fuzzy_default_params(pyrt_fuzzy_params *p);

/* PYRT_OK when *p is usable; PYRT_ENONFINITE or PYRT_EINVAL otherwise. */
int pyrt_fuzzy_check_params(const pyrt_fuzzy_params *p);

/*
 * Evaluate the ten rules for n axes (1 .. PYRT_FUZZY_MAX_AXES) in one call.
 *   params   nparams structs: 1 (shared by every axis) or n (one per axis)
 *   inputs   n x PYRT_FUZZY_NINPUTS, row-major
 *   dv       n outputs: the velocity change of each axis, cm/s
 *   rules    n x PYRT_FUZZY_NRULES outputs: premise truth x velocity change
 *            of every rule (the document's a0rules.dat), or NULL
 * Everything is checked before anything is written: PYRT_EINVAL (NULL, n or
 * nparams out of range, FREE or NEAR_END outside 0..1, TENSION_LOW >=
 * TENSION_HIGH, bad params), PYRT_ENONFINITE (NaN or infinity anywhere).
 */
int pyrt_fuzzy_step(int32_t n, const pyrt_fuzzy_params *params, int32_t nparams,
                    const double *inputs, double *dv, double *rules);

/*
 * A prepared batch: the arguments of pyrt_fuzzy_step bound once, so that a
 * control poll makes one call with one argument.  Pointers are borrowed.
 */
typedef struct {
    int32_t n;
    const pyrt_fuzzy_params *params;
    int32_t nparams;
    const double *inputs;
    double *dv;
    double *rules;
} pyrt_fuzzy_batch;

/* pyrt_fuzzy_step on the bound arguments; PYRT_EINVAL for NULL. */
int pyrt_fuzzy_run(const pyrt_fuzzy_batch *b);

#endif /* PYRT_FUZZY_H */
