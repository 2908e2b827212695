"""Journal benchmarks: what recording costs the loop thread, what the writer thread
spends encoding, and how large a minute of a 1 kHz gripper is.

Run: ``python -m pytest bench/bench_journal.py --benchmark-only -s``.  The figures
are in ``extra_info`` and on stdout.

* ``record_tick``: the loop thread's cost per tick (40 inputs of which 10 change,
  3 outputs written), the writer thread parked so that it takes no interpreter time
  while it is measured; target a few us, <= 5 % of the gripper's ~30 us tick work.
* ``record_tick at 1 kHz``: the same on a 1 kHz wall-clock loop with the writer
  thread running (encoding, compressing, writing a file): p50 and p99 of the call,
  and the loop's lateness with and without the journal.
* ``encode``: the writer thread's work per tick (off the loop thread).
* ``size``: bytes per minute at 1 kHz, idle and moving (10 inputs change every tick,
  3 outputs written, wall-clock lateness recorded); target <= 1 MB/min moving.

The stations themselves (the figures of docs/performance.md, "Flight recorder"):
the gripper at 1 kHz moving (``P`` back and forth) and the manipulator's
prototype at 200 Hz (5 ms tick) moving in the plane y = 0, each as plain
``sim:`` (the process image alone: every run has one), with a
:class:`~pyrt.station.recording.Recorder` writing a file, and with the 10 s
black box alone (what a real-time run keeps without ``--journal``), the rows
interleaved round by round (the first two rows are one program since
``sim:`` has one tick shape):

* ``station tick work``: virtual time; the work of every tick (from the top of
  one tick to the top of the next, the loop thread's CPU time and the wall
  time), p50, p99 and mean, the journal handler's own mean and the writer
  thread's CPU and the collections inside ticks; the image's price against
  plain ``sim:`` and the recorder's and the black box's against the image
  alone; target <= 5 %.
* ``station at real time`` (marker ``wallclock``; ``PYRT_JOURNAL_WALL_S``
  seconds a row, default 20, in ``PYRT_JOURNAL_WALL_ROUNDS`` parts, default 4;
  0 seconds skips it): a WallClock run of each row: the tick work (the
  handlers' wall time, tick by tick), lateness, overruns and the entries the
  loop blames them on, the journal's gaps and its size at real time; target:
  no added overruns.
* ``station size per minute``: virtual time, idle and moving, the second
  minute of a run (the header, with the databases, is in the first);
  target <= 1 MB/min for the gripper at 1 kHz moving.
* ``replay speed``: a run of ``PYRT_JOURNAL_REPLAY_MIN`` minutes of loop time
  (default 10) of each robot moving back and forth, recorded on virtual time
  and replayed with ``pyrt replay`` (the command's ``run``, the station's
  build included); target: the manipulator's in under 30 s.

``PYRT_JOURNAL_ROUNDS`` (default 3) sets the rounds of the virtual-time rows.
Skip the real-time rows with ``-m "not wallclock"``.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import random
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from pyrt.cli._journal import start_recorder
from pyrt.cli._station import station_parser
from pyrt.cli.replay import run as replay_run
from pyrt.commands import RobotShell
from pyrt.journal import DEFAULT_BLOCK_TICKS, Header, Journal, JournalReader
from pyrt.journal.format import BlockEncoder
from pyrt.scheduler import Loop, SimClock, WallClock
from pyrt.station.factory import find_station

PERIOD = 1_000_000
N_IN = 40
TICKS = 20_000


def gripper_header() -> Header:
    return Header(station="gripper", period_ns=PERIOD,
                  inputs=[f"in{i}" for i in range(N_IN)], outputs=[f"out{i}" for i in range(8)],
                  writers=("sensors", "jaw-move", "jaw-watch"))


def moving(n: int, seed: int = 1, late: bool = True, changing: int = 10) -> list[tuple]:
    """A moving gripper: ``changing`` of 40 inputs change every tick (encoder counts,
    ADC readings), 3 outputs are written, lateness as a wall clock has it."""
    rng = random.Random(seed)
    inputs = [rng.randrange(4000) for _ in range(N_IN)]
    out = []
    for k in range(n):
        for i in range(changing):
            inputs[i] += rng.randrange(-2, 4)
        lat = rng.randrange(20_000, 80_000) if late else 0
        writes = tuple((i, 1000 + (k // 7) % 50 + i, i % 3) for i in range(3)) \
            if changing else ()
        out.append((k, k * PERIOD + lat, lat, 0, list(inputs), writes, (), ()))
    return out


class Parked(io.RawIOBase):
    """A sink that holds the writer thread in its first write until released."""

    def __init__(self):
        self.release = threading.Event()

    def writable(self) -> bool:
        return True

    def write(self, b) -> int:
        self.release.wait(60)
        return len(b)


@pytest.mark.benchmark(group="journal: loop thread")
def test_record_tick(benchmark):
    """record_tick per TICKS ticks, the writer thread parked (the loop thread's cost alone)."""
    recs = moving(TICKS)
    journals = []

    def setup():
        sink = Parked()
        j = Journal(gripper_header(), sink, queue_ticks=TICKS + 10)
        journals.append((j, sink))
        return (j,), {}

    def run(j):
        rec = j.record_tick
        for r in recs:
            rec(*r)

    benchmark.pedantic(run, setup=setup, rounds=5, iterations=1)
    for j, sink in journals:
        sink.release.set()
        j.close()
    per_tick_us = benchmark.stats.stats.median / TICKS * 1e6
    benchmark.extra_info["us_per_tick"] = round(per_tick_us, 3)
    benchmark.extra_info["percent_of_30us_tick"] = round(per_tick_us / 30 * 100, 1)
    print(f"\nrecord_tick: {per_tick_us:.3f} us per tick "
          f"({per_tick_us / 30 * 100:.1f} % of a 30 us tick)")


@pytest.mark.benchmark(group="journal: writer thread")
def test_encode(benchmark):
    """The writer thread's encoding (and zlib) per TICKS ticks of a moving gripper."""
    recs = [(k, t, late, m, tuple(ins), outs, c, e) for k, t, late, m, ins, outs, c, e
            in moving(TICKS)]

    def run():
        enc = BlockEncoder(gripper_header())
        for r in recs:
            enc.add(*r)
            if enc.count >= DEFAULT_BLOCK_TICKS:
                enc.take()

    benchmark.pedantic(run, rounds=3, iterations=1)
    per_tick_us = benchmark.stats.stats.median / TICKS * 1e6
    benchmark.extra_info["us_per_tick"] = round(per_tick_us, 2)
    print(f"\nencode (writer thread): {per_tick_us:.2f} us per tick")


@pytest.mark.parametrize("kind", ["idle", "moving"])
def test_size_per_minute(kind, benchmark):
    """Bytes of one minute at 1 kHz through a Journal with its defaults."""
    recs = moving(60_000, changing=10 if kind == "moving" else 0)
    buf = io.BytesIO()

    def run():
        buf.seek(0)
        buf.truncate()
        j = Journal(gripper_header(), buf, lossless=True)
        for r in recs:
            j.record_tick(*r)
        j.close()

    benchmark.pedantic(run, rounds=1, iterations=1)
    size = len(buf.getvalue())
    benchmark.extra_info["bytes_per_minute"] = size
    print(f"\n{kind}: {size / 1e6:.3f} MB per minute at 1 kHz")
    if kind == "moving":
        assert size <= 1_000_000


def _wall_loop(seconds: float, journal: Journal | None, recs: list[tuple]
               ) -> tuple[list[int], list[int]]:
    """A 1 kHz loop on the wall clock (sleep, then spin, to absolute deadlines) that
    hands each tick to ``journal``; the call durations and the lateness, ns."""
    calls, late = [], []
    now = time.monotonic_ns
    deadline = now() + PERIOD
    n = int(seconds * 1000)
    for k in range(n):
        while True:
            left = deadline - now()
            if left <= 0:
                break
            if left > 200_000:
                time.sleep((left - 150_000) / 1e9)
        start = now()
        late.append(start - deadline)
        if journal is not None:
            r = recs[k % len(recs)]
            journal.record_tick(k, start, start - deadline, 0, r[4], r[5])
            calls.append(now() - start)
        deadline += PERIOD
        if now() > deadline:
            deadline += ((now() - deadline) // PERIOD + 1) * PERIOD
    return calls, late


def _pct(xs: list[int], p: float) -> float:
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(p * len(xs)))] / 1e3


def test_record_tick_at_1khz(benchmark, tmp_path):
    """On a 1 kHz wall-clock loop with the writer running: record_tick p50/p99 and the
    loop's lateness p50/p99 with and without the journal (3 s each)."""
    recs = moving(3000)
    results = {}

    def run():
        _calls, base = _wall_loop(3.0, None, recs)
        j = Journal(gripper_header(), tmp_path / "bench.pj")
        calls, late = _wall_loop(3.0, j, recs)
        j.close()
        results.update(calls=calls, late=late, base=base, dropped=j.dropped,
                       size=j.bytes_written)

    benchmark.pedantic(run, rounds=1, iterations=1)
    info = {
        "record_tick_p50_us": _pct(results["calls"], 0.5),
        "record_tick_p99_us": _pct(results["calls"], 0.99),
        "record_tick_max_us": max(results["calls"]) / 1e3,
        "lateness_p50_us_without": _pct(results["base"], 0.5),
        "lateness_p99_us_without": _pct(results["base"], 0.99),
        "lateness_p50_us_with": _pct(results["late"], 0.5),
        "lateness_p99_us_with": _pct(results["late"], 0.99),
        "ticks_dropped": results["dropped"],
        "bytes": results["size"],
    }
    benchmark.extra_info.update(info)
    print("\n" + "\n".join(f"{k}: {v:.1f}" if isinstance(v, float) else f"{k}: {v}"
                           for k, v in info.items()))


# -- the stations: a real tick's cost, a real minute's size, a replay's speed ----------------

ROUNDS = int(os.environ.get("PYRT_JOURNAL_ROUNDS", "3"))
WALL_S = float(os.environ.get("PYRT_JOURNAL_WALL_S", "20"))
WALL_ROUNDS = int(os.environ.get("PYRT_JOURNAL_WALL_ROUNDS", "4"))
REPLAY_MIN = float(os.environ.get("PYRT_JOURNAL_REPLAY_MIN", "10"))

ROBOTS = ("gripper", "manipulator")
#: Loop seconds of one virtual-time row (the gripper ticks at 1 ms, the manipulator at 5 ms).
VIRTUAL_S = {"gripper": 30.0, "manipulator": 90.0}
#: Back and forth: the gripper's jaws, the prototype's source in the plane y = 0.
MOVES = {"gripper": ("P 30mm", "P 20mm"),
         "manipulator": ("prototype to 10 0 60", "prototype to -10 0 40")}
#: Loop seconds between two moves.
PAUSE_S = {"gripper": 0.2, "manipulator": 1.0}
#: (board URL, row name, what is recorded: None, "file" or "box"): the rows of
#: every table, in the order they run.  The last is what ``pyrt NAME --speed 1``
#: runs without ``--journal``: its black box (10 s in memory, no file).
VARIANTS = (("sim:", "sim:", None), ("sim:", "image", None),
            ("sim:", "image + recorder", "file"),
            ("sim:", "image + black box", "box"))


class TimedSimClock(SimClock):
    """A SimClock that notes the top of every tick: perf_counter_ns and the
    loop thread's CPU time (``end_run`` closes a run of the loop: -1 follows)."""

    def __init__(self) -> None:
        super().__init__()
        self.wall: list[int] = []
        self.cpu: list[int] = []
        self._w = time.perf_counter_ns
        self._c = time.thread_time_ns

    def start_tick(self, deadline_ns: int) -> int:
        self.wall.append(self._w())
        self.cpu.append(self._c())
        return super().start_tick(deadline_ns)

    def end_run(self) -> None:
        self.wall.append(self._w())
        self.cpu.append(self._c())
        self.wall.append(-1)
        self.cpu.append(-1)

    def ticks_from(self, i0: int) -> tuple[list[int], list[int]]:
        """The work of every tick noted from index ``i0`` on: (wall ns, CPU ns)."""
        w, c = self.wall, self.cpu
        dw, dc = [], []
        for i in range(i0, len(w) - 1):
            if w[i] >= 0 and w[i + 1] >= 0:
                dw.append(w[i + 1] - w[i])
                dc.append(c[i + 1] - c[i])
        return dw, dc


class TimedWallClock(WallClock):
    """A WallClock that notes when each tick starts and how late; with
    :meth:`attach_end` (the loop's last handler), each tick's work."""

    def __init__(self) -> None:
        super().__init__()
        self.start = 0
        self.late: list[int] = []
        self.work: list[int] = []

    def wait_until(self, deadline_ns: int) -> None:
        super().wait_until(deadline_ns)
        self.start = now = time.monotonic_ns()
        self.late.append(now - self.wall_deadline(deadline_ns))

    def attach_end(self, loop: Loop) -> None:
        mono, work = time.monotonic_ns, self.work

        def end_of_tick(now_ns: int) -> None:
            work.append(mono() - self.start)

        loop.attach(end_of_tick, name="bench:end")


@dataclass
class Rig:
    """A built station as ``pyrt NAME`` builds it, with its console and recorder."""

    robot: str
    station: object
    loop: Loop
    shell: RobotShell
    recorder: object
    out: io.StringIO = field(default_factory=io.StringIO)

    @property
    def journal(self) -> Journal:
        return self.recorder.journal  # type: ignore[attr-defined]

    def start(self) -> None:
        """Start the loop and run the start-up commands (the gripper's I)."""
        self.station.start()  # type: ignore[attr-defined]
        for line in self.station.profile.startup_commands:  # type: ignore[attr-defined]
            self.shell.onecmd(line)

    def close(self) -> None:
        self.station.close()  # type: ignore[attr-defined]
        if self.recorder is not None:
            self.recorder.close()  # type: ignore[attr-defined]


_dbs = iter(range(1_000_000))


def build(robot: str, boards: str, clock, tmp: Path, journal: Path | None = None,
          black_box: float = 0.0) -> Rig:
    """The station ``robot`` on ``boards``, built as ``pyrt ROBOT --boards BOARDS
    [--journal FILE] --black-box SECONDS|off`` builds it (the manipulator: a
    fresh copy of the prototype's database in ``tmp``), on a loop of ``clock``."""
    factory = find_station(robot)
    argv = ["--boards", boards]
    if robot == "manipulator":
        argv += ["--init-db", str(tmp / f"db{next(_dbs)}"), "--station", "prototype"]
    args = station_parser(factory, f"pyrt {robot}").parse_args(argv)
    args.speed = None if clock.virtual else 1.0
    args.journal = str(journal) if journal is not None else None
    args.black_box = black_box
    factory.configure(args, lambda _line: None)
    loop = Loop(clock, period_ns=args.tick_us * 1000, timing=True)
    station = factory.build(loop, args)
    recorder = start_recorder(station, args, robot, lambda _line: None)
    out = io.StringIO()
    return Rig(robot, station, loop, RobotShell(station, out), recorder, out)


def drive(rig: Rig, seconds: float) -> int:
    """Move back and forth for ``seconds`` of loop time; the moves begun."""
    loop, shell = rig.loop, rig.shell
    end = loop.now_ns + int(seconds * 1e9)
    moves = MOVES[rig.robot]
    k = 0
    while loop.now_ns < end:
        shell.onecmd(moves[k % 2])
        k += 1
        left = (end - loop.now_ns) / 1e9
        if left > 0:
            shell.onecmd(f"wait {left:.3f}")
        left = (end - loop.now_ns) / 1e9
        if left > 0:
            shell.onecmd(f"sleep {min(PAUSE_S[rig.robot], left):.3f}")
    shell.onecmd("stop")
    return k


def writer_cpu_ns() -> int:
    """The CPU time of the journal's writer thread (0 if there is none)."""
    for t in threading.enumerate():
        if t.name == "pyrt-journal" and t.is_alive() and t.ident is not None:
            return time.clock_gettime_ns(time.pthread_getcpuclockid(t.ident))
    return 0


def _us(xs: list[int], p: float) -> float:
    return _pct(xs, p) if xs else 0.0


def _mean_us(xs: list[int]) -> float:
    return sum(xs) / len(xs) / 1e3 if xs else 0.0


def _plus(a: float, b: float) -> str:
    return f"{b - a:+.2f} µs ({(b - a) / a * 100:+.1f} %)" if a else "n/a"


def _load() -> str:
    return (time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime())
            + " load average " + " ".join(f"{x:.2f}" for x in os.getloadavg()))


@contextlib.contextmanager
def _clean() -> Iterator[None]:
    import gc
    gc.collect()
    yield


@pytest.mark.benchmark(group="journal: stations")
def test_station_tick_work(benchmark, tmp_path):
    """Virtual time, moving: the work of every tick of each robot as sim:, image,
    image + recorder (rows interleaved, ROUNDS rounds pooled)."""
    pooled: dict[tuple[str, str], dict[str, list]] = {}

    def one(robot: str, boards: str, name: str, record: str | None) -> None:
        clock = TimedSimClock()
        path = tmp_path / f"{robot}.pj" if record == "file" else None
        rig = build(robot, boards, clock, tmp_path, path, 10.0 if record == "box" else 0.0)
        run = rig.loop.run

        def timed_run(*a, **kw):
            try:
                return run(*a, **kw)
            finally:
                clock.end_run()

        rig.loop.run = timed_run  # type: ignore[method-assign]
        rig.start()
        rig.loop.reset_statistics()
        i0 = len(clock.wall)
        cpu0 = writer_cpu_ns()
        drive(rig, VIRTUAL_S[robot])
        writer = writer_cpu_ns() - cpu0
        dw, dc = clock.ticks_from(i0)
        st = rig.loop.statistics()
        rig.close()
        p = pooled.setdefault((robot, name), {"wall": [], "cpu": [], "writer": [], "ticks": [],
                                              "journal": [], "gc": []})
        p["wall"] += dw
        p["cpu"] += dc
        p["writer"].append(writer)
        p["ticks"].append(len(dc))
        j = st.tasks.get("journal")
        p["journal"].append((j.calls, j.mean_ns) if j else (0, 0.0))
        g = st.tasks.get("gc")
        p["gc"].append(g.calls if g else 0)

    def run() -> None:
        for _ in range(ROUNDS):
            for robot in ROBOTS:
                for boards, name, record in VARIANTS:
                    with _clean():
                        one(robot, boards, name, record)

    load0 = _load()
    benchmark.pedantic(run, rounds=1, iterations=1)
    lines = [f"\n{load0} -> {_load()}"]
    for robot in ROBOTS:
        lines.append(f"\n{robot}, virtual time, moving ({ROUNDS} x {VIRTUAL_S[robot]:g} s of loop "
                     "time a row): work per tick, µs")
        lines.append("| row | ticks | CPU p50 | CPU p99 | CPU mean | wall p50 | wall p99 | wall mean "
                     "| journal handler mean | writer thread CPU a tick | gc in ticks |")
        lines.append("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
        means = {}
        for _b, name, _r in VARIANTS:
            p = pooled[(robot, name)]
            ticks = sum(p["ticks"])
            jc = sum(c for c, _ in p["journal"])
            jm = (sum(c * m for c, m in p["journal"]) / jc / 1e3) if jc else 0.0
            row = {"ticks": ticks, "cpu_p50": _us(p["cpu"], .5), "cpu_p99": _us(p["cpu"], .99),
                   "cpu_mean": _mean_us(p["cpu"]), "wall_p50": _us(p["wall"], .5),
                   "wall_p99": _us(p["wall"], .99), "wall_mean": _mean_us(p["wall"]),
                   "journal_mean": jm, "writer_cpu": sum(p["writer"]) / ticks / 1e3 if ticks else 0,
                   "gc": sum(p["gc"])}
            means[name] = row
            benchmark.extra_info[f"{robot}/{name}"] = {k: round(v, 3) for k, v in row.items()}
            lines.append(f"| {name} | {ticks:,} | {row['cpu_p50']:.2f} | {row['cpu_p99']:.2f} | "
                         f"{row['cpu_mean']:.2f} | {row['wall_p50']:.2f} | {row['wall_p99']:.2f} | "
                         f"{row['wall_mean']:.2f} | "
                         + (f"{jm:.2f}" if jc else "") + " | "
                         + (f"{row['writer_cpu']:.2f}" if name.startswith("image +") else "")
                         + f" | {row['gc']} |")
        a, b, c, d = (means[n] for _u, n, _r in VARIANTS)
        for what in ("cpu_p50", "cpu_p99", "cpu_mean", "wall_mean"):
            lines.append(f"  {what}: image - sim: {_plus(a[what], b[what])}; "
                         f"recorder - image: {_plus(b[what], c[what])}; "
                         f"black box - image: {_plus(b[what], d[what])}; "
                         f"recorder + image - sim: {_plus(a[what], c[what])}")
    print("\n".join(lines))


def _window(rig: Rig, clock: TimedWallClock, seconds: float) -> dict:
    """Drive ``rig`` at real time for ``seconds``; what its loop and journal did."""
    loop = rig.loop
    i0, l0 = len(clock.work), len(clock.late)
    ov0 = loop.overruns
    journal = rig.journal if rig.recorder is not None else None
    if journal is not None:
        journal.flush(10)
        b0, d0 = journal.bytes_written, journal.dropped
    runner = rig.station.runner  # type: ignore[attr-defined]
    blamed0 = {k: t.overruns for k, t in runner.statistics().tasks.items()}
    cpu0 = writer_cpu_ns()
    t0 = loop.now_ns
    drive(rig, seconds)
    span = loop.now_ns - t0
    blamed = {k: t.overruns - blamed0.get(k, 0) for k, t in runner.statistics().tasks.items()}
    out = {"work": clock.work[i0:], "late": clock.late[l0:], "overruns": loop.overruns - ov0,
           "writer": writer_cpu_ns() - cpu0, "span_ns": span, "bytes": 0, "dropped": 0,
           "blamed": [blamed]}
    if journal is not None:
        journal.flush(10)
        out.update(bytes=journal.bytes_written - b0, dropped=journal.dropped - d0)
    return out


@pytest.mark.wallclock
@pytest.mark.skipif(WALL_S <= 0, reason="PYRT_JOURNAL_WALL_S=0")
@pytest.mark.benchmark(group="journal: stations")
def test_station_at_real_time(benchmark, tmp_path):
    """Real time (WallClock), moving, WALL_S s a row in WALL_ROUNDS parts, rows
    interleaved: the tick work, lateness, overruns (and the entries they are
    blamed on), and the journal's gaps and size."""
    pooled: dict[tuple[str, str], dict[str, list]] = {}

    def one(robot: str, boards: str, name: str, record: str | None, seconds: float) -> None:
        clock = TimedWallClock()
        path = tmp_path / f"{robot}-rt.pj" if record == "file" else None
        rig = build(robot, boards, clock, tmp_path, path, 10.0 if record == "box" else 0.0)
        clock.attach_end(rig.loop)
        rig.start()
        w = _window(rig, clock, seconds)
        rig.close()
        p = pooled.setdefault((robot, name), {k: [] for k in w})
        for k, v in w.items():
            if isinstance(v, list):
                p[k] += v
            else:
                p[k].append(v)

    def run() -> None:
        for _ in range(WALL_ROUNDS):
            for robot in ROBOTS:
                for boards, name, record in VARIANTS:
                    with _clean():
                        one(robot, boards, name, record, WALL_S / WALL_ROUNDS)

    load0 = _load()
    benchmark.pedantic(run, rounds=1, iterations=1)
    lines = [f"\n{load0} -> {_load()}"]
    for robot in ROBOTS:
        lines.append(f"\n{robot}, real time, moving ({WALL_ROUNDS} x {WALL_S / WALL_ROUNDS:g} s "
                     "a row): µs")
        lines.append("| row | ticks | work p50 | work p99 | work mean | lateness p99 | overruns "
                     "| writer thread CPU a tick | ticks lost (gaps) | journal MB/min |")
        lines.append("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
        rows = {}
        for _b, name, _r in VARIANTS:
            p = pooled[(robot, name)]
            ticks = len(p["work"])
            minutes = sum(p["span_ns"]) / 60e9
            row = {"ticks": ticks, "work_p50": _us(p["work"], .5), "work_p99": _us(p["work"], .99),
                   "work_mean": _mean_us(p["work"]), "late_p99": _us(p["late"], .99),
                   "overruns": sum(p["overruns"]),
                   "writer_cpu": sum(p["writer"]) / ticks / 1e3 if ticks else 0.0,
                   "dropped": sum(p["dropped"]),
                   "mb_per_min": sum(p["bytes"]) / 1e6 / minutes if minutes else 0.0}
            rows[name] = row
            benchmark.extra_info[f"{robot}/{name}"] = {k: round(v, 3) for k, v in row.items()}
            rec = name.startswith("image +")
            size = f"{row['mb_per_min']:.3f}" if name.endswith("recorder") else ""
            lines.append(f"| {name} | {ticks:,} | {row['work_p50']:.2f} | {row['work_p99']:.2f} | "
                         f"{row['work_mean']:.2f} | {row['late_p99']:.1f} | {row['overruns']} | "
                         + (f"{row['writer_cpu']:.2f} | {row['dropped']} | {size}" if rec
                            else " | | ") + " |")
        for _b, name, _r in VARIANTS:
            blamed: dict[str, int] = {}
            for b in pooled[(robot, name)]["blamed"]:
                for k, v in b.items():
                    blamed[k] = blamed.get(k, 0) + v
            top = sorted(((v, k) for k, v in blamed.items() if v), reverse=True)
            lines.append(f"  {name}: overruns blamed on "
                         + (", ".join(f"{k} {v}" for v, k in top) or "nothing"))
        a, b, c, d = (rows[n] for _u, n, _r in VARIANTS)
        for what in ("work_p50", "work_p99", "work_mean"):
            lines.append(f"  {what}: image - sim: {_plus(a[what], b[what])}; "
                         f"recorder - image: {_plus(b[what], c[what])}; "
                         f"black box - image: {_plus(b[what], d[what])}")
    print("\n".join(lines))


@pytest.mark.benchmark(group="journal: stations")
def test_station_size_per_minute(benchmark, tmp_path):
    """Virtual time: the journal's bytes in the second minute of an idle and of a
    moving run of each robot (the header, with the databases, is in the first)."""
    rows = []

    def run() -> None:
        for robot in ROBOTS:
            for kind in ("idle", "moving"):
                with _clean():
                    path = tmp_path / f"{robot}-{kind}.pj"
                    rig = build(robot, "sim:", SimClock(), tmp_path, path)
                    rig.start()
                    header = len(rig.recorder.header.encode())  # type: ignore[attr-defined]
                    sizes = []
                    for _ in range(2):
                        if kind == "moving":
                            drive(rig, 60.0)
                        else:
                            rig.shell.onecmd("sleep 60")
                        rig.journal.flush(60)
                        sizes.append(rig.journal.bytes_written)
                    rig.close()
                    rows.append((robot, kind, rig.loop.period_ns, header, sizes[1] - sizes[0],
                                 path.stat().st_size))

    benchmark.pedantic(run, rounds=1, iterations=1)
    lines = ["\n| robot | tick | run | MB a minute (the second) | header kB | file after 2 min, MB |",
             "|---|---:|---|---:|---:|---:|"]
    for robot, kind, period, header, minute, total in rows:
        benchmark.extra_info[f"{robot}/{kind}"] = {"bytes_per_minute": minute, "header": header,
                                                   "file": total}
        lines.append(f"| {robot} | {period / 1e6:g} ms | {kind} | {minute / 1e6:.3f} | "
                     f"{header / 1e3:.1f} | {total / 1e6:.3f} |")
    print("\n".join(lines))


def _replay(path: Path) -> tuple[float, str, int]:
    """``pyrt replay FILE`` (its ``run``): wall seconds, its output, its status."""
    args = argparse.Namespace(file=str(path), until=None, scope=None, scope_save=None)
    buf = io.StringIO()
    t0 = time.perf_counter()
    with contextlib.redirect_stdout(buf):
        status = replay_run(args)
    return time.perf_counter() - t0, buf.getvalue(), status


@pytest.mark.benchmark(group="journal: stations")
def test_replay_speed(benchmark, tmp_path):
    """REPLAY_MIN minutes of loop time of each robot moving back and forth,
    recorded on virtual time, then replayed by pyrt replay: wall seconds."""
    rows = []

    def run() -> None:
        for robot in ("manipulator", "gripper"):
            with _clean():
                path = tmp_path / f"{robot}-{REPLAY_MIN:g}min.pj"
                t0 = time.perf_counter()
                rig = build(robot, "sim:", SimClock(), tmp_path, path)
                rig.start()
                moves = drive(rig, REPLAY_MIN * 60)
                ticks = rig.loop.tick_index
                rig.close()
                recorded_s = time.perf_counter() - t0
            with _clean():
                t0 = time.perf_counter()
                n = sum(1 for _ in JournalReader(path))
                read_s = time.perf_counter() - t0
            with _clean():
                replay_s, text, status = _replay(path)
            rows.append((robot, ticks, moves, path.stat().st_size, recorded_s, read_s, n, replay_s,
                         text, status))

    benchmark.pedantic(run, rounds=1, iterations=1)
    lines = [f"\n{REPLAY_MIN:g} minutes of loop time, moving back and forth",
             "| robot | ticks | moves | journal MB | recording run (virtual time), s | "
             "reading the journal alone, s | pyrt replay, s | loop time / replay |",
             "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for robot, ticks, moves, size, rec_s, read_s, _n, rep_s, text, status in rows:
        verdict = [ln for ln in text.splitlines() if ln.startswith(("replayed", "replay differs"))]
        benchmark.extra_info[robot] = {"ticks": ticks, "bytes": size, "record_s": round(rec_s, 2),
                                       "read_s": round(read_s, 2), "replay_s": round(rep_s, 2),
                                       "verdict": verdict}
        lines.append(f"| {robot} | {ticks:,} | {moves} | {size / 1e6:.2f} | {rec_s:.1f} | "
                     f"{read_s:.1f} | {rep_s:.1f} | {REPLAY_MIN * 60 / rep_s:.0f}x |")
        lines.append(f"  {robot}: {' / '.join(verdict)} (exit {status})")
    print("\n".join(lines))
    for row in rows:
        assert row[9] == 0, row[8]
