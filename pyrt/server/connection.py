"""One client connection: the state its I/O thread and its worker share."""

from __future__ import annotations

import socket
import threading
import time
from collections import deque
from typing import Any

__all__ = ["Connection"]


class Connection:
    """One client connection (state shared by the I/O thread and its worker)."""

    def __init__(self, cid: int, sock: socket.socket, peer: Any):
        self.id = cid
        self.sock = sock
        self.peer = peer
        #: The peer's address (the per-address bound counts by it).
        self.addr = str(peer[0]) if isinstance(peer, tuple) and peer else str(peer)
        self.connected_at = time.monotonic()
        #: No request yet (a complete line of text): the greeting bound applies.
        self.fresh = True
        #: In a reserved slot (the server was full): AUTH or a stop only.
        self.reserve = False
        self.inbuf = bytearray()
        self.out = bytearray()
        self.lock = threading.Lock()
        self.cv = threading.Condition(self.lock)
        self.requests: deque[tuple[bool, str]] = deque()  # (ready-made reply?, text)
        self.pending = 0  # requests handed to the worker and not yet answered
        self.worker: threading.Thread | None = None
        self.shell: Any = None
        self.shell_privileged = False
        self.privileged = False
        self.subscribed = 0.0
        self.auth_failures = 0
        self.last_active = time.monotonic()
        #: When a subscription sample was last queued for it (a subscriber
        #: that has neither requests nor samples is idle: it may be evicted).
        self.last_sample = 0.0
        #: When the peer last took bytes of its replies (or, with nothing
        #: owed before, when the first unsent byte was queued).
        self.last_sent = time.monotonic()
        #: A bug in pyrt was met handling it: it is being closed.
        self.failed = False
        self.paused = False  # too many requests queued: read no more for now
        self.backlogged = False  # over the server's rate: lines wait in inbuf
        self.writing = False
        self.dirty = False
        self.closing = False  # read nothing more; flush, then close
        self.stop_requests = False  # run no more of its queued requests
        self.eof = False  # the peer has closed its end
        self.events = 0  # selector events registered
        self.linger_until = 0.0
        self.drop: str | None = None  # close at once (slow reader ...)
        self.closed = False
        #: Set once the connection holds no privilege any more (its worker has
        #: released its session, or it never had one): an AUTH waits for it.
        self.released = threading.Event()

    def __repr__(self) -> str:
        return f"client {self.id} {self.peer}"
