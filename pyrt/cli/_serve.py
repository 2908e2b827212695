"""``--serve``, ``--token-file``, ``--headless``, ``--epics``: the DAQ link of a robot command.

Shared by every station (``pyrt NAME``, ``pyrt run``)::

    service = prepare_service(args, runner, robot)   # before runner.start()
    runner.start()
    service.start(say)
    status = service.run_headless() if args.headless else console.run()
    service.close()

The token is read from ``--token-file`` (its first line; the file must be
its owner's only, mode 600) or the ``PYRT_TOKEN`` environment variable,
and is at least 16 characters.  Without a token nobody is privileged
(the server only reports), and serving on anything but a loopback address
(``--serve``, ``--epics-interface``) is refused.  A service whose server
thread dies trips the station (every motor stopped) and, headless, exits 1.
``--headless`` runs without a console: a service that logs to stderr and,
on SIGTERM, SIGHUP or SIGINT, stops every motor and exits 0.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import sys
import threading
import time
from collections.abc import Callable
from typing import Any

from pyrt.client import parse_address
from pyrt.errors import ConfigError, PyrtError, UsageError
from pyrt.server import ServedRobot, Server
from pyrt.server.guard import MAX_TOKEN, check_token
from pyrt.station.moves import MessageLine

__all__ = ["Service", "add_serve_options", "prepare_service", "read_token"]

log = logging.getLogger("pyrt.service")

#: Longest wait, at start, for the loop's first status snapshot (the loop runs already).
FIRST_STATUS_S = 5.0



def add_serve_options(parser: argparse.ArgumentParser) -> None:
    """Add the DAQ link options to a robot command's parser."""
    g = parser.add_argument_group("DAQ link")
    g.add_argument("--serve", metavar="[HOST:]PORT",
                   help="serve the line protocol on HOST:PORT (default host 127.0.0.1)")
    g.add_argument("--token-file", metavar="FILE",
                   help="privilege token (first line of FILE; default: $PYRT_TOKEN)")
    g.add_argument("--headless", action="store_true",
                   help="no console: a service logging to stderr; SIGTERM/SIGHUP/SIGINT stop "
                        "every motor and exit 0 (a second within 2 s: at once)")
    g.add_argument("--epics", metavar="PREFIX",
                   help="also serve the robot over EPICS Channel Access with this PV prefix: "
                        "status, every signal, STATE, STOP (anyone); CMD and ACK with the "
                        "token (needs pyrt[epics])")
    g.add_argument("--epics-interface", metavar="ADDR", action="append",
                   help="serve EPICS on this interface address (repeat for more; default "
                        "127.0.0.1, or $EPICS_CAS_INTF_ADDR_LIST); beyond loopback a token "
                        "is required, and it crosses the network in clear (docs/daq.md)")
    g.add_argument("--verbose", action="store_true",
                   help="log caproto's INFO lines too (one per Channel Access client connect); "
                        "default: its warnings only")


def read_token(token_file: str | None) -> str | None:
    """The token from ``token_file`` (first line) or ``$PYRT_TOKEN``; None if neither.

    Refused with the reason (:class:`~pyrt.errors.ConfigError`): a token
    shorter than :data:`~pyrt.server.guard.MIN_TOKEN` characters, and a token
    file that anybody but its owner may read or write (as ssh refuses such a key).
    """
    if token_file:
        try:
            with open(token_file, encoding="utf-8") as f:
                mode = os.fstat(f.fileno()).st_mode
                if mode & 0o077:
                    raise ConfigError(
                        f"the token file may be read or written by others (mode "
                        f"{mode & 0o777:04o}); make it its owner's only: chmod 600 {token_file}",
                        token_file)
                token = f.readline(MAX_TOKEN + 2).strip()
        except OSError as exc:
            raise ConfigError(f"cannot read the token: {exc.strerror}", token_file) from None
        except UnicodeDecodeError:
            raise ConfigError("the token file is not UTF-8 text", token_file) from None
        if not token:
            raise ConfigError("the token file's first line is empty", token_file)
    else:
        token = os.environ.get("PYRT_TOKEN", "").strip()
        if not token:
            return None
    try:
        return check_token(token)
    except ConfigError as exc:
        where = token_file if token_file else "$PYRT_TOKEN"
        raise ConfigError(exc.message, where) from None


class Service:
    """The server (and the EPICS IOC) of one robot, and the headless wait."""

    def __init__(
        self, runner: Any, robot: ServedRobot, server: Server, epics: Any = None,
        serve: bool = True,
    ):
        self.serve = serve
        self.runner = runner
        self.robot = robot
        self.server = server
        self.epics = epics
        self._stop = threading.Event()

    def start(self, say: Callable[[str], None] | None = None) -> None:
        """Start listening; log where (and ``say`` it, for a console)."""

        def tell(text: str) -> None:
            log.info("%s", text)
            if say is not None:
                say(text)

        if self.serve:
            host, port = self.server.start()
            # "serving" means STATUS is answered: wait (bounded) for the loop's first snapshot
            deadline = time.monotonic() + FIRST_STATUS_S
            while (self.server.hub.snapshot[2] is None and self.runner.crashed is None
                   and time.monotonic() < deadline):
                time.sleep(0.005)
            who = ("AUTH with the token to command" if self.server.has_token
                   else "no token: status only")
            tell(f"serving {self.robot.name} on {host}:{port} ({who})")
        if self.epics is not None:
            self.epics.start()
            tell(f"EPICS Channel Access: PVs {self.epics.prefix}* ({self.epics.summary})")

    def run_headless(self) -> int:
        """Serve until :meth:`stop` is called or the caller's signal handler
        raises (SIGTERM, SIGHUP, SIGINT: :func:`pyrt.cli._shutdown.run_until_shutdown`
        closes the station); 1 if the control loop stops by itself, else 0."""
        while not self._stop.wait(0.2):
            for line in self.runner.messages():  # the loop's messages: to the log
                if not isinstance(line, MessageLine):  # (a message is in it already)
                    log.info("%s", line)
            if self.runner.crashed is not None:
                log.error("the control loop has stopped: %r", self.runner.crashed)
                return 1
            dead = self._dead_door()
            if dead:  # nothing can reach the station: stop, and say so by the exit status
                log.error("%s; every motor stopped, exiting", dead)
                self.stop_motors()
                return 1
        self.stop_motors()
        return 0

    def _dead_door(self) -> str:
        """Why a door this service opened has stopped serving ('' if none has)."""
        if self.serve and self.server.crashed is not None:
            return f"the DAQ server has stopped ({self.server.crashed!r})"
        epics = self.epics
        if epics is not None and getattr(epics, "error", None) is not None:
            return f"the EPICS server has stopped ({epics.error!r})"
        return ""

    def stop(self) -> None:
        """End :meth:`run_headless` (from another thread)."""
        self._stop.set()

    def stop_motors(self) -> None:
        """Stop every motor through the mailbox (a pending fault does not prevent it)."""
        for _ in range(4):
            try:
                self.runner.call(self.robot.stop_all, name="stop every motor", take_fault=False)
                log.info("every motor stopped")
                return
            except PyrtError as exc:
                log.warning("stopping the motors: %s", exc)

    def close(self) -> None:
        """Stop the IOC and the server."""
        if self.epics is not None:
            with contextlib.suppress(Exception):
                self.epics.close()
        self.server.close()


def prepare_service(args: argparse.Namespace, runner: Any, robot: ServedRobot) -> Service | None:
    """The service the options ask for (None without ``--serve``/``--epics``);
    call it before ``runner.start()``: it attaches its handler to the loop."""
    if args.headless and not (args.serve or args.epics):
        raise UsageError("--headless needs --serve [HOST:]PORT or --epics PREFIX")
    if not (args.serve or args.epics):
        if args.token_file:
            raise UsageError("--token-file needs --serve or --epics")
        return None
    if getattr(args, "epics_interface", None) and not args.epics:
        raise UsageError("--epics-interface needs --epics PREFIX")
    if args.headless:
        logging.basicConfig(stream=sys.stderr, level=logging.INFO,
                            format="%(asctime)s %(name)s: %(message)s")
    token = read_token(args.token_file)
    host, port = "127.0.0.1", 0
    if args.serve:
        try:
            host, port = parse_address(args.serve, allow_zero=True)
        except ValueError as exc:
            raise UsageError(f"--serve: {exc}") from None
    server = Server(runner, robot, host, port, token=token)
    if args.serve:
        server.bind()  # a port that cannot be had fails here, before any banner
    epics = None
    if args.epics:
        from pyrt.server.epics import EpicsService

        epics = EpicsService(runner, robot, server, args.epics, token=token,
                             interfaces=getattr(args, "epics_interface", None),
                             verbose=bool(getattr(args, "verbose", False)))
    return Service(runner, robot, server, epics, serve=bool(args.serve))
