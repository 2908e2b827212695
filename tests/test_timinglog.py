"""The timing log when its file refuses a write (a full disk)."""

from __future__ import annotations

import errno
import io
import os
import subprocess
import sys

import pytest

from pyrt.scheduler.timinglog import TimingLog


class FullDisk(io.StringIO):
    """A text stream whose every write is refused as a full disk refuses it."""

    def write(self, s: str) -> int:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


def test_a_refused_write_ends_the_log_and_never_the_run():
    """A refused write is kept as the log's failure; later records are dropped, nothing raises."""
    log = TimingLog(FullDisk(), version="t")
    log.header(period_ns=1_000_000, clock="sim", tasks=["a"], handlers=[])
    assert isinstance(log.failed, OSError) and log.failed.errno == errno.ENOSPC
    log.overrun(tick=1, deadline_ns=0, start_ns=0, end_ns=2, lateness_ns=0, tasks=[("a", 5)])
    log.flush()
    log.close()
    assert log.failed.errno == errno.ENOSPC


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs /dev/full (Linux)")
def test_a_station_with_its_timing_log_on_a_full_disk_runs_and_says_so(tmp_path):
    """pyrt gripper --timing-log /dev/full runs, quits with status 0 and says the log ended early: no traceback."""
    run = subprocess.run(
        [sys.executable, "-m", "pyrt", "gripper", "--speed", "max", "--black-box", "off",
         "--timing-log", "/dev/full"],
        input="S\nquit\n", capture_output=True, text=True, timeout=120, cwd=tmp_path)
    out = run.stdout + run.stderr
    assert "Traceback" not in out, out
    assert run.returncode == 0, out
    assert "timing log /dev/full: ended early" in out, out
