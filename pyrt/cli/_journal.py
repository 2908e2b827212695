"""The flight recorder's options of every station: ``--journal FILE`` and ``--black-box``."""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from typing import Any

from pyrt.journal import DEFAULT_BUDGET, DEFAULT_SECONDS, BlackBox
from pyrt.station.blackbox import (
    AFTER_S,
    SIGNAL_BUDGET,
    SIGNAL_RATE_HZ,
    TOTAL_BUDGET,
    FaultRecorder,
)
from pyrt.station.recording import Recorder

__all__ = ["add_journal_options", "prepare_journal", "start_recorder"]


def _black_box(text: str) -> float:
    if text.strip().lower() == "off":
        return 0.0
    try:
        seconds = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected seconds or off, got {text!r}") from None
    if not 0 < seconds <= 600:
        raise argparse.ArgumentTypeError(f"black box: 0 < SECONDS <= 600 (or off), got {text}")
    return seconds


def add_journal_options(parser: argparse.ArgumentParser) -> None:
    """``--journal FILE`` and ``--black-box SECONDS|off`` on ``parser``."""
    g = parser.add_argument_group("flight recorder")
    g.add_argument(
        "--journal", metavar="FILE",
        help="record the run's inputs, commands, clock and outputs into FILE, at any speed; "
             "'pyrt replay FILE' re-runs it on virtual time and checks every output "
             "(on sim: the boards are then reached through a process image, as a link's are)")
    g.add_argument(
        "--black-box", type=_black_box, default=None, metavar="SECONDS|off",
        help=f"keep the last SECONDS (default {DEFAULT_SECONDS:g} at real time; off on "
             "virtual time, where a run repeats) of inputs and of every signal in memory, "
             f"at most {TOTAL_BUDGET >> 20} MiB in all (the journal's ring "
             f"{DEFAULT_BUDGET >> 20} MiB; the signals' {SIGNAL_BUDGET >> 20} MiB, every "
             f"signal sampled at up to {SIGNAL_RATE_HZ:g} Hz), and on a fault, {AFTER_S:g} s "
             "later, write them beside the databases (or in the working directory) as "
             "NAME-fault-ID-TIME.pj (a journal), .csv and .png (with matplotlib); "
             "the fault's message names them; off: none")


def black_box_seconds(args: argparse.Namespace) -> float:
    """The black box's span asked for (0: none): the option, else the default
    at real time and none on virtual time."""
    given = getattr(args, "black_box", None)
    if given is not None:
        return float(given)
    return DEFAULT_SECONDS if getattr(args, "speed", None) == 1.0 else 0.0


def prepare_journal(args: argparse.Namespace) -> bool:
    """Before the station is built: whether anything is to be recorded (every
    back end has the process image a journal records; nothing to change)."""
    return bool(getattr(args, "journal", None) or black_box_seconds(args))


def _plain(args: argparse.Namespace) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in vars(args).items():
        if key.startswith("_") or callable(value):
            continue
        if value is None or isinstance(value, bool | int | float | str):
            out[key] = value
        elif isinstance(value, list | tuple) and all(
                isinstance(v, bool | int | float | str) for v in value):
            out[key] = list(value)
    return out


def _at_most_one_a_second(say: Callable[[str], None]) -> Callable[[str], None]:
    """``say`` for the journal's warnings (a writer that falls behind at a fast
    tick may warn of a gap every few ms): one line a second, then how many were not said."""
    last = [0.0]
    held = [0]

    def warn(line: str) -> None:
        now = time.monotonic()
        if now - last[0] < 1.0:
            held[0] += 1
            return
        more = f" (and {held[0]} more such lines)" if held[0] else ""
        last[0], held[0] = now, 0
        say(line + more)

    return warn


def start_recorder(station: Any, args: argparse.Namespace, factory: str,
                   say: Callable[[str], None]) -> Recorder | None:
    """The station's recorder (its journal and black box), or None if neither is on.
    With a black box it is a :class:`~pyrt.station.blackbox.FaultRecorder`: the
    black box is written on every fault."""
    path = getattr(args, "journal", None)
    seconds = black_box_seconds(args)
    if not path and not seconds:
        return None
    if not path and getattr(getattr(station, "boards", None), "image", None) is None:
        if getattr(args, "black_box", None) is not None:  # asked for: say why not
            say("black box: off: these boards have no process image to record")
        return None  # the default black box: where there is an image to record
    metadata = {"factory": factory, "args": _plain(args)}
    warn = _at_most_one_a_second(say)
    rec: Recorder
    if seconds:  # the journal's ring holds the aftermath too
        rec = FaultRecorder(station, path, black_box=BlackBox(seconds=seconds + AFTER_S),
                            seconds=seconds, metadata=metadata, warn=warn)
    else:
        rec = Recorder(station, path, metadata=metadata, warn=warn)
    if path:
        say(f"journal: recording into {path}")
    return rec
