"""What the flight recorder costs a tick, and what an idle recorded gripper costs a core,
for one or more source trees side by side in one run.

    python bench/recorder_cost.py                              # this tree
    python bench/recorder_cost.py --tree /tmp/old --tree .     # two trees, interleaved
    python bench/recorder_cost.py --tree . --callgrind 0       # time only

Every row runs in a child process whose ``PYTHONPATH`` is the tree measured
(its compiled modules built in place), the trees interleaved row by row and
round by round, so that what the machine does meanwhile falls on all of them
alike.  Three measures:

* ``work`` (time): virtual time, each robot moving (the gripper at 1 kHz with
  ``P`` back and forth, the manipulator's prototype at 200 Hz), built as
  ``pyrt NAME`` builds it (:mod:`bench_journal`'s ``build`` and ``drive``):
  the loop thread's CPU time from the top of one tick to the top of the
  next.  The rows: ``image`` (plain ``sim:``: every run has a process
  image), ``image + recorder`` (a journal file), ``image + black box`` (the
  10 s ring, no file: what ``pyrt NAME`` keeps at real time), and the black
  box without its signal samples and without its snapshots (what each
  costs); ``--rows all`` adds ``sim:`` (the same program as ``image``: an
  A/A check of the bench) and ``image + empty handler`` (one more timed
  handler that does nothing).  A virtual-time run is deterministic: tick
  ``i`` of a row does the same work in every round, so what the machine
  adds to a tick (a preemption's cold caches, an interrupt, a neighbour on
  the core) is taken out by keeping each tick's least CPU time over the
  rounds: the ``steady`` columns (p50 and mean of those), the figures to
  compare.  The spread of the rounds' own means is shown beside them: what
  runs beside the loop moves whole rows (up to 1.8x on a loaded machine),
  which the steady figures narrow to a few per cent, not to 5 %.  The
  cyclic collector is off while a row is measured (its start-up heap frozen
  first), as it is at real time, where the loop runs the collections in the
  idle part of a tick (a 10 s row collects 0-2 times: not where the spread
  comes from).
  And the journal writer thread's CPU a tick, whole and less its time in the
  calls that release the interpreter lock (zlib's compress and the C tick
  encoder, timed in the child): its turns with the lock.
* ``instructions`` (``--callgrind N``, default 1 round; 0 skips it): the same
  rows under ``valgrind --tool=callgrind --separate-threads=yes``,
  instrumented only while the row is measured (a client request from a
  small cffi module built once): instructions a tick of the loop's thread
  (on virtual time the loop runs in the thread that drives it, whose
  console commands between runs are in its count, the same in every row)
  and of the journal writer thread.  The load of the machine does not
  change them: the figure to decide by.
* ``idle`` (``--idle S``, 0 skips it): ``pyrt gripper`` (1 kHz) and ``pyrt
  manipulator`` (200 Hz) themselves, idle at real time with their stdin a pipe,
  the black box on (the default) and ``--black-box off``, and a bare Python
  sleep loop at 1 kHz: the process's CPU share (``/proc``) over ``S`` seconds
  after the start-up; the targets 5 % (gripper) and 3 % (manipulator).

Not part of the test run (it is a script, not a ``bench_*`` module).
"""

from __future__ import annotations

import argparse
import concurrent.futures
import gc
import json
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
#: Every row; the default ones are :data:`DEFAULT_ROWS`.
ROWS = ("sim:", "image", "image + empty handler", "image + recorder", "image + black box",
        "black box, no samples", "black box, no snapshots")
DEFAULT_ROWS = ("image", "image + recorder", "image + black box", "black box, no samples",
                "black box, no snapshots")
#: Loop seconds a row is timed, and measured under callgrind (a whole number of
#: the black box's snapshot intervals: 2 s on the gripper, 5 s on the manipulator).
SECONDS = {"gripper": 10.0, "manipulator": 30.0}
CG_SECONDS = {"gripper": 4.0, "manipulator": 15.0}
#: Where the client-request module is built (``PYRT_BENCH_CG``: its directory).
CG_ENV = "PYRT_BENCH_CG"


# -- one row, in a child process -------------------------------------------------------------


def _callgrind_requests():
    """``(start, stop)``: callgrind's instrumentation switched on and off (no-ops
    outside valgrind), from the module :func:`build_requests` built."""
    where = os.environ.get(CG_ENV)
    if not where:
        return (lambda: None), (lambda: None)
    sys.path.insert(0, where)
    import _pyrt_cg  # type: ignore[import-not-found]

    return _pyrt_cg.lib.cg_start, _pyrt_cg.lib.cg_stop


def build_requests(where: Path) -> None:
    """Build the client-request module (``<valgrind/callgrind.h>``) in ``where``."""
    import cffi

    ffi = cffi.FFI()
    ffi.cdef("void cg_start(void); void cg_stop(void);")
    ffi.set_source("_pyrt_cg", """
        #include <valgrind/callgrind.h>
        void cg_start(void) { CALLGRIND_ZERO_STATS; CALLGRIND_START_INSTRUMENTATION; }
        void cg_stop(void) { CALLGRIND_STOP_INSTRUMENTATION; }
    """)
    ffi.compile(tmpdir=str(where), verbose=False)


def _count_black_box(box) -> dict:
    """Counts, filled in as the row runs: the black box's signal samples and
    snapshots (taken, refused)."""
    counts = {"samples": 0, "snapshots": 0, "refused": 0}
    if box is None:
        return counts
    sample, snapshot = box.ring.sample, box._snapshot

    def counted_sample(now_ns):
        counts["samples"] += 1
        return sample(now_ns)

    def counted_snapshot(tick):
        n = len(box.snapshots)
        snapshot(tick)
        counts["snapshots" if len(box.snapshots) != n or box.snapshots.maxlen == n
               else "refused"] += 1

    box.ring.sample = counted_sample
    box._snapshot = counted_snapshot
    return counts


def _strip_black_box(rig, row: str) -> None:
    """The black box of ``rig`` without its signal samples or its snapshots."""
    box = getattr(rig.recorder, "fault_box", None)
    if box is None:
        return
    if row == "black box, no samples":
        box.ring.sample = lambda now_ns: None
    elif row == "black box, no snapshots":
        box._snapshot = lambda tick: setattr(box, "_next_snapshot", 1 << 62)


def one_row(robot: str, row: str, seconds: float) -> dict:
    """Build ``robot`` as the row says, drive it ``seconds`` of loop time; the
    per-tick CPU ns (loop thread), the tick measured first, and the journal
    handler's mean.  Under callgrind, instrumented only while it is measured."""
    sys.path.insert(0, str(HERE))
    import bench_journal as bj

    cg_start, cg_stop = _callgrind_requests()
    boards = "sim:" if row == "sim:" or _one_tick_shape() else "sim:?image=1"
    outside = _time_outside_the_lock()
    with tempfile.TemporaryDirectory() as tmp:
        t = Path(tmp)
        clock = bj.TimedSimClock()
        path = t / "run.pj" if row == "image + recorder" else None
        box = 10.0 if "black box" in row else 0.0
        rig = bj.build(robot, boards, clock, t, path, box)
        counted = _count_black_box(getattr(rig.recorder, "fault_box", None))
        _strip_black_box(rig, row)
        if row == "image + empty handler":
            # what the loop charges for one more timed handler at the recorder's place
            rig.loop.attach(lambda now_ns: None, name="journal")
        run = rig.loop.run

        def timed_run(*a, **kw):
            try:
                return run(*a, **kw)
            finally:
                clock.end_run()

        rig.loop.run = timed_run  # type: ignore[method-assign]
        rig.start()
        bj.drive(rig, 1.0)  # warm up: the first moves run code for the first time
        rig.loop.reset_statistics()
        # as at real time: no collection inside a tick (the loop runs them when idle)
        gc.collect()
        gc.freeze()
        gc.disable()
        i0 = len(clock.wall)
        tick0 = rig.loop.tick_index
        w0, o0 = bj.writer_cpu_ns(), outside[0]
        cg_start()
        bj.drive(rig, seconds)
        cg_stop()
        w1, o1 = bj.writer_cpu_ns(), outside[0]
        ticks = rig.loop.tick_index - tick0
        _dw, dc = clock.ticks_from(i0)
        st = rig.loop.statistics()
        rig.close()
        gc.enable()
    j = st.tasks.get("journal")
    return {"cpu": dc, "tick0": tick0, "ticks": ticks, **counted,
            "journal_ns": j.mean_ns if j else 0.0,
            "writer_ns": (w1 - w0) / max(1, len(dc)),
            "writer_locked_ns": (w1 - w0 - (o1 - o0)) / max(1, len(dc))}


class _Proxy:
    """``target`` with some attributes replaced."""

    def __init__(self, target: object, **replaced: object):
        self._target = target
        self.__dict__.update(replaced)

    def __getattr__(self, name: str) -> object:
        return getattr(self._target, name)


def _time_outside_the_lock() -> list[int]:
    """Count the journal writer thread's CPU time in the calls that release the
    interpreter lock (zlib's compress, the C tick encoder where the tree has one):
    its CPU time less this is its turns with the lock."""
    import threading

    import pyrt.journal.format as fmt
    spent = [0]

    def timed(fn):
        def call(*a, **kw):
            if threading.current_thread().name != "pyrt-journal":
                return fn(*a, **kw)
            t = time.thread_time_ns()
            try:
                return fn(*a, **kw)
            finally:
                spent[0] += time.thread_time_ns() - t
        return call

    import zlib
    zp = _Proxy(zlib, compress=timed(zlib.compress))
    fmt.zlib = zp  # type: ignore[attr-defined]
    try:
        import pyrt.journal.encoder as enc
        import pyrt.native._journal as nj
    except ImportError:
        return spent
    enc.zlib = zp  # type: ignore[attr-defined]
    nj.lib = _Proxy(nj.lib, pyrt_journal_encode=timed(nj.lib.pyrt_journal_encode))
    return spent


def handler_alone(robot: str) -> dict:
    """The recorder's handler alone, called in a loop on a built station (the
    loop stopped, the tick index moved by hand, the writer emptied between
    repeats): µs a call, with the image's inputs as the list it makes and as
    an ``array('q')`` (what an image keeping 64-bit integers would hand over)."""
    import timeit
    from array import array

    sys.path.insert(0, str(HERE))
    import bench_journal as bj

    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        t = Path(tmp)
        rig = bj.build(robot, "sim:" if _one_tick_shape() else "sim:?image=1", bj.TimedSimClock(), t,
                       t / "run.pj")
        rig.start()
        bj.drive(rig, 0.5)
        rec, loop = rig.recorder, rig.loop
        journal = rec.journal  # type: ignore[attr-defined]

        def tick() -> None:
            loop.tick_index += 1
            rec._tick(loop.now_ns)  # type: ignore[attr-defined]

        def best() -> float:
            timer = timeit.Timer(tick, setup=lambda: journal.flush(30))
            return min(timer.repeat(7, 1000)) / 1000 * 1e6

        image = rec.image  # type: ignore[attr-defined]
        inputs = image.last_inputs
        out["inputs"] = len(inputs)
        out["list"] = best()
        image.last_inputs = array("q", inputs)
        out["array"] = best()
        image.last_inputs = inputs
        journal.flush(30)
        rig.close()
    return out


def _one_tick_shape() -> bool:
    """Whether the tree measured has one tick shape (``sim:`` is the image path and
    ``?image=1`` is refused): then the rows ``sim:`` and ``image`` are one program."""
    from pyrt.boards import open_boards
    from pyrt.errors import ConfigError
    from pyrt.sim.world import GRIPPER_BOARDS

    try:
        open_boards("sim:?image=1", "gripper", GRIPPER_BOARDS).close()
    except ConfigError:
        return True
    return False


#: The idle rows: ``pyrt gripper`` (1 kHz) and ``pyrt manipulator`` (200 Hz) with the
#: black box on (the default) and off, and a bare Python sleep loop at 1 kHz.
IDLE_ROWS = ("black box on", "black box off", "manipulator", "manipulator black box off",
             "bare sleep")


def idle_row(row: str, seconds: float) -> dict:
    """The CPU share of ``pyrt gripper`` or ``pyrt manipulator`` idle at real time
    (or of a bare sleep loop)."""
    if row == "bare sleep":
        code = ("import time\nn=time.monotonic_ns()\nwhile True:\n n+=1000000\n"
                " d=n-time.monotonic_ns()\n if d>0: time.sleep(d/1e9)\n")
        argv = [sys.executable, "-c", code]
    else:
        robot = "manipulator" if row.startswith("manipulator") else "gripper"
        argv = [sys.executable, "-m", "pyrt", robot]
        if row.endswith("black box off"):
            argv += ["--black-box", "off"]
    with tempfile.TemporaryDirectory() as tmp:
        # the station's files (the manipulator's databases) in the temporary
        # directory too, never in the user's state
        env = dict(os.environ, PYRT_HOME=str(Path(tmp) / "pyrt-home"),
                   XDG_STATE_HOME=str(Path(tmp) / "state"))
        proc = subprocess.Popen(argv, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL, cwd=tmp, env=env)
        try:
            # start-up: imports, the station built (the manipulator's databases), the
            # loop running
            time.sleep(3.0 if row.startswith("manipulator") else 1.5)
            c0, t0 = _cpu_s(proc.pid), time.monotonic()
            time.sleep(seconds)
            c1, t1 = _cpu_s(proc.pid), time.monotonic()
        finally:
            proc.kill()
            proc.wait()
    return {"cpu_pct": (c1 - c0) / (t1 - t0) * 100}


def _cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


# -- the driver ------------------------------------------------------------------------------


def _child(tree: Path, *argv: str, wrap: tuple[str, ...] = (), env: dict | None = None) -> dict:
    env = dict(os.environ, PYTHONPATH=str(tree), **(env or {}))
    out = subprocess.run([*wrap, sys.executable, str(Path(__file__).resolve()), *argv], env=env,
                         capture_output=True, text=True, check=False, cwd=tree)
    if out.returncode:
        raise SystemExit(f"{tree}: {' '.join(argv)} failed:\n{out.stderr[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


#: The writer thread's file holds the C encoder or zlib.
_WRITER_FNS = re.compile(r"^fn=.*(pyrt_journal_encode|deflate)", re.M)


def callgrind_row(tree: Path, robot: str, row: str, requests: Path) -> dict:
    """One row under callgrind: instructions a tick of the loop's thread (thread 1:
    on virtual time the loop runs in the thread that drives it) and of the
    journal writer thread (the one that ran the encoder or zlib)."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "cg.out"
        wrap = ("valgrind", "--tool=callgrind", "--separate-threads=yes",
                "--instr-atstart=no", f"--callgrind-out-file={out}")
        r = _child(tree, "--one", robot, row, str(CG_SECONDS[robot]), wrap=wrap,
                   env={CG_ENV: str(requests), "OPENBLAS_NUM_THREADS": "1"})
        loop = writer = other = 0
        for f in sorted(Path(tmp).glob("cg.out*")):
            text = f.read_text(errors="replace")
            m = re.search(r"^totals:\s*(\d+)", text, re.M)
            n = int(m.group(1)) if m else 0
            if f.name.endswith("-01"):
                loop += n
            elif _WRITER_FNS.search(text):
                writer += n
            else:
                other += n
    ticks = max(1, r["ticks"])
    return {"loop": loop / ticks, "writer": writer / ticks, "other": other / ticks,
            "ticks": r["ticks"], "samples": r.get("samples", 0),
            "snapshots": r.get("snapshots", 0)}


def _pct(xs: list[int], p: float) -> float:
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(p * len(xs)))] / 1e3


def steady(rounds: list[dict]) -> tuple[list[int], bool]:
    """Each tick's least CPU time over the rounds (tick ``i`` of every round is the
    same work on virtual time); False when the rounds did not run the same ticks
    (then the first ticks common to all are kept)."""
    same = len({(r["tick0"], len(r["cpu"])) for r in rounds}) == 1
    n = min(len(r["cpu"]) for r in rounds)
    return [min(col) for col in zip(*(r["cpu"][:n] for r in rounds), strict=True)], same


def _share(x: float, base: float) -> str:
    return f"{(x - base) / base * 100:+.1f} %" if base else ""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--tree", action="append", type=Path,
                    help="a source tree (repeat: side by side); default this one")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--robot", action="append", choices=sorted(SECONDS))
    ap.add_argument("--rows", default="default",
                    help="'default', 'all', or rows separated by '/' (of: " + " / ".join(ROWS)
                    + ")")
    ap.add_argument("--callgrind", type=int, default=1, metavar="N",
                    help="rounds under callgrind (instructions a tick; 0: none)")
    ap.add_argument("--jobs", type=int, default=1,
                    help="callgrind rows run at once (their counts do not depend on load)")
    ap.add_argument("--idle", type=float, default=10.0, help="seconds of idle a row (0: none)")
    ap.add_argument("--no-work", action="store_true", help="no timed rows")
    ap.add_argument("--one", nargs=3, metavar=("ROBOT", "ROW", "SECONDS"), help=argparse.SUPPRESS)
    ap.add_argument("--one-idle", nargs=2, metavar=("ROW", "SECONDS"), help=argparse.SUPPRESS)
    ap.add_argument("--alone", action="store_true",
                    help="also time the recorder's handler alone (loop thread)")
    ap.add_argument("--one-alone", metavar="ROBOT", help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.one_alone:
        print(json.dumps(handler_alone(a.one_alone)))
        return
    if a.one:
        print(json.dumps(one_row(a.one[0], a.one[1], float(a.one[2]))))
        return
    if a.one_idle:
        print(json.dumps(idle_row(a.one_idle[0], float(a.one_idle[1]))))
        return
    trees = [t.resolve() for t in (a.tree or [HERE.parent])]
    robots = a.robot or ["gripper", "manipulator"]
    rows = (DEFAULT_ROWS if a.rows == "default" else ROWS if a.rows == "all"
            else tuple(r.strip() for r in a.rows.split("/")))
    if "image" not in rows or not set(rows) <= set(ROWS):
        raise SystemExit(f"rows {rows}: the row 'image' (the base) and rows of {ROWS}")
    t0 = time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime())
    load0 = os.getloadavg()[0]
    work: dict[tuple, list[dict]] = {}
    idle: dict[tuple, list[float]] = {}
    for _ in range(a.rounds):
        if not a.no_work:
            for robot in robots:
                for row in rows:
                    for tree in trees:
                        r = _child(tree, "--one", robot, row, str(SECONDS[robot]))
                        work.setdefault((tree, robot, row), []).append(r)
        if a.idle > 0:
            for row in IDLE_ROWS:
                for tree in trees:
                    if row == "bare sleep" and tree != trees[0]:
                        continue
                    r = _child(tree, "--one-idle", row, str(a.idle))
                    idle.setdefault((tree, row), []).append(r["cpu_pct"])
    t1 = time.strftime("%H:%M:%S UTC", time.gmtime())
    load1 = os.getloadavg()[0]
    instr: dict[tuple, list[dict]] = {}
    if a.callgrind > 0 and not a.no_work:
        if shutil.which("valgrind") is None:
            raise SystemExit("--callgrind needs valgrind (0 skips it)")
        with tempfile.TemporaryDirectory() as req:
            build_requests(Path(req))
            jobs = [(tree, robot, row) for _ in range(a.callgrind) for robot in robots
                    for row in rows for tree in trees]
            with concurrent.futures.ThreadPoolExecutor(max(1, a.jobs)) as pool:
                done = pool.map(lambda j: callgrind_row(*j, Path(req)), jobs)
                for j, r in zip(jobs, done, strict=True):
                    instr.setdefault(j, []).append(r)
    t2 = time.strftime("%H:%M:%S UTC", time.gmtime())
    print(f"{t0} -> {t1} (timed rows; load average {load0:.2f} -> {load1:.2f}), callgrind "
          f"-> {t2} (load average {os.getloadavg()[0]:.2f}); {a.rounds} rounds, rows interleaved")
    names = {t: (t.name if len(trees) > 1 else "") for t in trees}
    for robot in robots if work else ():
        print(f"\n{robot}, virtual time, moving ({a.rounds} x {SECONDS[robot]:g} s a row): "
              "loop-thread CPU a tick, µs; steady: each tick's least over the rounds")
        print("| tree | row | ticks | p50 | mean | the rounds' means | steady p50 | steady mean"
              " | added steady p50 | added steady mean | writer CPU a tick | of it with the lock"
              " | added steady mean with the writer's turns |")
        print("|---|---|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|")
        for tree in trees:
            bs, _ = steady(work[(tree, robot, "image")])
            b50, bmean = _pct(bs, .5), statistics.fmean(bs) / 1e3
            for row in rows:
                rs = work[(tree, robot, row)]
                pooled = [c for r in rs for c in r["cpu"]]
                st, same = steady(rs)
                s50, smean = _pct(st, .5), statistics.fmean(st) / 1e3
                means = [statistics.fmean(r["cpu"]) / 1e3 for r in rs]
                wm = statistics.fmean(r["writer_ns"] for r in rs) / 1e3
                lm = statistics.fmean(r["writer_locked_ns"] for r in rs) / 1e3
                added = (f"{_share(s50, b50)} | {_share(smean, bmean)} | {wm:.2f} | {lm:.2f}"
                         f" | {_share(smean + lm, bmean)}" if row not in ("image", "sim:")
                         else " | | | | ")
                print(f"| {names[tree]} | {row} | {len(pooled):,} | {_pct(pooled, .5):.2f} | "
                      f"{statistics.fmean(pooled) / 1e3:.2f} | "
                      + ", ".join(f"{m:.2f}" for m in means)
                      + f" | {s50:.2f}{'' if same else ' (*)'} | {smean:.2f} | {added} |")
    for robot in robots if instr else ():
        print(f"\n{robot}, under callgrind ({a.callgrind} x {CG_SECONDS[robot]:g} s a row): "
              "instructions a tick")
        print("| tree | row | ticks | loop thread | added | writer thread | "
              "added, both threads | samples, snapshots in it |")
        print("|---|---|---:|---:|---:|---:|---:|---|")
        for tree in trees:
            base = instr[(tree, robot, "image")]
            bl = statistics.fmean(r["loop"] for r in base)
            bw = statistics.fmean(r["writer"] for r in base)
            for row in rows:
                rs = instr[(tree, robot, row)]
                lp = statistics.fmean(r["loop"] for r in rs)
                wr = statistics.fmean(r["writer"] for r in rs)
                extra = (f"{_share(lp, bl)} | {wr:,.0f} | {_share(lp + wr - bw, bl)}"
                         if row not in ("image", "sim:") else f" | {wr:,.0f} | ")
                counts = (f"{rs[0]['samples']}, {rs[0]['snapshots']}" if "black box" in row
                          else "")
                print(f"| {names[tree]} | {row} | {rs[0]['ticks']:,} | {lp:,.0f} | {extra} "
                      f"| {counts} |")
    if a.alone:
        print("\nthe recorder's handler alone (loop thread, µs a call, best of 7 x 1000)")
        print("| tree | robot | inputs | a list of inputs | an array('q') of inputs |")
        print("|---|---|---:|---:|---:|")
        for robot in robots:
            for tree in trees:
                r = _child(tree, "--one-alone", robot)
                print(f"| {names[tree]} | {robot} | {r['inputs']} | {r['list']:.2f} | "
                      f"{r['array']:.2f} |")
    if idle:
        print(f"\nidle at real time, {a.idle:g} s a row: CPU % of one core (median of "
              f"{a.rounds}; all rounds)")
        print("| tree | row | CPU % | rounds |")
        print("|---|---|---:|---|")
        for (tree, row), xs in idle.items():
            print(f"| {names[tree]} | {row} | {statistics.median(xs):.2f} | "
                  + ", ".join(f"{x:.2f}" for x in xs) + " |")


if __name__ == "__main__":
    main()
