"""The arm's package passes mypy --strict (when mypy is installed: the package's test extra)."""

from __future__ import annotations

from pathlib import Path

import pyrt
import pytest

PACKAGE_ROOT = Path(__file__).resolve().parents[1]


def test_pyrt_arm_passes_mypy_strict(tmp_path, monkeypatch):
    """mypy --strict over pyrt_arm reports no error (pyrt's own modules only give their types)."""
    api = pytest.importorskip("mypy.api")
    monkeypatch.chdir(PACKAGE_ROOT)
    source = Path(pyrt.__file__).resolve().parents[1]
    if source.name not in ("site-packages", "dist-packages"):
        # pyrt installed in editable mode: mypy finds it only on its own path
        monkeypatch.setenv("MYPYPATH", str(source))
    out, err, status = api.run(["--strict", "--cache-dir", str(tmp_path / "cache"),
                                "-p", "pyrt_arm"])
    assert status == 0, out + err
    assert "no issues found" in out
