/*
 * The simulated arm's integration step: every internal step of one
 * ArmWorld.step(dt) in one call (pyrt.sim.arm describes the physics).
 *
 * Per internal step h (dt split into k = ceil(dt / max_step) equal steps),
 * with q, qd the joints and their rates:
 *
 *     tau_m = clamp(dac * enable * NM_PER_COUNT, -EFFORT, EFFORT)
 *     A  = M(q) + diag(ARMATURE)                       (the chain's mass matrix)
 *     f  = tau_m - rnea(q, qd, 0, g)
 *          - FRICTION tanh(qd / vs) + dfr qd           dfr = FRICTION / vs (1 - tanh^2)
 *          - BRAKE / bvs qd                            joints whose brake is engaged
 *                                                      (release[j] 0; bvs PYRT_ARM_BRAKE_VS)
 *          + stop springs (joints beyond STOP_LO / STOP_HI, pushing)
 *          + J_tip^T F_contact + contact damping terms
 *     (A + h D + h^2 K) qd+ = A qd + h f               D, K: the damping and stiffness
 *     q+ = q + h qd+                                   of the friction, stops and contact
 *
 * linearly implicit (semi-implicit) Euler: the stiff terms (viscous damping,
 * the friction's slope, the end stops' spring-dampers, the table's normal
 * spring-damper and its friction) enter the matrix, the rigid-body terms
 * are explicit.  The solve is a Cholesky factorisation (the matrix is
 * symmetric positive definite when every joint moves some inertia).
 *
 * The table: a plane z = table_z (world) that the tip (tip, in the tool
 * frame) may press into; normal force fn = k depth - c vz when positive,
 * friction -ct v_xy with ct = mu fn tanh(|v_xy| / 1 mm/s) / |v_xy|.
 *
 * After the steps the inputs are published (as pyrt_arm_publish does):
 * count[j] = floor(q[j] COUNTS_PER_UNIT[j]) wrapped to 32 bits; the
 * contact force at the final state, and the wrench the wrist sensor feels
 * (contact plus the payload's weight, in the tool frame, moment about the
 * sensor at the tool origin: tip x f); ft[k] = rint((wrench[k] + noise[k])
 * ft_scale[k]) + ft_offsets[k], within int32, noise[k] = ft_sigma[k] times
 * a standard normal of the arm's generator.
 *
 * The noise generator (reproducible anywhere): splitmix64 over the 64-bit
 * state rng (state += 0x9E3779B97F4A7C15; z = state;
 * z = (z ^ z >> 30) * 0xBF58476D1CE4E5B9; z = (z ^ z >> 27) *
 * 0x94D049BB133111EB; z ^= z >> 31), u = (z >> 11) 2^-53; three
 * Box-Muller pairs per publish (u1 then u2: r = sqrt(-2 ln(1 - u1)),
 * normals r cos(2 pi u2) and r sin(2 pi u2)) for fx fy, fz tx, ty tz.
 *
 * Every call works on copies and commits at its end: a refused call
 * (status code) changes nothing, not even the generator.  The caller owns
 * every array (no allocation).  SI units: m, rad, kg, s, N.  Plain C99, no
 * globals.
 */
#ifndef PYRT_ARMWORLD_H
#define PYRT_ARMWORLD_H

#include "kinematics.h"
#include "pyrt_native.h"

/* Joints: 1 .. PYRT_ARM_MAX_JOINTS (the kinematics kernels' limit). */
#define PYRT_ARM_MAX_JOINTS 64

/* Internal steps per call: at most this many. */
#define PYRT_ARM_MAX_SUBSTEPS 1000000000

/* The table friction's smoothing speed (m/s). */
#define PYRT_ARM_TABLE_VS 1e-3

/* Rows of the per-joint parameters (PYRT_ARM_NROWS x n, row-major). */
#define PYRT_ARM_ARMATURE 0       /* reflected rotor inertia, kg m^2, >= 0 */
#define PYRT_ARM_DAMPING 1        /* viscous, N m s/rad, >= 0 */
#define PYRT_ARM_FRICTION 2       /* Coulomb, N m, >= 0 */
#define PYRT_ARM_STOP_LO 3        /* lower end stop, rad (may be -inf) */
#define PYRT_ARM_STOP_HI 4        /* upper end stop, rad (may be +inf) */
#define PYRT_ARM_STOP_K 5         /* end stop stiffness, N m/rad, >= 0 */
#define PYRT_ARM_STOP_C 6         /* end stop damping, N m s/rad, >= 0 */
#define PYRT_ARM_NM_PER_COUNT 7   /* joint torque per DAC count, > 0 */
#define PYRT_ARM_AMPS_PER_COUNT 8 /* motor current per DAC count, > 0 */
#define PYRT_ARM_EFFORT 9         /* torque limit, N m, > 0 */
#define PYRT_ARM_COUNTS 10        /* encoder counts per rad (or per m), > 0 */
#define PYRT_ARM_BRAKE 11         /* the brake's rated holding torque, N m, >= 0 (0: none) */
#define PYRT_ARM_NROWS 12

/* The engaged brake is a stiff viscous lock of BRAKE / BRAKE_VS (N m s/rad):
 * it holds a joint to a creep of BRAKE_VS (rad/s, m/s) times the torque on it
 * over BRAKE, taken wholly into the implicit step (it never chatters; it does
 * not slip either: a torque beyond BRAKE is held all the same, creeping faster). */
#define PYRT_ARM_BRAKE_VS 1e-4

/*
 * One simulated arm.  The caller fills the description and the pointers
 * (pyrt_arm_check says whether they are acceptable) and may change the
 * table, the payload and the chain between calls; the kernel writes the
 * state, the truth, the generator and the input registers.
 *
 *   n            joints, = chain->n
 *   chain        the chain (inertials with the payload folded into the last
 *                link), checked by pyrt_kin_check; ws its workspace
 *   max_step     s, > 0: the longest internal step
 *   friction_vs  m/s or rad/s, > 0: the Coulomb friction's smoothing speed
 *   gravity      m/s^2, world frame
 *   tip          the tip in the tool frame (m)
 *   table        1: the table at table_z (m, world z); 0: none
 *   table_k, table_c, table_mu   normal stiffness N/m, damping N s/m,
 *                friction coefficient (>= 0; table_k > 0)
 *   payload      kg at the tip (>= 0; its weight on the wrist sensor)
 *   ft_scale     counts per N (fx fy fz) and per N m (tx ty tz), > 0
 *   ft_offsets   counts at zero load
 *   ft_sigma     noise standard deviation, N and N m, >= 0
 *   params       PYRT_ARM_NROWS x n
 *   dac, enable  n: the board's outputs (in)
 *   release      n: each joint's brake released (non-zero) or engaged (0)
 *                (in); NULL: no brakes
 *   count, ft    n and 6: the board's inputs (out)
 *   q, qd        n: the state (in and out)
 *   torque, current  n: the motors' joint torque and current (out)
 *   contact      3: the table's force on the tip, world frame (out)
 *   wrench       6: the noise-free wrench at the sensor, tool frame (out)
 *   work         pyrt_arm_work_size(n) doubles
 *   rng          the noise generator's state
 */
typedef struct {
    int32_t n;
    const pyrt_kin_chain *chain;
    double *ws;
    double max_step;
    double friction_vs;
    double gravity[3];
    double tip[3];
    int32_t table;
    double table_z;
    double table_k;
    double table_c;
    double table_mu;
    double payload;
    double ft_scale[6];
    double ft_offsets[6];
    double ft_sigma[6];
    const double *params;
    int32_t *dac;
    const int32_t *enable;
    const int32_t *release;
    int32_t *count;
    int32_t *ft;
    double *q;
    double *qd;
    double *torque;
    double *current;
    double *contact;
    double *wrench;
    double *work;
    uint64_t rng;
} pyrt_arm;

/* size (out): doubles of work an arm of n joints needs. */
int pyrt_arm_work_size(int32_t n, int32_t *size);

/* Check the description, the pointers and the state: PYRT_EINVAL (a NULL
 * pointer, n out of range or not the chain's, a value out of its range,
 * stops out of order) or PYRT_ENONFINITE (NaN, or infinity where only a
 * stop may be infinite). */
int pyrt_arm_check(const pyrt_arm *a);

/* Advance by dt seconds (>= 0; 0 does nothing), the board's outputs held,
 * then publish the inputs.  PYRT_ESINGULAR when the step's matrix is not
 * positive definite, PYRT_ENONFINITE when the motion blew up; nothing
 * changed then. */
int pyrt_arm_step(pyrt_arm *a, double dt);

/* pyrt_arm_step with the DACs' new counts: dac (n) copied into a->dac first,
 * then the step; refused (status code), a->dac is as it was. */
int pyrt_arm_step_dac(pyrt_arm *a, double dt, const int32_t *dac);

/* Publish the inputs at the present state (after the caller put the arm
 * somewhere): counts, contact, wrench and one draw of the sensor's noise. */
int pyrt_arm_publish(pyrt_arm *a);

#endif /* PYRT_ARMWORLD_H */
