"""What a connection asks (its requests, the server's verbs, the privilege)
and the worker thread that runs its console commands in order.

The cheap verbs (``STATUS``, ``AUTH``, ``SUBSCRIBE`` ...) are answered in
the I/O thread unless commands of the same connection wait before them;
console commands run in the connection's worker through a
:class:`~pyrt.commands.CommandShell` of its own (:func:`run_shell` frames
its output).  One connection at a time is privileged; a privileged client
that leaves is released by its worker, and an ``AUTH`` meanwhile waits for
that release instead of getting ``ERR busy``.
"""

from __future__ import annotations

import hmac
import io
import logging
import math
import re
import threading
import time
from typing import Any

from pyrt.errors import MailboxTimeout, PyrtError
from pyrt.scope.spew import MIN_SPEW_HZ
from pyrt.server.connection import Connection
from pyrt.server.limits import MAX_AUTH_FAILURES, lower_priority
from pyrt.server.protocol import format_error, format_reply, split_verb
from pyrt.server.state import ServerState

__all__ = ["SessionMixin", "run_shell"]

log = logging.getLogger("pyrt.server")

_VERBS = frozenset({"AUTH", "FIELDS", "QUIT", "STATUS", "SUBSCRIBE", "UNSUBSCRIBE"})
#: A rate as SUBSCRIBE takes it: a decimal number in ASCII digits (no
#: ``nan``/``inf``, no ``_`` separators, no digits of other scripts).
_RATE = re.compile(r"\+?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]{1,4})?", re.ASCII)


def _control(line: str) -> int:
    """Index of the first character of ``line`` that is not printable text
    (tab allowed), or -1: controls, line and paragraph separators, format
    characters (bidi overrides ...), so that no request can put a line or a
    terminal escape of its own into a log or a console."""
    for i, c in enumerate(line):
        if not c.isprintable() and c != "\t":
            return i
    return -1


def _denied(line: str) -> str:
    return format_error("denied", f"{line.strip()[:60]!r} changes the robot: AUTH first")


def _server_verb(verb: str, rest: str) -> bool:
    """True when the request is one of the server's own verbs; ``STATUS
    OBJECT`` is the console's ``status OBJECT`` (an object's signals)."""
    return verb in _VERBS and not (verb == "STATUS" and rest)


def run_shell(shell: Any, line: str, extra: list[str] | None = None) -> tuple[str, bool]:
    """Run ``line`` in a console ``shell``, its output captured; the framed reply
    and whether the shell asked to end the session.

    What the shell reports through ``error()`` makes the reply ``ERR command``;
    a bug in pyrt (its ``internal_error()``) ``ERR internal``, the traceback
    to the server's log; a fault it meets (a :class:`~pyrt.errors.FaultError`, handed to its
    ``fault()``) ``ERR fault``, with what the command then said as the lines.
    """
    out = io.StringIO()
    errors: list[str] = []
    faults: list[Any] = []
    bugs: list[BaseException] = []
    shell.stdout = out
    shell.error = errors.append
    shell.fault = faults.append
    shell.internal_error = bugs.append
    end = bool(shell.onecmd(line))
    lines = out.getvalue().splitlines() + list(extra or [])
    if bugs:
        exc = bugs[0]
        log.error("a bug in pyrt running %r", line[:60], exc_info=exc)
        return format_error("internal", f"{type(exc).__name__}: {exc} (a bug in pyrt; the "
                            "server log has the traceback)", lines), end
    if errors:
        return format_error("command", "; ".join(errors), lines), end
    if faults:
        return format_error("fault", f"{faults[0].fault}; every motor stopped; nothing "
                            "moves until you type ack", lines), end
    return format_reply(lines), end



class SessionMixin(ServerState):
    """The requests part of :class:`~pyrt.server.Server` (see the module text)."""

    def _request(self, conn: Connection, raw: bytes) -> None:
        self.counters["requests"] += 1
        try:
            line = raw.decode("utf-8")
        except UnicodeDecodeError as exc:
            self.counters["utf8"] += 1
            self._reply(conn, format_error(
                "utf8", f"invalid UTF-8 at byte {exc.start}; request ignored"))
            return
        bad = _control(line)
        if bad >= 0:
            self.counters["text"] += 1
            self._reply(conn, format_error(
                "text", f"control character {ord(line[bad]):#04x} at character {bad}; "
                "request ignored"))
            return
        verb, rest = split_verb(line)
        if verb:  # a request: the connection is no longer silent
            conn.fresh = False
            conn.last_active = time.monotonic()
        if (conn.reserve and not conn.privileged and verb and verb not in ("AUTH", "QUIT")
                and not self.robot.is_stop(line)):
            self.counters["refused_full"] += 1
            self._output(conn, format_error(
                "full", f"{self.max_clients} clients already: this reserved slot serves "
                "AUTH and stop only; closing"))
            self._close_after_flush(conn)
            return
        if verb == "TABLE":  # a read of the loop: in the worker, in order, for anyone
            self._enqueue(conn, line)
            return
        if _server_verb(verb, rest):
            if conn.pending == 0 and not (verb == "AUTH" and self._held_by_a_closing(conn)):
                self._output(conn, self._verb(conn, verb, rest))
            else:  # in order behind its commands, or waiting for a release (worker)
                self._enqueue(conn, line)
            return
        if not verb:
            self._reply(conn, format_reply([]))
            return
        # Behind queued requests (an AUTH among them, perhaps) the worker decides.
        if conn.pending == 0 and verb != "HELP" and not (
            conn.privileged or self.robot.is_read_only(line)
        ):
            self._output(conn, self._refusal(line))
            return
        self._enqueue(conn, line)

    def _reply(self, conn: Connection, text: str) -> None:
        """A reply produced in the I/O thread, kept in order behind queued commands."""
        if conn.pending:
            self._enqueue(conn, text, ready=True)
        else:
            self._output(conn, text)

    def _enqueue(self, conn: Connection, line: str, ready: bool = False) -> None:
        with conn.lock:
            conn.requests.append((ready, line))
            conn.pending += 1
            if conn.pending >= self.max_pending:
                conn.paused = True  # stop reading: TCP pushes back on the client
            conn.cv.notify()
        if conn.paused:
            self._set_events(conn)
        if conn.worker is None:
            conn.worker = threading.Thread(
                target=self._work, args=(conn,), name=f"pyrt-server-{conn.id}", daemon=True
            )
            conn.worker.start()


    # -- the server's verbs (I/O thread, or a worker when queued behind commands) ----

    def _verb(self, conn: Connection, verb: str, rest: str) -> str:
        if verb == "STATUS":
            self.counters["status"] += 1
            t_ns, _tick, values = self.hub.snapshot
            if values is None:
                return format_error("timeout", "no status yet: the control loop has not run")
            return format_reply([f"t={t_ns / 1e9:.6f} {self.robot.format_status(values)}"])
        if verb == "FIELDS":
            if rest:
                return format_error("syntax", "FIELDS takes no argument")
            # one line per STATUS field: its name and units ('-' for none)
            return format_reply([f"{name} {getattr(sig, 'units', '') or '-'}"
                                 for name, sig, _fmt in self.robot.fields])
        if verb == "AUTH":
            return self._auth(conn, rest)
        if verb == "SUBSCRIBE":
            hz = float(rest) if _RATE.fullmatch(rest) else math.nan
            if not MIN_SPEW_HZ <= hz <= self.max_hz:  # NaN fails too
                return format_error(
                    "syntax", f"SUBSCRIBE needs a rate {MIN_SPEW_HZ:g} <= hz <= "
                    f"{self.max_hz:g}, got {rest[:40]!r}")
            with self._lock:
                if conn.closed:
                    return format_reply([])
                others = sum(c.subscribed for c in list(self._conns.values()) if c is not conn)
                if others + hz > self.max_subscription_rate:
                    return format_error(
                        "limit", f"subscriptions would total {others + hz:g} samples/s; "
                        f"the server serves at most {self.max_subscription_rate:g}")
                self.hub.subscribe(conn.id, hz)
                conn.subscribed = hz
            return format_reply(
                [f"subscribed at {hz:g} Hz: t {' '.join(self.robot.status_names)}"])
        if verb == "UNSUBSCRIBE":
            if rest:
                return format_error("syntax", "UNSUBSCRIBE takes no argument")
            with self._lock:
                had = self.hub.unsubscribe(conn.id)
                conn.subscribed = 0.0
            return format_reply(["unsubscribed" if had else "not subscribed"])
        if verb == "QUIT":
            self._close_after_flush(conn)
            return format_reply(["bye"])
        return format_error("internal", f"no verb {verb!r}")  # pragma: no cover

    def _held_by_a_closing(self, conn: Connection) -> bool:
        """The privilege is held by another connection that is closing (its
        session not yet released): an AUTH of ``conn`` waits for it in ``conn``'s worker."""
        holder = self._privileged
        return holder is not None and holder is not conn and (holder.closing or holder.closed)

    def _audit_failed_auth(self, conn: Connection) -> float:
        """A wrong token: an audit line of the station (console and audit log)
        while the guard's budget allows, else counted for its summary; the
        back-off now in force for the client's address, seconds."""
        host, port = conn.peer[:2]
        return self.guard.failed(conn.addr, f"DAQ client {conn.id} {host}:{port}",
                                 f"failed AUTH ({conn.auth_failures} of {MAX_AUTH_FAILURES})",
                                 "failed AUTH")

    def _auth(self, conn: Connection, given: str) -> str:
        holder = self._privileged
        if (holder is not None and holder is not conn and (holder.closing or holder.closed)
                and threading.current_thread() is not self._thread):
            # A privileged client that has gone: its worker releases the
            # session (leaves the monitor ...) and then the privilege.  Wait
            # for that, so that "disconnect, reconnect, AUTH" never sees busy.
            holder.released.wait(self.command_timeout_s)
        with self._lock:
            if conn.privileged:
                return format_reply(["already privileged"])
            if self._token is None:
                self.counters["auth_failed"] += 1
                return format_error("auth", "no token is configured: this server only reports")
            wait_s = self.guard.blocked(conn.addr, "AUTH")
            if wait_s > 0:  # backing off: the token is not even looked at
                self.counters["auth_backoff"] += 1
                self._close_after_flush(conn)
                return format_error("auth", f"too many failed AUTH from {conn.addr}: try again "
                                    f"in {math.ceil(wait_s):.0f} s; closing")
            if not given or not hmac.compare_digest(given.encode("utf-8"), self._token):
                self.counters["auth_failed"] += 1
                conn.auth_failures += 1
                wait_s = self._audit_failed_auth(conn)
                if wait_s > 0 or conn.auth_failures >= MAX_AUTH_FAILURES:
                    self._close_after_flush(conn)
                    more = (f" ({conn.addr} may AUTH again in {math.ceil(wait_s):.0f} s)"
                            if wait_s > 0 else "")
                    return format_error("auth", f"wrong token; too many failures, closing{more}")
                return format_error("auth", "wrong token")
            holder = self._privileged
            if holder is not None and holder is not conn:
                return format_error("busy", "another client is privileged (one at a time)")
            lease = self._lease_text()
            if lease:
                return format_error("busy", lease)
            self._privileged = conn
            conn.privileged = True
        log.info("%r is privileged", conn)
        return format_reply(["privileged: every console command is accepted"])

    # -- the other master: commands over EPICS ----------------------------------------

    def claim_privilege(self, who: str) -> str | None:
        """Take the one privilege for ``who`` (``EPICS CMD``: a master without a
        connection of its own) while its command runs; None when taken, else
        why not (a DAQ client, or another such master, holds it)."""
        with self._lock:
            holder = self._privileged
            if holder is not None:
                host, port = holder.peer[:2]
                return (f"DAQ client {holder.id} {host}:{port} is privileged "
                        "(one master at a time); nothing was run")
            if self._lease_who not in (None, who):
                busy = self._lease_text()
                if busy:
                    return busy + "; nothing was run"
            self._lease_who = who
            self._lease_until = math.inf
        return None

    def renew_privilege(self, who: str, lease_s: float) -> None:
        """``who``'s command has ended: it keeps the privilege ``lease_s`` more
        seconds (a master's commands come one after another), then it is free."""
        with self._lock:
            if self._lease_who == who:
                self._lease_until = time.monotonic() + lease_s

    def _lease_text(self) -> str:
        """Why the privilege is not free because of a lease ('' when it is; lock held)."""
        who = self._lease_who
        if who is None:
            return ""
        left = self._lease_until - time.monotonic()
        if left <= 0:
            self._lease_who = None
            return ""
        if math.isinf(left):
            return f"{who} holds the privilege: one of its commands runs (one master at a time)"
        return (f"{who} holds the privilege {math.ceil(left):.0f} s more after its last "
                "command (one master at a time)")

    # -- the worker thread of a connection -------------------------------------------

    def _work(self, conn: Connection) -> None:
        lower_priority(self.nice)
        try:
            self._work_on(conn)
        except Exception as exc:  # a bug outside a command: this client only
            self._client_failed(conn, exc)
        self._release(conn)

    def _work_on(self, conn: Connection) -> None:
        """Run ``conn``'s queued requests in order until it closes (its worker)."""
        while True:
            with conn.lock:
                while not conn.requests and not conn.closed:
                    conn.cv.wait()
                if conn.closed:
                    break
                ready, line = conn.requests.popleft()
            self._stand_aside()
            if ready:
                reply = line
            else:
                try:
                    reply = self._execute(conn, line)
                except Exception as exc:  # a bug must not end the service
                    log.exception("%r: %s failed", conn, line[:60])
                    reply = format_error("internal", f"{type(exc).__name__}: {exc}")
            self._output(conn, reply)
            with conn.lock:
                conn.pending -= 1
            if conn.paused or conn.closing:  # the I/O thread resumes reading, or closes
                self._touch(conn)

    def _release(self, conn: Connection) -> None:
        if conn.privileged and conn.shell is not None and conn.shell_privileged:
            try:
                self.robot.release(conn.shell)
            except Exception:
                log.exception("%r: release failed", conn)
        with self._lock:
            if self._privileged is conn:
                self._privileged = None
        conn.released.set()

    def _execute(self, conn: Connection, line: str) -> str:
        verb, rest = split_verb(line)
        if _server_verb(verb, rest):
            return self._verb(conn, verb, rest)
        if verb == "TABLE":
            return self._table(conn, rest)
        if verb != "HELP" and not (conn.privileged or self.robot.is_read_only(line)):
            return self._refusal(line)
        extra = self._help_lines(conn) if verb == "HELP" and not rest else []
        reply, end = run_shell(self._shell(conn), line, extra)
        if end:
            self._close_after_flush(conn)
        return reply

    def _table(self, conn: Connection, prefix: str) -> str:
        """``TABLE [PREFIX]``: the rows the console's ``show PREFIX`` lists, as
        data (one JSON object a row, then one for the table); a read, served
        to every client that may read (an unprivileged one through the
        observer: the operator's fault stays pending)."""
        if len(prefix.split()) > 1:
            return format_error("syntax", "TABLE takes at most one PREFIX (the rows whose "
                                f"OBJECT.NAME starts with it), got {prefix[:60]!r}")
        runner = self.runner if conn.privileged else self.observer
        try:
            return format_reply(self.robot.table(runner, prefix))
        except MailboxTimeout as exc:
            return format_error("timeout", f"the control loop did not answer: {exc}")
        except PyrtError as exc:
            return format_error("command", str(exc))

    def _refusal(self, line: str) -> str:
        """An unprivileged client's line that is not served: ``ERR command``
        when it names no command (as the console would say), else ``ERR denied``."""
        why = self.robot.unknown(line)
        if why:
            return format_error("command", why)
        self.counters["denied"] += 1
        return _denied(line)

    def _shell(self, conn: Connection) -> Any:
        if conn.shell is None or conn.shell_privileged != conn.privileged:
            runner = self.runner if conn.privileged else self.observer
            host, port = conn.peer[:2]
            conn.shell = self.robot.make_shell(runner, io.StringIO(),
                                               source=f"DAQ client {conn.id} {host}:{port}")
            conn.shell_privileged = conn.privileged
        return conn.shell

    def _help_lines(self, conn: Connection) -> list[str]:
        lines = [
            "server (any case): AUTH TOKEN | STATUS | FIELDS | TABLE [PREFIX] | SUBSCRIBE HZ | "
            "UNSUBSCRIBE | QUIT",
        ]
        if not conn.privileged:
            lines.append("read-only until AUTH: commands that change the robot get ERR denied; "
                         "stop is served to every client")
        return lines
