/*
 * pyrt native kernels: the only C functions Python may call.
 *
 * Plain C99.  No Python.h, no globals, no allocation: every function takes
 * explicit arrays and sizes and returns a status code (PYRT_OK on success).
 * build_native.py mirrors this header in its cdef; pyrt/native.py is the
 * only Python module that calls these functions.
 */
#ifndef PYRT_NATIVE_H
#define PYRT_NATIVE_H

#include <stdint.h>

/* Status codes shared by every kernel. */
#define PYRT_OK            0
#define PYRT_EINVAL        1   /* bad argument: size out of range, NULL pointer */
#define PYRT_ENONFINITE    2   /* NaN or infinity in an input */
#define PYRT_ESINGULAR     3   /* singular linear system */
#define PYRT_ENOCONVERGE   4   /* iteration limit reached */
#define PYRT_EDEGENERATE   5   /* zero-length segment or similar geometry */

/*
 * Saturating conversion of a signed drive value to an excess-128 DAC byte
 * (002, "Features of the Gripper Controller Hardware": null current = 0x80,
 * full positive = 0xFF, full negative = 0x00).  Values beyond -128..127 are
 * clamped, never wrapped.
 */
uint8_t pyrt_excess128(int32_t value);

/* Inverse of pyrt_excess128: DAC byte to signed drive value (-128..127). */
int32_t pyrt_from_excess128(uint8_t byte);

/*
 * Saturating excess-128 conversion of n values at once; out[i] receives the
 * DAC byte for in[i].  Returns PYRT_EINVAL for a NULL pointer.
 */
int pyrt_excess128_many(const int32_t *in, uint8_t *out, int32_t n);

#endif /* PYRT_NATIVE_H */
