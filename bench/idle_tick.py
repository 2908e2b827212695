"""What one idle tick of a station costs on virtual time, for one or more source
trees side by side: Python calls and bytecodes a tick (deterministic), and the
instructions of the tick under callgrind.

    python bench/idle_tick.py                                   # this tree
    python bench/idle_tick.py --tree /tmp/old --tree .          # side by side
    python bench/idle_tick.py --tree . --callgrind 0 --top 20   # the calls a tick, by function

The station is built as ``pyrt ROBOT`` builds it at real time (``sim:``, the
black box on, :mod:`bench_journal`'s ``build``), started, left idle for a
second of loop time, then measured idle for ``--seconds`` of loop time: the
ticks run as ``sleep`` runs them on a :class:`~pyrt.scheduler.SimClock`.
Idle at real time the tick runs on cold caches after each sleep, so what it
calls is what it costs; these counts do not depend on the load of the machine.

Not part of the test run (it is a script, not a ``bench_*`` module).
"""

from __future__ import annotations

import argparse
import cProfile
import gc
import json
import os
import pstats
import re
import subprocess
import sys
import tempfile
from collections import Counter
from pathlib import Path

HERE = Path(__file__).resolve().parent


def _rig(robot: str, tmp: Path):
    sys.path.insert(0, str(HERE))
    import bench_journal as bj

    rig = bj.build(robot, "sim:", bj.TimedSimClock(), tmp, None, 10.0)
    rig.start()
    rig.shell.onecmd("sleep 1")
    return rig


def one(robot: str, seconds: float, measure: str, top: int) -> dict:
    """``measure`` (calls, bytecodes, callgrind) of the idle station's ticks."""
    with tempfile.TemporaryDirectory() as tmp:
        rig = _rig(robot, Path(tmp))
        gc.collect()
        gc.freeze()
        gc.disable()
        tick0 = rig.loop.tick_index
        out: dict = {}
        if measure == "calls":
            prof = cProfile.Profile()
            prof.enable()
            rig.shell.onecmd(f"sleep {seconds}")
            prof.disable()
            ticks = rig.loop.tick_index - tick0
            st = pstats.Stats(prof)
            rows = sorted(((v[1], f"{Path(k[0]).name}:{k[2]}") for k, v in st.stats.items()),
                          reverse=True)
            out = {"calls": st.total_calls / ticks,
                   "top": [(name, n / ticks) for n, name in rows[:top]]}
        elif measure == "bytecodes":
            counts = Counter()

            def local(frame, event, arg):
                if event == "opcode":
                    counts[frame.f_code] += 1
                return local

            def glob(frame, event, arg):
                frame.f_trace_opcodes = True
                return local

            sys.settrace(glob)
            rig.shell.onecmd(f"sleep {seconds}")
            sys.settrace(None)
            ticks = rig.loop.tick_index - tick0
            rows = sorted(((n, f"{Path(c.co_filename).name}:{c.co_name}")
                           for c, n in counts.items()), reverse=True)
            out = {"bytecodes": sum(counts.values()) / ticks,
                   "top": [(name, n / ticks) for n, name in rows[:top]]}
        else:
            sys.path.insert(0, str(HERE))
            from recorder_cost import _callgrind_requests

            start, stop = _callgrind_requests()
            start()
            rig.shell.onecmd(f"sleep {seconds}")
            stop()
            ticks = rig.loop.tick_index - tick0
        out["ticks"] = ticks
        rig.close()
        gc.enable()
    return out


def _child(tree: Path, argv: list[str], wrap: tuple[str, ...] = (),
           env: dict | None = None) -> dict:
    env = dict(os.environ, PYTHONPATH=str(tree), **(env or {}))
    r = subprocess.run([*wrap, sys.executable, str(Path(__file__).resolve()), *argv], env=env,
                       capture_output=True, text=True, check=False, cwd=tree)
    if r.returncode:
        raise SystemExit(f"{tree}: {' '.join(argv)} failed:\n{r.stderr[-2000:]}")
    return json.loads(r.stdout.strip().splitlines()[-1])


def callgrind(tree: Path, robot: str, seconds: float, requests: Path) -> float:
    """Instructions a tick of the loop's thread (the thread that sleeps on virtual time)."""
    sys.path.insert(0, str(HERE))
    from recorder_cost import CG_ENV

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "cg.out"
        wrap = ("valgrind", "--tool=callgrind", "--separate-threads=yes",
                "--instr-atstart=no", f"--callgrind-out-file={out}")
        r = _child(tree, ["--one", robot, str(seconds), "callgrind", "0"], wrap,
                   {CG_ENV: str(requests), "OPENBLAS_NUM_THREADS": "1"})
        n = 0
        for f in Path(tmp).glob("cg.out*"):
            if f.name.endswith("-01"):
                m = re.search(r"^totals:\s*(\d+)", f.read_text(errors="replace"), re.M)
                n += int(m.group(1)) if m else 0
    return n / max(1, r["ticks"])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--tree", action="append", type=Path)
    ap.add_argument("--robot", default="manipulator")
    ap.add_argument("--seconds", type=float, default=5.0, help="loop seconds measured")
    ap.add_argument("--callgrind", type=int, default=1, help="0: no callgrind row")
    ap.add_argument("--top", type=int, default=0, help="the N functions called most a tick, and those that run the most bytecodes")
    ap.add_argument("--one", nargs=4, help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.one:
        robot, seconds, measure, top = a.one
        print(json.dumps(one(robot, float(seconds), measure, int(top))))
        return
    trees = a.tree or [Path.cwd()]
    sys.path.insert(0, str(HERE))
    from recorder_cost import build_requests

    with tempfile.TemporaryDirectory() as req:
        if a.callgrind:
            build_requests(Path(req))
        for tree in trees:
            calls = _child(tree, ["--one", a.robot, str(a.seconds), "calls", str(a.top)])
            codes = _child(tree, ["--one", a.robot, str(a.seconds), "bytecodes", str(a.top)])
            line = (f"{tree}: {a.robot} idle, {calls['ticks']} ticks: "
                    f"{calls['calls']:.1f} calls, {codes['bytecodes']:.0f} bytecodes a tick")
            if a.callgrind:
                line += f", {callgrind(tree, a.robot, a.seconds, Path(req)):,.0f} instructions"
            print(line, flush=True)
            for (name, n), (bname, b) in zip(calls["top"], codes["top"], strict=False):
                print(f"    {n:6.2f}  {name:<44} {b:7.1f}  {bname}")


if __name__ == "__main__":
    main()
