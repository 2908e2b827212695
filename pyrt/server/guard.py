"""What the doors keep out of the audit trail: client strings made harmless,
and failures (a wrong token, a refused write) that back off and are summarised.

Every string a client chooses (a Channel Access client's host and user
names, a line it wrote) passes :func:`escape_text` before it reaches a log
or a console: a line end, a terminal escape or any other character that is
not printable becomes a visible ``\\xNN``/``\\uNNNN`` escape, so a client
can neither start a line of its own nor move the operator's cursor.

:class:`FailureGuard` counts failures per peer address (the address the
connection really comes from, never a name the client claims) and overall:

* the first failures of an address in a window are audit lines of their
  own, at most ``lines_per_window`` lines for all addresses together;
  the rest are counted and written as one summary line per window
  (``N failures from ADDR in T s``), so that a flood writes a few lines a
  minute, never enough to rotate the real lines out of the audit log;
* ``per_address`` failures from one address within the window start a
  back-off for that address (``first_backoff_s``, doubling at each new
  back-off up to ``max_backoff_s``): until it ends, what the address asks
  with a token is refused without looking at the token, so guessing runs at
  a few attempts a minute instead of thousands a second;
* ``overall`` failures from all addresses together within the window start
  the same back-off for every address but loopback (the operator on the
  robot's own computer, who could stop the process anyway, always gets in).
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections import OrderedDict, deque
from collections.abc import Callable
from dataclasses import dataclass, field

from pyrt.errors import ConfigError
from pyrt.server.limits import address_is_loopback

__all__ = ["MAX_TOKEN", "MIN_TOKEN", "FailureGuard", "check_token", "escape_text"]

#: Longest client string kept in an audit line (characters, before escaping).
MAX_CLIENT_TEXT = 120
#: Shortest token accepted: 16 characters (about 95 bits when made by
#: ``secrets.token_urlsafe``); a short one is guessed, back-off or not.
MIN_TOKEN = 16
#: Longest token accepted (one line of its file).
MAX_TOKEN = 256


def check_token(token: str) -> str:
    """``token`` when it may guard a door; else :class:`~pyrt.errors.ConfigError`
    with the reason (too short, too long, spaces or characters that are not printable)."""
    if len(token) < MIN_TOKEN:
        raise ConfigError(
            f"the token is {len(token)} characters; at least {MIN_TOKEN} are needed (a short "
            "token is guessed): make one with  python -c 'import secrets; "
            "print(secrets.token_urlsafe(24))'")
    if len(token) > MAX_TOKEN or any(c.isspace() or not c.isprintable() for c in token):
        raise ConfigError(f"a token is one word of printable characters, at most {MAX_TOKEN}")
    return token


def escape_text(text: object, limit: int = MAX_CLIENT_TEXT) -> str:
    """``text`` as one harmless line: characters that are not printable (line
    ends, ESC and other controls, Unicode line and paragraph separators,
    format characters such as bidi overrides) become ``\\xNN``, ``\\uNNNN``
    or ``\\UNNNNNNNN``; a backslash is doubled (an escape cannot be forged);
    longer than ``limit`` characters: cut, with ``...``."""
    s = text if isinstance(text, str) else str(text)
    cut = len(s) > limit
    out = []
    for c in s[:limit]:
        if c == "\\":
            out.append("\\\\")
        elif c.isprintable():
            out.append(c)
        else:
            n = ord(c)
            out.append(f"\\x{n:02x}" if n < 0x100 else f"\\u{n:04x}" if n < 0x10000
                       else f"\\U{n:08x}")
    return "".join(out) + ("..." if cut else "")


@dataclass
class _Peer:
    """One address's failures."""

    window_start: float
    count: int = 0  # failures in the window (towards its back-off)
    logged: int = 0  # audit lines of its own in the window
    strikes: int = 0  # back-offs so far (each doubles the next)
    until: float = 0.0  # back-off end
    last: float = 0.0  # the latest failure
    unlogged: int = 0  # failures (and refusals) counted, not yet written (summary)
    unlogged_since: float = 0.0
    kinds: set[str] = field(default_factory=set)


class FailureGuard:
    """Back-off and bounded audit lines for failures (see the module text).

    ``audit(who, line)`` writes one audit line (the served station's
    :meth:`~pyrt.server.station.ServedStation.audit`).  Thread-safe: the DAQ
    server's threads and the EPICS thread share one guard.
    """

    def __init__(
        self,
        audit: Callable[[str, str], None],
        *,
        window_s: float = 60.0,
        per_address: int = 3,
        overall: int = 30,
        lines_per_window: int = 10,
        first_backoff_s: float = 2.0,
        max_backoff_s: float = 300.0,
        max_addresses: int = 4096,
        clock: Callable[[], float] = time.monotonic,
    ):
        if window_s <= 0 or per_address < 1 or overall < 1 or lines_per_window < 0:
            raise ValueError("window_s > 0, per_address >= 1, overall >= 1 and "
                             "lines_per_window >= 0 are needed")
        self._audit = audit
        self.window_s = float(window_s)
        self.per_address = int(per_address)
        self.overall = int(overall)
        self.lines_per_window = int(lines_per_window)
        self.first_backoff_s = float(first_backoff_s)
        self.max_backoff_s = float(max_backoff_s)
        self.max_addresses = int(max_addresses)
        self._clock = clock
        self._lock = threading.Lock()
        self._peers: OrderedDict[str, _Peer] = OrderedDict()
        self._recent: deque[float] = deque()  # failure times within the window, all addresses
        self._overall_strikes = 0
        self._overall_until = 0.0
        self._window_start = clock()
        self._lines = 0  # audit lines of their own in the current window
        #: Every failure recorded, and every request refused while backing off.
        self.failures = 0
        self.refused = 0

    # -- asking -----------------------------------------------------------------------

    def blocked(self, addr: str, kind: str = "request") -> float:
        """Seconds of back-off left for ``addr`` (0: it may try).  A ``kind`` of
        request refused for it is counted (:attr:`refused`, and in the summary)."""
        now = self._clock()
        with self._lock:
            peer = self._peers.get(addr)
            left = peer.until - now if peer is not None else 0.0
            if self._overall_until > now and not address_is_loopback(addr):
                left = max(left, self._overall_until - now)
            if left <= 0:
                return 0.0
            self.refused += 1
            if peer is None:
                peer = self._peers[addr] = _Peer(window_start=now, last=now)
            if not peer.unlogged:
                peer.unlogged_since = now
            peer.unlogged += 1
            peer.kinds.add(f"{kind} refused while backing off")
            return left

    def failed(self, addr: str, who: str, what: str, kind: str = "") -> float:
        """Record a failure of ``who`` (from ``addr``): ``what`` happened (an
        audit line when the budget allows, else counted for the summary).
        Returns the back-off now in force for ``addr``, seconds (0: none)."""
        now = self._clock()
        lines: list[tuple[str, str]] = []
        with self._lock:
            self._summaries(now, lines)
            self.failures += 1
            peer = self._peers.get(addr)
            if peer is None:
                peer = self._peers[addr] = _Peer(window_start=now)
                while len(self._peers) > self.max_addresses:
                    _old, gone = self._peers.popitem(last=False)
                    self._drop(gone, _old, now, lines)
            else:
                self._peers.move_to_end(addr)
            if now - peer.window_start >= self.window_s:
                peer.window_start, peer.count, peer.logged = now, 0, 0
            if peer.strikes and now - peer.last > self.max_backoff_s:
                peer.strikes = 0  # quiet for long: forgiven
            peer.last = now
            peer.count += 1
            backoff = 0.0
            if peer.count >= self.per_address:
                backoff = min(self.max_backoff_s, self.first_backoff_s * 2 ** peer.strikes)
                peer.strikes += 1
                peer.count = 0
                peer.until = now + backoff
            recent = self._recent
            recent.append(now)
            while recent and now - recent[0] > self.window_s:
                recent.popleft()
            overall = 0.0
            if len(recent) >= self.overall and self._overall_until <= now:
                overall = min(self.max_backoff_s, self.first_backoff_s * 2 ** self._overall_strikes)
                self._overall_strikes += 1
                self._overall_until = now + overall
                recent.clear()
            if now - self._window_start >= self.window_s:
                self._window_start, self._lines = now, 0
            text = what
            if backoff:
                text += f"; {addr} backs off {backoff:g} s"
            if overall:
                text += (f"; {self.overall} failures in {self.window_s:g} s from all addresses: "
                         f"every address but loopback backs off {overall:g} s")
            if (peer.logged < self.per_address and self._lines < self.lines_per_window) or overall:
                peer.logged += 1
                self._lines += 1
                lines.append((who, text))
            else:
                if not peer.unlogged:
                    peer.unlogged_since = now
                peer.unlogged += 1
                peer.kinds.add(kind or what.split(" (")[0])
            left = max(peer.until - now, 0.0)
            if self._overall_until > now and not address_is_loopback(addr):
                left = max(left, self._overall_until - now)
        self._write(lines)
        return left

    def flush(self, force: bool = False) -> None:
        """Write the summaries whose window has ended (all of them if ``force``)."""
        lines: list[tuple[str, str]] = []
        with self._lock:
            self._summaries(self._clock(), lines, force)
        self._write(lines)

    # -- inside -----------------------------------------------------------------------

    def _summaries(self, now: float, lines: list[tuple[str, str]], force: bool = False) -> None:
        """Summary lines for the failures not written one by one (lock held):
        one line per address, or one for all when more than three are due."""
        due = [(a, p) for a, p in self._peers.items()
               if p.unlogged and (force or now - p.unlogged_since >= self.window_s)]
        if due:
            if len(due) <= 3:
                for addr, p in due:
                    lines.append(("audit", _summary(p.unlogged, addr, now - p.unlogged_since,
                                                    p.kinds)))
            else:
                n = sum(p.unlogged for _a, p in due)
                since = min(p.unlogged_since for _a, p in due)
                top_addr, top = max(due, key=lambda ap: ap[1].unlogged)
                kinds = set().union(*(p.kinds for _a, p in due))
                lines.append(("audit", _summary(n, f"{len(due)} addresses", now - since, kinds)
                              + f"; most from {top_addr} ({top.unlogged})"))
            for _a, p in due:
                p.unlogged = 0
                p.kinds = set()
        # forget addresses that are quiet, forgiven and fully written
        stale = [a for a, p in self._peers.items()
                 if not p.unlogged and p.until <= now and now - p.last > self.max_backoff_s]
        for a in stale:
            del self._peers[a]

    def _drop(self, peer: _Peer, addr: str, now: float, lines: list[tuple[str, str]]) -> None:
        if peer.unlogged:
            lines.append(("audit", _summary(peer.unlogged, addr, now - peer.unlogged_since,
                                            peer.kinds)))

    def _write(self, lines: list[tuple[str, str]]) -> None:
        for who, text in lines:
            with contextlib.suppress(Exception):  # auditing must never break a door
                self._audit(who, text)


def _summary(n: int, where: str, secs: float, kinds: set[str]) -> str:
    what = ", ".join(sorted(kinds)) or "failures"
    return f"{n} failures from {where} in {secs:.0f} s ({what}), not written one by one"
