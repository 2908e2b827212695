"""board-sim over tcp:// under abuse, over loopback: one owning controller, readers that never
feed the watchdog, idle and half-open connections, a bounded number of connections, and a
bounded fuzz of the wire."""

from __future__ import annotations

import contextlib
import random
import socket
import threading
import time
from collections.abc import Iterator

import pytest

from pyrt.boards import open_boards
from pyrt.boards.gripper import DAC, DAC_NULL
from pyrt.boards.wire import MAX_LINE, WireError, parse_request
from pyrt.cli import main
from pyrt.errors import BoardError
from pyrt.sim.boardsim import BoardServer
from pyrt.sim.world import GRIPPER_BOARDS, GripperWorld

#: Generous bounds for a loaded two-core machine; what is asserted is that it happens.
BOUND_S = 15.0


class _Raw:
    """A wire client on a bare socket: it reads the greeting and sends lines."""

    def __init__(self, port: int):
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=5)
        self.f = self.sock.makefile("rb")
        self.greeting = self.f.readline().decode()

    def ask(self, line: str | bytes) -> str:
        data = line if isinstance(line, bytes) else line.encode()
        self.sock.sendall(data + b"\n")
        reply = self.f.readline()
        if not reply:
            raise EOFError
        return reply.decode().rstrip("\n")

    def closed_by_server(self) -> bool:
        """Whether the server has closed this connection (EOF or reset), looking once."""
        self.sock.settimeout(0.05)
        try:
            return self.sock.recv(1) == b""
        except TimeoutError:
            return False
        except OSError:
            return True
        finally:
            self.sock.settimeout(5)

    def close(self) -> None:
        self.f.close()
        self.sock.close()


def _until(predicate, seconds: float = BOUND_S) -> bool:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.01)
    return predicate()


def _serve(**kw) -> tuple[BoardServer, GripperWorld]:
    world = GripperWorld(start=-0x100)
    server = BoardServer(world, "127.0.0.1", 0, **{"watchdog_s": 30.0, **kw})
    server.start()
    return server, world


@pytest.fixture
def served() -> Iterator[tuple[BoardServer, GripperWorld]]:
    server, world = _serve()
    yield server, world
    server.close()


def _dac(world: GripperWorld) -> int:
    return world.registers("gripper").read("dac")


def test_an_idle_socket_does_not_keep_a_controller_out(served):
    """A client that connects and says nothing: a controller still opens the boards, drives
    them, and the idle client is still answered as a reader."""
    server, world = served
    idle = _Raw(server.port)
    try:
        assert idle.greeting.startswith("OK pyrt-board-sim 2 gripper ")
        with open_boards(server.url, "gripper", GRIPPER_BOARDS) as boards:
            boards["gripper"].write(DAC, 0x90)
            assert _dac(world) == 0x90
            assert idle.ask("R gripper dac") == "OK 144"
            assert idle.ask("SNAP").startswith("OK 0 ")
    finally:
        idle.close()


def test_a_second_writer_is_busy_while_the_controller_owns_the_outputs(served):
    """The controller owns the outputs: another client's write is ERR busy naming it and
    changes nothing; its reads are answered.  Once the controller has gone, the other client's
    write is taken (it owns them now)."""
    server, world = served
    other = _Raw(server.port)
    try:
        with open_boards(server.url, "gripper", GRIPPER_BOARDS) as boards:
            boards["gripper"].write(DAC, 0x90)
            reply = other.ask("W gripper dac 0x10")
            assert reply.startswith("ERR busy ") and "owns the outputs" in reply, reply
            assert _dac(world) == 0x90 and other.ask("R gripper dac") == "OK 144"
            with pytest.raises(BoardError, match="busy"):
                open_boards(server.url, "gripper", GRIPPER_BOARDS)
        assert _until(lambda: _dac(world) == DAC_NULL)  # its close turned them off
        assert other.ask("W gripper dac 0x10") == "OK" and _dac(world) == 0x10
    finally:
        other.close()


def test_own_is_a_request_of_its_own_without_arguments():
    """OWN parses as the claim (any case); OWN with an argument is a syntax error."""
    kinds = GRIPPER_BOARDS
    assert parse_request(b"OWN", kinds).verb == "OWN"
    assert parse_request(b"own\r", kinds).verb == "OWN"
    with pytest.raises(WireError) as err:
        parse_request(b"OWN gripper", kinds)
    assert err.value.code == "syntax"


@pytest.mark.wallclock
def test_a_reader_does_not_feed_the_watchdog():
    """The controller writes the DAC and falls silent; a reader polls SNAP every 50 ms: the
    watchdog (0.3 s) turns the DAC off all the same, and the reader is served throughout."""
    server, world = _serve(watchdog_s=0.3)
    ctl, reader = _Raw(server.port), _Raw(server.port)
    stop = threading.Event()
    replies: list[str] = []
    try:
        assert ctl.ask("OWN") == "OK"
        assert ctl.ask("W gripper dac 0x90") == "OK"

        def poll() -> None:
            while not stop.wait(0.05):
                replies.append(reader.ask("SNAP"))

        t = threading.Thread(target=poll, daemon=True)
        t.start()
        assert _until(lambda: _dac(world) == DAC_NULL), "the reader kept the outputs on"
        stop.set()
        t.join(5)
        assert server.watchdog_trips >= 1
        assert replies and all(r.startswith("OK ") for r in replies), replies[-3:]
    finally:
        stop.set()
        ctl.close()
        reader.close()
        server.close()


@pytest.mark.wallclock
def test_a_silent_owner_is_displaced_by_a_new_controller_after_the_watchdog_time():
    """A controller that owns the outputs and then says nothing (its host gone, the socket
    half-open): once the watchdog has turned the outputs off, a new controller opens the boards
    and the old connection is closed."""
    server, world = _serve(watchdog_s=0.2)
    old = _Raw(server.port)
    try:
        assert old.ask("W gripper dac 0x90") == "OK"
        assert _until(lambda: server.watchdog_trips >= 1)
        with open_boards(server.url, "gripper", GRIPPER_BOARDS) as boards:
            boards["gripper"].write(DAC, 0x70)
            assert _dac(world) == 0x70
            assert _until(old.closed_by_server)
    finally:
        old.close()
        server.close()


@pytest.mark.wallclock
def test_idle_and_half_open_connections_are_closed_and_the_server_keeps_serving():
    """A connection that sends nothing and one that stops mid-line are closed after the idle
    time (0.3 s); a fresh connection is still served."""
    server, _world = _serve(idle_s=0.3)
    idle, half = _Raw(server.port), _Raw(server.port)
    try:
        half.sock.sendall(b"R grip")
        assert _until(idle.closed_by_server), "an idle connection stayed open"
        assert _until(half.closed_by_server), "a half-sent line kept its connection open"
        fresh = _Raw(server.port)
        assert fresh.ask("R gripper dac") == f"OK {DAC_NULL}"
        fresh.close()
    finally:
        idle.close()
        half.close()
        server.close()


def test_connections_are_bounded_and_a_controller_always_gets_in():
    """max_clients 4 and twelve readers: at most 4 connections are held (the longest idle
    reader makes room), and a controller that comes last opens the boards and drives them."""
    server, world = _serve(max_clients=4)
    readers: list[_Raw] = []
    try:
        for _ in range(12):
            r = _Raw(server.port)
            readers.append(r)
            with contextlib.suppress(EOFError, OSError):
                r.ask("SNAP")
        with open_boards(server.url, "gripper", GRIPPER_BOARDS) as boards:
            boards["gripper"].write(DAC, 0x90)
            assert _dac(world) == 0x90
            open_ = [r for r in readers if not r.closed_by_server()]
            assert len(open_) <= 3, f"{len(open_)} readers connected besides the controller"
    finally:
        for r in readers:
            r.close()
        server.close()


# -- a bounded fuzz of the wire -------------------------------------------------------------

_TOKENS = ["R", "W", "SNAP", "INFO", "OWN", "w", "r", "snap", "gripper", "GRIPPER", "dac",
           "cmd", "led_lo", "led_hi", "pa", "up", "down", "nothing", "0", "1", "-1", "0x90",
           "0x100", "256", "255", "128", "0x7fff", "-129", "99999999999999999999", "0x", "1e3",
           ";", "; W gripper dac", "\t", "\r", "\x00", "\xff", "٣", "é"]


def _random_line(rng: random.Random) -> bytes:
    kind = rng.random()
    if kind < 0.15:
        return bytes(rng.randrange(256) for _ in range(rng.randrange(0, 80))).replace(b"\n", b"")
    if kind < 0.2:
        return b"R " + b"1" * rng.choice([MAX_LINE - 10, MAX_LINE, MAX_LINE + 10, 3 * MAX_LINE])
    tokens = [rng.choice(_TOKENS) for _ in range(rng.randrange(0, 7))]
    return " ".join(tokens).encode("utf-8", "surrogateescape")


#: The fuzz's bounds: lines sent, and a wall-time bound on the whole run that only a
#: hang reaches (the run takes seconds, on a loaded machine too).
FUZZ_LINES = 2000
FUZZ_S = 120.0


def _outputs(world: GripperWorld) -> dict[str, int]:
    regs = world.registers("gripper")
    return {name: regs.read(name) for name in ("cmd", "led_lo", "led_hi", "dac")}


def _legal(world: GripperWorld, values: dict[str, int]) -> bool:
    kind = world.kinds["gripper"]
    for name, v in values.items():
        try:
            kind.check_write(name, 0, v)
        except ValueError:
            return False
    return True


def test_fuzzed_wire_lines_never_crash_the_server_nor_write_an_illegal_value(served):
    """2000 random lines (seeded: tokens of the protocol, bytes, over-long lines): every line
    gets one reply line, an ERR changes no output, no reply is 'internal', every output holds
    a legal value throughout, and a well-formed request is answered afterwards."""
    server, world = served
    rng = random.Random(20261126)
    c = _Raw(server.port)
    t_end = time.monotonic() + FUZZ_S
    errors = 0
    try:
        for n in range(FUZZ_LINES):
            assert time.monotonic() < t_end, f"fuzz too slow: {n} lines"
            line = _random_line(rng)
            if line.strip().upper() == b"QUIT":
                continue
            before = _outputs(world)
            reply = c.ask(line)
            if len(line) + 1 > MAX_LINE and "too-long" not in reply:
                raise AssertionError((line[:40], reply))
            after = _outputs(world)
            assert not reply.startswith("ERR internal"), (line, reply)
            assert reply.startswith(("OK", "ERR ")), (line, reply)
            if reply.startswith("ERR"):
                errors += 1
                assert after == before, (line, reply, before, after)
            assert _legal(world, after), (line, after)
            assert server.alive
        assert errors > FUZZ_LINES // 2, errors
        fresh_reply = c.ask("R gripper dac")
        assert fresh_reply == f"OK {_dac(world)}"
    finally:
        c.close()


@pytest.mark.parametrize(("argv", "message"), [
    (["--max-clients", "1"], "--max-clients must be 2..1024 connections, got 1"),
    (["--max-clients", "many"], "--max-clients must be a whole number of connections"),
    (["--idle", "0"], "must be 0.01..86400 s, got '0'"),
])
def test_board_sim_refuses_bad_connection_bounds_in_one_line(capsys, argv, message):
    """pyrt board-sim gripper with a bound it cannot keep: exit 2 (a usage error), one line
    naming it."""
    assert main(["board-sim", "gripper", *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1, err


def test_random_byte_streams_on_many_connections_leave_the_server_serving(served):
    """Fifty connections (seeded) each blast 4 kB of random bytes, some cut mid-line, some
    closed at once: the server keeps running, every output holds a legal value, and a
    well-formed request is answered afterwards."""
    server, world = served
    rng = random.Random(37)
    for _ in range(50):
        c = _Raw(server.port)
        data = bytes(rng.randrange(256) for _ in range(4096))
        with contextlib.suppress(OSError):
            c.sock.sendall(data)
        c.close()
        assert server.alive and _legal(world, _outputs(world))
    fresh = _Raw(server.port)
    try:
        assert fresh.ask("R gripper dac") == f"OK {_dac(world)}"
    finally:
        fresh.close()
