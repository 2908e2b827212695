"""The examples use pyrt's public API only: no name starting with an underscore from pyrt."""

from __future__ import annotations

import ast
import importlib.metadata
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[2]


def _private(name: str) -> bool:
    """A private name: one leading underscore, not a dunder (``__version__`` is public)."""
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _pyrt_module(module: str) -> bool:
    return module == "pyrt" or module.startswith("pyrt.")


def _private_path(module: str) -> bool:
    return _pyrt_module(module) and any(_private(part) for part in module.split("."))


def _root(node: ast.expr) -> str | None:
    while isinstance(node, ast.Attribute):
        node = node.value
    return node.id if isinstance(node, ast.Name) else None


def private_uses(source: str, filename: str = "<source>") -> list[str]:
    """Each use of a private pyrt name in ``source``, as ``file:line: what``.

    Caught: ``import pyrt._x``, ``from pyrt._x import y``, ``from pyrt import _x``,
    ``import_module("pyrt._x")``, and ``._x`` reached from a name bound by a pyrt import
    (``pyrt._x``, ``Station._x``, ``boards.registry._x``), directly or through
    ``getattr``/``setattr``/``hasattr``/``delattr`` with a constant name.
    """
    tree = ast.parse(source, filename)
    found: list[str] = []
    bound: set[str] = set()

    def report(node: ast.AST, what: str) -> None:
        found.append(f"{filename}:{getattr(node, 'lineno', 0)}: {what}")

    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if _pyrt_module(alias.name):
                    if _private_path(alias.name):
                        report(node, f"import {alias.name}")
                    bound.add(alias.asname or alias.name.split(".")[0])
        elif (isinstance(node, ast.ImportFrom) and node.level == 0 and node.module
              and _pyrt_module(node.module)):
            if _private_path(node.module):
                report(node, f"from {node.module} import ...")
            for alias in node.names:
                if _private(alias.name):
                    report(node, f"from {node.module} import {alias.name}")
                bound.add(alias.asname or alias.name)
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and _private(node.attr) and _root(node) in bound:
            report(node, f"attribute .{node.attr} of pyrt's {_root(node)}")
        elif isinstance(node, ast.Call):
            func = node.func
            name = func.id if isinstance(func, ast.Name) else (
                func.attr if isinstance(func, ast.Attribute) else "")
            args = node.args
            if (name in ("getattr", "setattr", "hasattr", "delattr") and len(args) >= 2
                    and _root(args[0]) in bound and isinstance(args[1], ast.Constant)
                    and isinstance(args[1].value, str) and _private(args[1].value)):
                report(node, f"{name}(..., {args[1].value!r}) on pyrt's {_root(args[0])}")
            if (name in ("import_module", "__import__") and args
                    and isinstance(args[0], ast.Constant) and isinstance(args[0].value, str)
                    and _private_path(args[0].value)):
                report(node, f"{name}({args[0].value!r})")
    return found


def unlisted_imports(source: str, filename: str = "<source>") -> list[str]:
    """Each name imported ``from pyrt...`` in ``source`` that its module does not list in
    ``__all__`` (a name a module merely happens to hold is not its public API)."""
    found = []
    for node in ast.walk(ast.parse(source, filename)):
        if (isinstance(node, ast.ImportFrom) and node.level == 0 and node.module
                and _pyrt_module(node.module) and not _private_path(node.module)):
            public = set(getattr(importlib.import_module(node.module), "__all__", ()))
            found += [f"{filename}:{node.lineno}: {node.module}.{a.name}"
                      for a in node.names if a.name not in public]
    return found


def example_files() -> list[Path]:
    return sorted(p for p in EXAMPLES.rglob("*.py")
                  if not any(part.startswith(".") or part in ("build", "__pycache__")
                             for part in p.relative_to(EXAMPLES).parts))


def test_no_example_uses_a_private_pyrt_name():
    """No file under examples/ imports or reaches a pyrt name that starts with an underscore."""
    files = example_files()
    assert any(p.name == "kinematics.py" for p in files)
    uses = [use for p in files for use in private_uses(p.read_text(), str(p.relative_to(EXAMPLES)))]
    assert uses == []


def test_every_pyrt_name_an_example_imports_is_in_its_modules_all():
    """Every name an example imports from pyrt or a pyrt subpackage is in that module's __all__."""
    files = example_files()
    found = [u for p in files for u in unlisted_imports(p.read_text(), str(p.relative_to(EXAMPLES)))]
    assert found == []


def test_the_all_checker_catches_a_name_outside_all():
    """A name a pyrt module holds but does not list in __all__ is reported; listed ones are not."""
    assert unlisted_imports("from pyrt import Station, Arg") == []
    assert unlisted_imports("from pyrt.motion import Evaluator") == []
    assert len(unlisted_imports("from pyrt.motion import importlib_not_there")) == 1
    assert len(unlisted_imports("from pyrt.kinematics.chain import np")) == 1


@pytest.mark.parametrize("source", [
    "import pyrt._version",
    "import pyrt.cli._station as st",
    "from pyrt.cli._loopopts import make_loop",
    "from pyrt import _LAZY",
    "from pyrt.boards import registry as r, _helper",
    "import pyrt\npyrt._LAZY",
    "import pyrt.boards\npyrt.boards.registry._ROBOTS",
    "from pyrt import Station\nStation._trip",
    "from pyrt import Station as S\nS.x._y",
    "import pyrt\ngetattr(pyrt, '_LAZY')",
    "import importlib\nimportlib.import_module('pyrt.cli._serve')",
])
def test_the_checker_catches_private_uses(source):
    """Each way of reaching a private pyrt name that the checker knows is reported."""
    assert len(private_uses(source)) == 1


@pytest.mark.parametrize("source", [
    "import pyrt\nfrom pyrt import Station, command\nprint(pyrt.__version__)",
    "from pyrt_arm import _helper",
    "import pyrt_arm._x",
    "class Arm:\n    def f(self):\n        return self._faults",
    "from pyrt import Station\nclass A(Station):\n    def f(self):\n        return self._mine",
    "import numpy as np\nnp._x",
    "from . import _local",
])
def test_the_checker_passes_public_uses_and_other_packages(source):
    """Public pyrt names, dunders, the example's own private names and other packages are not reported."""
    assert private_uses(source) == []


def test_the_station_module_imports_and_is_registered_as_arm():
    """pyrt_arm.station imports cleanly and the installed package registers it as 'arm' in pyrt.stations."""
    import pyrt_arm.station

    assert hasattr(pyrt_arm.station, "ARM")
    eps = {ep.name: ep.value for ep in importlib.metadata.entry_points(group="pyrt.stations")}
    assert eps.get("arm") == "pyrt_arm.station:ARM"
