"""What the flight recorder costs a tick, and what an idle recorded gripper costs a core,
for one or more source trees side by side in one run.

    python bench/recorder_cost.py                         # this tree
    python bench/recorder_cost.py --tree /tmp/old --tree .   # two trees, interleaved
    python bench/recorder_cost.py --tree . --tree .:int64    # this tree, and its image
                                                             # over 64-bit register files

Every row runs in a child process whose ``PYTHONPATH`` is the tree measured
(its compiled modules built in place), the trees interleaved row by row and
round by round, so that what the machine does meanwhile falls on all of them
alike.  Two measures:

* ``work``: virtual time, each robot moving (the gripper at 1 kHz with ``P``
  back and forth, the manipulator's prototype at 200 Hz), built as
  ``pyrt NAME`` builds it (:mod:`bench_journal`'s ``build`` and ``drive``):
  the loop thread's CPU time from the top of one tick to the top of the
  next, pooled over the rounds (p50, mean), for the rows ``sim:``, ``image``
  (``sim:?image=1``), ``image + empty handler`` (a handler that does nothing
  where the recorder's would be: what the loop charges for one more timed
  handler), ``image + recorder`` (a journal file) and ``image + black box``
  (the 10 s ring, no file); the recorder's and the black box's
  share is against ``image``, the target 5 %; and the journal writer
  thread's CPU a tick, whole and less its time in the calls that release
  the interpreter lock (zlib's compress and the C tick encoder, timed in
  the child): its turns with the lock, added to the loop thread's mean in
  the last column.
* ``idle`` (``--idle S``, 0 skips it): ``pyrt gripper`` (1 kHz) and ``pyrt
  manipulator`` (200 Hz) themselves, idle at real time with their stdin a pipe,
  the black box on (the default) and ``--black-box off``, and a bare Python
  sleep loop at 1 kHz: the process's CPU share (``/proc``) over ``S`` seconds
  after the start-up; the targets 5 % (gripper) and 3 % (manipulator).

Not part of the test run (it is a script, not a ``bench_*`` module).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROWS = ("sim:", "image", "image + empty handler", "image + recorder", "image + black box")
SECONDS = {"gripper": 10.0, "manipulator": 30.0}
#: A tree given as ``PATH:int64`` is measured with its simulated boards keeping
#: their inputs in 64-bit integers (:func:`int64_boards`: a projection).
INT64 = ":int64"


# -- one row, in a child process -------------------------------------------------------------


def int64_boards() -> bool:
    """A projection, not the product: the simulated boards of the gripper and the
    manipulator keep their inputs in an ``array('q')`` (their plant methods write
    it as they write the list) and offer it as ``input_buffer()``, so that a tree
    whose process image gathers such register files in C (``LocalImage.native``)
    reads them that way.  False where the tree has no such boards to change."""
    from array import array

    try:
        import pyrt.boards.simboards as sb

        from pyrt.boards.gripper import SimGripperBoard
    except ImportError:
        return False
    for cls, attr in ((sb.SimTIO10, "_in"), (sb.SimDataConcentrator, "_inputs"),
                      (SimGripperBoard, "_in")):
        init = cls.__init__

        def patched(self, *a, _init=init, _attr=attr, **kw):
            _init(self, *a, **kw)
            setattr(self, _attr, array("q", getattr(self, _attr)))

        cls.__init__ = patched  # type: ignore[method-assign]
        cls.input_buffer = lambda self, _attr=attr: getattr(self, _attr)  # type: ignore[attr-defined]
    return True


def one_row(robot: str, row: str, seconds: float) -> dict:
    """Build ``robot`` as the row says, drive it ``seconds`` of loop time; the
    per-tick CPU ns (loop thread) and the journal handler's mean."""
    sys.path.insert(0, str(HERE))
    import bench_journal as bj

    if os.environ.get("PYRT_BENCH_INT64"):
        int64_boards()

    boards = "sim:" if row == "sim:" or _one_tick_shape() else "sim:?image=1"
    outside = _time_outside_the_lock()
    with tempfile.TemporaryDirectory() as tmp:
        t = Path(tmp)
        clock = bj.TimedSimClock()
        path = t / "run.pj" if row == "image + recorder" else None
        rig = bj.build(robot, boards, clock, t, path, 10.0 if row.endswith("black box") else 0.0)
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
        i0 = len(clock.wall)
        w0, o0 = bj.writer_cpu_ns(), outside[0]
        bj.drive(rig, seconds)
        w1, o1 = bj.writer_cpu_ns(), outside[0]
        _dw, dc = clock.ticks_from(i0)
        st = rig.loop.statistics()
        rig.close()
    j = st.tasks.get("journal")
    native = getattr(rig.station.boards.image, "native", None) is not None
    return {"cpu": dc, "journal_ns": j.mean_ns if j else 0.0, "native": native,
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


def _child(tree: Path, *argv: str) -> dict:
    env = dict(os.environ, PYTHONPATH=str(tree))
    if str(tree).endswith(INT64):
        tree = Path(str(tree)[:-len(INT64)])
        env = dict(os.environ, PYTHONPATH=str(tree), PYRT_BENCH_INT64="1")
    out = subprocess.run([sys.executable, str(Path(__file__).resolve()), *argv], env=env,
                         capture_output=True, text=True, check=False, cwd=tree)
    if out.returncode:
        raise SystemExit(f"{tree}: {' '.join(argv)} failed:\n{out.stderr[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def _pct(xs: list[int], p: float) -> float:
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(p * len(xs)))] / 1e3


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--tree", action="append", type=Path,
                    help="a source tree (repeat: side by side); default this one")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--robot", action="append", choices=sorted(SECONDS))
    ap.add_argument("--idle", type=float, default=10.0, help="seconds of idle a row (0: none)")
    ap.add_argument("--no-work", action="store_true", help="only the idle rows")
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
    trees = [Path(str(Path(str(t)[:-len(INT64)]).resolve()) + INT64)
             if str(t).endswith(INT64) else t.resolve() for t in (a.tree or [HERE.parent])]
    robots = a.robot or ["gripper", "manipulator"]
    t0 = time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime())
    load0 = os.getloadavg()[0]
    work: dict[tuple, dict] = {}
    idle: dict[tuple, list[float]] = {}
    for _ in range(a.rounds):
        if not a.no_work:
            for robot in robots:
                for row in ROWS:
                    for tree in trees:
                        r = _child(tree, "--one", robot, row, str(SECONDS[robot]))
                        p = work.setdefault((tree, robot, row),
                                            {"cpu": [], "journal": [], "writer": [],
                                             "locked": []})
                        p["cpu"] += r["cpu"]
                        p["journal"].append(r["journal_ns"])
                        p["writer"].append(r.get("writer_ns", 0.0))
                        p["locked"].append(r.get("writer_locked_ns", 0.0))
        if a.idle > 0:
            for row in IDLE_ROWS:
                for tree in trees:
                    if row == "bare sleep" and tree != trees[0]:
                        continue
                    r = _child(tree, "--one-idle", row, str(a.idle))
                    idle.setdefault((tree, row), []).append(r["cpu_pct"])
    t1 = time.strftime("%H:%M:%S UTC", time.gmtime())
    print(f"{t0} -> {t1}, load average {load0:.2f} -> {os.getloadavg()[0]:.2f}; "
          f"{a.rounds} rounds, rows interleaved")
    names = {t: (t.name if len(trees) > 1 else "") for t in trees}
    if work:
        for robot in robots:
            print(f"\n{robot}, virtual time, moving ({a.rounds} x {SECONDS[robot]:g} s a row): "
                  "loop-thread CPU a tick, µs")
            print("| tree | row | ticks | p50 | p99 | mean | journal handler mean | "
                  "added p50 | added mean | writer CPU a tick | of it with the lock | "
                  "added mean with the writer's turns |")
            print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
            for tree in trees:
                base = work[(tree, robot, "image")]["cpu"]
                b50, bmean = _pct(base, .5), statistics.fmean(base) / 1e3
                for row in ROWS:
                    p = work[(tree, robot, row)]
                    c = p["cpu"]
                    p50, mean = _pct(c, .5), statistics.fmean(c) / 1e3
                    jm = statistics.fmean(p["journal"]) / 1e3
                    wm = statistics.fmean(p["writer"]) / 1e3
                    lm = statistics.fmean(p["locked"]) / 1e3
                    added = (f"{(p50 - b50) / b50 * 100:+.1f} % | {(mean - bmean) / bmean * 100:+.1f} %"
                             f" | {wm:.2f} | {lm:.2f} | {(mean + lm - bmean) / bmean * 100:+.1f} %"
                             if row.startswith("image +") else " | | | | ")
                    print(f"| {names[tree]} | {row} | {len(c):,} | {p50:.2f} | {_pct(c, .99):.2f} "
                          f"| {mean:.2f} | " + (f"{jm:.2f}" if jm else "") + f" | {added} |")
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
