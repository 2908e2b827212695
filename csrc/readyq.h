/*
 * The 8031 ready-queue check (002, "The Ready Queue") over a byte image.
 *
 * T: capacity schedule bytes at t_addr; Q: capacity 16-bit routine
 * addresses at q_addr, little-endian (low byte at the lower address); a Q
 * word of 0000 is a free slot.  One check decrements the schedule byte of
 * every occupied slot modulo 256 and tests it for zero after the decrement
 * (DJNZ: a byte of 00 lasts 256 checks); a slot reaching zero is freed
 * (its Q word cleared, its T byte left 00) and its routine address is
 * appended to ready[] in slot order.  The routines themselves run in
 * Python, after the check.
 *
 * pyrt_rq_check_wide is the same check over a queue whose schedule
 * variables are 32-bit words (T: capacity little-endian words at t_addr),
 * decremented modulo 2**32 and tested for zero after the decrement: the
 * ready queue of a station that has no 8031, whose periods do not fit a
 * byte.  The layout of Q and the result are as above.
 */
#ifndef PYRT_READYQ_H
#define PYRT_READYQ_H

#include <stdint.h>

/* Where the queue lies, and room for the result (bound once, reused). */
typedef struct {
    uint8_t *mem;       /* the byte image */
    int32_t mem_len;
    int32_t t_addr;     /* T: capacity schedule bytes */
    int32_t q_addr;     /* Q: capacity little-endian words */
    int32_t capacity;   /* 1..255 */
    int32_t n_ready;    /* out: routines found ready */
    uint16_t *ready;    /* out: their addresses, room for capacity entries */
} pyrt_rq;

/*
 * One queue check.  Returns PYRT_EINVAL (nothing changed) for a NULL
 * pointer, capacity out of 1..255 or a T/Q range outside mem_len.
 */
int pyrt_rq_check(pyrt_rq *rq);

/*
 * One check of a queue with 32-bit schedule words (T takes 4 * capacity
 * bytes at t_addr).  Errors as pyrt_rq_check.
 */
int pyrt_rq_check_wide(pyrt_rq *rq);

#endif /* PYRT_READYQ_H */
