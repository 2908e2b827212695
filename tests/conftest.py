"""The whole test run is sandboxed: pyrt's state (a manipulator's working copy of
its station) goes to a temporary directory, never to the user's.

For the run, ``PYRT_HOME`` and ``XDG_STATE_HOME`` point into a temporary
directory (subprocesses inherit them); a test that needs a fresh working copy
sets ``PYRT_HOME`` to its own ``tmp_path``.  The user's real state directories
(pyrt's platformdirs state directory, and ``$PYRT_HOME`` if it was set) are
listed before the run and after it: anything that appeared or changed there
fails the run, naming the paths.
"""

from __future__ import annotations

import os
import signal
from collections.abc import Iterator
from pathlib import Path

import platformdirs
import pytest
from hypothesis import settings

pytest_plugins = ["pytester"]

# A run started in the background by a non-interactive shell (``cmd &``, nohup, a CI
# runner) inherits SIGINT ignored, and so would every pyrt it starts: the tests that
# send a Ctrl-C (SIGINT) to a console would then see it ignored.  Ctrl-C as a terminal
# gives it: the run's own SIGINT back to Python's handler, which a child's exec resets
# to the default action.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

# Property tests explore new examples on a developer's machine; under CI (CI set,
# as .ci/run's caller does) they draw the same examples every run, so a result
# can be reproduced and a green run does not depend on the draw.  Every failure
# found locally is kept in the example database and tried again.
settings.register_profile("ci", derandomize=True, print_blob=True)
settings.register_profile("dev", print_blob=True)
settings.load_profile(os.environ.get("PYRT_HYPOTHESIS_PROFILE", "ci" if os.environ.get("CI") else "dev"))


def real_state_directories() -> list[Path]:
    """Where pyrt would keep its state without the sandbox (read from the environment now)."""
    dirs = [Path(platformdirs.user_state_dir("pyrt", appauthor=False))]
    home = os.environ.get("PYRT_HOME")
    if home:
        dirs.append(Path(home))
    return dirs


def snapshot(dirs: list[Path]) -> dict[str, tuple[int, int] | None]:
    """Every path under ``dirs`` (and the directories themselves): size and
    modification time of files, None for directories."""
    seen: dict[str, tuple[int, int] | None] = {}
    for d in dirs:
        if not d.exists():
            continue
        for p in [d, *d.rglob("*")]:
            try:
                st = p.lstat()
            except OSError:
                continue
            seen[str(p)] = None if p.is_dir() else (st.st_size, st.st_mtime_ns)
    return seen


@pytest.fixture(scope="session", autouse=True)
def pyrt_state_sandbox(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """PYRT_HOME and XDG_STATE_HOME in a temporary directory for the whole run;
    the run fails if anything appears or changes in the real state directories."""
    real = real_state_directories()
    before = snapshot(real)
    sandbox = tmp_path_factory.mktemp("pyrt-state")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("PYRT_HOME", str(sandbox / "pyrt-home"))
        mp.setenv("XDG_STATE_HOME", str(sandbox / "xdg-state"))
        yield sandbox
    after = snapshot(real)
    changed = sorted(p for p in before.keys() | after.keys() if before.get(p, 0) != after.get(p, 0))
    if changed:
        shown = ", ".join(changed[:5]) + (f" and {len(changed) - 5} more" if len(changed) > 5
                                           else "")
        pytest.fail(f"the test run wrote outside its sandbox, in the user's pyrt state "
                    f"({', '.join(map(str, real))}): {shown}", pytrace=False)


@pytest.fixture(autouse=True)
def _motion_types_restored():
    """A motion type a test registers is gone after it (the registry is process-wide)."""
    # pyrt's own types register on import: import them before the snapshot, so that
    # a test that happens to import one first does not take it away from the rest.
    import pyrt.robots.gripper
    import pyrt.robots.paths
    import pyrt.robots.trajectory  # noqa: F401
    from pyrt.scheduler import motion

    before = dict(motion._registry)
    yield
    motion._registry.clear()
    motion._registry.update(before)


_SHUTDOWN_SIGNALS = tuple(getattr(signal, n) for n in ("SIGTERM", "SIGHUP", "SIGINT")
                          if hasattr(signal, n))


@pytest.fixture(autouse=True)
def _signal_handlers_restored():
    """The shutdown signals' handlers are as they were after each test.  A console run
    in process ends by ignoring SIGTERM and SIGHUP (its process is ending); left so, the
    ignore would pass to every process a later test starts, and a SIGTERM it sends a
    ``pyrt board-sim`` before that process takes the signal would be lost."""
    before = {s: signal.getsignal(s) for s in _SHUTDOWN_SIGNALS}
    yield
    for s, handler in before.items():
        if signal.getsignal(s) is not handler and handler is not None:
            signal.signal(s, handler)
