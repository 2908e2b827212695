"""The DAQ link's line protocol: limits, reply framing and error codes.

One request per line (ASCII or UTF-8, ``\\n`` or ``\\r\\n``).  Every reply
line starts with ``OK``, ``ERR <code>`` or ``STATUS``:

* ``OK-<text>``: a continuation line of a reply (more lines follow);
* ``OK`` or ``OK <text>``: the last line of a successful reply;
* ``ERR <code> <text>``: the last line of a refused or failed request;
* ``STATUS <fields>``: a line of a subscription (``SUBSCRIBE <hz>``), or
  pushed to a subscribed client as it happens: a fault (``STATUS FAULT
  <fault>``), the end of a move (``STATUS STOP <how it ended>``, once per
  move) or a message of the robot (``STATUS MESSAGE <source> <level>:
  <text>``); never part of a reply, so a client can take them out of the
  stream wherever they come.

The server's own verbs are case-insensitive words that no robot command
uses: ``AUTH``, ``STATUS``, ``FIELDS``, ``TABLE``, ``SUBSCRIBE``, ``UNSUBSCRIBE``,
``QUIT``.  ``TABLE [PREFIX]`` is the console's ``show [PREFIX]`` as data: one
``OK-`` line per row, each a JSON object (name, kind, value, text, units,
range, lo, hi, writable), then ``OK`` and one for the table (rows, matched,
total, left_out, note), or ``ERR command`` when the prefix matches nothing;
anyone that may read may ask.
Everything else is a robot console command.
"""

from __future__ import annotations

from collections.abc import Sequence

__all__ = [
    "ERROR_CODES",
    "MAX_LINE",
    "SERVER_VERBS",
    "format_error",
    "format_reply",
    "split_verb",
]

#: Longest request line accepted, bytes without the line end.
MAX_LINE = 1024

#: Verbs the server answers itself (upper case; requests are case-insensitive).
SERVER_VERBS = ("AUTH", "FIELDS", "QUIT", "STATUS", "SUBSCRIBE", "TABLE", "UNSUBSCRIBE")

#: The ``ERR`` codes and what each means.
ERROR_CODES = {
    "auth": "AUTH failed: wrong token, or no token is configured",
    "busy": "another client is privileged (at most one at a time)",
    "command": "the robot's console refused the command (nothing changed)",
    "denied": "the command changes the robot: AUTH first",
    "fault": "the robot was stopped by a fault; the command was not run",
    "full": "no slot for this connection (too many clients, too many silent ones from "
            "its address, or a reserved slot asked for more than AUTH or stop); it is closed",
    "idle": "no request within the idle bound (5 s before the first request, 30 s "
            "unprivileged, 10 min privileged); the connection is closed",
    "internal": "a bug in pyrt; the server goes on serving",
    "limit": "a server limit was reached (the total subscription rate)",
    "syntax": "a malformed server verb (AUTH, SUBSCRIBE ...)",
    "timeout": "the control loop did not answer in time",
    "too-long": "a request line longer than the limit; the connection is closed",
    "text": "the request held control characters (not a line of text); it was ignored",
    "utf8": "the request was not valid UTF-8; it was ignored",
}


def _clean(text: str) -> str:
    """One line of text: line ends and other control characters become spaces."""
    return "".join(c if c.isprintable() else " " for c in text)


def format_reply(lines: Sequence[str]) -> str:
    """A successful reply: ``OK-`` continuation lines, then ``OK [last]``."""
    if not lines:
        return "OK\n"
    body = [f"OK-{_clean(line)}\n" for line in lines[:-1]]
    last = _clean(lines[-1])
    body.append(f"OK {last}\n" if last else "OK\n")
    return "".join(body)


def format_error(code: str, text: str = "", lines: Sequence[str] = ()) -> str:
    """A failed reply: any output as ``OK-`` lines, then ``ERR code text``."""
    if code not in ERROR_CODES:
        raise ValueError(f"unknown error code {code!r}")
    body = [f"OK-{_clean(line)}\n" for line in lines]
    body.append(f"ERR {code} {_clean(text)}\n" if text else f"ERR {code}\n")
    return "".join(body)


def split_verb(line: str) -> tuple[str, str]:
    """``(VERB, rest)`` of a request: the first word upper-cased, the rest stripped."""
    word, _, rest = line.strip().partition(" ")
    return word.upper(), rest.strip()
