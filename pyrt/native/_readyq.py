"""The ready-queue check in C (csrc/readyq.c), bound once to a byte image."""

from __future__ import annotations

from typing import Any

from pyrt.native._errors import raise_for_status
from pyrt.native._lib import ffi, lib

__all__ = ["QueueChecker", "native_dispatcher"]


class QueueChecker:
    """A prepared ready-queue check over ``mem`` (a bytearray, held for life).

    :meth:`check` decrements every occupied slot's schedule byte, frees the
    slots that reach zero and returns their routine addresses in slot order
    (exactly the pure-Python walk it replaces; see csrc/readyq.h).  With
    ``wide`` the schedule variables are 32-bit little-endian words (T takes
    ``4 * capacity`` bytes), decremented modulo 2**32.
    """

    __slots__ = ("_buf", "_check", "_ready", "_rq", "_unpack", "capacity", "wide")

    def __init__(self, mem: bytearray, t_addr: int, q_addr: int, capacity: int, *,
                 wide: bool = False):
        if not isinstance(mem, bytearray):
            raise TypeError(f"the byte image must be a bytearray, got {type(mem).__name__}")
        if not 1 <= capacity <= 255:
            raise ValueError(f"ready queue capacity must be 1..255, got {capacity}")
        size = len(mem)
        t_size = 4 * capacity if wide else capacity
        if t_addr < 0 or t_addr + t_size > size or q_addr < 0 or q_addr + 2 * capacity > size:
            raise ValueError("T or Q lies outside the byte image")
        self.capacity = capacity
        self.wide = wide
        self._ready = ffi.new("uint16_t[]", capacity)
        self._buf = ffi.from_buffer("uint8_t[]", mem, require_writable=True)
        self._rq = ffi.new("pyrt_rq *", {
            "mem": self._buf, "mem_len": size, "t_addr": t_addr, "q_addr": q_addr,
            "capacity": capacity, "ready": self._ready,
        })
        self._check = lib.pyrt_rq_check_wide if wide else lib.pyrt_rq_check
        self._unpack = ffi.unpack

    def check(self) -> list[int]:
        """One queue check; the addresses of the routines now ready."""
        rq = self._rq
        raise_for_status(self._check(rq), "QueueChecker.check")
        n = rq.n_ready
        return self._unpack(self._ready, n) if n else []


def native_dispatcher(mem: bytearray, t_addr: int, q_addr: int, capacity: int, *,
                      wide: bool = False) -> Any:
    """The ready queue's check-and-dispatch in C (csrc/ext/dispatch.c) over
    ``mem``: :meth:`check` does what :class:`QueueChecker` does and then runs
    the routines it found, rescheduling and timing them (see the C file)."""
    from pyrt.native._dispatch import Dispatcher

    return Dispatcher(mem, t_addr, q_addr, capacity, wide)
