"""``pyrt send HOST:PORT COMMAND...``: one command to a pyrt server, from the shell.

The words after the address are sent as one request line; the reply's lines
are printed (without the ``OK`` framing).  An ``ERR`` reply is printed on
stderr and the exit status is 1.  With a token (``--token-file F`` or the
``PYRT_TOKEN`` environment variable) the command is sent after ``AUTH``.
``SUBSCRIBE HZ`` prints ``STATUS`` lines until ``--count`` of them have
come, the server closes, or Ctrl-C.

``-f FILE`` (``-f -``: stdin) sends FILE's lines instead, one request
each, in order, over one connection: a script.  It fails loudly
(docs/scripts.md): the first line the server refuses (``ERR``) is named
on stderr (file, line number, text, the reply) and the script stops
there, status 1; ``-k`` runs on and exits 1 at the end.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
from collections.abc import Iterator
from typing import TextIO

from pyrt.cli._serve import read_token
from pyrt.client import Client, ServerError, parse_address
from pyrt.errors import UsageError

__all__ = ["add_parser", "run"]


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "send",
        help="send one command to a pyrt server (pyrt NAME --serve)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("address", metavar="[HOST:]PORT", help="the server (default host 127.0.0.1)")
    p.add_argument("words", nargs="*", metavar="COMMAND", help="the command line to send")
    p.add_argument("-f", "--file", metavar="FILE",
                   help="send FILE's lines as a script ('-': stdin), one request each")
    p.add_argument("-k", "--keep-going", action="store_true",
                   help="with -f: run on after a refused line (and exit 1 at the end); "
                        "without it the script stops at the first (docs/scripts.md)")
    p.add_argument("--token-file", metavar="FILE",
                   help="AUTH with the token in FILE first (default: $PYRT_TOKEN if set)")
    p.add_argument("--count", type=int, metavar="N",
                   help="SUBSCRIBE: stop after N STATUS lines")
    p.add_argument("--timeout", type=float, default=30.0, metavar="S",
                   help="seconds to wait for a reply (default 30)")
    p.set_defaults(run=run)


class _ReaderGone(Exception):
    """Whoever read our stdout has closed it (``| head``)."""


def _emit(text: str | None, out: TextIO, flush: bool = False) -> None:
    """Print ``text`` (None: only flush); :class:`_ReaderGone` if the reader has left."""
    try:
        if text is None:
            out.flush()
        else:
            print(text, file=out, flush=flush)
    except BrokenPipeError:
        raise _ReaderGone from None


def _script_lines(name: str) -> Iterator[tuple[int, str]]:
    """The numbered lines of a script (``-``: stdin), blank lines and ``#`` comments left out."""
    if name == "-":
        stream: TextIO = sys.stdin
        close = False
    else:
        try:
            stream = open(name, encoding="utf-8", errors="replace")  # noqa: SIM115
        except OSError as exc:
            raise UsageError(f"-f {name}: {exc.strerror}") from None
        close = True
    try:
        for number, raw in enumerate(stream, 1):
            text = raw.strip()
            if text and not text.startswith("#"):
                yield number, text
    finally:
        if close:
            stream.close()


def _run_script(client: Client, args: argparse.Namespace, out: TextIO) -> int:
    """Send the script's lines in order (see the module text); the exit status."""
    where = "stdin" if args.file == "-" else args.file
    failed: list[int] = []
    for number, text in _script_lines(args.file):
        try:
            lines = client.command(text)
        except ServerError as exc:
            for said in exc.lines:
                _emit(said, out)
            _emit(None, out)
            failed.append(number)
            stop = "" if args.keep_going else "; the script stops here (-k runs on)"
            shown = "AUTH ..." if text.split()[0].upper() == "AUTH" else text[:200]  # no token
            print(f"pyrt send: {where}:{number}: {shown!r} failed: {exc}{stop}",
                  file=sys.stderr, flush=True)
            if not args.keep_going:
                return 1
            continue
        for said in lines:
            _emit(said, out)
        _emit(None, out)
    if len(failed) > 1:
        print(f"pyrt send: {where}: {len(failed)} lines failed: "
              f"{', '.join(map(str, failed))}", file=sys.stderr)
    return 1 if failed else 0


def run(args: argparse.Namespace) -> int:
    try:
        host, port = parse_address(args.address)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    if bool(args.words) == bool(args.file):
        raise UsageError("give a COMMAND or -f FILE (one of them)")
    if args.keep_going and not args.file:
        raise UsageError("-k goes with -f FILE (a script)")
    if args.file and args.file != "-" and not os.path.isfile(args.file):
        raise UsageError(f"-f {args.file}: there is no such file")
    line = " ".join(args.words)
    token = read_token(args.token_file)
    out = sys.stdout
    try:
        with Client(host, port, timeout_s=args.timeout) as client:
            if token is not None:
                client.auth(token)
            if args.file:
                return _run_script(client, args, out)
            if line.split()[0].upper() == "SUBSCRIBE":
                client.command(line)
                for n, status in enumerate(client.statuses(args.timeout), 1):
                    _emit(status.raw, out, flush=True)
                    if args.count is not None and n >= args.count:
                        break
                return 0
            for text in client.command(line):
                _emit(text, out)
            _emit(None, out)
    except _ReaderGone:
        # `pyrt send ... SUBSCRIBE 10 | head -3`: the reader has what it wanted;
        # end quietly (and keep the interpreter's last flush from complaining)
        with contextlib.suppress(OSError):
            os.dup2(os.open(os.devnull, os.O_WRONLY), out.fileno())
        return 0
    except ServerError as exc:
        for text in exc.lines:
            print(text, file=out)
        print(f"pyrt send: {exc}", file=sys.stderr)
        return 1
    except (OSError, TimeoutError) as exc:
        print(f"pyrt send: {host}:{port}: {exc}", file=sys.stderr)
        return 1
    return 0
