"""Plain-text tables of timing statistics (the consoles' ``stats``, ``pyrt demo``)."""

from __future__ import annotations

from pyrt.scheduler.stats import QUANTILE_NOTE, LoopStatistics, format_bound_us

__all__ = ["format_statistics"]


def _us(ns: float) -> str:
    return f"{ns / 1e3:10.2f}"


def format_statistics(stats: LoopStatistics) -> str:
    """A table: tick summary, lateness, the rate groups (period, releases,
    time per release, overruns charged to the group, releases it missed),
    then calls/mean/p99/max/overruns per task (the ready queues' routines,
    under their group when there are several), then the same per loop
    handler (board polls, physics, motion, scope, mailbox:
    ``kind="handler"``), then the garbage collections (``gc``: inside
    ticks; ``gc idle``: run by the loop between ticks)."""
    lines = [
        f"tick {stats.period_ns / 1e3:g} µs: {stats.ticks} ticks, {stats.overruns} overruns, "
        f"{stats.missed} deadlines missed"
    ]
    if stats.startup_overruns:
        lines.append(
            f"start-up (not counted above): {stats.startup_overruns} tick(s) overran, "
            f"worst {stats.startup_worst_ns / 1e6:.2f} ms"
        )
    late = stats.lateness
    if late.count:
        m = late.max_ns
        lines.append(
            f"lateness µs: median {format_bound_us(late.p50_ns, m)}  "
            f"p99 {format_bound_us(late.p99_ns, m)}  p99.9 {format_bound_us(late.p999_ns, m)}  "
            f"max {m / 1e3:.2f}"
        )
    several = len(stats.groups) > 1
    width = max([12, *(len(name) + (3 if several else 1) for name in stats.tasks),
                 *(len(name) + 1 for name in stats.groups)])
    if stats.groups:
        lines.append(f"{'group':<{width}}{'period µs':>10}{'releases':>10}{'mean µs':>10}"
                     f"{'p99 µs':>10}{'max µs':>10}{'overruns':>10}{'missed':>10}")
        for g in stats.groups.values():
            lines.append(f"{g.name:<{width}}{g.period_ns / 1e3:>10g}{g.releases:>10}"
                         f"{_us(g.mean_ns)}{format_bound_us(g.p99_ns, g.max_ns):>10}"
                         f"{_us(g.max_ns)}{g.overruns:>10}{g.missed:>10}")
    for kind in ("task", "handler", "gc"):
        rows = sorted((n, t) for n, t in stats.tasks.items()
                      if t.kind == kind and not (kind == "handler" and t.group and several))
        if kind == "task" and several:  # under their groups, with the groups' handlers
            rows = [(n, t) for n, t in stats.tasks.items() if t.group and t.kind != "gc"]
        if kind != "task" and not rows:
            continue
        lines.append(
            f"{kind:<{width}}{'calls':>10}{'mean µs':>10}{'p99 µs':>10}{'max µs':>10}"
            f"{'overruns':>10}"
        )
        for group in stats.groups if kind == "task" and several else [""]:
            if group:
                lines.append(f"{group}:")
            for name, t in sorted(rows) if not group else sorted(
                    (n, t) for n, t in rows if t.group == group):
                label = f"  {name}" if group else name
                lines.append(
                    f"{label:<{width}}{t.calls:>10}{_us(t.mean_ns)}"
                    f"{format_bound_us(t.p99_ns, t.max_ns):>10}{_us(t.max_ns)}{t.overruns:>10}"
                )
    lines.append(f"({QUANTILE_NOTE})")
    return "\n".join(lines)
