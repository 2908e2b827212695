/*
 * Serial kinematic chains: forward kinematics, the geometric Jacobian, a
 * numerical inverse, inverse dynamics (Newton-Euler), the mass matrix and
 * forward dynamics.
 *
 * The chain (pyrt_kin_chain) is the constant description: n movable joints,
 * each with the fixed transform from the previous joint's child frame (the
 * chain's base frame for the first) to its own frame at zero motion, a unit
 * axis in that frame, a joint offset, limits, and the inertial of the link it
 * moves (mass, centre of mass and inertia about it, in the joint's child
 * frame).  Joint i's child frame is
 *
 *     F_i = F_{i-1} . origin_i . M_i(q_i + offset_i),   F_0 = base,
 *
 * M_i a rotation about the axis (revolute) or a translation along it
 * (prismatic), and the tool pose is F_n . tool.  Every pose is in the world
 * frame (the frame base is given in); 4x4 transforms are 16 doubles,
 * row-major.  Metres, radians, kilograms, seconds.
 *
 * The workspace (ws) is caller-owned, pyrt_kin_workspace_size(n) doubles,
 * allocated once per chain (the description/buffers split of Pinocchio's
 * Model/Data): no entry point allocates.  A workspace serves one call at a
 * time.  Entry points trust a chain that pyrt_kin_check accepted and check
 * their own arguments (NULL, NaN); every one returns a status code of
 * pyrt_native.h.
 *
 * Plain C99: no globals, no allocation.
 */
#ifndef PYRT_KINEMATICS_H
#define PYRT_KINEMATICS_H

#include "pyrt_native.h"

/* Movable joints per chain: 1 .. PYRT_KIN_MAX_JOINTS. */
#define PYRT_KIN_MAX_JOINTS 64

/* Joint kinds. */
#define PYRT_KIN_REVOLUTE 0
#define PYRT_KIN_PRISMATIC 1

/* An axis whose norm differs from 1 by more than this is refused. */
#define PYRT_KIN_AXIS_TOL 1e-6

/* Defaults of the numerical inverse: pose error (m and rad, 2-norm of the
 * 6-vector), null-space step (rad or m, redundant chains), iterations
 * (steps tried, refused ones included). */
#define PYRT_KIN_DEFAULT_TOL 1e-9
#define PYRT_KIN_DEFAULT_NULL_TOL 1e-7
#define PYRT_KIN_DEFAULT_MAX_ITER 100

/*
 * A chain.  Pointers are borrowed; every array is required.
 *
 *   n         movable joints, 1 .. PYRT_KIN_MAX_JOINTS
 *   kinds     n: PYRT_KIN_REVOLUTE or PYRT_KIN_PRISMATIC
 *   origins   n x 16: previous frame to joint frame at zero motion
 *   axes      n x 3 unit vectors in the joint frame
 *   offsets   n, added to q before the geometry
 *   base      16: the chain's base frame in the world
 *   tool      16: the tool frame in the last joint's child frame
 *   lower     n joint limits (may be -inf / +inf), lower <= upper
 *   upper     n
 *   masses    n link masses (>= 0)
 *   coms      n x 3 centres of mass, child frame
 *   inertias  n x 9 inertia about the centre of mass, child frame
 */
typedef struct {
    int32_t n;
    const int32_t *kinds;
    const double *origins;
    const double *axes;
    const double *offsets;
    const double *base;
    const double *tool;
    const double *lower;
    const double *upper;
    const double *masses;
    const double *coms;
    const double *inertias;
} pyrt_kin_chain;

/*
 * Options and outcome of the numerical inverse.
 *
 *   tol         in: stop when the pose error's norm is <= tol (> 0)
 *   null_tol    in: redundant chains (n > 6) move toward the seed until
 *               the null-space step is <= null_tol (> 0)
 *   max_iter    in: iteration limit (>= 1)
 *   iterations  out: steps tried before the answer
 *   residual    out: the answer's pose error norm
 */
typedef struct {
    double tol;
    double null_tol;
    int32_t max_iter;
    int32_t iterations;
    double residual;
} pyrt_kin_ik_opts;

/* size (out): doubles of workspace a chain of n joints needs. */
int pyrt_kin_workspace_size(int32_t n, int32_t *size);

/* Check a chain: sizes, kinds, finite values, unit axes, ordered limits,
 * non-negative masses.  PYRT_EINVAL or PYRT_ENONFINITE when refused. */
int pyrt_kin_check(const pyrt_kin_chain *c);

/* Tool pose (16) at joint values q (n). */
int pyrt_kin_fk(const pyrt_kin_chain *c, double *ws, const double *q, double *pose);

/* Base, then each joint's child frame: (n + 1) x 16. */
int pyrt_kin_frames(const pyrt_kin_chain *c, double *ws, const double *q, double *frames);

/* Geometric Jacobian, 6 x n row-major, world frame, rows (v; w) at the tool
 * origin; pose (16, or NULL) receives the tool pose as well. */
int pyrt_kin_jacobian(const pyrt_kin_chain *c, double *ws, const double *q, double *jac,
                      double *pose);

/*
 * Numerical inverse: joint values q (n, out) whose tool pose is target (16).
 * Levenberg-Marquardt on the pose error e (position; rotation vector of
 * target . pose^T): the damped minimum-norm step J^T (J J^T + lambda I)^-1 e
 * with lambda = mu (|e|^2 / 2 + 1e-9) (Chan and Lawrence's damping, mu
 * lowered tenfold on a step that reduces |e| and raised tenfold on one that
 * does not, which is refused), started from seed (n, clamped to the
 * limits), each step clamped to the limits.  Done when |e| <= tol.  A
 * redundant chain (n > 6) then takes the exact null-space step toward the
 * seed and reaches the pose again, until that step is <= null_tol or the
 * iterations run out; q is the pose-reaching point nearest the seed met, a
 * nearest solution on the self-motion manifold.  PYRT_ENOCONVERGE when the
 * pose was not reached within max_iter, q then the point of least error
 * (opts->residual says how good).
 */
int pyrt_kin_ik(const pyrt_kin_chain *c, double *ws, const double *target, const double *seed,
                double *q, pyrt_kin_ik_opts *opts);

/*
 * One call of fk or jacobian with its arguments in a struct that the caller
 * fills once and reuses (a binding pays one argument per call instead of
 * four): op PYRT_KIN_OP_FK (out: 16) or PYRT_KIN_OP_JACOBIAN (out: 6 x n).
 */
#define PYRT_KIN_OP_FK 0
#define PYRT_KIN_OP_JACOBIAN 1

typedef struct {
    int32_t op;
    const pyrt_kin_chain *chain;
    double *ws;
    const double *q;
    double *out;
} pyrt_kin_call_args;

int pyrt_kin_call(const pyrt_kin_call_args *a);

/* Inverse dynamics (recursive Newton-Euler): joint forces tau (n) for
 * motion q, qd, qdd (qd or qdd NULL: zero) under gravity (3, world frame;
 * NULL: none).  Rigid bodies only: joint friction and damping are not in it. */
int pyrt_kin_rnea(const pyrt_kin_chain *c, double *ws, const double *q, const double *qd,
                  const double *qdd, const double *gravity, double *tau);

/* Joint-space mass matrix (n x n, row-major, symmetric). */
int pyrt_kin_mass_matrix(const pyrt_kin_chain *c, double *ws, const double *q, double *mass);

/* Forward dynamics: qdd (n) from tau under gravity (3 or NULL), by the mass
 * matrix and a Cholesky solve.  PYRT_ESINGULAR when the mass matrix is not
 * positive definite (a joint that moves no inertia). */
int pyrt_kin_forward_dynamics(const pyrt_kin_chain *c, double *ws, const double *q,
                              const double *qd, const double *tau, const double *gravity,
                              double *qdd);

#endif /* PYRT_KINEMATICS_H */
