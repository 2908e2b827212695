"""The arm's package passes mypy --strict (when mypy is installed: the package's test extra)."""

from __future__ import annotations

from pathlib import Path

import pytest

PACKAGE_ROOT = Path(__file__).resolve().parents[1]


def test_pyrt_arm_passes_mypy_strict(tmp_path, monkeypatch):
    """mypy --strict over pyrt_arm reports no error."""
    api = pytest.importorskip("mypy.api")
    monkeypatch.chdir(PACKAGE_ROOT)
    out, err, status = api.run(["--strict", "--cache-dir", str(tmp_path / "cache"),
                                "-p", "pyrt_arm"])
    assert status == 0, out + err
