"""``pyrt logsort LOGFILE``: split a manipulator state log per axis (000, section 18).

The log (``log`` in ``pyrt manipulator``) holds, every control poll, one
``S`` line (state) and one ``R`` line (the ten rule outputs) per axis.
``logsort`` writes ``a<N>state.dat`` and ``a<N>rules.dat`` for each axis N,
as the document's logsort.cpp did, each with a header naming the columns
and units, and with ``--plot`` draws to ``a<N>.png`` each axis's measured tension
against its desired tension (drawn only while the rope is
tension-controlled: a length-controlled rope has none), its length error
and all ten rule outputs over time (the document used spreadsheets).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from pyrt.errors import ConfigError
from pyrt.fileio import atomic_write
from pyrt.native import FuzzyRule

__all__ = ["RULE_COLUMNS", "STATE_COLUMNS", "add_parser", "axis_figure", "run", "sort_log"]

STATE_COLUMNS = ("time_s", "length_cm", "tension_N", "error_length_cm", "error_tension_N",
                 "velocity_cm_s", "dv_cm_s", "desired_tension_N", "free")
RULE_COLUMNS = ("time_s", *(f"{r.name.lower()}_cm_s" for r in FuzzyRule))


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("logsort", help="split a manipulator log into per-axis state and "
                       "rules files (a0state.dat, a0rules.dat)", description=__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("logfile", metavar="LOGFILE",
                   help="a state log written by the manipulator's 'log [FILE]' command")
    p.add_argument("--out", metavar="DIR", help="where to write (default: beside LOGFILE)")
    p.add_argument("--plot", action="store_true", help="also draw a<N>.png per axis")
    p.set_defaults(run=run)


def sort_log(logfile: str | Path) -> tuple[dict[int, list[list[str]]], dict[int, list[list[str]]]]:
    """Per-axis state rows and rule rows of a log (ConfigError naming a bad line)."""
    path = Path(logfile)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"cannot read the log: {exc}", str(path)) from None
    states: dict[int, list[list[str]]] = {}
    rules: dict[int, list[list[str]]] = {}
    for n, line in enumerate(text.splitlines(), 1):
        parts = line.split()
        if not parts or parts[0] not in ("S", "R"):
            continue
        want = len(STATE_COLUMNS) + 2 if parts[0] == "S" else len(RULE_COLUMNS) + 2
        if len(parts) != want:
            raise ConfigError(f"expected {want} fields on a {parts[0]} line, got {len(parts)}",
                              str(path), n)
        try:
            axis = int(parts[2])
            for v in parts[1:]:
                float(v)
        except ValueError:
            raise ConfigError(f"non-numeric field on a {parts[0]} line", str(path), n) from None
        row = [parts[1], *parts[3:]]
        (states if parts[0] == "S" else rules).setdefault(axis, []).append(row)
    if not states and not rules:
        raise ConfigError("no state (S) or rule (R) lines: is this a manipulator log?",
                          str(path))
    return states, rules


def _table(columns: tuple[str, ...], rows: list[list[str]], title: str) -> bytes:
    lines = [f"# {title}", "# " + " ".join(columns)]
    lines.extend(" ".join(r) for r in rows)
    return ("\n".join(lines) + "\n").encode()


def run(args: argparse.Namespace) -> int:
    src = Path(args.logfile)
    out = Path(args.out) if args.out else src.parent
    states, rules = sort_log(src)
    if args.plot:  # before anything is written: all of the output, or none of it
        try:
            import matplotlib  # noqa: F401
        except ImportError:
            raise ConfigError("--plot needs matplotlib, which is not installed: "
                              "pip install 'pyrt[plot]'") from None
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError(f"cannot create the output directory: {exc.strerror}", str(out)) from None
    written = []
    for axis in sorted(set(states) | set(rules)):
        for kind, cols, table in (("state", STATE_COLUMNS, states), ("rules", RULE_COLUMNS, rules)):
            target = out / f"a{axis}{kind}.dat"
            atomic_write(target, _table(cols, table.get(axis, []),
                                        f"axis {axis} {kind} from {src.name}"))
            written.append(target)
        if args.plot:
            written.append(_plot(out / f"a{axis}.png", axis, states.get(axis, []),
                                 rules.get(axis, [])))
    for p in written:
        print(p, file=sys.stdout)
    return 0


def _plot(target: Path, axis: int, state: list[list[str]], rules: list[list[str]]) -> Path:
    import io

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = axis_figure(axis, state, rules)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=80)
    plt.close(fig)
    atomic_write(target, buf.getvalue())
    return target


def axis_figure(axis: int, state: list[list[str]], rules: list[list[str]]) -> Any:
    """One axis's figure: measured tension against the desired tension, the
    length error, and the ten rule outputs, each labelled (needs matplotlib).

    The controller sets a desired tension only while it controls the rope's
    tension (``free`` 0: the off-side ropes, or every rope with signal-all);
    while the rope is length-controlled (``free`` 1) the logged 0 means "none",
    so the desired line is drawn only where it is defined."""
    import matplotlib.pyplot as plt
    import numpy as np

    fig, (ax1, ax2, ax3) = plt.subplots(3, 1, sharex=True, figsize=(9, 8))
    if state:
        s = np.array(state, float)
        t = s[:, 0]
        ax1.plot(t, s[:, 2], label="measured tension")
        controlled = s[:, 8] == 0
        if controlled.any():
            ax1.plot(t, np.where(controlled, s[:, 7], np.nan), "--",
                     label="desired tension (tension-controlled)")
        else:
            ax1.text(0.01, 0.04, "no desired tension: length-controlled throughout",
                     transform=ax1.transAxes, fontsize="small")
        ax2.plot(t, s[:, 3], label="length error")
    if rules:
        r = np.array(rules, float)
        for k, rule in enumerate(FuzzyRule):  # all ten, silent ones too, each labelled
            ax3.plot(r[:, 0], r[:, k + 1], label=rule.name.lower())
    ax1.set_ylabel("tension (N)")
    ax2.set_ylabel("length error (cm)")
    ax3.set_ylabel("rule output (cm/s)")
    ax3.set_xlabel("loop time (s)")
    for a in (ax1, ax2, ax3):
        if a.get_legend_handles_labels()[0]:
            a.legend(fontsize="small", loc="upper right", ncol=2 if a is ax3 else 1)
    fig.suptitle(f"axis {axis}")
    return fig
