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
 * a field of pyrt_fuzzy_params.  Their defaults are the PYRT_FUZZY_DEFAULT_*
 * constants below, each with its reasoning (pyrt_fuzzy_default_params fills
 * a struct with them; pyrt.native.FuzzyParams reads them); they assume a
 * PYRT_FUZZY_REFERENCE_POLL_S axis poll and the prototype (5.3 kg source,
 * ropes of 10-60 N, motor speeds 0.07-7.0 cm/s, DV_LIMIT 0.5 cm/s per poll
 * applied by the Motor, off-side ropes driven toward 10 N).
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

/* The axis poll (s) the default per-poll velocity changes are tuned for. */
#define PYRT_FUZZY_REFERENCE_POLL_S 0.05

/*
 * Tension guards (rules 0, 1), offsets inward from the bounds.  LowT is
 * full 1 N above the lower bound and gone 5 N above it, so with a bound of
 * a few newtons it stays silent at the 10 N off-side target and takes over
 * well before LOW_TENSION_STOP.  HighT starts 15 N below the upper bound (a
 * quarter of the 60 N working range) and is full 2 N below it.  dv_tension
 * 0.4 cm/s per poll is the document's "increase tension = -0.4 cm/s"; it is
 * the strongest rule, below DV_LIMIT 0.5.
 */
#define PYRT_FUZZY_DEFAULT_LOW_T_FULL 1.0
#define PYRT_FUZZY_DEFAULT_LOW_T_ZERO 5.0
#define PYRT_FUZZY_DEFAULT_HIGH_T_ZERO 15.0
#define PYRT_FUZZY_DEFAULT_HIGH_T_FULL 2.0
#define PYRT_FUZZY_DEFAULT_DV_TENSION 0.4

/*
 * Length (rules 2, 3): linear from no error to 1 cm, no dead band, so that
 * near the target the rules act as the proportional term of a PD loop and
 * the velocity integrator cannot drift inside a dead band.  With the 50 ms
 * poll, 0.1 cm/s per poll at 1 cm is an acceleration of 2 cm/s^2 per cm of
 * error: omega = sqrt(0.1 / (1 cm * 0.05 s)) = 1.4 rad/s, a 4.4 s natural
 * period; the hare's 20 cm ramps to 2 cm/s ask for 0.1 cm/s^2, which this
 * loop follows 0.05 cm behind.
 */
#define PYRT_FUZZY_DEFAULT_LEN_ZERO 0.0
#define PYRT_FUZZY_DEFAULT_LEN_FULL 1.0
#define PYRT_FUZZY_DEFAULT_DV_LENGTH 0.1

/*
 * Length-error rate damping (rule 7): linear up to 2 cm/s (the hare's top
 * speed), 0.25 cm/s per poll at full: 0.25 / (2 * 0.05) = 2.5 /s =
 * 2 zeta omega, zeta = 0.9 with the length rules above.  With the length
 * rules saturated (errors over 1 cm) the two balance at a closing speed of
 * 0.1 / 0.125 = 0.8 cm/s, so a large error is taken up steadily instead of
 * with a lunge.
 */
#define PYRT_FUZZY_DEFAULT_LEN_RATE_ZERO 0.0
#define PYRT_FUZZY_DEFAULT_LEN_RATE_FULL 2.0
#define PYRT_FUZZY_DEFAULT_DV_LEN_RATE 0.25

/*
 * Relative tension (rules 4, 5) for a rope with a target (the off-side rope
 * at 10 N): a 0.5 N dead band for loadcell noise and offset (the document
 * found tension errors stopping the source near the end), full at 5 N.
 * 0.2 cm/s per poll at 5 N (0.04 per N) beats the length rules (0.1 per cm)
 * for any rope stiffer than 2.5 N/cm of paid-out length, which every
 * tensioned rope is (a 1000 cm rope of compliance 1e-4 per N is 10 N/cm), so
 * the off-side rope behaves as an idler as the document intends.  Near the
 * end 75 % of the rule is relaxed ("only partially relaxed").
 */
#define PYRT_FUZZY_DEFAULT_REL_ZERO 0.5
#define PYRT_FUZZY_DEFAULT_REL_FULL 5.0
#define PYRT_FUZZY_DEFAULT_DV_REL_TENSION 0.2
#define PYRT_FUZZY_DEFAULT_NEAR_END_RELAX 0.75

/*
 * Tension-error rate damping (rule 8): stops two side ropes trading tension
 * in an oscillation (the document's common scenario).  Full at 40 N/s (a
 * rope of ~40 N/cm moving at 1 cm/s), 0.25 cm/s per poll: 0.25 / 40 / 0.05 =
 * 0.125 cm/s^2 of velocity change per N/s.
 *
 * The whole set was checked in closed loop on the prototype statics (5.3 kg
 * source, dead length 453 cm, rope compliance 5e-6 to 1e-4 per N, loadcell
 * noise 0.5 N, 20 and 50 ms polls): every target the tension bounds allow
 * ends within 0.1 cm in plane with the tensions between 8 and 58 N; a
 * target that needs a rope below its bound is held off by the guards
 * instead of being reached.
 */
#define PYRT_FUZZY_DEFAULT_T_RATE_ZERO 0.0
#define PYRT_FUZZY_DEFAULT_T_RATE_FULL 40.0
#define PYRT_FUZZY_DEFAULT_DV_T_RATE 0.25

/*
 * Velocity high (rule 6): a soft speed limit between 5 cm/s and the motor's
 * 7.0 cm/s cruise maximum; the hare never asks for more than 2 cm/s of
 * source speed, so this only catches a run-away.
 */
#define PYRT_FUZZY_DEFAULT_VEL_ZERO 5.0
#define PYRT_FUZZY_DEFAULT_VEL_FULL 7.0
#define PYRT_FUZZY_DEFAULT_DV_VELOCITY 0.3

/*
 * dv high (rule 9, the document's deltaDV(dv, ...)): above 0.1 cm/s per poll
 * the next change is cut by up to half of the last one, full at DV_LIMIT
 * 0.5, so bursts of velocity change (the ones that stall a stepper) are
 * smoothed over several polls.
 */
#define PYRT_FUZZY_DEFAULT_DV_ZERO 0.1
#define PYRT_FUZZY_DEFAULT_DV_FULL 0.5
#define PYRT_FUZZY_DEFAULT_DV_DAMPING 0.5

/* Fill *p with the PYRT_FUZZY_DEFAULT_* values.  PYRT_EINVAL for NULL. */
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
