"""The DAQ link under abuse: range checks, one client's bug, back-off, eviction, tokens, timeouts, fuzz.

Every socket is on 127.0.0.1; every loop is bounded in count and time.
"""

from __future__ import annotations

import os
import random
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from _server_rig import TOKEN, read_lines, read_until_closed, served

from pyrt.cli._serve import Service
from pyrt.client import Client, ServerError
from pyrt.db import copy_station
from pyrt.errors import ConfigError
from pyrt.server import ServedStation, Server
from pyrt.server.guard import FailureGuard, check_token, escape_text
from pyrt.station.manipulator import ManipulatorStation

LONG_TOKEN = "doors-token-0123456789"


def _env(**extra: str) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "PYRT_TOKEN"}
    env.update(PYTHONUNBUFFERED="1", **extra)
    return env


def _start(args: list[str], cwd: Path, env: dict | None = None) -> tuple[subprocess.Popen, int]:
    """``pyrt ARGS`` in a subprocess; the port from its 'serving' line (30 s at most)."""
    proc = subprocess.Popen([sys.executable, "-m", "pyrt", *args], stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=env or _env(), cwd=cwd)
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        line = proc.stderr.readline()
        if not line:
            break
        m = re.search(r"serving \S+ on 127\.0\.0\.1:(\d+)", line)
        if m:
            # the service logs every connection: keep reading, or its pipe fills and it blocks
            kept: list[str] = []
            reader = threading.Thread(target=kept.extend, args=(proc.stderr,), daemon=True)
            reader.start()
            proc.kept, proc.reader = kept, reader  # type: ignore[attr-defined]
            return proc, int(m.group(1))
    proc.kill()
    raise AssertionError(f"no 'serving' line: {proc.communicate()}")


def _stop(proc: subprocess.Popen) -> tuple[int, str]:
    proc.send_signal(signal.SIGTERM)
    try:
        proc.wait(timeout=30)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
    proc.reader.join(10)  # type: ignore[attr-defined]
    return proc.returncode, "".join(proc.kept)  # type: ignore[attr-defined]


def _token_file(tmp_path: Path, token: str = LONG_TOKEN, mode: int = 0o600) -> Path:
    f = tmp_path / "token"
    f.write_text(token + "\n")
    f.chmod(mode)
    return f


def _served_gripper(tmp_path: Path) -> tuple[subprocess.Popen, int]:
    return _start(["gripper", "--serve", "127.0.0.1:0", "--headless", "--speed", "max",
                   "--token-file", str(_token_file(tmp_path))], cwd=tmp_path)


# -- servers no request can kill ---------------------------------------------------------

BAD_RATES = ["1e-300", "5e-324", "1e-10", "0", "-1", "nan", "inf", "-inf", "1e309", "1e400",
             "0.001", "20000", "0x10", "1_0", "\u0661\u0660", "", "10 20", "1e99999"]


@pytest.mark.wallclock
def test_subscribe_rates_out_of_range_are_refused_and_the_server_lives(tmp_path):
    """pyrt gripper --serve --headless: SUBSCRIBE 1e-300 and every other rate out of range or
    not ASCII gets ERR syntax; the server then still greets, answers STATUS and serves a stop."""
    proc, port = _served_gripper(tmp_path)
    try:
        replies = []
        with Client("127.0.0.1", port) as c:
            for rate in BAD_RATES:
                replies.append(c.request(f"SUBSCRIBE {rate}".strip()))
        assert [r.code for r in replies] == ["syntax"] * len(BAD_RATES), replies
        with Client("127.0.0.1", port, timeout_s=10) as c:
            assert c.status().fields["fault"] == 0
            assert c.command("stop")[0].startswith("gripper: every motor stopped")
            assert c.command("SUBSCRIBE 0.01")[0].startswith("subscribed at 0.01 Hz")
    finally:
        code, err = _stop(proc)
    assert code == 0, err
    assert "Traceback" not in err


def test_a_bug_in_one_clients_handling_closes_that_client_only(monkeypatch):
    """A request that meets a bug in the I/O thread: that client gets ERR internal and is
    closed; the server thread lives and every other client is served."""
    with served() as sv:
        robot = sv.server.robot
        real = robot.is_read_only

        def buggy(line: str) -> bool:
            if line.startswith("boom"):
                raise RuntimeError("a bug")
            return real(line)

        monkeypatch.setattr(robot, "is_read_only", buggy)
        other = sv.client()
        s = sv.raw()
        s.sendall(b"boom\nW\n")
        text = read_until_closed(s)
        assert text.startswith("ERR internal RuntimeError") and "closing" in text, text
        assert "OK" not in text  # the W after it was never run
        assert sv.server.alive and sv.server.counters["internal"] == 1
        assert other.command("W") == ["0000"]
        assert sv.client().status().fields["fault"] == 0


def test_a_dead_server_thread_is_a_fault_the_operator_sees(monkeypatch):
    """The I/O thread itself fails: the station is tripped naming the server (every motor
    stopped, ack needed) and newcomers are refused at once instead of hanging."""
    with served() as sv:

        def broken(now: float) -> None:
            raise RuntimeError("the I/O loop is broken")

        monkeypatch.setattr(sv.server, "_check_timeouts", broken)
        deadline = time.monotonic() + 10  # the check runs every 0.1 s
        while sv.server.alive and time.monotonic() < deadline:
            time.sleep(0.02)
        assert not sv.server.alive and isinstance(sv.server.crashed, RuntimeError)
        fault = sv.runner.call(lambda: sv.rig.fault, take_fault=False)
        assert fault is not None and "DAQ server has stopped" in fault.cause
        assert sv.still_and_null()
        with pytest.raises(OSError):
            Client(sv.host, sv.port, timeout_s=5)
        # headless, nothing could reach the station: the service stops and says so (exit 1)
        assert Service(sv.runner, sv.server.robot, sv.server).run_headless() == 1


@pytest.mark.parametrize("tool", [["send", "{addr}", "STATUS", "--timeout", "600"],
                                  ["connect", "{addr}", "--timeout", "600", "--hz", "0"]])
def test_send_and_connect_report_a_server_that_never_greets(tmp_path, tool):
    """pyrt send/connect against a port that accepts but never answers (a stuck server):
    exit 1 naming the missing greeting, well before their reply timeout of 600 s."""
    with socket.socket() as listener:
        listener.bind(("127.0.0.1", 0))
        listener.listen(4)  # the kernel completes the handshake; nobody ever greets
        addr = f"127.0.0.1:{listener.getsockname()[1]}"
        argv = [a.format(addr=addr) for a in tool]
        proc = subprocess.run([sys.executable, "-m", "pyrt", *argv], stdin=subprocess.DEVNULL,
                              capture_output=True, text=True, env=_env(), cwd=tmp_path,
                              timeout=120)
    assert proc.returncode == 1, proc
    assert "no greeting" in proc.stderr and "Traceback" not in proc.stderr


# -- tokens -------------------------------------------------------------------------------

@pytest.mark.parametrize(("how", "message"), [
    ("short-env", "at least 16"),
    ("short-file", "at least 16"),
    ("world-readable", "chmod 600"),
    ("group-readable", "chmod 600"),
])
def test_weak_tokens_and_open_token_files_are_refused(tmp_path, how, message):
    """A 1-character token (file or PYRT_TOKEN) and a token file others may read: exit 1 with
    the reason, no traceback, nothing served."""
    args = ["gripper", "--serve", "127.0.0.1:0", "--headless", "--speed", "max"]
    env = _env()
    if how == "short-env":
        env["PYRT_TOKEN"] = "x"
    elif how == "short-file":
        args += ["--token-file", str(_token_file(tmp_path, "x"))]
    else:
        mode = 0o644 if how == "world-readable" else 0o640
        args += ["--token-file", str(_token_file(tmp_path, mode=mode))]
    proc = subprocess.run([sys.executable, "-m", "pyrt", *args], stdin=subprocess.DEVNULL,
                          capture_output=True, text=True, env=env, cwd=tmp_path, timeout=120)
    assert proc.returncode == 1, proc
    assert message in proc.stderr and "Traceback" not in proc.stderr
    assert "serving" not in proc.stderr


def test_check_token_names_what_is_wrong():
    """check_token: 16 characters pass; 15 and a token with spaces or controls are refused."""
    assert check_token("a" * 16) == "a" * 16
    for bad, why in (("a" * 15, "at least 16"), ("a" * 16 + " b", "one word"),
                     ("a" * 16 + "\x1b", "one word"), ("a" * 300, "one word")):
        with pytest.raises(ConfigError, match=why):
            check_token(bad)


# -- an audit trail that holds ------------------------------------------------------------

FLOOD = 600


@pytest.mark.wallclock
def test_an_auth_flood_backs_off_and_cannot_rotate_the_audit_log(tmp_path):
    """600 wrong AUTH over fresh connections (the issue's reconnecting guesser): few tokens are
    even compared (back-off), a few audit lines plus a summary are written, the operator's
    earlier command stays in the live audit log, and the operator's session is untouched."""
    proc, port = _served_gripper(tmp_path)
    outcomes = {"wrong": 0, "backoff": 0, "other": 0}
    try:
        op = Client("127.0.0.1", port)
        op.auth(LONG_TOKEN)
        op.command("X 33")  # a real, audited command
        deadline = time.monotonic() + 60
        for i in range(FLOOD):
            if time.monotonic() > deadline:
                break
            with socket.create_connection(("127.0.0.1", port), timeout=10) as s:
                read_lines(s, 1)
                s.sendall(f"AUTH guess-{i:06d}-abcdefgh\n".encode())
                line = (read_lines(s, 1) or [""])[0]
            key = ("backoff" if "try again" in line
                   else "wrong" if line.startswith("ERR auth wrong token") else "other")
            outcomes[key] += 1
        assert sum(outcomes.values()) == FLOOD, outcomes
        assert outcomes["other"] == 0, outcomes
        assert outcomes["wrong"] <= 30, outcomes  # guesses actually compared
        # while 127.0.0.1 backs off, even the right token is not looked at
        with Client("127.0.0.1", port) as late, pytest.raises(ServerError, match="try again"):
            late.auth(LONG_TOKEN)
        assert op.command("X 34")[0].startswith("speed 33 -> 34")
        op.close()
    finally:
        code, err = _stop(proc)
    assert code == 0, err
    log = (tmp_path / "pyrt-gripper-audit.log").read_text()
    assert not (tmp_path / "pyrt-gripper-audit.log.1").exists()
    lines = log.splitlines()
    assert any(ln.endswith(": X 33") for ln in lines)
    assert any(ln.endswith(": X 34") for ln in lines)
    failed = [ln for ln in lines if "failed AUTH" in ln]
    assert len(failed) <= 12, failed
    summary = re.search(r"audit: (\d+) failures from 127\.0\.0\.1 in \d+ s \(.*AUTH refused "
                        r"while backing off.*\), not written one by one", log)
    assert summary and int(summary.group(1)) >= outcomes["backoff"], log


class _Clock:
    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


def test_the_guard_backs_off_per_address_and_overall_and_summarises():
    """FailureGuard on a simulated clock: 3 failures back an address off 2 s, then 4 s; 30 from
    many addresses back every address but loopback off; a flood writes a bounded number of
    lines and one summary per window, naming the count, the address and the span."""
    clock = _Clock()
    said: list[str] = []
    g = FailureGuard(lambda who, line: said.append(f"{who}: {line}"), clock=clock)
    for _ in range(2):
        assert g.failed("192.0.2.1", "c", "failed AUTH") == 0
    assert g.failed("192.0.2.1", "c", "failed AUTH") == pytest.approx(2.0)
    assert g.blocked("192.0.2.1") == pytest.approx(2.0) and g.blocked("192.0.2.2") == 0
    clock.t += 2.5
    assert g.blocked("192.0.2.1") == 0
    for _ in range(3):
        left = g.failed("192.0.2.1", "c", "failed AUTH")
    assert left == pytest.approx(4.0)  # doubled
    said.clear()
    for i in range(1000):  # a distributed flood, 1000 addresses
        g.failed(f"198.51.100.{i % 250}", "c", "failed AUTH")
    assert g.blocked("203.0.113.9") > 0  # overall back-off: a stranger waits too
    assert g.blocked("127.0.0.1") == 0  # the robot's own computer never does
    assert len(said) <= 12, said
    clock.t += 61
    g.flush()
    assert len(said) <= 13
    assert re.fullmatch(r"audit: \d+ failures from \d+ addresses in 6\d s \(failed AUTH, request "
                        r"refused while backing off\), not written one by one; most from "
                        r"[\d.]+ \(\d+\)", said[-1]), said[-1]


def test_escape_text_leaves_no_line_or_terminal_escape():
    """escape_text: newlines, ESC, Unicode separators and bidi overrides become visible escapes;
    a backslash is doubled; printable text is unchanged."""
    assert escape_text("axis0 P 10") == "axis0 P 10"
    out = escape_text("a\nb\x1b[2Jc\u2028d\u202ee\\x0a")
    assert out == "a\\x0ab\\x1b[2Jc\\u2028d\\u202ee\\\\x0a"
    assert out.isprintable()
    assert escape_text("x" * 500, 10) == "x" * 10 + "..."


# -- bounded work per request ---------------------------------------------------------------

def test_idle_subscribers_give_their_slot_to_a_newcomer():
    """Every slot held by subscribers too slow to be in use (SUBSCRIBE 0.01): a newcomer gets
    a slot (not ERR full); the subscriber quiet longest is closed with ERR full."""
    with served(wall=True, max_clients=4, reserved_slots=0, evict_idle_s=0.3) as sv:
        subs = []
        for _ in range(4):
            c = sv.client()
            c.command("SUBSCRIBE 0.01")
            subs.append(c)
        deadline = time.monotonic() + 10
        newcomer = None
        while newcomer is None and time.monotonic() < deadline:
            time.sleep(0.1)  # until the first samples are 0.3 s old
            try:
                newcomer = sv.client()
            except ServerError as exc:
                assert exc.code == "full"
        assert newcomer is not None and newcomer.command("W") == ["0000"]
        assert sv.server.counters["evicted"] == 1
        codes = [_code_or_closed(c) for c in subs]
        assert sorted(codes) == ["", "", "", "full"], codes
        assert sv.server.clients == 4


def _code_or_closed(c: Client) -> str:
    """'' when ``c`` is still served, else the code it was closed with ('closed' if none)."""
    try:
        reply = c.request("W")
    except (ConnectionError, OSError):
        return "closed"
    return reply.code


def test_readloop_is_privileged_on_the_manipulator(tmp_path):
    """axisNEncoder readloop (a line on the operator's console every poll) is ERR denied
    without AUTH; stoploop and read stay open; with the token readloop is served."""
    station = ManipulatorStation(copy_station("prototype", tmp_path / "prototype"),
                                 tick_ns=5_000_000)
    runner = station.runner
    server = Server(runner, ServedStation(station), token=TOKEN)
    runner.start()
    host, port = server.start()
    try:
        with Client(host, port) as guest:
            assert guest.request("axis0Encoder readloop").code == "denied"
            assert guest.request("axis1Encoder readloop").code == "denied"
            assert guest.command("axis0Encoder stoploop") == ["axis0Encoder: stoploop"]
            assert guest.command("axis0Encoder read")[0].endswith("cm")
        assert not any(getattr(c, "looping", False) for c in station.components())
        with Client(host, port) as op:
            op.auth(TOKEN)
            assert op.command("axis0Encoder readloop") == ["axis0Encoder: readloop"]
            op.command("axis0Encoder stoploop")
    finally:
        server.close()
        runner.stop()
        station.close()


def test_a_silent_reader_is_dropped():
    """A client that takes no byte of what it is owed for write_stall_s is dropped, however
    little waits for it (its TCP window closed)."""
    with served(write_stall_s=0.3) as sv:
        s = sv.raw()
        conn = next(iter(sv.server._conns.values()))
        with conn.lock:  # as if the peer's window had closed with bytes still owed
            conn.out += b"OK pending\n"
            conn.last_sent = time.monotonic() - 1.0
        deadline = time.monotonic() + 10
        while sv.server.clients and time.monotonic() < deadline:
            time.sleep(0.05)
        assert sv.server.clients == 0 and sv.server.counters["dropped_slow"] == 1
        s.close()


# -- fuzz -------------------------------------------------------------------------------

_WORDS = ["AUTH", "SUBSCRIBE", "UNSUBSCRIBE", "STATUS", "HELP", "help", "W", "T", "S", "E",
          "P", "X", "I", "stop", "wait", "set", "get", "gripper", "gripper.speed", "sim",
          "scope", "stats", "monitor", "ack", "sleep", "status", "statusline", "quit"]
_NUMBERS = ["0", "1", "-1", "1e-300", "1e308", "nan", "inf", "-0", "0x7FFF", "FFFF", "E47A",
            "99999999999999999999", "1e-10", "0.5", "\u0663\u0660", "1_000", ""]
_JUNK = ["\x00", "\x1b[2J", "\u2028", "\u202e", "\t", "\ufeff", "\udcff", "é", "\x7f", "\\",
         "'", '"', ";", "|", "$(id)", "%s%n", "../../etc/passwd", "{}", "\r"]


def _fuzz_line(rng: random.Random) -> bytes:
    parts = []
    for _ in range(rng.randint(1, 5)):
        pick = rng.random()
        if pick < 0.4:
            parts.append(rng.choice(_WORDS))
        elif pick < 0.75:
            parts.append(rng.choice(_NUMBERS))
        elif pick < 0.95:
            parts.append(rng.choice(_JUNK))
        else:
            parts.append("A" * rng.choice([100, 1023, 1100]))
    text = " ".join(parts)
    if rng.random() < 0.05:
        return bytes(rng.randrange(256) for _ in range(rng.randint(1, 40)))
    return text.encode("utf-8", "surrogateescape")


FUZZ_LINES = 1500


@pytest.mark.parametrize("privileged", [False, True])
def test_fuzzed_daq_lines_never_meet_a_bug_or_move_a_guest(privileged):
    """1,500 generated lines (verbs, commands, extreme numbers, control and format characters,
    invalid UTF-8, over-long lines): each gets one final OK or ERR line, never ERR internal;
    the server lives; without the token nothing moves and no fault is raised."""
    rng = random.Random(37 + privileged)
    with served() as sv:
        internal, answered = [], 0
        s = None
        deadline = time.monotonic() + 120
        for _ in range(FUZZ_LINES):
            if time.monotonic() > deadline:
                break
            if s is None:
                s = socket.create_connection((sv.host, sv.port), timeout=20)
                greeting = read_lines(s, 1)
                if not greeting or not greeting[0].startswith("OK pyrt"):
                    s.close()
                    s = None  # a reserved slot or full: try again
                    continue
                if privileged:
                    s.sendall(f"AUTH {TOKEN}\n".encode())
                    read_lines(s, 1)
            line = _fuzz_line(rng).replace(b"\n", b" ")
            if line.strip().upper().startswith((b"QUIT", b"WAIT", b"SLEEP", b"SCOPE")):
                line = b"W"  # leaving, waiting and files are not what is fuzzed here
            s.sendall(line + b"\n")
            final = _final_line(s)
            answered += 1
            if final is None or final.startswith("ERR too-long") or " closing" in final:
                s.close()
                s = None
            if final is not None and final.startswith("ERR internal"):
                internal.append((line, final))
        if s is not None:
            s.close()
        assert answered >= FUZZ_LINES // 2
        assert internal == []
        assert sv.server.alive and sv.server.counters["internal"] == 0
        if not privileged:
            assert sv.still_and_null()
            assert sv.runner.call(lambda: sv.rig.fault, take_fault=False) is None


def _final_line(s: socket.socket) -> str | None:
    """Lines until the final OK/ERR line of one reply (STATUS lines skipped); None if closed."""
    buf = b""
    s.settimeout(20)
    while True:
        while b"\n" in buf:
            raw, buf = buf.split(b"\n", 1)
            text = raw.decode("utf-8", "replace")
            if text.startswith("OK-") or text.startswith("STATUS"):
                continue
            if text.startswith(("OK", "ERR")):
                return text
        try:
            data = s.recv(65536)
        except (ConnectionResetError, TimeoutError):
            return None
        if not data:
            return None
        buf += data
