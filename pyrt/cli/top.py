"""``pyrt top [HOST:]PORT``: a refreshing one-screen status view of a served robot.

Connects to a robot served with ``--serve`` (no token needed: it only
reads) and shows, every ``1/--hz`` seconds, the robot's status fields (the
``STATUS`` line: position, target, tensions, state, fault ..., each with
its units as the server's ``FIELDS`` names them) and the loop's timing
(``stats``: ticks, overruns, lateness, per-task times).

On a terminal the screen is redrawn in place; Ctrl-C leaves (the robot
keeps running: watching stops nothing).  When stdout is not a terminal,
each refresh is printed as a block of plain lines (none of them empty)
followed by an empty line; ``--once`` prints one block and exits,
``--count N`` stops after N.  If the server goes away, the last line says
so and the exit status is 1.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import time
from typing import TextIO

from pyrt.client import Client, ServerError, parse_address
from pyrt.errors import UsageError

__all__ = ["add_parser", "render", "run"]

#: Clear the screen and home the cursor; hide and show the cursor.
_HOME_CLEAR = "\x1b[H\x1b[2J"
_HIDE, _SHOW = "\x1b[?25l", "\x1b[?25h"


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "top",
        help="a refreshing one-screen status view of a served robot (read only)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("address", metavar="[HOST:]PORT", help="the server (default host 127.0.0.1)")
    p.add_argument("--hz", type=float, default=2.0, metavar="HZ",
                   help="refreshes per second (default 2; 0.5..20)")
    p.add_argument("--once", action="store_true", help="print one snapshot and exit")
    p.add_argument("--count", type=int, metavar="N", help="stop after N snapshots")
    p.add_argument("--no-stats", action="store_true",
                   help="leave out the loop's timing (status fields only)")
    p.add_argument("--timeout", type=float, default=10.0, metavar="S",
                   help="seconds to wait for a reply before giving up (default 10)")
    p.set_defaults(run=run)


def _fields(raw: str) -> tuple[str, list[tuple[str, str]]]:
    """The time and the ``key=value`` fields of a ``STATUS`` line, values as
    the server wrote them (hex stays hex)."""
    t = ""
    fields: list[tuple[str, str]] = []
    for item in raw.split():
        key, sep, value = item.partition("=")
        if not sep:
            continue
        if key == "t":
            t = value
        else:
            fields.append((key, value))
    return t, fields


def render(title: str, status_line: str, stats: list[str] | None,
           spaced: bool = False, shown: str = "",
           units: dict[str, str] | None = None) -> list[str]:
    """One snapshot as lines: a title, the time, the robot's status line as its
    console shows it (``shown``, if given), the status fields in two
    columns (each value with its ``units``, where known), then the loop's
    timing table (``stats``) if given.  ``spaced``
    (the screen): an empty line between the parts; without it the snapshot
    has none, so that piped snapshots are told apart by the empty line
    between them."""
    gap = [""] if spaced else []
    t, fields = _fields(status_line)
    try:
        when = f"t = {float(t):.3f} s (loop time)"
    except ValueError:
        when = "t = ?"
    lines = [title, when, *([shown] if shown else []), *gap]
    width = max((len(k) for k, _ in fields), default=0)
    units = units or {}
    lines += [f"  {k:<{width}}  {v}" + (f" {units[k]}" if units.get(k) else "")
              for k, v in fields] or ["  (no status fields)"]
    if stats is not None:
        lines += gap + stats
    return lines


class _Source:
    """One connection to the server; a snapshot per call."""

    def __init__(self, host: str, port: int, timeout_s: float, with_stats: bool):
        self.client = Client(host, port, timeout_s=timeout_s)
        self.with_stats = with_stats
        words = self.client.greeting.split()  # "pyrt 0.1.0 NAME server; ..."
        robot = words[2] if len(words) > 2 and words[0] == "pyrt" else "robot"
        self.title = f"pyrt top: {robot} at {host}:{port}"
        #: Each STATUS field's units (none known from a server without FIELDS).
        self.units: dict[str, str] = {}
        try:
            for line in self.client.command("FIELDS"):
                name, _, unit = line.partition(" ")
                if unit and unit != "-":
                    self.units[name] = unit
        except ServerError:
            pass

    def snapshot(self, spaced: bool) -> list[str]:
        status = self.client.command("STATUS")
        try:
            shown = self.client.command("statusline")
        except ServerError:  # a server without it: the fields alone
            shown = []
        stats = None
        if self.with_stats:
            try:
                stats = self.client.command("stats")
            except ServerError as exc:  # a server without it: say so, keep the status
                stats = [f"(no timing: {exc})"]
        return render(self.title, status[-1] if status else "", stats, spaced,
                      shown[-1] if shown else "", self.units)

    def close(self) -> None:
        self.client.close()


def _draw(out: TextIO, lines: list[str]) -> None:
    """Redraw the screen in place, every line cut to the terminal's size."""
    cols, rows = shutil.get_terminal_size((80, 24))
    shown = [ln[:cols] for ln in lines[: max(1, rows - 1)]]
    out.write(_HOME_CLEAR + "\n".join(shown) + "\n")
    out.flush()


def run(args: argparse.Namespace) -> int:
    try:
        host, port = parse_address(args.address)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    if not 0.5 <= args.hz <= 20:
        raise UsageError(f"--hz must be 0.5..20, got {args.hz:g}")
    if args.count is not None and args.count < 1:
        raise UsageError(f"--count must be >= 1, got {args.count}")
    count = 1 if args.once else args.count
    out = sys.stdout
    try:
        source = _Source(host, port, args.timeout, not args.no_stats)
    except (OSError, TimeoutError, ServerError) as exc:
        print(f"pyrt top: {host}:{port}: {exc}", file=sys.stderr)
        return 1
    screen = out.isatty() and not args.once
    period = 1.0 / args.hz
    shown = 0
    if screen:
        out.write(_HIDE)
    try:
        next_at = time.monotonic()
        while count is None or shown < count:
            lines = source.snapshot(spaced=screen)
            if screen:
                _draw(out, [*lines, "", f"every {period:g} s; Ctrl-C leaves (the robot runs on)"])
            else:
                out.write("\n".join(lines) + "\n\n")
                out.flush()
            shown += 1
            if count is not None and shown >= count:
                break
            next_at += period
            time.sleep(max(0.0, next_at - time.monotonic()))
        return 0
    except KeyboardInterrupt:
        return 0
    except (OSError, TimeoutError, ServerError) as exc:
        if screen:
            out.write("\n")
        print(f"pyrt top: {host}:{port}: {exc}", file=sys.stderr)
        return 1
    finally:
        if screen:
            out.write(_SHOW)
            out.flush()
        source.close()
