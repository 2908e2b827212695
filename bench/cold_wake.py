"""What a tick costs when it follows a sleep: the same work back to back and
after each of a range of sleeps, by the thread's own CPU time.

    python bench/cold_wake.py                         # the C probes and both robots
    python bench/cold_wake.py --robot manipulator --gaps 0 1 5

Idle at real time, a loop sleeps between ticks, and on a shared machine the
caches are used for something else while it sleeps.  This script tells that
apart from a slower clock:

* ``C arithmetic``: a fixed loop of floating-point work that touches no
  memory.  If a sleep made the CPU slower (a frequency step, a deeper idle
  state), this row would grow with the gap.
* ``C touch N kB``: one read of every 64-byte line of an N kB buffer.  This
  row grows with the gap when the sleep leaves the caches cold.
* ``ROBOT idle tick``: one tick of the idle station (built as ``pyrt ROBOT``
  builds it, ``sim:``, the black box on) on a :class:`~pyrt.scheduler.SimClock`,
  run one at a time with the gap between: the same instructions every time.

Each row is the mean of ``--reps`` runs, in µs of the thread's CPU time.
Not part of the test run (it is a script, not a ``bench_*`` module).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent

_C = r"""
#include <stddef.h>
static volatile double sink_d;
static volatile long sink_l;
void arith(long n) {
    double x = 1.0;
    for (long i = 0; i < n; i++) x = x * 1.0000001 + 1e-9;
    sink_d = x;
}
void touch(const char *buf, size_t size) {
    long s = 0;
    for (size_t i = 0; i < size; i += 64) s += buf[i];
    sink_l = s;
}
"""


def _probes(tmp: Path):
    from cffi import FFI  # type: ignore[import-untyped]

    ffi = FFI()
    ffi.cdef("void arith(long n); void touch(const char *buf, size_t size);")
    ffi.set_source("_pyrt_cold_wake", _C, extra_compile_args=["-O2"])
    sys.path.insert(0, str(tmp))
    ffi.compile(tmpdir=str(tmp), verbose=False)
    import _pyrt_cold_wake as mod  # type: ignore[import-not-found]

    return mod.ffi, mod.lib


def _mean_us(run, gap_s: float, reps: int) -> float:
    total = 0
    clock = time.thread_time_ns
    for _ in range(reps):
        if gap_s:
            time.sleep(gap_s)
        t = clock()
        run()
        total += clock() - t
    return total / reps / 1e3


def _rig(robot: str, tmp: Path):
    sys.path.insert(0, str(HERE))
    import bench_journal as bj

    from pyrt.scheduler.clock import SimClock

    rig = bj.build(robot, "sim:", SimClock(), tmp, None, 10.0)
    rig.start()
    rig.shell.onecmd("sleep 1")
    return rig


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--robot", action="append", choices=["gripper", "manipulator"],
                    help="the stations' idle ticks to run (default both)")
    ap.add_argument("--gaps", type=float, nargs="+", default=[0, 0.2, 1, 5],
                    help="sleeps before each run, ms (default 0 0.2 1 5)")
    ap.add_argument("--reps", type=int, default=300, help="runs a row (default 300)")
    ap.add_argument("--touch-kb", type=int, nargs="+", default=[256, 1024],
                    help="buffer sizes of the touch probe, kB (default 256 1024)")
    args = ap.parse_args(argv)
    robots = args.robot or ["gripper", "manipulator"]
    gaps = [g / 1e3 for g in args.gaps]
    with tempfile.TemporaryDirectory() as tmp:
        ffi, lib = _probes(Path(tmp))
        rows: list[tuple[str, object]] = [("C arithmetic (20k steps)", lambda: lib.arith(20_000))]
        for kb in args.touch_kb:
            buf = ffi.new("char[]", kb * 1024)
            rows.append((f"C touch {kb} kB", lambda buf=buf, n=kb * 1024: lib.touch(buf, n)))
        for robot in robots:
            (Path(tmp) / robot).mkdir()
            rig = _rig(robot, Path(tmp) / robot)
            rows.append((f"{robot} idle tick", lambda loop=rig.loop: loop.run(1)))
        head = " | ".join(f"after {g:g} ms" for g in args.gaps)
        sys.stdout.write(f"| µs of CPU | {head} |\n|---|{'---:|' * len(gaps)}\n")
        for name, run in rows:
            cells = " | ".join(f"{_mean_us(run, g, args.reps):.1f}" for g in gaps)  # type: ignore[arg-type]
            sys.stdout.write(f"| {name} | {cells} |\n")
            sys.stdout.flush()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
