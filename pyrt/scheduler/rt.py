"""Linux real-time knobs, offered as options and never applied by default.

Each function returns a one-line message saying what it did, or raises
:class:`PermissionError`/``OSError`` with a message saying what was refused
and why (the usual cause: no CAP_SYS_NICE / RLIMIT_RTPRIO / RLIMIT_MEMLOCK).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import sys

__all__ = ["lock_memory", "set_fifo", "set_timer_slack"]

_PR_SET_TIMERSLACK = 29
_MCL_CURRENT = 1
_MCL_FUTURE = 2


def _libc() -> ctypes.CDLL:
    name = ctypes.util.find_library("c") or "libc.so.6"
    return ctypes.CDLL(name, use_errno=True)


def set_timer_slack(ns: int = 1) -> str:
    """Set this thread's timer slack (prctl PR_SET_TIMERSLACK) to ``ns``.

    Threads started afterwards inherit it.  Elsewhere than on Linux it raises
    :class:`OSError` saying so (there is no timer slack to set)."""
    if ns < 1:
        raise ValueError(f"timer slack must be >= 1 ns, got {ns}")
    if not sys.platform.startswith("linux"):
        raise OSError(0, f"timer slack is Linux only (prctl PR_SET_TIMERSLACK); "
                         f"not set on {sys.platform}")
    rc = _libc().prctl(_PR_SET_TIMERSLACK, ctypes.c_ulong(ns), 0, 0, 0)
    if rc != 0:
        err = ctypes.get_errno()
        raise OSError(err, f"prctl(PR_SET_TIMERSLACK, {ns}) failed: {os.strerror(err)}")
    return f"timer slack set to {ns} ns"


def set_fifo(priority: int = 50) -> str:
    """Run the calling process under SCHED_FIFO at ``priority``."""
    lo = os.sched_get_priority_min(os.SCHED_FIFO)
    hi = os.sched_get_priority_max(os.SCHED_FIFO)
    if not lo <= priority <= hi:
        raise ValueError(f"SCHED_FIFO priority must be {lo}..{hi}, got {priority}")
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except PermissionError as exc:
        raise PermissionError(
            exc.errno,
            f"SCHED_FIFO refused ({exc.strerror}): run with CAP_SYS_NICE or raise RLIMIT_RTPRIO",
        ) from None
    return f"scheduling policy SCHED_FIFO, priority {priority}"


def lock_memory() -> str:
    """Lock current and future pages in RAM (mlockall)."""
    rc = _libc().mlockall(_MCL_CURRENT | _MCL_FUTURE)
    if rc != 0:
        err = ctypes.get_errno()
        raise PermissionError(
            err,
            f"mlockall refused ({os.strerror(err)}): raise RLIMIT_MEMLOCK or run with CAP_IPC_LOCK",
        )
    return "memory locked (mlockall MCL_CURRENT|MCL_FUTURE)"
