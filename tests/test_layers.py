"""Architecture checks: the import-linter layer contracts, and who may touch the compiled module."""

from __future__ import annotations

import ast
import shutil
import subprocess
import sys
from pathlib import Path

import pyrt

PACKAGE = Path(pyrt.__file__).parent


def test_import_linter_contracts_are_kept():
    """lint-imports keeps every contract in pyproject.toml (imports go down only; control never imports physics)."""
    exe = shutil.which("lint-imports") or str(Path(sys.executable).parent / "lint-imports")
    proc = subprocess.run(
        [exe, "--no-cache"], cwd=PACKAGE.parent, capture_output=True, text=True, timeout=300
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "BROKEN" not in proc.stdout and "KEPT" in proc.stdout


def test_only_pyrt_native_imports_the_compiled_module():
    """No module outside pyrt.native imports pyrt._native (the argon2-cffi rule)."""
    offenders = []
    for path in PACKAGE.rglob("*.py"):
        rel = path.relative_to(PACKAGE.parent)
        if rel.parts[:2] == ("pyrt", "native"):
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        for node in ast.walk(tree):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
            if any(n == "pyrt._native" or n.startswith("pyrt._native.") for n in names):
                offenders.append(str(rel))
    assert offenders == []


def test_library_code_does_not_print():
    """Library code writes through a passed-in stdout, never bare print() (the CLI entry points may)."""
    offenders = []
    for path in PACKAGE.rglob("*.py"):
        rel = path.relative_to(PACKAGE.parent)
        if rel.parts[1] in ("cli", "__main__.py"):
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "print":
                offenders.append(f"{rel}:{node.lineno}")
    assert offenders == []
