/* The journal's tick records, delta-encoded into a block; see journal.h. */
#include "journal.h"

#include <stddef.h>

/* Bytes of a uvarint / svarint of 64 bits at most. */
#define VARINT_MAX 10

static uint8_t *put_uvarint(uint8_t *p, uint64_t v)
{
    while (v > 0x7F) {
        *p++ = (uint8_t)((v & 0x7F) | 0x80);
        v >>= 7;
    }
    *p++ = (uint8_t)v;
    return p;
}

/* Zigzag: 0, -1, 1, -2 ... to 0, 1, 2, 3 ... (v within +-(2^63 - 1)). */
static uint8_t *put_svarint(uint8_t *p, int64_t v)
{
    uint64_t z = v >= 0 ? (uint64_t)v << 1 : ((uint64_t)(-v) << 1) - 1;
    return put_uvarint(p, z);
}

static int value_ok(int64_t v)
{
    return v >= -PYRT_JOURNAL_VMAX && v <= PYRT_JOURNAL_VMAX;
}

static int time_ok(int64_t v)
{
    return v >= -PYRT_JOURNAL_TMAX && v <= PYRT_JOURNAL_TMAX;
}

int pyrt_journal_init(pyrt_journal_state *st, int64_t period_ns, int32_t n_inputs,
                      int32_t n_outputs)
{
    if (st == NULL || period_ns <= 0 || period_ns > PYRT_JOURNAL_TMAX || n_inputs < 0
        || n_outputs < 0)
        return PYRT_EINVAL;
    st->period_ns = period_ns;
    st->n_inputs = n_inputs;
    st->n_outputs = n_outputs;
    st->count = 0;
    st->have_prev = 0;
    st->tick = 0;
    st->deadline = 0;
    st->first_tick = 0;
    st->first_time = 0;
    st->last_time = 0;
    return PYRT_OK;
}

static int64_t record_bound(const pyrt_journal_state *st, int32_t n_writes)
{
    /* a keyframe: every input and output once; a delta: an index gap and a change */
    return 8 * VARINT_MAX + (int64_t)st->n_inputs * 2 * VARINT_MAX
           + (int64_t)st->n_outputs * VARINT_MAX + (int64_t)n_writes * 3 * VARINT_MAX;
}

int pyrt_journal_record_bound(const pyrt_journal_state *st, int32_t n_writes, int64_t *bound)
{
    if (st == NULL || bound == NULL || n_writes < 0 || st->n_inputs < 0 || st->n_outputs < 0)
        return PYRT_EINVAL;
    *bound = record_bound(st, n_writes);
    return PYRT_OK;
}

/*
 * Whether record (c, in, w: nw writes) may follow the state: the checks
 * of a refusal, made before anything is written.  *shift receives the
 * deadline's departure from its prediction (deltas only).
 */
static int record_ok(const pyrt_journal_state *st, int key, const int64_t *c,
                     const int64_t *in, const int64_t *w, int32_t nw, int64_t *shift)
{
    int64_t tick = c[0], time_ns = c[1], late = c[2], missed = c[3];
    int64_t deadline, predicted, span;
    int32_t i;
    if (tick < 0 || missed < 0 || !time_ok(time_ns) || !time_ok(late))
        return 0;
    for (i = 0; i < st->n_inputs; i++)
        if (!value_ok(in[i]))
            return 0;
    for (i = 0; i < nw; i++) {
        const int64_t *x = w + (int64_t)i * PYRT_JOURNAL_WRITE;
        if (x[0] < 0 || x[0] >= st->n_outputs || !value_ok(x[1]) || x[2] < 0)
            return 0;
    }
    *shift = 0;
    if (key)
        return 1;
    if (tick <= st->tick)
        return 0;
    /* the prediction: previous deadline + period x (1 + missed), kept in range */
    if (missed >= PYRT_JOURNAL_TMAX / st->period_ns)
        return 0;
    span = st->period_ns * (1 + missed);
    deadline = time_ns - late;
    predicted = st->deadline + span;
    if (!time_ok(predicted))
        return 0;
    *shift = deadline - predicted;
    return 1;
}

int pyrt_journal_encode(pyrt_journal_state *st, int64_t *prev, int64_t *outs,
                        const int64_t *rows, const int32_t *n_writes, const int64_t *writes, int32_t extra,
                        int32_t n, uint8_t *body, int64_t capacity, int64_t *pos,
                        int32_t *done)
{
    int32_t k, i;
    int64_t at, stride;
    const int64_t *w = writes;
    if (done != NULL)
        *done = 0;
    if (st == NULL || pos == NULL || done == NULL || n < 0 || body == NULL || *pos < 0
        || *pos > capacity || (extra & ~(PYRT_JF_COMMANDS | PYRT_JF_EVENTS)) != 0
        || st->n_inputs < 0 || st->n_outputs < 0 || st->period_ns <= 0)
        return PYRT_EINVAL;
    if (n > 0 && (rows == NULL || n_writes == NULL || (st->n_inputs > 0 && prev == NULL)
                  || (st->n_outputs > 0 && outs == NULL)))
        return PYRT_EINVAL;
    at = *pos;
    stride = PYRT_JOURNAL_CLOCK + (int64_t)st->n_inputs;
    for (k = 0; k < n; k++) {
        const int64_t *c = rows + (int64_t)k * stride;
        const int64_t *in = c + PYRT_JOURNAL_CLOCK;
        int32_t nw = n_writes[k];
        int key = st->count == 0 || !st->have_prev;
        int64_t shift = 0, deadline, step;
        int32_t flags = 0, changes = 0, last;
        uint8_t *p;
        if (nw < 0 || (nw > 0 && writes == NULL))
            return PYRT_EINVAL;
        if (!record_ok(st, key, c, in, w, nw, &shift))
            return PYRT_EINVAL;
        if (capacity - at < record_bound(st, nw))
            return PYRT_OK; /* the caller takes the block or grows the body */
        if (nw > 0)
            flags |= PYRT_JF_OUTPUTS;
        if (k == n - 1)
            flags |= extra;
        p = body + at;
        deadline = c[1] - c[2];
        if (key) {
            p = put_uvarint(p, (uint64_t)(flags | PYRT_JF_KEY));
            p = put_uvarint(p, (uint64_t)c[0]);
            p = put_svarint(p, c[1]);
            p = put_uvarint(p, (uint64_t)c[3]);
            p = put_svarint(p, c[2]);
            for (i = 0; i < st->n_inputs; i++) {
                p = put_svarint(p, in[i]);
                prev[i] = in[i];
            }
            for (i = 0; i < st->n_outputs; i++)
                p = put_svarint(p, outs[i]);
            st->first_tick = c[0];
            st->first_time = c[1];
        } else {
            step = c[0] - st->tick - 1;
            for (i = 0; i < st->n_inputs; i++)
                changes += in[i] != prev[i];
            if (step)
                flags |= PYRT_JF_STEP;
            if (c[3])
                flags |= PYRT_JF_MISSED;
            if (shift)
                flags |= PYRT_JF_SHIFT;
            if (c[2])
                flags |= PYRT_JF_LATE;
            if (changes)
                flags |= PYRT_JF_INPUTS;
            p = put_uvarint(p, (uint64_t)flags);
            if (step)
                p = put_uvarint(p, (uint64_t)step);
            if (c[3])
                p = put_uvarint(p, (uint64_t)c[3]);
            if (shift)
                p = put_svarint(p, shift);
            if (c[2])
                p = put_svarint(p, c[2]);
            if (changes) {
                p = put_uvarint(p, (uint64_t)changes);
                last = -1;
                for (i = 0; i < st->n_inputs; i++) {
                    if (in[i] != prev[i]) {
                        p = put_uvarint(p, (uint64_t)(i - last - 1));
                        p = put_svarint(p, in[i] - prev[i]);
                        prev[i] = in[i];
                        last = i;
                    }
                }
            }
        }
        if (nw > 0) {
            p = put_uvarint(p, (uint64_t)nw);
            for (i = 0; i < nw; i++, w += PYRT_JOURNAL_WRITE) {
                p = put_uvarint(p, (uint64_t)w[0]);
                p = put_svarint(p, w[1] - outs[w[0]]);
                p = put_uvarint(p, (uint64_t)w[2]);
                outs[w[0]] = w[1];
            }
        }
        at = p - body;
        *pos = at;
        st->have_prev = 1;
        st->deadline = deadline;
        st->tick = c[0];
        st->last_time = c[1];
        st->count += 1;
        *done = k + 1;
    }
    return PYRT_OK;
}
