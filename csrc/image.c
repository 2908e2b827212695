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

/* One ring row: the tick's clock, then a copy of the inputs. */
static void put_row(int64_t *row, int64_t tick, int64_t time_ns, int64_t lateness_ns,
                    int64_t missed, const int64_t *inputs, int32_t n_inputs)
{
    row[0] = tick;
    row[1] = time_ns;
    row[2] = lateness_ns;
    row[3] = missed;
    if (n_inputs > 0)
        memcpy(row + PYRT_IMAGE_CLOCK, inputs, (size_t)n_inputs * sizeof(int64_t));
}

int pyrt_image_row(int64_t *ring, int64_t rows, int64_t slot, int64_t tick, int64_t time_ns,
                   int64_t lateness_ns, int64_t missed, const int64_t *inputs,
                   int32_t n_inputs)
{
    if (ring == NULL || n_inputs < 0 || (n_inputs > 0 && inputs == NULL) || rows <= 0
        || slot < 0 || slot >= rows)
        return PYRT_EINVAL;
    put_row(ring + slot * (PYRT_IMAGE_CLOCK + (int64_t)n_inputs), tick, time_ns, lateness_ns,
            missed, inputs, n_inputs);
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

/* Publish the new count of ticks handed over after the row it covers: the
 * journal's writer thread reads put without the loop thread's lock. */
static void publish_put(pyrt_image_handover *h, int64_t put)
{
#if defined(__GNUC__) || defined(__clang__)
    __atomic_store_n(&h->put, put, __ATOMIC_RELEASE);
#else
    *(volatile int64_t *)&h->put = put;
#endif
}

static int64_t read_taken(const pyrt_image_handover *h)
{
#if defined(__GNUC__) || defined(__clang__)
    return __atomic_load_n(&h->taken, __ATOMIC_ACQUIRE);
#else
    return *(const volatile int64_t *)&h->taken;
#endif
}

int pyrt_image_hand_over(pyrt_image_handover *h, int64_t now_ns)
{
    int64_t put, taken, late, tick;
    if (h == NULL || h->ring == NULL || h->rows <= 0 || h->n_inputs < 0
        || (h->n_inputs > 0 && h->inputs == NULL) || h->put < 0
        || h->period_ns <= 0 || h->period_ns > PYRT_IMAGE_TMAX)
        return PYRT_EINVAL;
    if (h->slow || !h->open)
        return PYRT_IMAGE_SLOW;
    put = h->put;
    taken = read_taken(h);
    if (taken < 0 || taken > put || put - taken >= h->rows || put >= PYRT_IMAGE_TMAX)
        return PYRT_IMAGE_SLOW;  /* the ring is full (or the counts are not ours to trust) */
    if (h->tick < 0 || h->tick >= PYRT_IMAGE_TMAX || now_ns > PYRT_IMAGE_TMAX || now_ns < -PYRT_IMAGE_TMAX
        || h->deadline_ns > PYRT_IMAGE_TMAX || h->deadline_ns < -PYRT_IMAGE_TMAX)
        return PYRT_IMAGE_SLOW;
    late = now_ns - h->deadline_ns;  /* within +-2^62: no overflow */
    if (late < h->late_lo || late > h->late_hi)
        return PYRT_IMAGE_SLOW;
    tick = h->tick;
    put_row(h->ring + (put % h->rows) * (PYRT_IMAGE_CLOCK + (int64_t)h->n_inputs), tick, now_ns,
            late, 0, h->inputs, h->n_inputs);
    publish_put(h, put + 1);
    h->tick = tick + 1;
    h->deadline_ns += h->period_ns;  /* |deadline| + period <= 2^62: no overflow */
    return tick >= h->listen_at ? PYRT_IMAGE_DUE : PYRT_OK;
}
