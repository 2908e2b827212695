"""The DAQ server on real loopback sockets, the gripper on a SimClock."""

from __future__ import annotations

import io
import itertools
import socket
import struct
import threading
import time

import pytest
from _gripper_rig import make_rig
from _server_rig import TOKEN, read_lines, read_only_lines, read_until_closed, served
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from pyrt.client import ServerError
from pyrt.errors import ConfigError
from pyrt.server import ObserverRunner, ServedStation, Server, format_error, format_reply
from pyrt.server.protocol import split_verb

#: Only a hang takes this long: a bound that catches one, never a measure of speed.
HANG_S = 30.0


def _signed(word: str) -> int:
    v = int(word, 16)
    return v - 0x10000 if v & 0x8000 else v


# -- a full move ------------------------------------------------------------------------


def test_full_move_commanded_by_a_client_and_reported_to_a_subscriber():
    """I and P E47A from the privileged client move the jaws; a subscriber sees the whole move and its end."""
    with served() as sv:
        sub = sv.client()
        sub.command("SUBSCRIBE 50")
        op = sv.operator()
        assert op.command("I") == ["jaws wide open (limit sensor on), encoder 0000"]
        assert op.command("P E47A") == []
        (line,) = op.command("wait")
        assert line.startswith("at target: position")
        assert abs(_signed(op.command("W")[0]) + 0x1B86) <= 16
        pushed = list(sub.statuses(1.0))
        samples = [s for s in pushed if s.time_s is not None]
        # the end of each move once, as it happened: I's, then P's
        assert [s.stop for s in pushed if s.stop is not None] == ["at target", "at target"]
        moving = [s for s in samples if s.fields.get("moving") == 1]
        assert len(moving) > 20
        positions = [s.fields["position"] for s in moving if s.fields["target"] == -0x1B86]
        closing = positions[: positions.index(min(positions)) + 1]
        assert closing == sorted(closing, reverse=True)  # closing all the way, then settling
        assert closing[0] > -0x100 and abs(closing[-1] + 0x1B86) <= 32
        times = [s.time_s for s in samples]
        assert times == sorted(times)
        assert all(b - a == pytest.approx(0.02, abs=1e-3) for a, b in itertools.pairwise(times))
        final = sv.client().status()
        assert final.fields["moving"] == 0 and final.fields["fault"] == 0
        assert abs(final.fields["position"] + 0x1B86) <= 16
        assert sv.still_and_null()


def test_status_request_answers_from_the_snapshot():
    """STATUS answers one OK line with the loop time and every status field."""
    with served() as sv:
        c = sv.client()
        reply = c.request("status")
        assert reply.ok and len(reply.lines) == 1
        fields = dict(kv.split("=") for kv in reply.lines[0].split())
        assert set(fields) == {"t", "position", "target", "moving", "busy", "sensors", "fault"}
        assert c.request("STATUS now").code == "command"  # the console's 'status now': no such object


def test_status_of_an_object_and_unknown_commands_answer_a_reader_as_the_console_would():
    """Without AUTH, 'STATUS gripper' lists the object's signals (a read); an unknown command is ERR command, not ERR denied."""
    with served() as sv:
        c = sv.client()
        lines = c.command("STATUS gripper")
        assert "gripper.moving = 0 bool" in lines and "gripper.dac = 80 byte" in lines
        assert c.command("status gripper") == lines
        reply = c.request("gripper fly")
        assert reply.code == "command" and "fly" in reply.text
        reply = c.request("foo bar")
        assert reply.code == "command" and "unknown command 'foo'" in reply.text
        assert c.request("P E47A").code == "denied"  # a known command that moves
        assert sv.still_and_null()


# -- privilege --------------------------------------------------------------------------

READ_ONLY = ["W", "w", "T", "E", "S", "help", "help P", "stats", "sim", "STATUS", ""]
PRIVILEGED = ["P E47A", "p-1b86", "X 33", "I", "C", "M", "wait", "sleep 1", "sim object 20",
              "sim fault jam", "scope add ram:4A", "scope save /tmp/x.csv"]


def test_read_only_commands_are_served_without_auth():
    """Without AUTH the reads (W T E S help stats sim STATUS) answer OK."""
    with served() as sv:
        c = sv.client()
        for line in READ_ONLY:
            reply = c.request(line)
            assert reply.ok, (line, reply)
        assert c.command("W") == ["0000"]


@pytest.mark.parametrize("token", [None, "wrong", TOKEN[:-1], TOKEN + "x", TOKEN.upper()])
def test_commands_that_change_the_robot_are_denied_without_the_token(token):
    """Without AUTH, or after a wrong token, every command that changes anything is ERR denied and nothing moves."""
    with served() as sv:
        c = sv.client()
        if token is not None:
            with pytest.raises(ServerError) as exc:
                c.auth(token)
            assert exc.value.code == "auth"
        before = sv.runner.call(lambda: bytes(sv.rig.cpu.ram))
        for line in PRIVILEGED:
            reply = c.request(line)
            assert (reply.ok, reply.code) == (False, "denied"), line
        sv.runner.sleep(0.5)
        assert sv.still_and_null()
        after = sv.runner.call(lambda: bytes(sv.rig.cpu.ram))
        assert after[0x4C:0x4E] == before[0x4C:0x4E]  # COMMAND_CNT untouched
        assert sv.server.counters["denied"] == len(PRIVILEGED)


def test_three_wrong_tokens_close_the_connection():
    """The third wrong AUTH is answered and the connection closed; the address backs off."""
    with served() as sv:
        s = sv.raw()
        s.sendall(b"AUTH a\nAUTH b\nAUTH c\nW\n")
        text = read_until_closed(s)
        assert text.splitlines() == ["ERR auth wrong token", "ERR auth wrong token",
                                     "ERR auth wrong token; too many failures, closing "
                                     "(127.0.0.1 may AUTH again in 2 s)"]


def test_no_token_configured_means_nobody_is_privileged():
    """A server without a token only reports: AUTH fails, commands are denied."""
    with served(token=None) as sv:
        c = sv.client()
        assert "status only" in c.greeting
        assert c.request("AUTH anything").code == "auth"
        assert c.request("P E47A").code == "denied"
        assert c.command("W") == ["0000"]


def test_a_second_privileged_client_is_refused_not_demoted():
    """While one client is privileged a second AUTH gets ERR busy; after the first leaves it succeeds."""
    with served() as sv:
        first = sv.operator()
        second = sv.client()
        with pytest.raises(ServerError) as exc:
            second.auth(TOKEN)
        assert exc.value.code == "busy"
        assert second.request("P E47A").code == "denied"
        assert first.command("X 33")[0].startswith("speed 7F -> 33")  # still privileged
        assert first.request("AUTH " + TOKEN).lines == ["already privileged"]
        first.close()
        deadline = time.monotonic() + HANG_S  # a bound for a hang only
        while sv.server.privileged_client is not None and time.monotonic() < deadline:
            time.sleep(0.01)
        second.auth(TOKEN)
        assert second.command("T") == ["0000"]


def test_serving_beyond_loopback_without_a_token_is_refused():
    """A non-loopback address without a token is a ConfigError at start-up; with a token it is allowed."""
    rig = make_rig()
    runner = rig.runner
    robot = ServedStation(rig.station)
    for host in ("0.0.0.0", "", "::", "192.0.2.1"):
        with pytest.raises(ConfigError, match="without a token"):
            Server(runner, robot, host, 0)
    Server(runner, robot, "0.0.0.0", 0, token="t" * 16)  # allowed (not started)
    with pytest.raises(ConfigError, match="at least 16"):  # reachable: a token not guessed
        Server(runner, robot, "0.0.0.0", 0, token="t" * 15)
    with pytest.raises(ConfigError):
        Server(runner, robot, "127.0.0.1", 0, token="")


def test_faults_are_pushed_to_subscribers_and_left_for_the_operator():
    """A corrupted ready queue trips the robot: subscribers get STATUS FAULT, readers never consume it, the operator's next command reports it."""
    with served() as sv:
        sub = sv.client()
        sub.command("SUBSCRIBE 100")
        reader = sv.client()
        op = sv.operator()
        op.command("M")
        assert op.command("C 35 00") == ["35 00"]  # Q slot 0 now names no routine
        for _ in range(200):  # let the queue walk, without taking the fault
            sv.runner.call(lambda: None, take_fault=False)
        assert sv.rig.fault is not None
        faults = [s for s in sub.statuses(0.5) if s.fault]
        assert len(faults) == 1 and faults[0].fault.startswith("gripper: fault")
        assert reader.command("W") == ["0000"]  # a read neither takes nor acknowledges it
        assert reader.status().fields["fault"] == 1
        reply = op.request("Q")
        assert (reply.ok, reply.code) == (False, "fault")
        assert "type ack" in reply.text
        assert op.command("W") == ["0000"]  # Q ran after the report: back at the CMD: level
        assert reader.status().fields["fault"] == 1  # the robot stays stopped until ack
        assert op.command("ack")[0].startswith("fault acknowledged")
        assert reader.status().fields["fault"] == 0
        assert sv.still_and_null()


# -- robustness ---------------------------------------------------------------------------


def test_over_long_line_gets_too_long_and_is_closed():
    """A line over the limit gets ERR too-long and the connection closes; others are served."""
    with served(max_line=64) as sv:
        other = sv.client()
        s = sv.raw()
        s.sendall(b"W" * 65 + b"\n")
        assert read_until_closed(s).startswith("ERR too-long")
        s2 = sv.raw()
        s2.sendall(b"P" * 500)  # no line end at all
        assert read_until_closed(s2).startswith("ERR too-long")
        assert other.command("W") == ["0000"]
        assert sv.server.counters["too_long"] == 2


def test_invalid_utf8_gets_an_error_line_and_the_connection_stays():
    """Invalid UTF-8 is answered ERR utf8 and ignored; the next request is served."""
    with served() as sv:
        s = sv.raw()
        s.sendall(b"\xff\xfe W\nW\n")
        lines = read_lines(s, 2)
        assert lines[0].startswith("ERR utf8") and lines[1] == "OK 0000"


def test_half_lines_and_abrupt_disconnects_run_nothing():
    """A half line left by a disconnect is never run; resets leave the server serving and no motor moving."""
    with served() as sv:
        op = sv.operator()
        op.send_line("X 33")  # privileged, complete
        assert op._read_reply().ok
        op._sock.sendall(b"P E47A")  # half a line, then gone
        op._sock.close()
        for _ in range(5):  # abrupt resets in the middle of requests
            s = sv.raw()
            s.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
            s.sendall(b"STATUS\nW\nT\nsta")
            s.close()
        c = sv.client()
        sv.runner.sleep(0.5)
        assert c.command("T") == ["0000"]
        assert sv.still_and_null()
        c.auth(TOKEN)  # the privilege was released with the vanished operator


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.binary(max_size=80), min_size=1, max_size=6))
def test_garbage_never_moves_a_motor_and_every_reply_is_framed(chunks):
    """Random bytes from an unprivileged client: every reply line is OK/ERR framed, nothing moves, others are served."""
    with served(max_line=64) as sv:
        s = sv.raw()
        data = b"\n".join(chunks) + b"\n"
        s.sendall(data)
        s.shutdown(socket.SHUT_WR)
        text = read_until_closed(s)
        for line in text.splitlines():
            assert line == "OK" or line.startswith(("OK ", "OK-", "ERR ")), line
        assert sv.still_and_null()
        assert sv.client().command("T") == ["0000"]


def test_requests_are_answered_in_order_when_pipelined():
    """Requests sent in one packet are answered in the order sent, server verbs included."""
    with served() as sv:
        s = sv.raw()
        s.sendall(b"W\nSTATUS\nT\nAUTH " + TOKEN.encode() + b"\nX 33\nSTATUS\nQUIT\n")
        lines = read_until_closed(s).splitlines()
        assert lines[0] == "OK 0000"
        assert lines[1].startswith("OK t=")
        assert lines[2] == "OK 0000"
        assert lines[3].startswith("OK privileged")
        assert lines[4].startswith("OK speed 7F -> 33: JSPEED 33")
        assert lines[5].startswith("OK t=")
        assert lines[6] == "OK bye"


def test_slow_reader_is_dropped_and_nobody_else_stalls():
    """A subscriber that never reads is dropped when its output buffer is full; the operator and the loop go on."""
    with served(max_output=8192) as sv:
        slow = socket.socket()
        slow.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        slow.connect((sv.host, sv.port))
        slow.sendall(b"SUBSCRIBE 1000\n")
        op = sv.operator()
        for _ in range(40):
            op.command("sleep 1")
            if sv.server.counters["dropped_slow"]:
                break
        assert sv.server.counters["dropped_slow"] == 1
        assert sv.server.hub.subscribers == 0
        assert op.command("W") == ["0000"]


def test_idle_clients_are_closed_but_subscribers_are_not():
    """A client with no request for the idle timeout gets ERR idle and is closed; a subscriber stays."""
    with served(idle_timeout_s=0.3) as sv:
        sub = sv.client()
        sub.command("SUBSCRIBE 1")
        s = sv.raw()
        assert read_until_closed(s, HANG_S).startswith("ERR idle")
        assert sub.command("W") == ["0000"]


def test_clients_beyond_the_limit_and_the_reserve_are_refused():
    """With every slot held by a client that has asked something and the reserve taken, a newcomer gets ERR full; the others are served."""
    with served(max_clients=2, reserved_slots=1) as sv:
        a, b = sv.client(), sv.client()
        assert a.command("W") == b.command("W") == ["0000"]  # both asked: not evictable
        spare = sv.client()
        assert "reserved slot" in spare.greeting
        assert spare.command("stop")[0].startswith("gripper: every motor stopped; position ")
        with pytest.raises(ServerError) as exc:
            sv.client()
        assert exc.value.code == "full"
        assert a.command("W") == b.command("W") == ["0000"]
        assert sv.server.counters["refused_full"] == 1


# -- a server that cannot be starved -----------------------------------------------------


def _silent(sv, n: int) -> list[socket.socket]:
    """``n`` connections that send nothing (their greetings left unread)."""
    return [socket.create_connection((sv.host, sv.port), timeout=10) for _ in range(n)]


def _moving(sv) -> bool:
    return sv.runner.call(lambda: sv.ctl.moving, take_fault=False)


def test_200_silent_connections_do_not_lock_out_the_operator_or_a_stop():
    """After 200 connections that send nothing, the operator's AUTH and move and an unprivileged stop are served."""
    with served() as sv:
        socks = _silent(sv, 200)
        try:
            op = sv.operator()  # ERR full here before: 64 slots held by silent clients
            op.command("I")
            assert op.command("P E47A") == []
            sv.runner.sleep(0.1)
            assert _moving(sv)
            guest = sv.client()
            assert guest.command("stop")[0].startswith("gripper: every motor stopped; position ")
            assert not _moving(sv) and sv.still_and_null()
            assert sv.server.counters["evicted"] >= 200 - 64
            assert sv.server.clients <= sv.server.max_clients + sv.server.reserved_slots
        finally:
            for s in socks:
                s.close()


def test_when_every_slot_is_busy_a_reserved_slot_takes_auth_and_stop_only():
    """Every slot held by a subscriber (never evicted): the operator AUTHs in a reserved slot and moves, another newcomer's stop halts it, anything else there is ERR full."""
    with served(max_clients=3, reserved_slots=2, greeting_timeout_s=0.3) as sv:
        subs = [sv.client() for _ in range(3)]
        for c in subs:
            c.command("SUBSCRIBE 1")
        op = sv.operator()
        assert "reserved slot" in op.greeting
        op.command("I")
        op.command("P E47A")
        sv.runner.sleep(0.1)
        assert _moving(sv)
        reader = sv.client()
        reply = reader.request("W")
        assert (reply.code, "AUTH and stop only" in reply.text) == ("full", True)
        stopper = sv.client()
        assert stopper.command("") == []  # an empty line is no request: answered, not refused
        assert stopper.command("stop")[0].startswith("gripper: every motor stopped; position ")
        assert not _moving(sv) and sv.still_and_null()
        # The reserved slots' 0.3 s bound closes the reader or the stopper, both active after
        # the operator: the pass that closed one found the operator idle longer, and kept it
        # (its bound is 600 s).  The poll's bound catches a hang only.
        deadline = time.monotonic() + HANG_S
        while sv.server.counters["idle"] == 0:
            assert time.monotonic() < deadline, "no reserved slot was closed for idleness"
            time.sleep(0.01)
        assert op.command("T") == ["E47A"]  # the operator keeps its session


def test_silent_and_unprivileged_connections_have_short_idle_bounds():
    """A connection with no request is closed after the greeting bound, an unprivileged one after the guest bound, the operator's stays; the defaults are seconds, not minutes."""
    assert Server.__init__.__kwdefaults__["greeting_timeout_s"] <= 10
    assert Server.__init__.__kwdefaults__["guest_idle_s"] <= 60
    with served(greeting_timeout_s=0.3, guest_idle_s=1.0) as sv:
        op = sv.operator()
        guest = sv.raw()
        guest.sendall(b"W\n")
        assert read_lines(guest, 1) == ["OK 0000"]
        silent = sv.raw()
        # closed for its 0.3 s bound, said so, while the guest (1 s) and the operator stay
        assert read_until_closed(silent, HANG_S) == "ERR idle no request for 0.3 s; closing\n"
        assert read_until_closed(guest, HANG_S).startswith("ERR idle unprivileged")
        assert op.command("T") == ["0000"]  # 600 s for the operator
        assert sv.server.counters["idle"] == 2


def test_silent_connections_from_one_address_are_capped():
    """Beyond max_fresh_per_address connections that sent nothing from one address, a newcomer is refused until one of them asks something; loopback is exempt by default."""
    with served(max_fresh_per_address=3, exempt_loopback=False) as sv:
        socks = [sv.raw() for _ in range(3)]
        extra = socket.create_connection((sv.host, sv.port), timeout=10)
        assert read_until_closed(extra).startswith(
            "ERR full 3 connections from 127.0.0.1 have sent nothing yet")
        socks[0].sendall(b"STATUS\n")
        assert read_lines(socks[0], 1)[0].startswith("OK t=")
        fourth = sv.raw()
        fourth.sendall(b"W\n")
        assert read_lines(fourth, 1) == ["OK 0000"]
        assert sv.server.counters["refused_address"] == 1
    with served(max_fresh_per_address=3) as sv:
        socks = [sv.raw() for _ in range(10)]
        for s in socks:
            s.sendall(b"W\n")
            assert read_lines(s, 1) == ["OK 0000"]


@pytest.mark.parametrize("line", [b"W\x00", b"T\x1b[A", b"\x07", b"P\x7fE47A", "W\x85".encode(),
                                  b"AUTH \x00" + TOKEN.encode()])
def test_a_line_with_control_characters_is_refused_with_one_line(line):
    """A line that is not text (control characters) gets one ERR text line, runs nothing, and the connection goes on."""
    with served() as sv:
        s = sv.raw()
        s.sendall(line + b"\nW\n")
        first, second = read_lines(s, 2)
        assert first.startswith("ERR text control character"), first
        assert second == "OK 0000"
        assert sv.server.counters["text"] == 1 and sv.server.privileged_client is None


@pytest.fixture(scope="module")
def shared_server():
    """One served gripper for the property tests (a fresh connection per example)."""
    with served() as sv:
        yield sv


@settings(max_examples=60, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(st.text(alphabet=st.characters(blacklist_characters="\n\r"), max_size=30))
def test_a_line_is_refused_as_text_exactly_when_it_holds_a_character_not_printable(
        shared_server, line):
    """Any line from an unprivileged client: ERR text if and only if it holds a character that is not printable (controls, separators, format characters; tab aside), one reply either way, and the next request is answered in step."""
    assume(split_verb(line)[0] != "QUIT")
    control = any(not c.isprintable() and c != "\t" for c in line)
    with shared_server.client() as c:
        reply = c.request(line)
        assert (reply.code == "text") == control, (line, reply)
        if reply.code != "auth":  # three wrong tokens would close it; one does not
            assert c.command("T") == ["0000"]


def test_an_unprivileged_stop_halts_the_operators_move():
    """A client without AUTH gives stop while the operator's move runs: every motor stops at once."""
    with served() as sv:
        op = sv.operator()
        op.command("I")
        op.command("P E47A")
        sv.runner.sleep(0.2)
        assert _moving(sv)
        assert sv.client().command("stop")[0].startswith("gripper: every motor stopped; position ")
        assert not _moving(sv) and sv.still_and_null()


def test_every_read_only_gripper_command_returns_its_value_over_the_network():
    """Each read-only command record (no argument) sent by an unprivileged client answers OK with at least one line (its value)."""
    with served() as sv:
        c = sv.client()
        lines = read_only_lines(sv.rig, sv.server.robot.make_shell(sv.runner, io.StringIO()))
        assert {"W", "T", "E", "S", "status", "stats"} <= set(lines)
        for line in lines:
            reply = c.request(line)
            assert reply.ok and reply.lines and reply.lines[0], (line, reply)
        assert c.command("W") == ["0000"]


def test_quit_and_unsubscribe():
    """QUIT answers OK bye and closes; UNSUBSCRIBE stops the samples."""
    with served() as sv:
        c = sv.client()
        c.command("SUBSCRIBE 100")
        assert c.command("UNSUBSCRIBE") == ["unsubscribed"]
        assert c.command("UNSUBSCRIBE") == ["not subscribed"]
        assert sv.server.hub.subscribers == 0
        for bad in ("SUBSCRIBE", "SUBSCRIBE 0", "SUBSCRIBE -5", "SUBSCRIBE nan", "SUBSCRIBE 1e9"):
            assert c.request(bad).code == "syntax", bad
        others = [sv.client() for _ in range(20)]
        for o in others:
            o.command("SUBSCRIBE 1000")  # 20,000 samples/s: the limit
        assert c.request("SUBSCRIBE 1").code == "limit"
        others[0].command("UNSUBSCRIBE")
        c.command("SUBSCRIBE 1")
        assert c.command("QUIT") == ["bye"]
        with pytest.raises(ConnectionError):
            c.command("W")


# -- the pieces -----------------------------------------------------------------------------


def test_reply_framing():
    """Replies: OK- continuation lines, a last OK line; errors end ERR code; control characters are blanked."""
    assert format_reply([]) == "OK\n"
    assert format_reply(["a", "b"]) == "OK-a\nOK b\n"
    assert format_reply(["x\ry"]) == "OK x y\n"
    assert format_error("denied", "no", ["out"]) == "OK-out\nERR denied no\n"
    with pytest.raises(ValueError):
        format_error("nonsense")
    assert split_verb("  subscribe   10 ") == ("SUBSCRIBE", "10")


LINES = st.text(alphabet="PpXxIiCcMmEeSsTtWwQqDdLlNn hlpwaitsimfuljo0123456789ABCDEF-", max_size=12)


@settings(max_examples=150, deadline=None)
@given(LINES)
def test_read_only_classification_never_changes_the_robot(line):
    """Any line the gripper classifies read-only, run by an unprivileged shell, leaves the RAM, the DAC and the fault state alone."""
    rig = _CLASSIFY_RIG
    robot = ServedStation(rig.station)
    if not robot.is_read_only(line):
        return
    runner = _CLASSIFY_RUNNER
    before = bytes(rig.cpu.ram), rig.board.dac, rig.station.fault, rig.cpu.sp
    shell = robot.make_shell(ObserverRunner(runner), io.StringIO())
    shell.onecmd(line)
    ram = bytes(rig.cpu.ram)
    # What moves on its own: FLAGS' status bits, the sensor image, the clock
    # counter and the ready queue's T/Q (the routines reschedule themselves).
    autonomous = {0x2C, 0x2D, 0x2E, 0x41, *range(0x2F, 0x41)}
    changed = {i for i in range(len(ram)) if ram[i] != before[0][i]} - autonomous
    assert not changed, (line, sorted(changed))
    drive_bits = 0x08 | 0x10  # DRVON, DOJOG
    assert ram[0x2C] & drive_bits == before[0][0x2C] & drive_bits == 0
    assert rig.board.dac == before[1] and rig.station.fault is before[2]
    assert rig.cpu.sp == before[3] and rig.ctl.clock_enabled


_CLASSIFY_RIG = make_rig()
_CLASSIFY_RUNNER = _CLASSIFY_RIG.runner
_CLASSIFY_RUNNER.start()


def test_pipelined_requests_beyond_the_rate_budget_wait_and_are_all_answered():
    """A client pipelining far more requests than the rate budget allows gets every reply, in order."""
    with served(max_rate=2000) as sv:
        s = sv.raw()
        s.sendall(b"".join(b"STATUS\nT\n" for _ in range(300)))
        lines = read_lines(s, 600, timeout_s=20.0)
        assert len(lines) == 600
        assert all(a.startswith("OK t=") and b == "OK 0000" for a, b in zip(lines[::2], lines[1::2], strict=True))


def test_a_bug_in_a_command_is_err_internal_and_the_connection_goes_on(monkeypatch, caplog):
    """A bug raised by a console command comes back as ERR internal (not ERR command), the traceback goes to the server's log, and the connection keeps serving."""
    with served() as sv:

        def broken() -> str:
            raise KeyError("no such register")

        monkeypatch.setattr(sv.ctl, "position", broken)
        s = sv.raw()
        with caplog.at_level("ERROR", logger="pyrt.server"):
            s.sendall(b"W\n")
            (line,) = read_lines(s, 1)
        assert line.startswith("ERR internal KeyError: 'no such register'"), line
        assert any(r.exc_info and r.exc_info[0] is KeyError for r in caplog.records)
        s.sendall(b"T\n")
        assert read_lines(s, 1) == ["OK 0000"]
        s.close()


def test_reconnect_and_auth_after_a_privileged_client_left_is_never_busy(monkeypatch):
    """A privileged client that ran a command and closed, then a new client's AUTH at once: OK (it waits for the old session's release), even when the release is slow."""
    with served() as sv:
        release = sv.server.robot.release
        hold = threading.Event()
        sent = threading.Event()

        def slow_release(shell) -> None:
            if hold.is_set():  # the old session's: still releasing when the next AUTH comes
                hold.clear()
                sent.wait(HANG_S)  # a bound for a hang only
            release(shell)

        monkeypatch.setattr(sv.server.robot, "release", slow_release)
        for _ in range(3):
            first = sv.operator()  # its AUTH waited for the last round's release
            assert first.command("X 33")[0].startswith("speed ")
            sent.clear()
            hold.set()
            first.close()
            nxt = sv.raw()
            nxt.sendall(f"AUTH {TOKEN}\n".encode())
            sent.set()
            assert read_lines(nxt, 1)[0].startswith("OK"), "ERR busy here before the fix"
            nxt.sendall(b"T\n")
            assert read_lines(nxt, 1) == ["OK 0000"]
            nxt.close()
