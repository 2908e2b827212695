"""pyrt STATION --stream udp://HOST:PORT: the scope streamed live from the first tick, every option checked before anything runs."""

from __future__ import annotations

import itertools
import json
import socket
import subprocess
import sys

import pytest


def _pyrt(*argv: str, script: str = "quit\n") -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "pyrt", *argv], input=script, text=True,
                          capture_output=True, timeout=120)


@pytest.fixture
def listener():
    """A UDP socket on loopback (ephemeral port), as PlotJuggler's UDP server."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 * 2**20)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(10)  # a bound on each wait: the run has ended when we read
    yield sock
    sock.close()


def test_a_piped_gripper_move_reaches_the_listener_from_the_first_tick(listener):
    """pyrt gripper --speed max --stream ... --stream-channel encoder: the jaw move of a piped script arrives as PlotJuggler's UDP JSON at 20 objects a second of loop time, the encoder falling."""
    port = listener.getsockname()[1]
    run = _pyrt("gripper", "--speed", "max", "--stream", f"udp://127.0.0.1:{port}",
                "--stream-hz", "20", "--stream-channel", "encoder",
                script="I\nP E47A\nsleep 2\nquit\n")
    assert run.returncode == 0, run.stderr
    assert f"streaming encoder to udp://127.0.0.1:{port} at 20 Hz" in run.stdout
    got = []
    listener.settimeout(0.5)
    while True:
        try:
            got.append(json.loads(listener.recv(65536)))
        except TimeoutError:
            break
    assert len(got) >= 40  # 2 s of the move at 20 Hz, and the script's other ticks
    times = [m["timestamp"] for m in got]
    assert all(abs(b - a - 0.05) < 1e-9 for a, b in itertools.pairwise(times))
    assert got[-1]["encoder"] < got[0]["encoder"]


@pytest.mark.parametrize(("argv", "said"), [
    (["--stream", "http://127.0.0.1:9870", "--stream-channel", "encoder"], "udp://HOST:PORT"),
    (["--stream", "udp://127.0.0.1:9870", "--stream-hz", "0", "--stream-channel", "encoder"],
     "outside"),
    (["--stream", "udp://127.0.0.1:9870", "--stream-hz", "fast", "--stream-channel", "encoder"],
     "not a number"),
    (["--stream", "udp://127.0.0.1:9870"], "at least one --stream-channel"),
    (["--stream", "udp://127.0.0.1:9870", "--stream-channel", "gripper.nope"], "gripper.nope"),
    (["--stream-channel", "encoder"], "needs --stream"),
])
def test_a_bad_stream_option_is_a_usage_error_and_nothing_runs(argv, said):
    """A bad destination, rate or channel, or a channel without --stream: exit 2 naming it, before the banner (the station never started)."""
    run = _pyrt("gripper", "--speed", "max", *argv)
    assert run.returncode == 2
    assert said in run.stderr
    assert "type help" not in run.stdout
