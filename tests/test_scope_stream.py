"""scope stream udp://HOST:PORT: the scope's samples live as PlotJuggler's UDP JSON, at the stated rate of loop time."""

from __future__ import annotations

import io
import itertools
import json
import socket
import struct

import pytest
from _server_rig import served

from pyrt.errors import CommandError
from pyrt.scheduler import Loop, SimClock
from pyrt.scope import Scope, Source
from pyrt.scope.stream import QUEUE, Layout, UdpStream, parse_udp_url


@pytest.fixture
def listener():
    """A UDP socket on loopback (ephemeral port), as PlotJuggler's UDP server."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 * 2**20)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(10)  # a bound on each wait; the sender says how many it sent
    yield sock
    sock.close()


def _receive(sock: socket.socket, n: int) -> list[dict]:
    """``n`` datagrams, each one JSON object."""
    return [json.loads(sock.recv(65536)) for _ in range(n)]


def _gripper(tmp_path, monkeypatch, *lines: str) -> tuple[str, object]:
    from pyrt.commands import RobotShell
    from pyrt.station.gripper import build_gripper

    monkeypatch.chdir(tmp_path)
    station = build_gripper(Loop(SimClock()))
    station.start()
    out = io.StringIO()
    shell = RobotShell(station, out)
    try:
        for line in lines:
            shell.onecmd(line)
        scope = station.scope
    finally:
        station.shutdown()
    return out.getvalue(), scope


def test_a_listener_gets_the_move_at_the_stated_rate_and_the_values_scope_save_has(
        tmp_path, monkeypatch, listener):
    """During a move, a listener on loopback receives one object every 1/50 s of loop
    time, stamped with the loop time, and each holds the values of the saved frame's row
    of that time (grouped by object, as PlotJuggler shows them)."""
    port = listener.getsockname()[1]
    said, _scope = _gripper(tmp_path, monkeypatch, "I", "scope add encoder gripper.dac sim.x",
                            "scope run roll", f"scope stream udp://127.0.0.1:{port} 50",
                            "P E47A", "sleep 2", "scope stream", "scope stream off",
                            "scope stop", "scope save f.csv")
    assert f"to udp://127.0.0.1:{port} at 50 Hz of loop time" in said
    sent = int(said.split("stream off; streaming to ")[1].split(": ")[1].split(" sent")[0])
    assert 100 <= sent <= 102  # 2 s of loop time at 50 Hz (and the commands' own ticks)
    got = _receive(listener, sent)
    times = [m["timestamp"] for m in got]
    assert all(abs(b - a - 0.02) < 1e-9 for a, b in itertools.pairwise(times))
    assert set(got[0]) == {"timestamp", "encoder", "gripper", "sim"}
    rows = {round(float(r.split(",")[0]), 6): [float(x) for x in r.split(",")[1:]]
            for r in (tmp_path / "f.csv").read_text().splitlines()[1:]}
    for m in got:
        enc, dac, x = rows[round(m["timestamp"], 6)]
        assert (m["encoder"], m["gripper"]["dac"]) == (enc, dac)
        assert m["sim"]["x"] == pytest.approx(x, rel=1e-8)
    encs = [m["encoder"] for m in got]
    assert encs[-1] < encs[0]  # the move is in the stream


def test_an_absent_receiver_changes_nothing_the_controller_does(tmp_path, monkeypatch):
    """Streaming to a port where nobody listens: the move samples the same as without a
    stream, and nothing is raised."""
    free = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    free.bind(("127.0.0.1", 0))
    port = free.getsockname()[1]
    free.close()
    lines = ["I", "scope add encoder gripper.dac", "scope run roll", "P E47A", "sleep 1",
             "scope stop", "scope save f.csv"]
    _gripper(tmp_path, monkeypatch, *lines)
    plain = _from_the_move(tmp_path / "f.csv")
    said, _ = _gripper(tmp_path, monkeypatch, *lines[:3], f"scope stream udp://127.0.0.1:{port}",
                       *lines[3:], "scope stream off")
    assert "error" not in said and "streaming to" in said
    streamed = _from_the_move(tmp_path / "f.csv")
    n = min(len(streamed), len(plain))  # the stream's command takes ticks of its own
    assert n > 900 and streamed[:n] == plain[:n]


def _from_the_move(path) -> list[list[str]]:
    """The saved rows' values (time left out) from the first with the drive on."""
    rows = [r.split(",")[1:] for r in path.read_text().splitlines()[1:]]
    start = next(i for i, r in enumerate(rows) if float(r[1]) != 0x80)
    return rows[start:]


def test_a_full_queue_drops_and_counts_never_blocks():
    """When the stream's thread falls behind, offers past the queue's room are counted
    as dropped, not buffered and not waited for."""
    stream = UdpStream("127.0.0.1", 9, 10)
    stream._stop.set()
    stream._thread.join(5)  # the thread gone: nothing drains
    layout = Layout(struct.Struct("<qd"), ("x",))
    row = layout.packer.pack(1_000_000, 2.5)
    for _ in range(QUEUE + 100):
        stream.offer(layout, row)
    assert stream.dropped == 100
    assert stream.encode(layout, row) == b'{"timestamp":0.001,"x":2.5}'
    stream.close()
    assert "100 dropped (the stream fell behind the loop)" in stream.describe()


def test_the_scope_offers_one_sample_per_period_of_loop_time():
    """On a bare scope sampling every tick (1 ms), a 100 Hz stream is offered every 10th
    sample, the first at once; 'off' stops the offers."""
    loop = Loop(SimClock())
    plant = type("P", (), {"x": 0.0})()
    loop.attach(lambda now: setattr(plant, "x", now / 1e6))
    scope = Scope(capacity=100)
    loop.attach(scope.sample)
    scope.add("x", Source.attr(plant, "x"))
    offered = []

    class Probe:
        period_ns = 10_000_000

        def offer(self, layout, row):
            offered.append(layout.packer.unpack(row))

        def bind(self, owner):
            pass

    scope.run("roll")
    loop.run(5)
    scope.start_stream(Probe())
    loop.run(45)
    assert [t for t, _ in offered] == [k * 1_000_000 for k in (6, 16, 26, 36, 46)]
    assert all(x == t / 1e6 for t, x in offered)
    scope.stop_stream()
    loop.run(50)
    assert len(offered) == 5


BAD_STREAMS = ["tcp://127.0.0.1:9870", "udp://127.0.0.1", "udp://:9870",
               "udp://127.0.0.1:99999", "udp://127.0.0.1:9870/x", "9870", "udp://h:p"]


@pytest.mark.parametrize("url", BAD_STREAMS)
def test_a_bad_destination_is_refused(url):
    """Anything but udp://HOST:PORT is refused, saying the form."""
    with pytest.raises(CommandError, match=r"udp://HOST:PORT|outside 1\.\.65535"):
        parse_udp_url(url)


@pytest.mark.parametrize("hz", [0, 0.05, 1001, float("nan")])
def test_a_rate_outside_the_range_is_refused(hz):
    """The rate is 0.1..1000 objects a second."""
    with pytest.raises(CommandError, match=r"rate must be 0\.1\.\.1000 Hz"):
        UdpStream("127.0.0.1", 9, hz)


def test_starting_a_stream_needs_the_token():
    """Over the DAQ link, without the token, 'scope stream' is denied (it sends data
    elsewhere); with it, it streams."""
    with served() as sv:
        c = sv.client()
        assert c.request("scope stream udp://127.0.0.1:9").code == "denied"
        op = sv.operator()
        assert "streaming" in op.command("scope stream udp://127.0.0.1:9")[0]
        assert op.command("scope stream off")[0].startswith("stream off")


def test_the_streams_thread_ends_when_its_scope_is_gone():
    """A scope dropped while it streams (a station closed without 'scope stream off'):
    the stream's thread ends by itself."""
    import gc

    scope = Scope(capacity=10)
    stream = UdpStream("127.0.0.1", 9, 10)
    scope.start_stream(stream)
    assert stream._thread.is_alive()
    del scope
    gc.collect()
    stream._thread.join(timeout=10)  # the thread looks every 10 ms
    assert not stream._thread.is_alive()
    stream.close()
