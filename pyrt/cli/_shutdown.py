"""The consoles' one way out: SIGTERM, SIGHUP, end of input and ``quit`` all
end in the station's close (every motor stopped through the reflex,
databases written back), said in one line, exit status 0.

A first SIGTERM or SIGHUP (and, ``--headless``, SIGINT) ends the console or
the service (the signal handler raises :class:`Shutdown` in the main thread,
where the console reads); a second within :data:`SECOND_SIGNAL_S` exits at
once with status 0, after the reflex, even while the first is still closing.
While the station closes, a Ctrl-C is held the same way: a first one lets the
close finish, a second within the interval exits at once after the reflex.
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import sys
import time
from collections.abc import Callable, Iterator
from typing import Any

from pyrt.console import ReaderGone, silence

__all__ = ["SECOND_SIGNAL_S", "Shutdown", "run_until_shutdown", "shutdown_signals"]

#: A second SIGTERM within this many seconds exits at once (after the reflex).
SECOND_SIGNAL_S = 2.0

_SIGNALS = tuple(s for s in (getattr(signal, "SIGTERM", None), getattr(signal, "SIGHUP", None))
                 if s is not None)


class Shutdown(BaseException):
    """Raised in the main thread by SIGTERM or SIGHUP; carries the signal's name."""

    def __init__(self, why: str):
        super().__init__(why)
        self.why = why


class _Guard:
    """The shutdown signals' handler: the first signal raises :class:`Shutdown`
    (once, and only while :attr:`raising`); a second within
    :data:`SECOND_SIGNAL_S` of the first runs the reflex and exits at once."""

    def __init__(self, reflex: Callable[[], Any], say: Callable[[str], Any]):
        self.reflex = reflex
        self.say = say
        self.first_at: float | None = None
        self.raising = True

    def __call__(self, signum: int, frame: Any) -> None:
        name = signal.Signals(signum).name
        now = time.monotonic()
        if self.first_at is not None and now - self.first_at < SECOND_SIGNAL_S:
            with contextlib.suppress(BaseException):
                self.reflex()
            with contextlib.suppress(BaseException):
                self.say(f"{name} again: every motor stopped; exiting now")
            os._exit(0)
        self.first_at = now
        if self.raising:
            self.raising = False
            raise Shutdown(name)


@contextlib.contextmanager
def shutdown_signals(reflex: Callable[[], Any], say: Callable[[str], Any],
                     signals: tuple[int, ...] = _SIGNALS) -> Iterator[_Guard]:
    """Within the block, the first SIGTERM or SIGHUP raises :class:`Shutdown`
    (the console ends and the caller closes the station); a second one within
    :data:`SECOND_SIGNAL_S` runs ``reflex`` and exits the process at once.
    Set the guard's ``raising`` to False while closing: a first signal then
    lets the close finish, and a second within the interval still cuts it short."""
    guard = _Guard(reflex, say)
    old = {s: signal.signal(s, guard) for s in signals}
    try:
        yield guard
    finally:
        # After a shutdown signal the process is ending: a second one that comes
        # after the close (two sent together, the close quicker than their gap)
        # must not kill it before it exits with its status, so it is ignored.
        ended = guard.first_at is not None
        for s, handler in old.items():
            signal.signal(s, signal.SIG_IGN if ended and s != signal.SIGINT else handler)


def _stop_now(station: Any) -> None:
    """Every motor stopped: through the mailbox, or directly if the loop does not answer."""
    try:
        station.runner.call(station.stop, name="stop every motor", take_fault=False,
                            timeout_s=0.5)
    except BaseException:  # the loop is gone or stuck: the reflex, from here
        station.reflex("shutdown")


def run_until_shutdown(station: Any, console: Any, service: Any, *, headless: bool,
                       say: Callable[[str], Any], what: str,
                       first: Callable[[], Any] | None = None) -> int:
    """Run the console (or, ``headless``, the service alone) until it ends or
    SIGTERM/SIGHUP ends it; the service, if any, serves meanwhile; ``first``
    runs before the console reads (a station's start-up commands).  Then close
    the service and the station (every motor stopped, databases written
    back) and say so in one line.  The exit status is the console's or the
    service's, 0 after SIGTERM or SIGHUP, 130 after a Ctrl-C that no console
    caught (a piped script); when the reader of stdout has gone (``| head``)
    the run ends as at end of input, status 0, the closing line on stderr."""
    reason = ""
    status = 0
    gone = False
    # --headless has no console to type Ctrl-C at: SIGINT ends it like SIGTERM.
    signals = (*_SIGNALS, signal.SIGINT) if headless else _SIGNALS
    with shutdown_signals(lambda: _stop_now(station), say, signals) as guard:
        try:
            if service is not None:
                service.start(None if headless else say)
            if first is not None:
                first()
            status = service.run_headless() if headless else console.run()
        except Shutdown as exc:
            reason = exc.why
        except KeyboardInterrupt:
            # Ctrl-C where no console catches it (a piped script, the power-up
            # I): the run ends as at end of input, with the shell's status
            reason, status = "SIGINT", 130
        except ReaderGone:  # before the console read (the power-up I): as in the console
            reason, gone = "output closed", True
            silence(sys.stdout)
        finally:
            guard.raising = False  # from here on a first signal lets the close finish
            # A Ctrl-C while closing is held like a first SIGTERM: it must not cut the
            # close short half-way (the stop unsent, the loop left running); a second
            # signal within SECOND_SIGNAL_S still runs the reflex and exits at once.
            held = None if headless else signal.signal(signal.SIGINT, guard)
            try:
                if service is not None:
                    service.close()
            finally:
                try:
                    station.close()
                finally:
                    if held is not None:
                        signal.signal(signal.SIGINT, held)
        why = reason or ("stopped" if headless else console.ended_by)
        try:  # where the robot stopped (a piped run's SIGINT says it too), what close did
            note = station.closing_note()
        except Exception:
            note = ""
        line = f"{what}: {why}: every motor stopped{note}"
        if gone or getattr(console, "reader_gone", False):
            # the reader of stdout has gone: the closing line goes to stderr
            with contextlib.suppress(OSError, ValueError):
                print(line, file=sys.stderr, flush=True)
        else:
            say(line)
        if headless and not _same_file(sys.stdout, sys.stderr):
            # a service's record is its log (stderr): said there too, unless
            # stderr is where the line was just said (a terminal, 2>&1)
            logging.getLogger("pyrt.service").info("%s", line)
    return status


def _same_file(a: Any, b: Any) -> bool:
    """True when the streams ``a`` and ``b`` write to the same file (a terminal, a 2>&1)."""
    try:
        sa, sb = os.fstat(a.fileno()), os.fstat(b.fileno())
    except (OSError, ValueError, AttributeError):
        return False
    return (sa.st_dev, sa.st_ino) == (sb.st_dev, sb.st_ino)
