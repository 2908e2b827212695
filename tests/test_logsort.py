"""pyrt logsort: a manipulator log split into a<N>state.dat / a<N>rules.dat, plots to PNG."""

from __future__ import annotations

import pytest
from _manipulator_rig import make_station, move

from pyrt.cli import main
from pyrt.cli.logsort import RULE_COLUMNS, STATE_COLUMNS, sort_log


@pytest.fixture(scope="module")
def logfile(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("logsort")
    station, runner = make_station(tmp)
    path = station.start_log(tmp / "run.log")
    move(station, runner, (10.0, 0.0, 105.0))
    station.stop_log()
    station.close()
    return path


def test_split_per_axis(logfile, tmp_path, capsys):
    """Each axis gets a state and a rules file with a column header and one row per poll."""
    assert main(["logsort", str(logfile), "--out", str(tmp_path)]) == 0
    polls = sum(1 for ln in logfile.read_text().splitlines() if ln.startswith("P "))
    for axis in range(3):
        state = (tmp_path / f"a{axis}state.dat").read_text().splitlines()
        rules = (tmp_path / f"a{axis}rules.dat").read_text().splitlines()
        assert state[1] == "# " + " ".join(STATE_COLUMNS)
        assert rules[1] == "# " + " ".join(RULE_COLUMNS)
        assert len(state) - 2 == polls and len(rules) - 2 == polls
        assert len(state[2].split()) == len(STATE_COLUMNS)
        assert len(rules[2].split()) == len(RULE_COLUMNS)
    assert "a2rules.dat" in capsys.readouterr().out


def test_rows_keep_the_logged_values(logfile):
    """The split rows are the log's S and R lines without the axis column, in order."""
    states, rules = sort_log(logfile)
    s_lines = [ln.split() for ln in logfile.read_text().splitlines() if ln.startswith("S 1 ")
               or (ln.startswith("S ") and ln.split()[2] == "1")]
    assert states[1][0] == [s_lines[0][1], *s_lines[0][3:]]
    assert set(rules) == {0, 1, 2}


def test_plot_writes_png(logfile, tmp_path):
    """--plot draws one PNG per axis."""
    assert main(["logsort", str(logfile), "--out", str(tmp_path), "--plot"]) == 0
    for axis in range(3):
        data = (tmp_path / f"a{axis}.png").read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize("text", ["", "hello\n", "S 1.0 0 1 2\n", "S 1.0 x 1 2 3 4 5 6 7 8 9\n"])
def test_bad_logs_are_refused(tmp_path, capsys, text):
    """A file that is not a manipulator log: one error line naming the file, exit 1."""
    p = tmp_path / "bad.log"
    p.write_text(text)
    assert main(["logsort", str(p), "--out", str(tmp_path / "out")]) == 1
    assert "bad.log" in capsys.readouterr().err
    assert not (tmp_path / "out" / "a0state.dat").exists()


def test_plot_without_matplotlib_writes_nothing_and_says_how(logfile, tmp_path, capsys,
                                                             monkeypatch):
    """--plot without matplotlib: the install hint, exit 1, and no file written at all."""
    import builtins

    real = builtins.__import__

    def no_matplotlib(name, *args, **kwargs):
        if name == "matplotlib" or name.startswith("matplotlib."):
            raise ImportError(name)
        return real(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_matplotlib)
    out = tmp_path / "out"
    assert main(["logsort", str(logfile), "--out", str(out), "--plot"]) == 1
    assert "pip install 'pyrt[plot]'" in capsys.readouterr().err
    assert not out.exists() or not any(out.iterdir())


def test_plot_draws_desired_tension_only_where_the_rope_is_tension_controlled(logfile):
    """The desired-tension line exists only where free is 0; elsewhere it is a gap, never a 0 N line."""
    pytest.importorskip("matplotlib")
    import matplotlib.pyplot as plt
    import numpy as np

    from pyrt.cli.logsort import axis_figure

    states, rules = sort_log(logfile)
    kinds = set()
    for axis in sorted(states):
        s = np.array(states[axis], float)
        fig = axis_figure(axis, states[axis], rules[axis])
        try:
            tension_ax, error_ax, rules_ax = fig.axes
            lines = {ln.get_label(): ln for ln in tension_ax.lines}
            np.testing.assert_allclose(lines["measured tension"].get_ydata(), s[:, 2])
            controlled = s[:, 8] == 0
            if controlled.any():
                kinds.add("controlled")
                desired = np.asarray(lines["desired tension (tension-controlled)"].get_ydata())
                assert np.all(np.isnan(desired[~controlled]))
                np.testing.assert_allclose(desired[controlled], s[controlled, 7])
            else:
                kinds.add("free")
                assert set(lines) == {"measured tension"}
                assert "length-controlled throughout" in tension_ax.texts[0].get_text()
            assert tension_ax.get_ylabel() == "tension (N)"
            assert error_ax.get_ylabel() == "length error (cm)"
            assert rules_ax.get_ylabel() == "rule output (cm/s)"
            assert rules_ax.get_xlabel() == "loop time (s)"
            legend = [t.get_text() for t in rules_ax.get_legend().get_texts()]
            assert legend == [c.removesuffix("_cm_s") for c in RULE_COLUMNS[1:]]
        finally:
            plt.close(fig)
    assert kinds == {"controlled", "free"}  # both cases drawn: a free rope and a mixed one


def test_plot_without_matplotlib_in_a_fresh_interpreter(logfile, tmp_path):
    """pyrt logsort --plot with matplotlib absent (a subprocess): one hint line on stderr, exit 1, nothing written."""
    import subprocess
    import sys

    out = tmp_path / "out"
    code = ("import sys; sys.modules['matplotlib'] = None\n"
            f"from pyrt.cli import main; sys.exit(main(['logsort', {str(logfile)!r}, '--out', "
            f"{str(out)!r}, '--plot']))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 1 and done.stdout == ""
    assert done.stderr.splitlines() == [
        "pyrt logsort: --plot needs matplotlib, which is not installed: pip install 'pyrt[plot]'"]
    assert not out.exists() or not any(out.iterdir())
