"""Packaging: the sdist carries what a wheel is built from, and the wheel built from it works."""

from __future__ import annotations

import shutil
import subprocess
import sys
import tarfile
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def _source_tree(dest: Path) -> Path:
    """A copy of the checkout's tracked files (what a clean clone holds)."""
    try:
        files = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, check=True,
                               capture_output=True).stdout.decode().split("\0")
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout: the sdist is built from the tracked files")
    for name in filter(None, files):
        src = ROOT / name
        if src.is_file():
            (dest / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dest / name)
    return dest


def _hook(tree: Path, hook: str, out: Path) -> Path:
    """Run a PEP 517 hook of setuptools in ``tree`` (no isolation, no network)."""
    out.mkdir(exist_ok=True)
    code = (f"from setuptools import build_meta as b; import sys; "
            f"print(b.{hook}(sys.argv[1]))")
    done = subprocess.run([sys.executable, "-c", code, str(out)], cwd=tree,
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "SetuptoolsDeprecationWarning" not in done.stderr, done.stderr[-3000:]
    return out / done.stdout.strip().splitlines()[-1]


def test_sdist_builds_a_wheel_that_installs_and_runs(tmp_path):
    """sdist → wheel → installed: the C kernels build from the sdist alone and pyrt runs."""
    sdist = _hook(_source_tree(tmp_path / "src"), "build_sdist", tmp_path / "dist")
    with tarfile.open(sdist) as tar:
        names = {n.split("/", 1)[1] for n in tar.getnames() if "/" in n}
        tar.extractall(tmp_path / "unpacked", filter="data")
    assert {"csrc/build_native.py", "csrc/pyrt_native.h", "csrc/fuzzy.c", "LICENSE",
            "pyrt/py.typed", "setup.py"} <= names
    (tree,) = (tmp_path / "unpacked").iterdir()
    wheel = _hook(tree, "build_wheel", tmp_path / "wheels")
    with zipfile.ZipFile(wheel) as zf:
        inside = zf.namelist()
    assert "pyrt/py.typed" in inside and any(n.startswith("pyrt/_native") for n in inside)
    assert {"pyrt/boards/maps/gripper.toml", "pyrt/boards/maps/manipulator.toml"} <= set(inside)
    assert any(n.endswith("licenses/LICENSE") for n in inside)
    site = tmp_path / "site"
    with zipfile.ZipFile(wheel) as zf:
        zf.extractall(site)
    run = subprocess.run(
        [sys.executable, "-c",
         "import pyrt, pyrt._native as n, sys; assert pyrt.__file__.startswith(sys.argv[1]); "
         "from pyrt.cli import main; main(['gripper', '--help'])", str(site)],
        cwd=tmp_path, env={"PYTHONPATH": str(site), "PATH": "/usr/bin:/bin"},
        capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-3000:]
    assert "usage: pyrt gripper" in run.stdout
