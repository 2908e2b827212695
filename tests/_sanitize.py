"""Shared by the sanitize-marked tests: one ASan/UBSan build of csrc/ per
test session, and a runner for driver scripts against it."""

from __future__ import annotations

import atexit
import functools
import os
import shutil
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
CFLAGS = (
    "-std=c99 -O1 -g -fsanitize=address,undefined -fno-omit-frame-pointer "
    "-fno-sanitize-recover=all"
)
LDFLAGS = "-fsanitize=address,undefined"

_BUILD = textwrap.dedent(
    """
    import runpy
    ns = runpy.run_path("csrc/build_native.py")
    print(ns["ffibuilder"].compile(tmpdir=".", verbose=False))
    """
)

#: Put at the top of a driver: loads the sanitized build as pyrt._native.
PRELUDE = textwrap.dedent(
    """
    import importlib.util, sys
    spec = importlib.util.spec_from_file_location("pyrt._native", sys.argv[1])
    native = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(native)
    sys.modules["pyrt._native"] = native
    """
)


def libasan() -> str | None:
    """The path of gcc's libasan, or None when there is none."""
    gcc = shutil.which("gcc")
    if gcc is None:
        return None
    path = subprocess.run([gcc, "-print-file-name=libasan.so"], capture_output=True, text=True,
                          check=False).stdout.strip()
    return path if os.path.isabs(path) and os.path.exists(path) else None


@functools.cache
def sanitized_build() -> Path:
    """Build a private copy of csrc/ with the sanitizers (once per session)."""
    if libasan() is None:
        pytest.skip("gcc with libasan is not available")
    where = Path(tempfile.mkdtemp(prefix="pyrt-asan-"))
    atexit.register(shutil.rmtree, where, True)
    # A private copy: the sanitized objects never land in the tree.
    shutil.copytree(ROOT / "csrc", where / "csrc",
                    ignore=shutil.ignore_patterns("*.o", "*.so", "__pycache__"))
    env = dict(os.environ, PYRT_CFLAGS=CFLAGS, PYRT_LDFLAGS=LDFLAGS)
    build = subprocess.run([sys.executable, "-c", _BUILD], cwd=where, env=env,
                           capture_output=True, text=True, timeout=300, check=False)
    assert build.returncode == 0, build.stdout + build.stderr
    built = list(where.rglob("_native*.so"))
    assert len(built) == 1, build.stdout
    return built[0]


def run_under_asan(code: str, cwd: Path) -> subprocess.CompletedProcess:
    """Run driver ``code`` (which starts with PRELUDE) against the sanitized build."""
    so = sanitized_build()
    driver = cwd / "driver.py"
    driver.write_text(code)
    env = dict(
        os.environ,
        LD_PRELOAD=libasan() or "",
        ASAN_OPTIONS="detect_leaks=0:abort_on_error=0:halt_on_error=1",
        UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1",
        PYTHONPATH=str(ROOT),
    )
    return subprocess.run([sys.executable, str(driver), str(so)], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=300, check=False)


def assert_clean(run: subprocess.CompletedProcess) -> None:
    """The driver finished and no sanitizer reported anything."""
    report = run.stdout + run.stderr
    assert run.returncode == 0, report
    assert "SANITIZE-DRIVER-OK" in run.stdout, report
    assert "ERROR: AddressSanitizer" not in report, report
    assert "runtime error" not in report, report
