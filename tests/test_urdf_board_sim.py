"""pyrt urdf against pyrt board-sim urdf over tcp:// (real time): the world in its own process."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.wallclock

ROOT = Path(__file__).resolve().parents[1]
TWO_LINK = Path(__file__).parent / "data" / "two_link.urdf"


def _env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(ROOT)}


@pytest.mark.parametrize("urdf", [None, TWO_LINK], ids=["puma560", "two-link"])
def test_the_controller_moves_the_arm_of_a_board_sim_over_tcp(urdf):
    """board-sim urdf [FILE] serves the arm's board and world; pyrt urdf [FILE] --boards tcp:// closes the loop over the link (the arm lies on its stops after falling while nobody held it: the first move brings it back inside its limits), moves a joint move, and the world's INFO says where the true arm is."""
    file_args = [] if urdf is None else [str(urdf)]
    sim = subprocess.Popen([sys.executable, "-m", "pyrt", "board-sim", "urdf", *file_args,
                            "--listen", "127.0.0.1:0", "--watchdog", "2"],
                           stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True, env=_env())
    try:
        first = sim.stdout.readline()
        m = re.search(r" on (tcp://127\.0\.0\.1:\d+) ", first)
        assert m, first + sim.stderr.read()
        name, target = (("puma560", "movej 5 40 -175 0 -45 0") if urdf is None
                        else ("twolink", "movej 20 -30"))
        # slowly: the controller runs at real time on a machine other work may share
        script = f"{name} {target} speed=0.1\nwait 60\n{name} where\nsim show\nquit\n"
        done = subprocess.run([sys.executable, "-m", "pyrt", "urdf", *file_args, "--boards",
                               m.group(1)], input=script, capture_output=True, text=True,
                              timeout=300, env=_env(), cwd=ROOT)
        out = done.stdout
        assert done.returncode == 0, out + done.stderr
        assert "last move: at target" in out, out
        info = re.search(r"board-sim at tcp://\S+: (.*)$", out, re.M)
        assert info, out
        want = [float(v) for v in target.split()[1:]]
        got = {k: float(v) for k, v in re.findall(r"q(\d+)=([-\d.]+)", info.group(1))}
        assert [round(got[str(j + 1)], 1) for j in range(len(want))] == pytest.approx(want, abs=0.1)
    finally:
        sim.kill()
        sim.wait(10)
