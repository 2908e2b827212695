/*
 * pyrt native kernels: what every kernel shares.
 *
 * Plain C99.  No Python.h, no globals, no allocation: every entry point
 * takes explicit arrays and sizes and returns one of the status codes below
 * (PYRT_OK on success).  The public API is this header and the one header of
 * each kernel (build_native.py generates the cffi cdef from exactly those);
 * pyrt.native is the only Python package that calls it, and its _errors
 * module the only place that turns a status code into an exception.
 */
#ifndef PYRT_NATIVE_H
#define PYRT_NATIVE_H

#include <stdint.h>

/* Status codes returned by every entry point. */
#define PYRT_OK            0
#define PYRT_EINVAL        1   /* bad argument: size out of range, NULL pointer */
#define PYRT_ENONFINITE    2   /* NaN or infinity in an input */
#define PYRT_ESINGULAR     3   /* singular linear system */
#define PYRT_ENOCONVERGE   4   /* iteration limit reached */
#define PYRT_EDEGENERATE   5   /* zero-length segment or similar geometry */

/*
 * A rope segment shorter than this (cm: one micrometre) has no direction:
 * the carriage pulley is on a top pulley, a bottom attachment or the neck
 * ring's rim.  The geometry kernels (findpos, neck, statics) answer
 * PYRT_EDEGENERATE.
 */
#define PYRT_MIN_SEGMENT_CM 1e-4

#endif /* PYRT_NATIVE_H */
