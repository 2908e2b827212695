"""How pyrt's costs grow with the work: four curves, each with a plot.

Run: ``python bench/bench_scaling.py [--out DIR] [--quick]`` (or
``python -m pytest bench/bench_scaling.py -s``).  It writes
``DIR/scaling.json`` (the figures) and ``DIR/scaling.png`` (four panels;
DIR defaults to ``docs/performance``), and prints a table.

1. **Dispatch** per tick against 1, 6, 32, 128 and 255 period-1 tasks on
   one ready queue (SimClock, timing on), side by side with simpy running
   the same number of processes each waking every time unit; best of 3,
   interleaved.
2. **Scope** sampling per tick against 1, 4, 16 and 64 channels (roll
   mode, every tick), median of 3 runs of 20,000 samples.
3. **Server**: the gripper served on a real-time loop; N load clients
   (1, 8, 32, 128, 256; each one STATUS in flight, in processes of their
   own at nice 19; the server's client limit raised to 264 for it) while
   the privileged client (authenticated) times its own STATUS round trips:
   total STATUS/s of the load, and the privileged round trip's median and
   p99.
4. **Manipulator poll** (one :meth:`PolyAxis.poll` during a move, physics
   not stepped) against the ropes of the packaged stations: 3 (prototype)
   and 5 (sno); median of 2,000 polls.  No synthetic 8-rope station is
   built (a station needs its whole geometry and calibration tables).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests"))

TASKS = (1, 6, 32, 128, 255)
CHANNELS = (1, 4, 16, 64)
CLIENTS = (1, 8, 32, 128, 256)
ROPES = {"prototype": 3, "sno": 5}
MOVES = {"prototype": (60.0, 0.0, 140.0), "sno": (80.0, 60.0, 100.0)}


def dispatch_curve(quick: bool = False) -> list[dict]:
    """µs per tick of pyrt (timing on) and simpy against the number of tasks."""
    from bench_scheduler import best_of, make_loop, simpy_run

    rows = []
    for n in TASKS:
        ticks = max(400, (30_000 if quick else 120_000) // n)
        pyrt_s = simpy_s = float("inf")
        for _ in range(3):
            pyrt_s = min(pyrt_s, best_of(lambda n=n, t=ticks: make_loop(n).run(t), 1))
            simpy_s = min(simpy_s, best_of(lambda n=n, t=ticks: simpy_run(n, t), 1))
        rows.append({"tasks": n, "ticks": ticks, "pyrt_us": pyrt_s / ticks * 1e6,
                     "simpy_us": simpy_s / ticks * 1e6, "ratio": simpy_s / pyrt_s})
    return rows


def scope_curve(quick: bool = False) -> list[dict]:
    """µs per tick of one scope sample against the number of channels."""
    from pyrt.scope.scope import Scope
    from pyrt.scope.sources import Source

    rows = []
    ticks = 5_000 if quick else 20_000
    for ch in CHANNELS:
        runs = []
        for _ in range(3):
            values = [float(i) for i in range(ch)]
            scope = Scope(capacity=16_000, max_channels=64)
            for i in range(ch):
                scope.add(f"c{i}", Source.item(values, i))
            scope.run("roll")
            sample = scope.sample
            t0 = time.perf_counter()
            for k in range(ticks):
                sample(k * 1_000_000)
            runs.append((time.perf_counter() - t0) / ticks * 1e6)
        rows.append({"channels": ch, "us": statistics.median(runs)})
    return rows


def server_curve(quick: bool = False) -> list[dict]:
    """STATUS/s of N load clients and the privileged client's round trip."""
    from _server_rig import run_load, served

    seconds = 1.0 if quick else 2.0
    rows = []
    with served(wall=True, max_clients=max(CLIENTS) + 8) as sv:
        op = sv.operator()
        for n in CLIENTS:
            trips: list[float] = []

            def privileged(trips=trips) -> None:
                end = time.perf_counter() + seconds * 0.8
                while time.perf_counter() < end:
                    t0 = time.perf_counter()
                    op.request("STATUS")
                    trips.append(time.perf_counter() - t0)

            load = run_load(sv.host, sv.port, n, seconds, "STATUS",
                            procs=1 if n == 1 else 2, during=privileged)
            trips.sort()
            rows.append({"clients": n, "status_per_s": load["per_s"], "errors": load["errors"],
                         "privileged_median_us": trips[len(trips) // 2] * 1e6,
                         "privileged_p99_us": trips[int(len(trips) * 0.99)] * 1e6,
                         "privileged_requests": len(trips)})
        op.close()
    return rows


def poll_curve(quick: bool = False) -> list[dict]:
    """µs of one manipulator control poll against the number of ropes."""
    from _manipulator_rig import make_station

    rows = []
    for name, ropes in ROPES.items():
        with tempfile.TemporaryDirectory() as tmp:
            station, runner = make_station(Path(tmp), name)
            pa = station.polyaxis
            runner.call(pa.to, MOVES[name])
            runner.sleep(20.0)
            clock = [station.loop.now_ns * 1e-9]
            times = []
            for _ in range(500 if quick else 2000):
                clock[0] += pa.poll_s
                t0 = time.perf_counter()
                pa.poll(clock[0])
                times.append(time.perf_counter() - t0)
            station.close()
        times.sort()
        rows.append({"ropes": ropes, "station": name, "median_us": times[len(times) // 2] * 1e6,
                     "min_us": times[0] * 1e6})
    return rows


def plot(results: dict, path: Path) -> None:
    """Four panels, one per curve, linear axes (log x where the sizes span decades)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(2, 2, figsize=(11, 8))
    d = results["dispatch"]
    a = ax[0][0]
    a.plot([r["tasks"] for r in d], [r["pyrt_us"] for r in d], "o-", label="pyrt (timing on)")
    a.plot([r["tasks"] for r in d], [r["simpy_us"] for r in d], "s--", label="simpy")
    a.set(title="dispatch: cost per tick", xlabel="period-1 tasks", ylabel="µs per tick")
    a.legend()
    s = results["scope"]
    a = ax[0][1]
    a.plot([r["channels"] for r in s], [r["us"] for r in s], "o-")
    a.set(title="scope: sampling cost per tick", xlabel="channels", ylabel="µs per tick")
    v = results["server"]
    a = ax[1][0]
    a.plot([r["clients"] for r in v], [r["status_per_s"] for r in v], "o-", label="STATUS/s")
    a.set(title="server: load and privileged round trip", xlabel="clients", ylabel="STATUS/s")
    a.set_xscale("log", base=2)
    b = a.twinx()
    b.plot([r["clients"] for r in v], [r["privileged_median_us"] / 1e3 for r in v], "s--",
           color="C1", label="privileged median")
    b.plot([r["clients"] for r in v], [r["privileged_p99_us"] / 1e3 for r in v], "^:",
           color="C2", label="privileged p99")
    b.set_ylabel("round trip ms")
    a.legend(loc="upper left")
    b.legend(loc="upper right")
    p = results["poll"]
    a = ax[1][1]
    a.plot([r["ropes"] for r in p], [r["median_us"] for r in p], "o-", label="median")
    a.plot([r["ropes"] for r in p], [r["min_us"] for r in p], "s--", label="fastest")
    a.set(title="manipulator control poll", xlabel="ropes", ylabel="µs per poll")
    a.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def run(out: Path, quick: bool = False) -> dict:
    """Measure the four curves, write DIR/scaling.json and DIR/scaling.png."""
    results = {
        "when": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "dispatch": dispatch_curve(quick),
        "scope": scope_curve(quick),
        "server": server_curve(quick),
        "poll": poll_curve(quick),
    }
    out.mkdir(parents=True, exist_ok=True)
    (out / "scaling.json").write_text(json.dumps(results, indent=1) + "\n")
    plot(results, out / "scaling.png")
    return results


def table(results: dict) -> str:
    """The figures as text."""
    lines = ["dispatch (µs per tick): tasks, pyrt, simpy, simpy/pyrt"]
    lines += [f"  {r['tasks']:4d} {r['pyrt_us']:9.2f} {r['simpy_us']:9.2f} {r['ratio']:6.2f}x"
              for r in results["dispatch"]]
    lines.append("scope (µs per tick): channels, cost")
    lines += [f"  {r['channels']:4d} {r['us']:9.3f}" for r in results["scope"]]
    lines.append("server: clients, STATUS/s, privileged median µs, p99 µs")
    lines += [f"  {r['clients']:4d} {r['status_per_s']:9.0f} {r['privileged_median_us']:9.0f}"
              f" {r['privileged_p99_us']:9.0f}" for r in results["server"]]
    lines.append("manipulator poll (µs): ropes, median, fastest")
    lines += [f"  {r['ropes']:4d} {r['median_us']:9.1f} {r['min_us']:9.1f}"
              for r in results["poll"]]
    return "\n".join(lines)


def test_scaling_curves(tmp_path):
    """The four curves, quick, into a temporary directory (the figures printed with -s)."""
    results = run(tmp_path, quick=True)
    assert (tmp_path / "scaling.png").stat().st_size > 0
    print("\n" + table(results))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=HERE.parent / "docs" / "performance")
    ap.add_argument("--quick", action="store_true", help="fewer ticks, shorter windows")
    args = ap.parse_args(argv)
    results = run(args.out, args.quick)
    sys.stdout.write(table(results) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
