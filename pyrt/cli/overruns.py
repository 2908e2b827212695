"""``pyrt overruns FILE``: what a timing log says about the loop's timing.

Prints the rate groups (period, releases, time per release, the overruns
charged to each group and the releases it missed), a per-task table (calls,
mean, p99 and max in µs, and the overruns attributed to the task: those in
which it ran longest; under their groups when there are several) and the
worst overruns with their tick, the group charged and the tasks run in them.
A log written before rate groups (pyrt-timing/1) is read too: no groups.  ``--json`` prints the
same as one JSON object; ``--plot PNG`` draws per-task histograms and an
overrun timeline (needs matplotlib: pip install 'pyrt[plot]').
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from pyrt.errors import ConfigError, UsageError
from pyrt.scheduler.stats import QUANTILE_NOTE, bin_edges, format_bound_us
from pyrt.scheduler.timinglog import TimingReport, read_timing_log


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "overruns",
        help="report per-task timing and the worst overruns from a --timing-log file",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("file", help="timing log (JSON Lines) written with --timing-log")
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.add_argument("--plot", metavar="PNG", help="also draw histograms and a timeline to PNG")
    p.add_argument(
        "--worst", type=int, default=10, metavar="N", help="overruns to list (default 10)"
    )
    p.set_defaults(run=run)


def report_dict(rep: TimingReport, worst: int) -> dict[str, Any]:
    """The report as plain data (what ``--json`` prints)."""
    s = rep.summary or {}
    return {
        "file": rep.path,
        "format": rep.format,
        "period_ns": rep.period_ns,
        "clock": rep.header.get("clock", ""),
        "ticks": s.get("ticks", 0),
        "overruns": len(rep.overruns),
        "missed": sum(int(r.get("missed", 0)) for r in rep.overruns),
        "startup_overruns": s.get("startup_overruns", 0),
        "startup_worst_ns": s.get("startup_worst_ns", 0),
        "lateness": s.get("lateness", {}),
        "groups": {
            name: {
                "period_us": g.period_ns / 1e3,
                "releases": g.releases,
                "mean_us": round(g.mean_ns / 1e3, 3),
                "p99_us": round(g.p99_ns / 1e3, 3),
                "max_us": round(g.max_ns / 1e3, 3),
                "overruns": g.overruns,
                "missed": g.missed,
                "tasks": g.tasks,
            }
            for name, g in rep.groups.items()
        },
        "tasks": {
            name: {
                "calls": t.calls,
                "mean_us": round(t.mean_ns / 1e3, 3),
                "p99_us": round(t.p99_ns / 1e3, 3),
                "max_us": round(t.max_ns / 1e3, 3),
                "overruns": t.overruns,
                "in_overruns": t.present,
                "group": t.group,
            }
            for name, t in rep.tasks.items()
        },
        "worst": [
            {
                "tick": r["tick"],
                "deadline_ns": r["deadline_ns"],
                "lateness_us": round(r["lateness_ns"] / 1e3, 3),
                "overrun_us": round(r["overrun_ns"] / 1e3, 3),
                "missed": r.get("missed", 0),
                "group": r.get("group"),
                "missed_releases": r.get("missed_releases", {}),
                "tasks": r["tasks"],
            }
            for r in rep.worst(worst)
        ],
    }


def format_report(rep: TimingReport, worst: int) -> str:
    """The report as the text table ``pyrt overruns`` prints."""
    d = report_dict(rep, worst)
    lines = [
        f"{rep.path}: tick {d['period_ns'] / 1e3:g} µs, clock {d['clock']}, "
        f"{d['ticks']} ticks, {d['overruns']} overruns, {d['missed']} deadlines missed"
    ]
    if rep.summary is None:
        lines.append("(no summary record: the log ends before the first summary)")
    if d["startup_overruns"]:
        lines.append(
            f"start-up (not counted above): {d['startup_overruns']} tick(s) overran, "
            f"worst {d['startup_worst_ns'] / 1e6:.2f} ms"
        )
    late = d["lateness"]
    if late and late.get("count"):
        m = late["max_ns"]
        lines.append(
            f"lateness µs: median {format_bound_us(late['p50_ns'], m)}  "
            f"p99 {format_bound_us(late['p99_ns'], m)}  "
            f"p99.9 {format_bound_us(late['p999_ns'], m)}  max {m / 1e3:.2f}"
        )
    lines.append("")
    groups = d["groups"]
    if groups:
        lines.append(f"{'group':<14}{'period µs':>10}{'releases':>10}{'mean µs':>11}"
                     f"{'p99 µs':>11}{'max µs':>11}{'overruns':>10}{'missed':>10}")
        for name, g in groups.items():
            lines.append(
                f"{name:<14}{g['period_us']:>10g}{g['releases']:>10}{g['mean_us']:>11.2f}"
                f"{format_bound_us(round(g['p99_us'] * 1e3), round(g['max_us'] * 1e3)):>11}"
                f"{g['max_us']:>11.2f}{g['overruns']:>10}{g['missed']:>10}")
        lines.append("")
    lines.append(
        f"{'task':<14}{'calls':>10}{'mean µs':>11}{'p99 µs':>11}{'max µs':>11}{'overruns':>10}"
    )
    several = len(groups) > 1
    for group in [*groups, ""] if several else [None]:
        rows = sorted((n, t) for n, t in d["tasks"].items()
                      if group is None or t["group"] == group)
        if group is not None and rows:
            lines.append(f"{group or '(no group)'}:")
        for name, t in rows:
            label = f"  {name}" if group is not None else name
            lines.append(
                f"{label:<14}{t['calls']:>10}{t['mean_us']:>11.2f}"
                f"{format_bound_us(round(t['p99_us'] * 1e3), round(t['max_us'] * 1e3)):>11}"
                f"{t['max_us']:>11.2f}{t['overruns']:>10}"
            )
    lines.append(f"({QUANTILE_NOTE})")
    if d["worst"]:
        lines.append("")
        lines.append(f"worst {len(d['worst'])} overruns:")
        lines.append(
            f"{'tick':>10}{'time s':>12}{'late µs':>10}{'over µs':>10}{'missed':>8}  "
            + ("charged to  " if groups else "") + "tasks (µs)"
        )
        for r in d["worst"]:
            tasks = ", ".join(f"{n} {ns / 1e3:.1f}" for n, ns in r["tasks"]) or "-"
            charged = f"{r['group'] or '-':<10}  " if groups else ""
            lines.append(
                f"{r['tick']:>10}{r['deadline_ns'] / 1e9:>12.6f}{r['lateness_us']:>10.1f}"
                f"{r['overrun_us']:>10.1f}{r['missed']:>8}  {charged}{tasks}"
            )
    return "\n".join(lines)


def histogram_steps(hist: list[list[int]]) -> tuple[list[int], list[int]]:
    """A sparse log-bin histogram (``[bin, count]`` pairs) as contiguous bars:
    ``len(counts) + 1`` edges in ns from the first bin's low edge to the last
    one's high edge, empty bins in between as 0."""
    if not hist:
        return [], []
    by_bin = {int(b): int(c) for b, c in hist}
    lo, hi = min(by_bin), max(by_bin)
    edges = [bin_edges(b)[0] for b in range(lo, hi + 1)] + [bin_edges(hi)[1]]
    return edges, [by_bin.get(b, 0) for b in range(lo, hi + 1)]


def _pyplot() -> Any:
    """matplotlib's pyplot on the Agg back end, or ConfigError with the install hint."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise ConfigError(
            "--plot needs matplotlib, which is not installed: pip install 'pyrt[plot]'"
        ) from None
    return plt


def plot_report(rep: TimingReport, png: str) -> None:
    """Per-task execution-time histograms and the overrun timeline, to PNG."""
    plt = _pyplot()
    fig = report_figure(rep)
    try:
        fig.savefig(png, dpi=100)
    except OSError as exc:
        raise ConfigError(f"cannot write plot: {exc.strerror}", png) from None
    finally:
        plt.close(fig)


def report_figure(rep: TimingReport) -> Any:
    """The figure ``--plot`` draws (matplotlib must be there): per-task
    execution-time histograms as closed bars, and the overrun timeline."""
    import matplotlib.pyplot as plt

    tasks = (rep.summary or {}).get("tasks", {})
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9, 7))
    for name, t in sorted(tasks.items()):
        edges, counts = histogram_steps(t.get("hist", []))
        if counts:
            # closed outline: every bar, the first and last included, has both edges
            ax1.stairs(counts, [e / 1e3 for e in edges], baseline=0.5, label=name)
    ax1.set_xscale("log")
    ax1.set_yscale("log")
    ax1.set_xlabel("execution time (µs)")
    ax1.set_ylabel("calls")
    ax1.set_title("per-task execution time")
    if tasks:
        ax1.legend(fontsize="small")
    if rep.overruns:
        ax2.plot(
            [r["deadline_ns"] / 1e9 for r in rep.overruns],
            [r["overrun_ns"] / 1e3 for r in rep.overruns],
            "r.",
        )
    ax2.set_xlabel("loop time (s)")
    ax2.set_ylabel("overrun past next deadline (µs)")
    ax2.set_title(f"{len(rep.overruns)} overruns")
    fig.tight_layout()
    return fig


def run(args: argparse.Namespace) -> int:
    if args.worst < 0:  # the options first: a usage error reads nothing
        raise UsageError(f"--worst must be >= 0, got {args.worst}")
    rep = read_timing_log(args.file)
    if args.plot:
        _pyplot()  # before any output: the whole report, or one line
    if args.json:
        json.dump(report_dict(rep, args.worst), sys.stdout, indent=2)
        sys.stdout.write("\n")
    else:
        sys.stdout.write(format_report(rep, args.worst) + "\n")
    if args.plot:
        plot_report(rep, args.plot)
        if not args.json:
            sys.stdout.write(f"plot written to {args.plot}\n")
    return 0
