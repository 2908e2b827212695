/* The 8031 ready-queue check over a byte image; see readyq.h. */
#include "pyrt_native.h"
#include "readyq.h"

#include <stddef.h>

/* The image checks of both forms: T holds t_width bytes per slot, Q two. */
static int rq_valid(pyrt_rq *rq, int32_t t_width)
{
    int32_t mem_len, capacity;
    if (rq == NULL || rq->mem == NULL || rq->ready == NULL)
        return 0;
    mem_len = rq->mem_len;
    capacity = rq->capacity;
    rq->n_ready = 0;
    return !(capacity < 1 || capacity > 255 || rq->t_addr < 0 || rq->q_addr < 0 ||
             rq->t_addr > mem_len - t_width * capacity ||
             rq->q_addr > mem_len - 2 * capacity);
}

int pyrt_rq_check(pyrt_rq *rq)
{
    int32_t i, n = 0;
    uint8_t *mem;
    uint16_t *ready;
    int32_t t_addr, q_addr, capacity;
    if (!rq_valid(rq, 1))
        return PYRT_EINVAL;
    mem = rq->mem;
    ready = rq->ready;
    t_addr = rq->t_addr;
    q_addr = rq->q_addr;
    capacity = rq->capacity;
    for (i = 0; i < capacity; i++) {
        uint8_t *q = mem + q_addr + 2 * i;
        uint16_t address = (uint16_t)(q[0] | (q[1] << 8));
        uint8_t v;
        if (address == 0)
            continue;
        v = (uint8_t)(mem[t_addr + i] - 1u);
        mem[t_addr + i] = v;
        if (v == 0) {
            q[0] = 0;
            q[1] = 0;
            ready[n++] = address;
        }
    }
    rq->n_ready = n;
    return PYRT_OK;
}

int pyrt_rq_check_wide(pyrt_rq *rq)
{
    int32_t i, n = 0;
    uint8_t *mem;
    uint16_t *ready;
    int32_t t_addr, q_addr, capacity;
    if (!rq_valid(rq, 4))
        return PYRT_EINVAL;
    mem = rq->mem;
    ready = rq->ready;
    t_addr = rq->t_addr;
    q_addr = rq->q_addr;
    capacity = rq->capacity;
    for (i = 0; i < capacity; i++) {
        uint8_t *q = mem + q_addr + 2 * i;
        uint8_t *t = mem + t_addr + 4 * i;
        uint16_t address = (uint16_t)(q[0] | (q[1] << 8));
        uint32_t v;
        if (address == 0)
            continue;
        /* byte by byte: no alignment assumed, little-endian on any host */
        v = (uint32_t)t[0] | ((uint32_t)t[1] << 8) | ((uint32_t)t[2] << 16) |
            ((uint32_t)t[3] << 24);
        v -= 1u;
        t[0] = (uint8_t)v;
        t[1] = (uint8_t)(v >> 8);
        t[2] = (uint8_t)(v >> 16);
        t[3] = (uint8_t)(v >> 24);
        if (v == 0) {
            q[0] = 0;
            q[1] = 0;
            ready[n++] = address;
        }
    }
    rq->n_ready = n;
    return PYRT_OK;
}
