"""The server's bounds and its manners toward the loop: the default limits,
the rate budget, the tick guard, thread priority, and what "loopback" is.

Every bound here is a default a :class:`~pyrt.server.Server` can override.
"""

from __future__ import annotations

import contextlib
import ipaddress
import os
import socket
import threading

__all__ = [
    "GUARD_NS", "GUARD_POLL_S", "IDLE_TIMEOUT_S", "LINGER_S", "MAX_AUTH_FAILURES",
    "MAX_CLIENTS", "MAX_OUTPUT", "MAX_PENDING", "MAX_RATE", "MAX_SUBSCRIPTION_RATE", "NICE",
    "PUMP_S", "RATE_WINDOW_S", "SWITCH_INTERVAL_S", "is_loopback", "lower_priority",
]

#: Defaults of the bounds (all overridable per server).
MAX_CLIENTS = 64
IDLE_TIMEOUT_S = 600.0
MAX_OUTPUT = 256 * 1024
MAX_PENDING = 32
MAX_AUTH_FAILURES = 3
#: How long a closing connection waits for its peer to take the last reply.
LINGER_S = 1.0
#: How often the I/O thread hands subscription samples on, seconds.
PUMP_S = 0.005
#: Requests per second the server serves at most (all clients together);
#: beyond it the I/O thread pauses, so the network cannot take the CPU
#: the loop needs.  Twice the DAQ target of 5,000 STATUS requests/s.
MAX_RATE = 10_000
#: STATUS lines per second all subscriptions together may ask for: each
#: sample is read in the loop thread, so their sum is bounded.
MAX_SUBSCRIPTION_RATE = 20_000
#: The budget is kept per window of this many seconds.
RATE_WINDOW_S = 0.01
#: Niceness added to the server's threads (Linux: per thread), so that the
#: loop thread wins the CPU when both want it.
NICE = 5
#: Real time: the server's threads pause from this long before the loop's
#: next tick until the tick has run, so that the loop thread never waits
#: for the interpreter lock at its deadline (the loop's spin is 200 µs).
GUARD_NS = 450_000
#: How long a standing-aside thread sleeps between looks at the loop.
GUARD_POLL_S = 0.0001
#: Longest the loop thread waits for the interpreter lock while a server
#: thread holds it (``sys.setswitchinterval``; CPython's default is 5 ms,
#: five ticks).  Set when the server starts, never raised.
SWITCH_INTERVAL_S = 0.0002


def lower_priority(nice: int) -> None:
    """Make the calling thread ``nice`` steps nicer (Linux; elsewhere nothing)."""
    if nice <= 0 or not hasattr(os, "setpriority"):
        return
    with contextlib.suppress(OSError, AttributeError):
        tid = threading.get_native_id()
        os.setpriority(os.PRIO_PROCESS, tid, min(19, os.getpriority(os.PRIO_PROCESS, tid) + nice))



def is_loopback(host: str) -> bool:
    """True when every address ``host`` resolves to is a loopback address."""
    if host in ("", "0.0.0.0", "::"):
        return False
    try:
        infos = socket.getaddrinfo(host, None, type=socket.SOCK_STREAM)
    except OSError:
        return False
    addrs = {info[4][0] for info in infos}
    return bool(addrs) and all(ipaddress.ip_address(a.split("%")[0]).is_loopback for a in addrs)
