"""The test run's sandbox (tests/conftest.py): pyrt's state goes to a temporary directory."""

from __future__ import annotations

import os
from pathlib import Path

CONFTEST = (Path(__file__).parent / "conftest.py").read_text()


def test_the_run_points_pyrt_home_and_xdg_state_home_at_a_temporary_directory(
        pyrt_state_sandbox, tmp_path_factory):
    """PYRT_HOME and XDG_STATE_HOME are inside the run's temporary directory (subprocesses inherit them)."""
    base = tmp_path_factory.getbasetemp()
    for name in ("PYRT_HOME", "XDG_STATE_HOME"):
        assert Path(os.environ[name]).is_relative_to(base)
        assert Path(os.environ[name]).is_relative_to(pyrt_state_sandbox)


def _inner_run(pytester, monkeypatch, tmp_path, test_body: str):
    """A pytest run in a subprocess, with this conftest and one test, whose user
    state directory is ``tmp_path/real-state``."""
    real = tmp_path / "real-state"
    pytester.makeconftest(CONFTEST)
    pytester.makepyfile(test_inner=f"import os\nfrom pathlib import Path\n\n"
                                   f"def test_x():\n    {test_body}\n")
    monkeypatch.delenv("PYRT_HOME", raising=False)
    monkeypatch.setenv("XDG_STATE_HOME", str(real))
    return pytester.runpytest_subprocess("-p", "no:cacheprovider"), real


def test_a_test_that_writes_into_the_real_state_directory_fails_the_run(pytester, monkeypatch,
                                                                       tmp_path):
    """An inner run whose test writes into the user's pyrt state directory fails, naming the path."""
    target = tmp_path / "real-state" / "pyrt" / "stations" / "prototype"
    result, _ = _inner_run(pytester, monkeypatch, tmp_path,
                           f"Path({str(target)!r}).mkdir(parents=True)")
    assert result.ret != 0
    result.stdout.fnmatch_lines(["*the test run wrote outside its sandbox*stations*"])


def test_a_test_that_keeps_to_the_sandbox_passes(pytester, monkeypatch, tmp_path):
    """An inner run whose test writes a working copy where PYRT_HOME says passes, and the real directory stays untouched."""
    result, real = _inner_run(
        pytester, monkeypatch, tmp_path,
        "Path(os.environ['PYRT_HOME'], 'stations', 'prototype').mkdir(parents=True)")
    assert result.ret == 0, result.stdout.str()
    assert not real.exists()
