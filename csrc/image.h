/*
 * The process image's side of a tick in C (pyrt/boards/image.py): the
 * read phase's exchange with in-process boards that keep their inputs in
 * 64-bit integers (one copy of each board's register file into the
 * image's flat array of inputs), the recorder's hand-over of the tick (the
 * tick's clock and every input appended as one row of the journal's ring,
 * pyrt/journal/writer.py; a plain tick in one call from the write phase,
 * pyrt_image_hand_over), and the change detection of a block of outputs.
 *
 * Every array is the caller's, allocated once; nothing here allocates or
 * touches Python, and only the hand-over's state keeps pointers (to arrays
 * its owner holds).  A refused call
 * (PYRT_EINVAL: a NULL array, a size or position out of range) changes
 * nothing.
 */
#ifndef PYRT_IMAGE_H
#define PYRT_IMAGE_H

#include "pyrt_native.h"

/* Fields of a tick's clock in a ring row: tick, time_ns, lateness_ns, missed. */
#define PYRT_IMAGE_CLOCK 4

/* One board's inputs: count values copied to the image's inputs at `at`. */
typedef struct pyrt_image_source {
    const int64_t *values;
    int32_t at;
    int32_t count;
} pyrt_image_source;

/*
 * inputs[src[k].at .. + src[k].count) = src[k].values, for every k < n_src.
 * PYRT_EINVAL (nothing copied) for a NULL array, n_inputs or n_src < 0, or a
 * source that does not lie within the n_inputs inputs.
 */
int pyrt_image_gather(int64_t *inputs, int32_t n_inputs, const pyrt_image_source *src,
                      int32_t n_src);

/*
 * Row `slot` of a ring of `rows` rows of PYRT_IMAGE_CLOCK + n_inputs values
 * each: tick, time_ns, lateness_ns, missed, then inputs[0 .. n_inputs).
 * PYRT_EINVAL (nothing written) for a NULL array, n_inputs < 0, rows <= 0 or
 * slot outside 0 .. rows - 1.
 */
int pyrt_image_row(int64_t *ring, int64_t rows, int64_t slot, int64_t tick, int64_t time_ns,
                   int64_t lateness_ns, int64_t missed, const int64_t *inputs,
                   int32_t n_inputs);

/*
 * Change detection of a block of n outputs: for each i with values[i] !=
 * current[i] (or every i when `all` is nonzero: write-only strobes),
 * current[i] = values[i] and i is appended to changed; *n_changed = how
 * many, in increasing order.  PYRT_EINVAL (nothing changed) for a NULL
 * array or n < 0.
 */
int pyrt_image_changes(int64_t *current, const int64_t *values, int32_t n, int32_t all,
                       int32_t *changed, int32_t *n_changed);

/* pyrt_image_hand_over's answers besides PYRT_OK (the tick handed over, nothing due). */
#define PYRT_IMAGE_SLOW 64   /* nothing handed over: the caller records the tick itself */
#define PYRT_IMAGE_DUE  65   /* the tick handed over; the tick listeners are due */
/* The largest magnitude of a plain tick's time or deadline (2^61 - 1). */
#define PYRT_IMAGE_TMAX 2305843009213693951

/*
 * The recorder's hand-over of a plain tick, made at the end of the image's
 * write phase: the state it needs, allocated once by the caller and shared
 * with the journal's writer thread (which only writes `taken` and `slow`).
 *
 * A tick is plain when nothing marked the hand-over slow (`slow`: an output
 * written, a request, a fault, a write error of the journal), the journal
 * takes ticks (`open`: not closed, not in a gap), the ring has room (put -
 * taken < rows) and the tick is the one expected: its index is `tick` and
 * its lateness against `deadline_ns` lies within [late_lo, late_hi] (the
 * recorder sets them so that a deadline skipped, a missed tick, or a deadline
 * moved between runs falls outside: on virtual time both are 0).
 */
typedef struct pyrt_image_handover {
    int64_t *ring;           /* rows x (PYRT_IMAGE_CLOCK + n_inputs) */
    const int64_t *inputs;   /* n_inputs: the image's inputs as the read phase left them */
    int64_t rows;            /* > 0 */
    int64_t put;             /* ticks handed over: the next goes in row put % rows */
    int64_t taken;           /* ticks the writer has taken (the writer thread writes it) */
    int64_t tick;            /* the index of the next plain tick */
    int64_t deadline_ns;     /* its deadline */
    int64_t period_ns;       /* the tick period, 1 .. PYRT_IMAGE_TMAX */
    int64_t late_lo;         /* a plain tick's lateness: late_lo .. late_hi */
    int64_t late_hi;
    int64_t listen_at;       /* the tick at which the tick listeners are next due */
    int32_t n_inputs;        /* >= 0 */
    int32_t open;            /* nonzero: the journal takes ticks */
    int32_t slow;            /* nonzero: the next tick is not plain */
    int32_t pad;
} pyrt_image_handover;

/*
 * Hand over the tick that starts at now_ns if it is plain (see above): row
 * put % rows = (tick, now_ns, now_ns - deadline_ns, 0, inputs), then put,
 * tick and deadline_ns (by period_ns) move on.  PYRT_OK, or PYRT_IMAGE_DUE
 * when tick >= listen_at; PYRT_IMAGE_SLOW (nothing written) when the tick
 * is not plain or a time lies beyond +-PYRT_IMAGE_TMAX; PYRT_EINVAL (nothing
 * written) for a NULL state or ring, NULL inputs with n_inputs > 0, rows <= 0,
 * n_inputs < 0, put < 0 or a period out of range.
 */
int pyrt_image_hand_over(pyrt_image_handover *h, int64_t now_ns);

#endif /* PYRT_IMAGE_H */
