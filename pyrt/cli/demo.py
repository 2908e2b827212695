"""``pyrt demo``: the ready queue running 002's three self-scheduling routines.

No robot is attached: the routines only count, so what you see is the
scheduler itself: the clock divisor, the periods, lateness and overruns.
``--slow-us`` makes one routine deliberately slow to show overrun detection
and the timing log.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable

from pyrt.cli._loopopts import add_loop_options, apply_rt_options, make_loop
from pyrt.errors import UsageError
from pyrt.scheduler import ReadyQueue
from pyrt.scheduler.report import format_statistics

# 002 Appendix B: routine addresses and their schedule values.
_ROUTINES = [(0x04C2, "MVJAWS", 0x0C), (0x0473, "SENSORS", 0x0A), (0x0541, "WATCHJAW", 0x01)]


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "demo",
        help="run the ready-queue scheduler alone and print its timing",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--seconds", type=float, default=2.0, help="loop time to run (default 2)")
    p.add_argument(
        "--divisor",
        type=lambda s: int(s, 16),
        default=0x04,
        metavar="HEX",
        help="SYSCLKPD: check the queue every N-th tick (hex, default 04)",
    )
    p.add_argument(
        "--slow-us",
        type=float,
        default=0.0,
        metavar="US",
        help="make SENSORS busy-wait this long on every call (shows overruns)",
    )
    add_loop_options(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    out = sys.stdout
    if not 0 < args.seconds <= 24 * 3600:
        raise UsageError("--seconds must be > 0 and at most a day")
    if not 0 <= args.divisor <= 0xFF:
        raise UsageError("--divisor must be 00..FF")
    apply_rt_options(args, lambda m: print(m, file=out))
    loop = make_loop(args)
    queue = ReadyQueue(capacity=6, divisor=args.divisor, name="demo")
    counts = dict.fromkeys((name for _, name, _ in _ROUTINES), 0)
    slow_ns = int(args.slow_us * 1000)

    def make(name: str) -> Callable[[], None]:
        def body() -> None:
            counts[name] += 1
            if slow_ns and name == "SENSORS":
                end = time.perf_counter_ns() + slow_ns
                while time.perf_counter_ns() < end:
                    pass

        return body

    for address, name, period in _ROUTINES:
        queue.add_periodic(address, name, make(name), period)
        queue.schedule(address, period)
    loop.attach(queue)
    speed = "max (virtual time)" if args.speed is None else f"{args.speed:g}x real time"
    print(
        f"ready queue: 6 slots, SYSCLKPD {args.divisor:02X}, tick {args.tick_us} µs, "
        f"speed {speed}, {args.seconds:g} s",
        file=out,
    )
    wall0 = time.perf_counter()
    loop.run(duration_ns=int(args.seconds * 1e9))
    wall = time.perf_counter() - wall0
    loop.close()
    print(format_statistics(loop.statistics()), file=out)
    print(f"ran {loop.tick_index} ticks in {wall:.3f} s wall time", file=out)
    if args.timing_log:
        print(f"timing log written to {args.timing_log}", file=out)
    return 0
