"""pip install ./examples/arm installs the package itself, not only its metadata."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

PACKAGE_ROOT = Path(__file__).resolve().parents[1]


def test_setuptools_finds_the_pyrt_arm_package():
    """The package find of pyproject.toml finds pyrt_arm (a regular package: it has an __init__.py), so a wheel holds its modules."""
    setuptools = pytest.importorskip("setuptools")
    config = tomllib.loads((PACKAGE_ROOT / "pyproject.toml").read_text())
    include = config["tool"]["setuptools"]["packages"]["find"]["include"]
    assert setuptools.find_packages(str(PACKAGE_ROOT), include=include) == ["pyrt_arm"]
    assert (PACKAGE_ROOT / "pyrt_arm" / "py.typed").exists()
    assert config["project"]["entry-points"]["pyrt.stations"] == {"arm": "pyrt_arm.station:ARM"}
