"""The server under load, against a real-time (WallClock) gripper loop.

Only what holds however late the ticks come is asserted: every reply right,
counts of replies (not rates), nothing faults.  The rates and the loop's
lateness idle and loaded are figures: bench/bench_server.py."""

from __future__ import annotations

import itertools

import pytest
from _server_rig import read_lines, run_load, served

pytestmark = pytest.mark.wallclock

def _signed(word: str) -> int:
    v = int(word, 16)
    return v - 0x10000 if v & 0x8000 else v


def test_32_clients_read_status_while_a_move_runs():
    """32 clients poll STATUS and W while the operator closes the jaws: every reply is OK and the move completes."""
    with served(wall=True) as sv:
        op = sv.operator()
        sub = sv.client()
        sub.command("SUBSCRIBE 20")

        def move() -> list[str]:
            op.command("P E47A")
            return op.command("wait 30")

        # counts of replies, not rates: they hold however loaded the machine is
        status = run_load(sv.host, sv.port, 32, 2.0, "STATUS", during=move, at_least=500)
        reads = run_load(sv.host, sv.port, 32, 0.5, "W", at_least=50)
        assert status["errors"] == reads["errors"] == 0
        assert status["requests"] >= 1000 and reads["requests"] >= 100
        (ended,) = status["during"]
        assert ended.startswith("at target: position")
        assert abs(_signed(op.command("W")[0]) + 0x1B86) <= 16
        moving = []
        # a live stream: stop at the end (the read's bound catches a hang only)
        for sample in itertools.islice(sub.statuses(30.0), 400):
            if sample.time_s is None:  # a pushed line (the end of the move), not a sample
                continue
            moving.append(sample.fields["moving"])
            if 1 in moving and moving[-1] == 0:
                break
        assert 1 in moving and moving[-1] == 0
        assert sv.still_and_null()


def test_32_busy_clients_get_only_right_replies_and_fault_nothing():
    """32 busy clients: no reply wrong or lost, nothing faults, the loop ticks on and a new connection is answered (lateness and STATUS/s idle vs loaded: bench/bench_server.py)."""
    with served(wall=True) as sv:
        loop = sv.rig.loop
        sv.runner.call(loop.reset_statistics)
        load = run_load(sv.host, sv.port, 32, 1.5, "STATUS", at_least=500)
        busy = sv.runner.call(loop.statistics)
        assert load["errors"] == 0 and load["requests"] >= 2 * 500
        assert sv.rig.fault is None
        assert busy.lateness.count > 0
        s = sv.raw()
        s.sendall(b"STATUS\n")
        assert read_lines(s, 1)[0].startswith("OK t=")
