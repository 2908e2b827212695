"""pyrt.client and ``pyrt send`` against a served gripper on loopback."""

from __future__ import annotations

import itertools

import pytest
from _server_rig import TOKEN, served
from hypothesis import given, settings
from hypothesis import strategies as st

from pyrt.cli import main
from pyrt.client import Client, ServerError, parse_address, parse_status

ADDRESSES = [
    ("5050", ("127.0.0.1", 5050)),
    (":5050", ("127.0.0.1", 5050)),
    ("localhost:1", ("localhost", 1)),
    ("10.0.0.7:65535", ("10.0.0.7", 65535)),
    ("[::1]:5050", ("::1", 5050)),
    (" 127.0.0.1:80 ", ("127.0.0.1", 80)),
]
BAD_ADDRESSES = ["", "host:", "host:0", "host:65536", "host:-1", "host:http", "[::1]5050",
                 "[::1", "5050x", "1.2.3.4:5:x"]


@pytest.mark.parametrize(("text", "expected"), ADDRESSES)
def test_parse_address(text, expected):
    """[HOST:]PORT and [IPv6]:PORT parse, the host defaulting to 127.0.0.1."""
    assert parse_address(text) == expected


@pytest.mark.parametrize("text", BAD_ADDRESSES)
def test_parse_address_refuses(text):
    """Missing, out-of-range or malformed ports raise ValueError."""
    with pytest.raises(ValueError):
        parse_address(text)


@settings(max_examples=200, deadline=None)
@given(st.text(max_size=30))
def test_parse_address_raises_only_value_error(text):
    """Any text either parses to a port 1..65535 or raises ValueError."""
    try:
        _host, port = parse_address(text)
    except ValueError:
        return
    assert 1 <= port <= 65535


def test_parse_status_lines():
    """STATUS samples become fields (ints, 0x hex, floats, words); STATUS FAULT lines a fault."""
    s = parse_status("STATUS t=1.500000 position=-7046 sensors=0xFBFF x=0.25 mode=idle junk")
    assert s.time_s == 1.5 and s.fault is None
    assert s.fields == {"position": -7046, "sensors": 0xFBFF, "x": 0.25, "mode": "idle"}
    f = parse_status("STATUS FAULT gripper: fault in SYSCLK at tick 9 (0.009000 s): bad Q")
    assert f.fault.startswith("gripper: fault") and f.fields == {} and f.time_s is None


def test_command_reply_and_errors():
    """command() returns the reply's lines; ERR raises ServerError with code, text and output."""
    with served() as sv, sv.client() as c:
        assert c.greeting.startswith("pyrt ") and "gripper" in c.greeting
        assert c.command("T") == ["0000"]
        help_lines = c.command("help")
        assert len(help_lines) > 10 and help_lines[-1].startswith("read-only until AUTH")
        with pytest.raises(ServerError) as exc:
            c.command("P E47A")
        assert exc.value.code == "denied" and "AUTH" in exc.value.text
        reply = c.request("W 12")  # a read, malformed: the shell's own error
        assert not reply.ok and reply.code == "command" and "no argument" in reply.text
        with pytest.raises(ValueError):
            c.send_line("W\nP E47A")


def test_subscription_lines_are_kept_apart_from_replies():
    """STATUS lines that arrive between replies are kept for statuses(), in time order."""
    with served() as sv, sv.client() as c:
        op = sv.operator()
        c.command("SUBSCRIBE 100")
        op.command("sleep 0.1")  # the loop runs 100 ticks: 10 samples
        assert c.command("W") == ["0000"]  # the samples came before this reply
        samples = list(itertools.islice(c.statuses(0.5), 10))
        assert len(samples) == 10
        times = [s.time_s for s in samples]
        assert times == sorted(times) and times[1] - times[0] == pytest.approx(0.01)
        c.unsubscribe()


def test_send_prints_the_reply(capsys):
    """pyrt send HOST:PORT W prints the reply's text and exits 0."""
    with served() as sv:
        assert main(["send", f"{sv.host}:{sv.port}", "W"]) == 0
        assert capsys.readouterr().out == "0000\n"


def test_send_reports_a_refusal(capsys, monkeypatch):
    """A denied command is reported on stderr with exit status 1; nothing moves."""
    monkeypatch.delenv("PYRT_TOKEN", raising=False)
    with served() as sv:
        assert main(["send", str(sv.port), "P", "E47A"]) == 1
        err = capsys.readouterr().err
        assert "ERR denied" in err
        assert sv.still_and_null()


def test_send_authenticates_with_the_token(capsys, monkeypatch, tmp_path):
    """With PYRT_TOKEN or --token-file the command is sent privileged."""
    with served() as sv:
        monkeypatch.setenv("PYRT_TOKEN", TOKEN)
        assert main(["send", f"{sv.host}:{sv.port}", "X", "33"]) == 0
        monkeypatch.delenv("PYRT_TOKEN")
        f = tmp_path / "token"
        f.write_text(TOKEN + "\n")
        f.chmod(0o600)
        assert main(["send", "--token-file", str(f), f"{sv.host}:{sv.port}", "T"]) == 0
        assert capsys.readouterr().out == (
            "speed 7F -> 33: JSPEED 33, MXPJSPD B3, MXNJSPD 4D (up to 860 counts/s)\n0000\n")
        f.write_text("wrong-but-long-enough\n")
        assert main(["send", "--token-file", str(f), f"{sv.host}:{sv.port}", "T"]) == 1
        assert "ERR auth" in capsys.readouterr().err


def test_send_subscribe_prints_status_lines(capsys):
    """pyrt send PORT SUBSCRIBE 50 --count 3 prints three STATUS lines (a real-time loop)."""
    with served(wall=True) as sv:
        assert main(["send", "--count", "3", f"{sv.host}:{sv.port}", "SUBSCRIBE", "50"]) == 0
        lines = capsys.readouterr().out.splitlines()
        assert len(lines) == 3 and all(x.startswith("STATUS t=") for x in lines)


def test_send_to_nobody_fails_cleanly(capsys):
    """No server at the address: one line on stderr saying so in words (no errno) and
    what to check, exit status 1."""
    with served() as sv:
        port = sv.port
    assert main(["send", f"127.0.0.1:{port}", "W"]) == 1
    err = capsys.readouterr().err
    assert err == (f"pyrt send: 127.0.0.1:{port}: cannot connect: connection refused (is a "
                   "station served there with --serve?)\n")
    assert main(["send", "nonsense:port", "W"]) == 2


def test_client_connects_by_address_string():
    """Client.connect('HOST:PORT') reads the greeting; closing twice is harmless."""
    with served() as sv:
        c = Client.connect(f"{sv.host}:{sv.port}")
        assert c.status().fields["fault"] == 0
        c.close()
        c.close()


class _ScriptedServer:
    """A one-connection line server on loopback whose replies the test releases."""

    def __init__(self):
        import socket
        import threading

        self._listen = socket.create_server(("127.0.0.1", 0))
        self.port = self._listen.getsockname()[1]
        self.conn = None
        self._ready = threading.Event()
        threading.Thread(target=self._accept, daemon=True).start()

    def _accept(self):
        self.conn, _ = self._listen.accept()
        self.conn.sendall(b"OK pyrt test server\n")
        self._ready.set()

    def send(self, text: str) -> None:
        assert self._ready.wait(10)
        self.conn.sendall(text.encode())

    def close(self):
        if self.conn is not None:
            self.conn.close()
        self._listen.close()


def test_a_reply_abandoned_by_a_timeout_is_dropped_before_the_next_request_is_answered():
    """A request whose reply was not read is still owed: the next request gets its own reply, never the abandoned one."""
    srv = _ScriptedServer()
    try:
        c = Client("127.0.0.1", srv.port, timeout_s=10)
        c.timeout_s = 0.05  # the 'wait' answers late
        srv.send("OK-moving\n")  # part of the reply comes before the timeout
        with pytest.raises(TimeoutError):
            c.request("wait")
        assert list(c.owed) == ["wait"]
        c.timeout_s = 10
        srv.send("OK at target: E47A\nOK E479\nOK E47A\n")  # wait's rest, W's, T's
        assert c.command("W") == ["E479"]
        assert c.command("T") == ["E47A"]
        assert not c.owed
        assert [(line, r.lines) for line, r in c.late] == [
            ("wait", ["moving", "at target: E47A"])]
        c.close()
    finally:
        srv.close()


def test_settle_reads_every_owed_reply_in_order():
    """settle() reads the owed replies in the order the requests were sent, failures included."""
    srv = _ScriptedServer()
    try:
        c = Client("127.0.0.1", srv.port, timeout_s=10)
        c.send_line("a")
        c.send_line("b")
        c.owed.extend(["a", "b"])
        srv.send("STATUS t=1 position=5\nOK one\nERR command no such thing\n")
        done = c.settle()
        assert [(line, r.ok, r.lines) for line, r in done] == [("a", True, ["one"]),
                                                               ("b", False, [])]
        assert done[1][1].code == "command" and not c.owed
        assert next(c.statuses(0.05)).fields["position"] == 5
        c.close()
    finally:
        srv.close()
