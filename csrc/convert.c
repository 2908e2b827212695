/* Excess-128 conversions of the gripper DAC (002); see convert.h. */
#include "convert.h"

#include <stddef.h>

static uint8_t saturate(int32_t value)
{
    if (value > 127)
        value = 127;
    else if (value < -128)
        value = -128;
    return (uint8_t)(value + 128);
}

int pyrt_excess128(int32_t value, uint8_t *byte)
{
    if (byte == NULL)
        return PYRT_EINVAL;
    *byte = saturate(value);
    return PYRT_OK;
}

int pyrt_from_excess128(uint8_t byte, int32_t *value)
{
    if (value == NULL)
        return PYRT_EINVAL;
    *value = (int32_t)byte - 128;
    return PYRT_OK;
}

int pyrt_excess128_many(const int32_t *in, uint8_t *out, int32_t n)
{
    int32_t i;
    if (n < 0 || (n > 0 && (in == NULL || out == NULL)))
        return PYRT_EINVAL;
    for (i = 0; i < n; i++)
        out[i] = saturate(in[i]);
    return PYRT_OK;
}
