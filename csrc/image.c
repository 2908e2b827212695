/* The process image's side of a tick; see image.h. */
#include "image.h"

#include <string.h>

int pyrt_image_gather(int64_t *inputs, int32_t n_inputs, const pyrt_image_source *src,
                      int32_t n_src)
{
    int32_t k;
    if (n_inputs < 0 || n_src < 0 || (n_src > 0 && src == NULL)
        || (n_inputs > 0 && inputs == NULL))
        return PYRT_EINVAL;
    for (k = 0; k < n_src; k++) {
        const pyrt_image_source *s = src + k;
        if (s->at < 0 || s->count < 0 || s->count > n_inputs - s->at
            || (s->count > 0 && s->values == NULL))
            return PYRT_EINVAL;
    }
    for (k = 0; k < n_src; k++)
        if (src[k].count > 0)
            memcpy(inputs + src[k].at, src[k].values, (size_t)src[k].count * sizeof(int64_t));
    return PYRT_OK;
}

int pyrt_image_row(int64_t *ring, int64_t rows, int64_t slot, int64_t tick, int64_t time_ns,
                   int64_t lateness_ns, int64_t missed, const int64_t *inputs,
                   int32_t n_inputs)
{
    int64_t *row;
    if (ring == NULL || n_inputs < 0 || (n_inputs > 0 && inputs == NULL) || rows <= 0
        || slot < 0 || slot >= rows)
        return PYRT_EINVAL;
    row = ring + slot * (PYRT_IMAGE_CLOCK + (int64_t)n_inputs);
    row[0] = tick;
    row[1] = time_ns;
    row[2] = lateness_ns;
    row[3] = missed;
    if (n_inputs > 0)
        memcpy(row + PYRT_IMAGE_CLOCK, inputs, (size_t)n_inputs * sizeof(int64_t));
    return PYRT_OK;
}

int pyrt_image_changes(int64_t *current, const int64_t *values, int32_t n, int32_t all,
                       int32_t *changed, int32_t *n_changed)
{
    int32_t i, k = 0;
    if (n < 0 || n_changed == NULL
        || (n > 0 && (current == NULL || values == NULL || changed == NULL)))
        return PYRT_EINVAL;
    for (i = 0; i < n; i++) {
        if (all || values[i] != current[i]) {
            current[i] = values[i];
            changed[k++] = i;
        }
    }
    *n_changed = k;
    return PYRT_OK;
}
