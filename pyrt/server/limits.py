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
    "EVICT_IDLE_S", "GREETING_TIMEOUT_S", "GUARD_NS", "GUARD_POLL_S", "GUEST_IDLE_S",
    "IDLE_TIMEOUT_S", "LINGER_S", "MAX_AUTH_FAILURES", "MAX_CLIENTS", "MAX_FRESH_PER_ADDRESS",
    "MAX_OUTPUT", "MAX_PENDING", "MAX_RATE", "MAX_SUBSCRIPTION_RATE", "NICE", "PUMP_S",
    "RATE_WINDOW_S", "RESERVED_SLOTS", "SWITCH_INTERVAL_S", "WRITE_STALL_S", "address_is_loopback",
    "is_loopback", "lower_priority",
]

#: Defaults of the bounds (all overridable per server).
MAX_CLIENTS = 64
#: The privileged client (the operator's session) is closed after this long
#: without a request; nobody is kept longer.
IDLE_TIMEOUT_S = 600.0
#: An unprivileged client that is not subscribed is closed after this long
#: without a request (a DAQ that polls less often reconnects).
GUEST_IDLE_S = 30.0
#: A connection that has sent no request (a complete line of text) this long
#: after it connected is closed: a silent connection holds a slot seconds, not minutes.
GREETING_TIMEOUT_S = 5.0
#: Connections from one address that have sent no request yet, at most (a
#: further one is refused).  Loopback is exempt: a client on the robot's own
#: computer can stop the process anyway, and the local DAQ and test rigs open
#: their connections together before their first request; a flood from there
#: is met by eviction and the reserved slots.
MAX_FRESH_PER_ADDRESS = 8
#: When every slot is taken, a newcomer takes the slot of the oldest connection
#: that has sent nothing, else of an unprivileged, unsubscribed one idle this long.
EVICT_IDLE_S = 5.0
#: Slots beyond ``max_clients`` for when no slot can be freed: a connection
#: there may only ``AUTH`` (the operator always gets in) or give a stop
#: (any client may); anything else gets ``ERR full``.
RESERVED_SLOTS = 4
#: Bytes of replies and samples a client may leave unread; beyond, it is dropped.
MAX_OUTPUT = 256 * 1024
#: A client that takes no byte of what it is owed for this long is dropped
#: (a silent peer: its TCP window closed), whatever the size of what waits.
WRITE_STALL_S = 30.0
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



def address_is_loopback(addr: str) -> bool:
    """True when the numeric address ``addr`` (a peer's) is a loopback address."""
    try:
        ip = ipaddress.ip_address(addr.split("%")[0])
    except ValueError:
        return False
    mapped = getattr(ip, "ipv4_mapped", None)
    return bool(ip.is_loopback or (mapped is not None and mapped.is_loopback))


def is_loopback(host: str) -> bool:
    """True when every address ``host`` resolves to is a loopback address."""
    if host in ("", "0.0.0.0", "::"):
        return False
    try:
        infos = socket.getaddrinfo(host, None, type=socket.SOCK_STREAM)
    except OSError:
        return False
    addrs = {str(info[4][0]) for info in infos}
    return bool(addrs) and all(ipaddress.ip_address(a.split("%")[0]).is_loopback for a in addrs)
