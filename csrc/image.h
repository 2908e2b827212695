/*
 * The process image's side of a tick in C (pyrt/boards/image.py): the
 * read phase's exchange with in-process boards that keep their inputs in
 * 64-bit integers (one copy of each board's register file into the
 * image's flat array of inputs), the recorder's hand-over of the tick (the
 * tick's clock and every input appended as one row of the journal's ring,
 * pyrt/journal/writer.py), and the change detection of a block of outputs.
 *
 * Every array is the caller's, allocated once; nothing here allocates,
 * keeps a pointer between calls or touches Python.  A refused call
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

#endif /* PYRT_IMAGE_H */
