/*
 * Excess-128 conversions of the gripper DAC (002, "Features of the Gripper
 * Controller Hardware": null current = 0x80, full positive = 0xFF, full
 * negative = 0x00).  Values beyond -128..127 are clamped, never wrapped.
 */
#ifndef PYRT_CONVERT_H
#define PYRT_CONVERT_H

#include "pyrt_native.h"

/* *byte = the DAC byte for a signed drive value.  PYRT_EINVAL for NULL. */
int pyrt_excess128(int32_t value, uint8_t *byte);

/* *value = the signed drive value (-128..127) of a DAC byte.  PYRT_EINVAL for NULL. */
int pyrt_from_excess128(uint8_t byte, int32_t *value);

/*
 * Saturating excess-128 conversion of n values at once; out[i] receives the
 * DAC byte for in[i].  PYRT_EINVAL for n < 0 or a NULL pointer.
 */
int pyrt_excess128_many(const int32_t *in, uint8_t *out, int32_t n);

#endif /* PYRT_CONVERT_H */
