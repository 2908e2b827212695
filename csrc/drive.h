/*
 * The on-board servo of a motion-control board that takes joint setpoints
 * at the trajectory rate (004's hardware (a)): every joint of one robot, one
 * call per board tick (the board's own rate, e.g. 1 kHz), as a drive in
 * cyclic synchronous position mode with interpolation does.
 *
 * The board's registers (pyrt.boards.armdrive declares them), per joint j:
 *
 *     setpoint[j]  out  position, encoder counts (32-bit, wrapping as the
 *                       counter does): the middle of count s, (s + 0.5) / COUNTS
 *     velocity[j]  out  velocity at the setpoint, counts/s
 *     torque[j]    out  torque offset (the dynamics feed-forward), DAC counts
 *     felim[j]     out  following-error limit, counts (> 0 to enable)
 *     enable       out  the power stage, one bit for the board
 *     sync         out  the setpoint strobe: the board takes the setpoints
 *                       when it changes (written after them)
 *     period_us    out  the interpolation period, microseconds (> 0 to enable)
 *     count[j]     in   the encoder (the motor side of the board)
 *     status       in   the status word (PYRT_DRIVE_* bits below)
 *     ferr[j]      in   the following error, counts (reference - measured)
 *
 * A tick:
 *
 * 1. The encoders: each counter's step since the last tick taken modulo
 *    2^32 into an unwrapped total; q = (total + 0.5) / COUNTS.
 * 2. Enable 0: the power stage off (every DAC and amplifier enable 0), a
 *    fault cleared (the fault reset of a drive: disable, then enable).
 *    Enable 1 while faulted: off, the fault kept.  Enable 1 while off: on,
 *    if every felim is > 0 and period_us > 0 (else off with REFUSED): the
 *    servo closes the loop where the arm is (pyrt_servo_reset at q, with
 *    the torque offsets as feed-forward), and the last knot is (q, 0,
 *    offsets); the sync value then seen is taken as old.
 * 3. On: a felim or period_us written 0 is the board's fault (joint 0, as
 *    in 4.); else the servo's following-error limits are felim / COUNTS.  A sync
 *    different from the last taken loads the next segment, a cubic from
 *    the last knot to the new one (setpoint, velocity, torque offset) over
 *    period_us: the reference runs one interpolation period behind the
 *    setpoints and never extrapolates (a late setpoint holds the last
 *    knot: LATE).  A setpoint is read as the count nearest the measured
 *    one modulo 2^32.
 * 4. pyrt_servo_tick; a trip (a following error beyond its limit) is the
 *    board's fault: every output 0 in that same tick, FAULT and the joint
 *    in the status word until enable is written 0.  Else dac[j] =
 *    rint(tau[j] / NM_PER_COUNT[j]) within +-32767 and amp[j] = 1.
 * 5. The inputs: status, ferr[j] = rint(error * COUNTS) within int32 (0
 *    while off; the trip's errors while faulted).
 *
 * pyrt_drive_run advances a simulated arm (armworld.h) by dt with the
 * drive ticking every period on the arm's encoders and driving its
 * amplifiers: the world step of an (a) board, the board's servo at its own
 * rate between the host's ticks.
 *
 * The caller owns every array (no allocation); a refused call (status
 * code) sets every DAC and amplifier enable 0.  Plain C99, no globals.
 */
#ifndef PYRT_DRIVE_H
#define PYRT_DRIVE_H

#include "armworld.h"
#include "pyrt_native.h"
#include "servo.h"

/* Joints per board: 1 .. PYRT_DRIVE_MAX_JOINTS. */
#define PYRT_DRIVE_MAX_JOINTS 64

/* Full-scale DAC counts (16-bit signed). */
#define PYRT_DRIVE_DAC_FULL 32767

/* The status word. */
#define PYRT_DRIVE_ENABLED 1     /* the power stage is on: the servo drives the motors */
#define PYRT_DRIVE_FAULT 2       /* a following error tripped it: off until enable is 0 */
#define PYRT_DRIVE_LATE 4        /* no new setpoint within the period: the last knot held */
#define PYRT_DRIVE_REFUSED 8     /* enable refused: a felim or period_us not > 0 */
#define PYRT_DRIVE_JOINT_SHIFT 8 /* bits 8..15: the joint that tripped, 1-based (0: none) */

/* Rows of the per-joint parameters (the board's commissioning). */
#define PYRT_DRIVE_COUNTS 0       /* encoder counts per rad (or per m), > 0 */
#define PYRT_DRIVE_NM_PER_COUNT 1 /* joint torque per DAC count, > 0 */
#define PYRT_DRIVE_NROWS 2

/* Rows of the work (PYRT_DRIVE_NWORK x n; the kernel's). */
#define PYRT_DRIVE_W_LAST 0   /* the counter as last read */
#define PYRT_DRIVE_W_TOTAL 1  /* its unwrapped total */
#define PYRT_DRIVE_W_Q 2      /* the measured joints (the servo's q) */
#define PYRT_DRIVE_W_TAU 3    /* the servo's outputs */
#define PYRT_DRIVE_W_KNOTS 4  /* PYRT_SERVO_NKNOTS rows: the segment; QB QDB FFB the last knot */
#define PYRT_DRIVE_NWORK (4 + PYRT_SERVO_NKNOTS)

/*
 * One board.  The caller fills n, period, params, the servo's gains and
 * state arrays (servo.n = n, servo.period = period) and the register
 * pointers once, and the scalar registers (enable, sync, period_us)
 * before each call; the kernel points servo.q and servo.tau into work and
 * writes the rest.
 *
 *   n, period    joints; the board's tick, s (> 0)
 *   servo        the board's servo (its gains: the board's tuning; the
 *                FELIM row is written from felim while on)
 *   params       PYRT_DRIVE_NROWS x n
 *   setpoint, velocity, torque, felim   n each (in)
 *   enable, sync, period_us             (in)
 *   count        n: the encoders (in)
 *   dac, amp     n: the amplifiers' current command and enable (out)
 *   status       the status word (out)
 *   ferr         n: following errors, counts (out)
 *   work         PYRT_DRIVE_NWORK x n doubles
 *   on, faulted, fault_joint, primed, sync_seen, since   the kernel's state
 */
typedef struct {
    int32_t n;
    double period;
    pyrt_servo servo;
    const double *params;
    const int32_t *setpoint;
    const int32_t *velocity;
    const int32_t *torque;
    const int32_t *felim;
    int32_t enable;
    int32_t sync;
    int32_t period_us;
    const int32_t *count;
    int32_t *dac;
    int32_t *amp;
    int32_t status;
    int32_t *ferr;
    double *work;
    int32_t on;
    int32_t faulted;
    int32_t fault_joint;
    int32_t primed;
    int32_t sync_seen;
    double since;
} pyrt_drive;

/* One board tick (see the header text). */
int pyrt_drive_tick(pyrt_drive *d);

/* Advance the arm a by dt seconds (>= 0) with the board ticking every
 * period: a tick whenever a period has passed since the last (the first
 * call ticks at once), the arm stepped between ticks with the amplifiers
 * held.  a->dac, a->enable and a->count must be d->dac, d->amp and
 * d->count (PYRT_EINVAL otherwise).  An arm step refused stops the run
 * there (its status returned). */
int pyrt_drive_run(pyrt_drive *d, pyrt_arm *a, double dt);

#endif /* PYRT_DRIVE_H */
