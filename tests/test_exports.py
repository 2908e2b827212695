"""Public names: each package's __all__ is sorted and every name in it exists."""

from __future__ import annotations

import importlib

import pytest

import pyrt
from pyrt.errors import PyrtError

PACKAGES = [
    "pyrt", "pyrt.errors", "pyrt.scheduler", "pyrt.native", "pyrt.units", "pyrt.fileio",
    "pyrt.db", "pyrt.scope", "pyrt.tasks", "pyrt.station", "pyrt.commands", "pyrt.console",
    "pyrt.client", "pyrt.server", "pyrt.cli", "pyrt.motion",
]


def _isort_key(name: str) -> tuple[int, str]:
    """ruff's RUF022 order: CONSTANTS, then Classes, then functions, each alphabetical."""
    if name.isupper() or (name.upper() == name and "_" in name):
        return (0, name)
    if name[:1].isupper():
        return (1, name)
    return (2, name)


@pytest.mark.parametrize("name", PACKAGES)
def test_all_is_sorted_and_complete(name):
    """__all__ is sorted (ruff's RUF022 order), has no duplicates, and lists only names the module has."""
    module = importlib.import_module(name)
    exported = list(module.__all__)
    assert len(set(exported)) == len(exported)
    assert exported == sorted(exported, key=_isort_key)
    for attr in exported:
        assert hasattr(module, attr), f"{name}.{attr} is in __all__ but missing"


def test_every_pyrt_error_derives_from_the_root():
    """Every exception pyrt exports derives from PyrtError, which is never raised itself."""
    for attr in pyrt.__all__:
        obj = getattr(pyrt, attr)
        if isinstance(obj, type) and issubclass(obj, BaseException):
            assert issubclass(obj, PyrtError)


def test_config_error_names_file_and_line():
    """ConfigError renders as FILE:LINE: message."""
    from pyrt.errors import ConfigError

    assert str(ConfigError("bad unit 'furlong'", "AXIS.dat", 7)) == "AXIS.dat:7: bad unit 'furlong'"
    assert str(ConfigError("missing", "AV.dat")) == "AV.dat: missing"
