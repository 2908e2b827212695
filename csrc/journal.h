/*
 * The journal's tick records (pyrt/journal/format.py, "Tick records"):
 * the delta encoding of a run of ticks into a block, in C, so that the
 * journal's writer thread encodes without the interpreter lock.
 *
 * The encoder's state (the previous record's inputs, every output as it
 * stands, the previous deadline and tick) lives in buffers the caller
 * allocates once; pyrt_journal_encode appends records to a body buffer the
 * caller owns and never allocates.  Values are int64: the caller keeps
 * every value within +-PYRT_JOURNAL_VMAX (and the clock's fields within
 * +-PYRT_JOURNAL_TMAX) so that no difference overflows; a record outside
 * those bounds is refused (PYRT_EINVAL), as is a tick that does not follow
 * the previous one, a negative count of missed deadlines, an output index
 * out of range or a negative writer index.  A refused record changes
 * nothing; the records before it are kept (*done says how many).
 */
#ifndef PYRT_JOURNAL_H
#define PYRT_JOURNAL_H

#include "pyrt_native.h"

/* Flags of a record (format.py's F_*). */
#define PYRT_JF_KEY      1
#define PYRT_JF_LATE     2
#define PYRT_JF_INPUTS   4
#define PYRT_JF_OUTPUTS  8
#define PYRT_JF_STEP     16
#define PYRT_JF_MISSED   32
#define PYRT_JF_SHIFT    64
#define PYRT_JF_COMMANDS 128
#define PYRT_JF_EVENTS   256

/* Fields of a tick's clock row: tick, time_ns, lateness_ns, missed. */
#define PYRT_JOURNAL_CLOCK 4
/* Fields of an output write: index, value, writer. */
#define PYRT_JOURNAL_WRITE 3
/* The largest magnitude of an input or output value (2^62 - 1). */
#define PYRT_JOURNAL_VMAX 4611686018427387903
/* The largest magnitude of a time or lateness (2^61 - 1). */
#define PYRT_JOURNAL_TMAX 2305843009213693951

typedef struct pyrt_journal_state {
    int64_t period_ns;   /* the tick period, > 0 */
    int32_t n_inputs;    /* inputs of a record */
    int32_t n_outputs;   /* output slots */
    int32_t count;       /* records in the block being filled (0: the next is a keyframe) */
    int32_t have_prev;   /* 0: the next record is a keyframe (a new run, after a gap) */
    int64_t tick;        /* the previous record's tick */
    int64_t deadline;    /* the previous record's deadline (time - lateness) */
    int64_t first_tick;  /* the block's first tick and time */
    int64_t first_time;
    int64_t last_time;   /* the previous record's time */
} pyrt_journal_state;

/*
 * Set up *st for n_inputs inputs and n_outputs outputs at period_ns.
 * PYRT_EINVAL for NULL, a count < 0 or a period <= 0.
 */
int pyrt_journal_init(pyrt_journal_state *st, int64_t period_ns, int32_t n_inputs,
                      int32_t n_outputs);

/*
 * *bound = the most bytes one record of n_writes output writes can take
 * (not counting its commands and events).  PYRT_EINVAL for NULL or bad sizes.
 */
int pyrt_journal_record_bound(const pyrt_journal_state *st, int32_t n_writes, int64_t *bound);

/*
 * Append n tick records to body[*pos .. capacity).
 *
 *   prev      n_inputs: the previous record's inputs (state; updated)
 *   outs      n_outputs: every output as it stands (state; updated)
 *   rows      n x (PYRT_JOURNAL_CLOCK + n_inputs): tick, time_ns, lateness_ns,
 *             missed, then every input in declared order
 *   n_writes  n: output writes of each tick
 *   writes    sum(n_writes) x PYRT_JOURNAL_WRITE, in the order written
 *   extra     flags added to the last record (PYRT_JF_COMMANDS, PYRT_JF_EVENTS:
 *             the caller appends those fields right after it), or 0
 *
 * Records are appended while each fits whole; *done = the records appended,
 * *pos advanced past them.  PYRT_OK when all n were (or the next did not
 * fit: *done < n), PYRT_EINVAL when record *done is refused (see above) or
 * for bad arguments (NULL, n < 0, extra not made of those two flags).
 */
int pyrt_journal_encode(pyrt_journal_state *st, int64_t *prev, int64_t *outs,
                        const int64_t *rows, const int32_t *n_writes, const int64_t *writes, int32_t extra,
                        int32_t n, uint8_t *body, int64_t capacity, int64_t *pos,
                        int32_t *done);

#endif /* PYRT_JOURNAL_H */
