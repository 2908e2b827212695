"""`pyrt overruns` and `pyrt demo`: reading timing logs back, and clear one-line errors."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
from _clocks import MS, WorkClock

from pyrt.cli import main
from pyrt.scheduler import Loop, ReadyQueue, TimingLog


def write_log(path, ticks=100, slow_every=4) -> None:
    clock = WorkClock()
    loop = Loop(clock, period_ns=MS, timing_log=TimingLog(str(path), version="test"))
    queue = ReadyQueue(divisor=1)
    n = [0]

    def task():
        n[0] += 1
        clock.work(2 * MS if n[0] % slow_every == 0 else 1000)

    queue.add_periodic(0x10, "JAWMOVE", task, 1)
    queue.add_periodic(0x20, "SENSE", lambda: clock.work(500), 2)
    queue.schedule(0x10, 1)
    queue.schedule(0x20, 2)
    loop.attach(queue)
    loop.run(ticks)
    loop.close()


def test_overruns_reads_a_log_the_loop_wrote(tmp_path, capsys):
    """The table shows per-task calls and the overruns attributed to the slow task."""
    path = tmp_path / "timing.jsonl"
    write_log(path)
    assert main(["overruns", str(path)]) == 0
    out = capsys.readouterr().out
    assert "25 overruns" in out
    row = next(line for line in out.splitlines() if line.startswith("JAWMOVE"))
    assert row.split()[1] == "100" and row.split()[-1] == "25"
    assert "worst 10 overruns:" in out


def test_overruns_names_a_slow_board_poll(tmp_path, capsys):
    """A loop handler (the board poll) that makes ticks overrun has a row of its own with those overruns."""
    path = tmp_path / "timing.jsonl"
    clock = WorkClock()
    loop = Loop(clock, period_ns=MS, timing_log=TimingLog(str(path), version="test"))
    queue = ReadyQueue(divisor=1)
    queue.add_periodic(0x10, "SENSE", lambda: clock.work(500), 1)
    queue.schedule(0x10, 1)
    loop.attach(queue)
    n = [0]

    def poll(now: int) -> None:
        n[0] += 1
        clock.work(2 * MS if n[0] % 5 == 0 else 1000)

    loop.attach(poll, name="boards")
    loop.run(100)
    loop.close()
    assert main(["overruns", str(path), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["overruns"] == 20
    assert data["tasks"]["boards"]["overruns"] == 20 and data["tasks"]["boards"]["calls"] == 100
    assert data["tasks"]["SENSE"]["overruns"] == 0
    assert main(["overruns", str(path)]) == 0
    row = next(line for line in capsys.readouterr().out.splitlines() if line.startswith("boards"))
    assert row.split()[1] == "100" and row.split()[-1] == "20"


def test_overruns_json_output(tmp_path, capsys):
    """--json prints one object with the same counts."""
    path = tmp_path / "timing.jsonl"
    write_log(path, ticks=40, slow_every=10)
    assert main(["overruns", str(path), "--json", "--worst", "2"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["overruns"] == 4 and data["tasks"]["JAWMOVE"]["overruns"] == 4
    assert data["tasks"]["JAWMOVE"]["calls"] == 40 and len(data["worst"]) == 2


def test_overruns_plot_writes_a_png(tmp_path, capsys):
    """--plot writes a PNG (matplotlib is an optional extra)."""
    pytest.importorskip("matplotlib")
    path = tmp_path / "timing.jsonl"
    write_log(path)
    png = tmp_path / "t.png"
    assert main(["overruns", str(path), "--plot", str(png)]) == 0
    assert png.read_bytes()[:4] == b"\x89PNG"


BAD_LOGS = [
    ("missing", None, "no such file"),
    ("empty", "", "empty file"),
    ("truncated", '{"type":"header","format":"pyrt-timing/1","period_ns":1000000}\n{"type":"ov', "truncated"),
    ("not json", "hello world\n", "not a JSON record"),
    ("no header", '{"type":"summary","tasks":{}}\n', "first record must be"),
    ("bad overrun", '{"type":"header","format":"pyrt-timing/1","period_ns":1}\n{"type":"overrun"}\n',
     "lacks"),
]


@pytest.mark.parametrize(("label", "content", "message"), BAD_LOGS, ids=[b[0] for b in BAD_LOGS])
def test_overruns_bad_file_is_one_clear_line(tmp_path, label, content, message):
    """A missing, empty, truncated or non-JSON log exits non-zero with one line and no traceback."""
    path = tmp_path / "log.jsonl"
    if content is not None:
        path.write_text(content)
    proc = subprocess.run(
        [sys.executable, "-m", "pyrt", "overruns", str(path)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 1
    assert proc.stdout == ""
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0] and "Traceback" not in proc.stderr


def test_help_lists_the_commands(capsys):
    """pyrt --help tells the truth: it lists the sub-commands."""
    with pytest.raises(SystemExit) as exit_:
        main(["--help"])
    assert exit_.value.code == 0
    out = capsys.readouterr().out
    assert "demo" in out and "overruns" in out


def test_demo_runs_on_virtual_time_and_writes_a_readable_log(tmp_path, capsys):
    """pyrt demo --speed max runs 002's three routines; its log reads back with pyrt overruns."""
    log = tmp_path / "demo.jsonl"
    assert main(["demo", "--speed", "max", "--seconds", "0.48", "--timing-log", str(log)]) == 0
    out = capsys.readouterr().out
    # 480 ticks at divisor 04 = 120 checks: WATCHJAW 120, SENSORS 12, MVJAWS 10.
    rows = {line.split()[0]: line.split()[1] for line in out.splitlines() if line[:1].isupper()}
    assert rows["WATCHJAW"] == "120" and rows["SENSORS"] == "12" and rows["MVJAWS"] == "10"
    assert main(["overruns", str(log)]) == 0


def test_demo_refuses_bad_options(capsys):
    """Bad option values give a usage error, not a traceback."""
    with pytest.raises(SystemExit) as exit_:
        main(["demo", "--speed", "fast"])
    assert exit_.value.code == 2
    assert "speed must be" in capsys.readouterr().err


def test_overruns_histogram_bars_are_closed_from_the_first_to_the_last(tmp_path):
    """Each task's histogram is drawn as contiguous bars whose first bar has its left edge (down to the baseline)."""
    pytest.importorskip("matplotlib")
    import matplotlib.pyplot as plt

    from pyrt.cli.overruns import histogram_steps, report_figure
    from pyrt.scheduler.stats import bin_edges
    from pyrt.scheduler.timinglog import read_timing_log

    edges, counts = histogram_steps([[40, 3], [42, 1], [60, 2]])
    assert len(edges) == len(counts) + 1 == 22
    assert edges[0] == bin_edges(40)[0] and edges[-1] == bin_edges(60)[1]
    assert all(bin_edges(40 + k) == (edges[k], edges[k + 1]) for k in range(21))
    assert counts[0] == 3 and counts[2] == 1 and counts[-1] == 2 and sum(counts) == 6
    assert histogram_steps([]) == ([], [])

    path = tmp_path / "timing.jsonl"
    write_log(path)
    rep = read_timing_log(str(path))
    fig = report_figure(rep)
    try:
        hist_ax, timeline_ax = fig.axes
        patches = {p.get_label(): p for p in hist_ax.patches}
        assert set(patches) == {n for n, t in rep.summary["tasks"].items() if t["hist"]}
        assert {"JAWMOVE", "SENSE"} <= set(patches)
        for name, patch in patches.items():
            values, xs, baseline = patch.get_data()
            first = rep.summary["tasks"][name]["hist"][0]
            assert baseline is not None and 0 < baseline < 1  # the bars close below one call
            assert values[0] == first[1] and xs[0] == bin_edges(first[0])[0] / 1e3
        assert hist_ax.get_xlabel() == "execution time (µs)" and hist_ax.get_ylabel() == "calls"
        assert timeline_ax.get_xlabel() == "loop time (s)"
        assert timeline_ax.get_ylabel() == "overrun past next deadline (µs)"
    finally:
        plt.close(fig)


def test_overruns_plot_without_matplotlib_is_one_line_before_any_output(tmp_path):
    """pyrt overruns --plot with matplotlib absent (a subprocess): only the install hint, exit 1, no PNG."""
    path = tmp_path / "timing.jsonl"
    write_log(path)
    png = tmp_path / "t.png"
    code = ("import sys; sys.modules['matplotlib'] = None\n"
            f"from pyrt.cli import main; sys.exit(main(['overruns', {str(path)!r}, '--plot', "
            f"{str(png)!r}]))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 1 and done.stdout == ""
    assert done.stderr.splitlines() == [
        "pyrt overruns: --plot needs matplotlib, which is not installed: pip install 'pyrt[plot]'"]
    assert not png.exists()


def test_overruns_reports_start_up_apart(tmp_path, capsys):
    """A slow first tick is reported once as start-up, not among the overruns."""
    clock = WorkClock()
    path = tmp_path / "timing.jsonl"
    loop = Loop(clock, period_ns=MS, timing_log=TimingLog(str(path), version="test"))
    first = [True]

    def cold(now):
        if first[0]:
            first[0] = False
            clock.work(5 * MS)

    loop.attach(cold)
    loop.run(50)
    loop.close()
    assert main(["overruns", str(path)]) == 0
    out = capsys.readouterr().out
    assert "50 ticks, 0 overruns, 0 deadlines missed" in out
    assert "start-up (not counted above): 1 tick(s) overran, worst 4.00 ms" in out


@pytest.mark.wallclock
def test_real_time_overrun_warnings_go_to_stderr_short_and_at_most_one_a_second(tmp_path):
    """A real-time run that overruns on purpose: stdout has no overrun line; stderr has at most one a second, each within 80 columns."""
    done = subprocess.run([sys.executable, "-m", "pyrt", "demo", "--seconds", "2.2",
                           "--slow-us", "1500"], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert "overrun:" not in done.stdout
    lines = done.stderr.splitlines()
    assert 1 <= len(lines) <= 3
    assert all(ln.startswith("overrun: ") and len(ln) <= 80 and "see stats" in ln for ln in lines)


def test_stderr_lines_never_block_the_caller(monkeypatch):
    """The loop's warning hand-over returns at once even while stderr blocks; the line is written when it unblocks."""
    import io
    import threading

    from pyrt.cli._loopopts import StderrLines

    gate = threading.Event()

    class Blocking(io.StringIO):
        def write(self, s):
            gate.wait(10)
            return super().write(s)

    err = Blocking()
    monkeypatch.setattr(sys, "stderr", err)
    lines = StderrLines()
    done = threading.Event()
    threading.Thread(target=lambda: (lines.put("overrun: 1 tick"), done.set())).start()
    assert done.wait(5)  # put() returned while the writer is stuck in write()
    gate.set()
    for _ in range(500):
        if "overrun: 1 tick" in err.getvalue():
            break
        threading.Event().wait(0.01)
    assert err.getvalue() == "overrun: 1 tick\n"


@pytest.mark.parametrize("args", [["overruns", "LOG", "--json"], ["overruns", "LOG"],
                                  ["--help"], ["overruns", "--help"]])
def test_a_command_into_a_reader_that_has_gone_ends_quietly(tmp_path, args):
    """'pyrt overruns F --json | head -c 400' (or --help) with head gone: status 0, nothing on stderr."""
    import os

    path = tmp_path / "timing.jsonl"
    write_log(path)
    r, w = os.pipe()
    os.close(r)
    try:
        done = subprocess.run(
            [sys.executable, "-m", "pyrt", *(str(path) if a == "LOG" else a for a in args)],
            stdout=w, stderr=subprocess.PIPE, text=True, timeout=60)
    finally:
        os.close(w)
    assert done.returncode == 0 and done.stderr == "", done.stderr
