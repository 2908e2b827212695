"""``--stream udp://HOST:PORT``: the scope's channels streamed live from the start.

The option does at start-up what the console's words do (``scope add``,
``scope stream URL HZ``, ``scope run``), so that a headless station or a
piped script plots in PlotJuggler from its first tick.  Every value is
checked before the station starts: a destination that is not
``udp://HOST:PORT``, a rate outside ``MIN_HZ..MAX_HZ`` or a channel the
station does not have is a usage error (exit 2), and nothing runs.
"""

from __future__ import annotations

import argparse
import math
from typing import Any

from pyrt.errors import CommandError, UsageError
from pyrt.scope.stream import DEFAULT_HZ, MAX_HZ, MIN_HZ, parse_udp_url

__all__ = ["add_stream_options", "stream_commands"]


def _destination(text: str) -> str:
    try:
        parse_udp_url(text)
    except CommandError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix("scope stream: ")) from None
    return text


def _rate(text: str) -> float:
    try:
        hz = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text[:40]!r} is not a number of Hz") from None
    if not (math.isfinite(hz) and MIN_HZ <= hz <= MAX_HZ):
        raise argparse.ArgumentTypeError(f"{text[:40]} Hz is outside {MIN_HZ:g}..{MAX_HZ:g}")
    return hz


def add_stream_options(parser: argparse.ArgumentParser) -> None:
    """``--stream URL``, ``--stream-hz HZ`` and ``--stream-channel CH`` on ``parser``."""
    g = parser.add_argument_group("live plots (PlotJuggler's UDP JSON; docs/operating.md)")
    g.add_argument("--stream", type=_destination, metavar="udp://HOST:PORT",
                   help="stream the channels named by --stream-channel from the first tick "
                        "(as 'scope add', 'scope stream', 'scope run' would)")
    g.add_argument("--stream-hz", type=_rate, default=None, metavar="HZ",
                   help=f"objects a second of loop time (default {DEFAULT_HZ:g}; "
                        f"{MIN_HZ:g}..{MAX_HZ:g})")
    g.add_argument("--stream-channel", action="append", default=None, metavar="OBJECT.SIGNAL",
                   help="a channel to stream (repeat for more; 'show' or 'scope list' in the "
                        "console names them)")


def stream_commands(args: argparse.Namespace, station: Any) -> list[str]:
    """The console lines that start the stream ``args`` ask for ([] for none);
    UsageError for a channel ``station`` does not have or options without
    ``--stream``."""
    url = getattr(args, "stream", None)
    channels = getattr(args, "stream_channel", None) or []
    hz = getattr(args, "stream_hz", None)
    if url is None:
        if channels or hz is not None:
            given = "--stream-channel" if channels else "--stream-hz"
            raise UsageError(f"{given} needs --stream udp://HOST:PORT")
        return []
    if not channels:
        raise UsageError("--stream needs at least one --stream-channel OBJECT.SIGNAL "
                         "('show' in the console names every signal)")
    room = station.scope.max_channels
    if len(channels) > room:
        raise UsageError(f"--stream-channel: {len(channels)} channels, the scope has {room}")
    for name in channels:
        try:
            station.resolve_signal(name)
        except CommandError as exc:
            raise UsageError(f"--stream-channel {name[:60]}: {exc}") from None
    rate = DEFAULT_HZ if hz is None else hz
    return [f"scope add {' '.join(channels)}", f"scope stream {url} {rate:g}", "scope run"]
