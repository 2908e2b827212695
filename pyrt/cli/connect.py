"""``pyrt connect [HOST:]PORT``: an interactive console on a robot served with ``--serve``.

Every line is sent to the server as a console command and its reply
printed (``ERR`` replies as ``error: ...``).  Local words: ``auth`` asks
for the token without echoing it, on a terminal only (piped, it is
refused: give ``--token-file`` or ``$PYRT_TOKEN``, read at start; a token
typed on a line is refused everywhere, as it would be shown); ``exit`` or
end of input leaves (the robot keeps running: leaving a monitoring session
stops nothing; type ``stop`` for that, which any client may).

Ctrl-C does what it does at a local console: a command that runs (a
``wait``) is abandoned and the robot stopped (``stop`` over a second
connection), and a move is stopped at the prompt; the abandoned reply is
dropped when it comes, so every reply answers its own line.  Piped, Ctrl-C
stops the robot and ends the script (status 130).

Piped, the lines are a script that fails loudly (docs/scripts.md): the
first line the robot refuses (an ``ERR`` reply) is named on stderr with its
number, the script stops there and the exit status is 1; ``-k`` runs on and
exits 1 at the end.

On a terminal there is history, Tab completion from the server's own
``help`` (its words, objects and their commands), and a live status line
from a second connection subscribed at ``--hz``; piped, it runs the lines
as a script and prints no status line.
"""

from __future__ import annotations

import argparse
import getpass
import sys
import threading
from typing import Any, TextIO

from pyrt.cli._serve import read_token
from pyrt.client import Client, ServerError, parse_address
from pyrt.console import Console
from pyrt.errors import UsageError

__all__ = ["RemoteShell", "add_parser", "run"]

#: How long Ctrl-C's ``stop`` (over a second connection) may take, seconds.
STOP_TIMEOUT_S = 5.0
#: How long a line waits, silently, for the reply of an interrupted request
#: before saying that the server is still serving it, seconds.
SETTLE_GLANCE_S = 0.2


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "connect",
        help="an interactive console on a served robot (pyrt NAME --serve)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("address", metavar="[HOST:]PORT", help="the server (default host 127.0.0.1)")
    p.add_argument("--token-file", metavar="FILE",
                   help="AUTH with the token in FILE at start (default: $PYRT_TOKEN if set)")
    p.add_argument("--hz", type=float, default=4.0, metavar="HZ",
                   help="status line refresh on a terminal (default 4; 0: no status line)")
    p.add_argument("--timeout", type=float, default=600.0, metavar="S",
                   help="seconds to wait for a reply (default 600: a 'wait' may be long)")
    p.add_argument("-k", "--keep-going", action="store_true",
                   help="a piped script runs on after a refused line (and exits 1 at the end); "
                        "without it the script stops at the first (docs/scripts.md)")
    p.set_defaults(run=run)


class RemoteShell:
    """The console interpreter of a connection: lines go to the server."""

    def __init__(self, client: Client, stdout: TextIO, name: str,
                 stdin: TextIO | None = None):
        self.client = client
        self.stdout = stdout
        #: Where ``auth`` would ask for the token (it asks only on a terminal).
        self.stdin = stdin if stdin is not None else sys.stdin
        self.prompt = f"{name}> "
        self._table: dict[str, Any] | None = None
        #: How many lines failed (refused, an ERR reply, the connection lost):
        #: a script's console reads it (docs/scripts.md).
        self.failures = 0

    def say(self, text: str) -> None:
        self.stdout.write(text + "\n")

    def error(self, text: str) -> None:
        """One ``error:`` line; the line failed."""
        self.failures += 1
        self.say(f"error: {text}")

    def onecmd(self, line: str) -> bool:
        """Send one line; True when the session ends (``exit``, ``QUIT``, server gone)."""
        text = line.strip()
        if not text:
            return False
        word = text.split()[0].lower()
        if word in ("exit", "quit") and len(text.split()) == 1:
            return True  # leaving a remote session stops nothing
        if word == "auth":
            if len(text.split()) > 1:
                self.error("a token typed on a line is shown (on the screen, in a "
                           "script's transcript); nothing sent: type 'auth' alone at a terminal, "
                           "or start with --token-file FILE or $PYRT_TOKEN")
                return False
            if not self.terminal():
                self.error("auth asks for the token on a terminal, and this input is "
                           "not one (the next line is not taken as the token); start with "
                           "--token-file FILE or $PYRT_TOKEN")
                return False
            return self.authenticate(getpass.getpass("token: "))
        return self._send(text)

    @staticmethod
    def redact(line: str) -> str:
        """``line`` as a script's failure names it: a token after ``auth`` left out."""
        words = line.split()
        return "auth ..." if len(words) > 1 and words[0].lower() == "auth" else line

    def terminal(self) -> bool:
        """True when the token can be asked for without echo (stdin is a terminal)."""
        try:
            return bool(self.stdin.isatty())
        except (AttributeError, ValueError):
            return False

    def authenticate(self, token: str) -> bool:
        """Send ``AUTH token`` (the line is never shown); True when the session ends."""
        return self._send(f"AUTH {token}", auth=True)

    def _send(self, text: str, auth: bool = False) -> bool:
        try:
            if self.client.owed:  # an interrupted request the server still serves
                try:
                    self.client.settle(SETTLE_GLANCE_S)
                except TimeoutError:
                    self.say(f"(the server first finishes the interrupted "
                             f"{self.client.owed[0][:40]!r}; its reply will be dropped)")
            reply = self.client.request(text)
        except (OSError, TimeoutError, ServerError) as exc:
            self.error(f"the connection failed: {exc}")
            return True
        for out in reply.lines:
            self.say(out)
        if not reply.ok:
            self.error(f"{reply.code} {reply.text}".rstrip())
        elif auth and not reply.lines:
            self.say("privileged: every command is accepted")  # the server said nothing
        return False

    def interrupt(self, at_prompt: bool) -> str:
        """Ctrl-C (the console calls it), as at a local console: a command that
        runs (a ``wait``, say) is abandoned and every motor stopped; at the
        prompt, a move that runs is stopped, and nothing else is done.

        The ``stop`` goes over a second connection (any client may stop the
        robot; this one's requests are served in order, behind the abandoned
        one).  The abandoned reply comes later; the client reads and drops it
        before the next request (:meth:`Client.settle`), so every reply shown
        answers the line just typed."""
        abandoned = list(self.client.owed)
        if at_prompt and not abandoned:
            moving = self._moving()
            if moving is not True:
                return ("(Ctrl-C stops a move; nothing is moving: 'exit' or Ctrl-D leaves, "
                        "the robot keeps running)" if moving is False else
                        "(Ctrl-C stops a move; the robot's status does not say whether it "
                        "moves: type stop to stop it)")
        said = self._stop()
        if abandoned:
            said += f"\n(the reply to {abandoned[-1][:40]!r} is dropped when it comes)"
        return said

    def _second(self) -> Client:
        host, port = self.client.address
        return Client(host, port, timeout_s=STOP_TIMEOUT_S)

    def _moving(self) -> bool | None:
        """Whether the robot moves, from its STATUS (None: not known)."""
        try:
            with self._second() as c:
                fields = c.status().fields
        except (OSError, TimeoutError, ServerError):
            return None
        flags = [fields[k] for k in ("moving", "busy") if k in fields]
        return any(bool(v) for v in flags) if flags else None

    def _stop(self) -> str:
        """``stop`` over a second connection; what the robot said, or why not."""
        try:
            with self._second() as c:
                reply = c.request("stop")
        except (OSError, TimeoutError, ServerError) as exc:
            return f"interrupted; could not reach the robot to stop it: {exc}; type stop"
        if not reply.ok:
            return f"interrupted; stop was refused: {reply.code} {reply.text}".rstrip()
        return "interrupted: " + ("; ".join(reply.lines) or "stopped")

    def completions(self) -> dict[str, Any]:
        """The completion table, from the server's ``help`` and ``help OBJECT`` (once)."""
        if self._table is None:
            self._table = self._read_table()
        return self._table

    def _read_table(self) -> dict[str, Any]:
        table: dict[str, Any] = {"auth": None, "exit": None}
        try:
            lines = self.client.command("help")
        except (OSError, TimeoutError, ServerError):
            return table
        objects: list[str] = []
        section = ""
        for line in lines:
            if not line.startswith(" "):
                section = line.split()[0].rstrip(":") if line.split() else ""
                continue
            if section == "objects":
                objects.extend(line.split())
            elif section == "words":
                table[line.split()[0].rstrip(":")] = None
        for obj in objects:
            try:
                verbs = self.client.command(f"help {obj}")
            except (OSError, TimeoutError, ServerError):
                verbs = []
            table[obj] = {v: None for v in (_verb(obj, ln) for ln in verbs) if v} or None
        table["help"] = {name: None for name in table if name not in ("auth", "exit")}
        return table


def _verb(obj: str, line: str) -> str | None:
    """The command a line of ``help OBJECT`` describes (``  up DIST: ...`` is
    ``up``; ``  sim object MM: ...`` is ``object``), or None."""
    words = line.split()
    if not line.startswith("  ") or not words or words[0] == "signals:":
        return None
    if words[0].rstrip(":").lower() == obj.lower():  # the usage repeats the object
        if words[0].endswith(":") or len(words) < 2:
            return None  # the object alone (its show)
        return words[1].rstrip(":")
    return words[0].rstrip(":")


class _StatusWatch:
    """A second connection reading the robot's status line (``statusline``: the
    console's own line, in its radix: the gripper's counts in hex with mm) at
    ``hz``; the latest line for the toolbar."""

    def __init__(self, host: str, port: int, hz: float):
        self.line = "connecting ..."
        self._period_s = 1.0 / hz
        self._stop = threading.Event()
        self._client = Client(host, port, timeout_s=max(5.0, 3.0 / hz))
        self._thread = threading.Thread(target=self._read, name="pyrt-connect-status",
                                         daemon=True)
        self._thread.start()

    def _read(self) -> None:
        while not self._stop.is_set():
            try:
                lines = self._client.command("statusline")
            except (OSError, TimeoutError, ServerError) as exc:
                self.line = f"status: {exc}"
                return
            if lines:
                self.line = lines[-1]
            self._stop.wait(self._period_s)

    def close(self) -> None:
        self._stop.set()
        self._client.close()


def run(args: argparse.Namespace) -> int:
    try:
        host, port = parse_address(args.address)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    if args.hz < 0 or args.hz > 50:
        raise UsageError(f"--hz must be 0..50, got {args.hz:g}")
    token = read_token(args.token_file)
    try:
        client = Client(host, port, timeout_s=args.timeout)
    except (OSError, TimeoutError, ServerError) as exc:
        print(f"pyrt connect: {host}:{port}: {exc}", file=sys.stderr)
        return 1
    watch: _StatusWatch | None = None
    try:
        words = client.greeting.split()  # "pyrt 0.1.0 NAME server; ..."
        name = words[2] if len(words) > 2 and words[0] == "pyrt" else f"{host}:{port}"
        shell = RemoteShell(client, sys.stdout, name)
        print(f"connected to {host}:{port}: {client.greeting}; 'exit' leaves "
              "(the robot keeps running), 'stop' stops it", flush=True)
        if token is not None:
            shell.authenticate(token)
        console = Console(shell, keep_going=args.keep_going, what="pyrt connect")
        if console.interactive() and args.hz > 0:
            try:
                watch = _StatusWatch(host, port, args.hz)
                console.status = lambda: watch.line if watch is not None else ""
                console.status_period_s = min(1.0, 1.0 / args.hz)
            except (OSError, TimeoutError, ServerError) as exc:
                print(f"(no status line: {exc})", flush=True)
        try:
            return console.run()
        except KeyboardInterrupt:  # a piped script: Ctrl-C ends it, the robot stopped
            print(f"pyrt connect: {shell.interrupt(False)}", flush=True)
            return 130
    finally:
        if watch is not None:
            watch.close()
        client.close()
