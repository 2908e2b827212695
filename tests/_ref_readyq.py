"""Pure-Python reference of csrc/readyq.c: one 8031 ready-queue check over a byte image."""

from __future__ import annotations


def check(mem: bytearray, t_addr: int, q_addr: int, capacity: int) -> list[int]:
    """Decrement each occupied slot's T byte (mod 256, DJNZ); free and return those reaching 0."""
    ready = []
    for i in range(capacity):
        lo, hi = mem[q_addr + 2 * i], mem[q_addr + 2 * i + 1]
        address = lo | (hi << 8)
        if not address:
            continue
        v = (mem[t_addr + i] - 1) & 0xFF
        mem[t_addr + i] = v
        if v == 0:
            mem[q_addr + 2 * i] = mem[q_addr + 2 * i + 1] = 0
            ready.append(address)
    return ready


def check_wide(mem: bytearray, t_addr: int, q_addr: int, capacity: int) -> list[int]:
    """As :func:`check`, with 32-bit little-endian T words decremented modulo 2**32."""
    ready = []
    for i in range(capacity):
        address = mem[q_addr + 2 * i] | (mem[q_addr + 2 * i + 1] << 8)
        if not address:
            continue
        at = t_addr + 4 * i
        v = (int.from_bytes(mem[at:at + 4], "little") - 1) & 0xFFFFFFFF
        mem[at:at + 4] = v.to_bytes(4, "little")
        if v == 0:
            mem[q_addr + 2 * i] = mem[q_addr + 2 * i + 1] = 0
            ready.append(address)
    return ready
