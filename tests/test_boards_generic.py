"""A robot of one's own over tcp://: a two-joint arm's servo board (a plain kind, a
RegisterBoard in process) served by board-sim in a thread on a clock the test moves: reads,
writes, SNAP, refusals, the watchdog turning the declared outputs off, the greeting checked."""

from __future__ import annotations

import argparse
import importlib.metadata
import socket
import threading
import time

import pytest

from pyrt.boards import Boards, open_boards
from pyrt.boards.kinds import GRIPPER_CAGE
from pyrt.boards.registers import OUTPUT, BoardKind, Register, RegisterBoard
from pyrt.boards.tcp import TcpBoardRegisters
from pyrt.errors import BoardError, ConfigError
from pyrt.sim.boardsim import BoardServer
from pyrt.sim.world import World, WorldFactory
from pyrt.station.factory import ENTRY_POINT_GROUP, StationFactory

SERVO = BoardKind("arm-servo", (
    Register("drive", count=2, width=16, signed=True, direction=OUTPUT, off=0),
    Register("enable", direction=OUTPUT, off=0),
    Register("count", count=2, width=32, signed=True),
    Register("home", width=1),
))
ARM_BOARDS = {"servo": SERVO}


class ArmPlant:
    """Each step, an enabled joint's counter moves by its drive / 100."""

    def __init__(self, board: RegisterBoard):
        self.board = board
        self.steps = 0

    def step(self, now_ns: int) -> None:
        self.steps += 1
        if self.board.output("enable"):
            for j in range(2):
                c = self.board.read("count", j) + self.board.output("drive", j) // 100
                self.board.set_input("count", c, j)

    def info(self) -> dict[str, object]:
        return {"steps": self.steps}


class ArmWorlds(WorldFactory):
    """The arm's world as a station factory gives it to board-sim."""

    name = "arm"

    def board_kinds(self) -> dict[str, BoardKind]:
        return dict(ARM_BOARDS)

    def world(self, boards: Boards, args: object) -> World:
        return World("arm", boards, ArmPlant(boards["servo"]))


class ArmStation(ArmWorlds, StationFactory):
    """A station of one's own as it is installed: its factory gives board-sim its world, with
    an option of the world's own."""

    name = "arm"

    def add_world_arguments(self, parser: argparse.ArgumentParser) -> None:
        parser.add_argument("--home", type=int, choices=(0, 1), default=0,
                            help="the home switch at start")

    def world(self, boards: Boards, args: argparse.Namespace) -> World:
        boards["servo"].set_input("home", args.home)
        return super().world(boards, args)


class Clock:
    """A monotonic clock the test moves (board-sim's steps and watchdog follow it)."""

    def __init__(self) -> None:
        self.now = 1_000_000_000
        self.lock = threading.Lock()

    def __call__(self) -> int:
        with self.lock:
            return self.now

    def advance(self, ns: int) -> None:
        with self.lock:
            self.now += ns


def _until(predicate, seconds: float = 5.0) -> bool:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.002)
    return predicate()


@pytest.fixture
def served():
    """The arm's world (opened from its factory, as board-sim does) served in a thread."""
    factory = ArmWorlds()
    world = factory.world(open_boards("sim:", "arm", factory.board_kinds()).simulated, None)
    clock = Clock()
    server = BoardServer(world, "127.0.0.1", 0, watchdog_s=0.5, clock=clock)
    server.start()
    yield server, world, clock
    server.close()


def _raw(server: BoardServer) -> tuple[socket.socket, object]:
    sock = socket.create_connection(("127.0.0.1", server.port), timeout=5)
    return sock, sock.makefile("rb")


def test_the_arm_board_over_tcp_reads_writes_and_snaps(served):
    """Writes reach the world's RegisterBoard; the plant's counts come back in one SNAP per poll;
    reads within the tick make no round trip; INFO is the plant's."""
    server, world, clock = served
    board = world.boards["servo"]
    with open_boards(server.url, "arm", ARM_BOARDS, max_age=60) as boards:
        servo = boards["servo"]
        assert isinstance(servo, TcpBoardRegisters) and servo.kind is SERVO
        assert boards.world == "arm" and boards.registers("servo") is servo
        servo.write("drive", -300, 1)
        servo.write("drive", 500, 0)
        servo.write("enable", 1)
        assert board.values("drive") == [500, -300] and board.output("enable") == 1
        steps = world.plant.steps
        clock.advance(10_000_000)
        assert _until(lambda: world.plant.steps > steps)
        board.set_input("home", 1)
        boards.poll(0)
        n = servo.link.requests
        counts = [servo.read("count", 0), servo.read("count", 1)]
        assert counts == [board.read("count", 0), board.read("count", 1)]
        assert counts[0] > 0 and counts[1] < 0 and servo.read("home") == 1
        assert servo.read("drive", 1) == -300 and servo.link.requests == n  # from the copy
        assert int(boards.info()["steps"]) >= 1


def test_writes_are_checked_before_sending_and_refused_by_the_server_alike(served):
    """A value too wide, a write to an input, an unknown register: ValueError on the client, and
    ERR range from the server; neither changes anything."""
    server, world, _clock = served
    with open_boards(server.url, "arm", ARM_BOARDS, max_age=0) as boards:
        servo = boards["servo"]
        n = servo.link.requests
        for action, message in ((lambda: servo.write("drive", 40000, 0), "-32768..32767"),
                                (lambda: servo.write("count", 1, 0), "count is an input"),
                                (lambda: servo.read("torque"), "no register 'torque'")):
            with pytest.raises(ValueError, match=message):
                action()
        assert servo.link.requests == n  # refused here, nothing sent
    sock, f = _raw(server)
    try:
        assert f.readline().decode().startswith("OK pyrt-board-sim 2 arm 500 servo=arm-servo@")
        cases = [(b"W servo drive 1 40000\n", b"ERR range servo: drive: value must be"),
                 (b"W servo count 0 1\n", b"ERR range servo: count is an input"),
                 (b"R servo drive 2\n", b"ERR range servo: drive: index must be 0..1"),
                 (b"W servo drive 0 -32768; W servo drive 1 32768\n", b"ERR range")]
        for line, want in cases:
            sock.sendall(line)
            assert f.readline().startswith(want), line
        assert world.boards["servo"].values("drive") == [0, 0]  # the bad line made no write
        sock.sendall(b"W servo drive 0 -32768; W servo drive 1 0x7FFF\nR servo drive 1\n")
        assert f.readline() == b"OK\n" and f.readline() == b"OK 32767\n"
        sock.sendall(b"SNAP\n")
        assert f.readline() == b"OK 0 0 0 0\n"
    finally:
        f.close()
        sock.close()


def test_write_many_sends_several_writes_in_one_round_trip(served):
    """write_many puts several writes on one line: one request, all made."""
    server, world, _clock = served
    with open_boards(server.url, "arm", ARM_BOARDS) as boards:
        servo = boards["servo"]
        n = servo.link.requests
        servo.client.write_many([("servo", "drive", 0, 7), ("servo", "drive", 1, -7),
                                 ("servo", "enable", 0, 1)])
        assert servo.link.requests == n + 1
        assert world.boards["servo"].values("drive") == [7, -7]
        assert servo.read("enable") == 1


def test_the_watchdog_turns_the_declared_outputs_off_and_the_controller_is_told(served):
    """No register access for the watchdog time (on board-sim's clock): not before (0.4 s
    of 0.5 s, board-sim having looked), then every output that declares an off value gets
    it; the next poll raises BoardError once and the outputs read off again; a later write
    drives again."""
    server, world, clock = served
    board = world.boards["servo"]
    with open_boards(server.url, "arm", ARM_BOARDS) as boards:
        servo = boards["servo"]
        servo.write("drive", 900, 0)
        servo.write("enable", 1)
        boards.poll(0)
        clock.advance(400_000_000)
        sock, f = _raw(server)  # a reader: its INFO feeds no watchdog
        try:
            f.readline()
            for _ in range(2):  # the second answer: board-sim has kept the watchdog since
                sock.sendall(b"INFO\n")
                assert f.readline().startswith(b"OK")
        finally:
            sock.close()
        assert server.watchdog_trips == 0 and board.output("enable") == 1
        clock.advance(200_000_000)
        assert _until(lambda: server.watchdog_trips == 1)
        assert board.values("drive") == [0, 0] and board.output("enable") == 0
        assert world.outputs_are_off()
        with pytest.raises(BoardError, match="watchdog turned the outputs off"):
            boards.poll(0)
        boards.poll(0)  # told once
        assert servo.read("drive", 0) == 0 and servo.read("enable") == 0
        servo.write("enable", 1)
        assert board.output("enable") == 1


def test_a_dropped_link_accepts_only_the_off_writes(served):
    """Once the connection is gone, writing an output's off value succeeds without a round trip
    (board-sim turned it off), it reads off; anything else raises BoardError naming the URL."""
    server, _world, _clock = served
    boards = open_boards(server.url, "arm", ARM_BOARDS, max_age=0)
    servo = boards["servo"]
    servo.write("enable", 1)
    server.close()
    with pytest.raises(BoardError, match=server.url):
        boards.poll(0)
    servo.write("enable", 0)
    servo.write("drive", 0, 1)
    assert servo.read("enable") == 0
    with pytest.raises(BoardError, match="link is down"):
        servo.write("drive", 5, 1)
    with pytest.raises(BoardError, match="link is down"):
        servo.read("count", 0)
    boards.close()


def test_a_greeting_without_a_declared_board_is_refused_naming_it(served):
    """Declaring a board board-sim does not serve, or one of another kind, is a ConfigError that
    names the station served, what is missing and what differs; the link is closed."""
    server, _world, _clock = served
    wider = BoardKind("arm-servo", (Register("drive", count=2, width=24, signed=True,
                                             direction=OUTPUT, off=0),))
    with pytest.raises(ConfigError) as err:
        open_boards(server.url, "arm", {"servo": SERVO, "gripper": GRIPPER_CAGE})
    text = str(err.value)
    assert server.url in text and "serves the arm station" in text
    assert "missing: gripper (gripper-cage)" in text
    assert _until(lambda: server.clients == 0)  # the refused link is closed first
    with pytest.raises(ConfigError) as err:
        open_boards(server.url, "arm", {"servo": wider})
    assert f"different: servo (declared {wider.tag}, served {SERVO.tag})" in str(err.value)
    assert _until(lambda: server.clients == 0)
    with open_boards(server.url, "arm", ARM_BOARDS) as boards:  # free again
        assert list(boards) == ["servo"]


def test_a_station_may_open_fewer_boards_than_are_served():
    """A controller that declares one of two served boards gets it; its SNAP names it."""
    both = open_boards("sim:", "rig", {"servo": SERVO, "gripper": GRIPPER_CAGE}).simulated
    server = BoardServer(World("rig", both), "127.0.0.1", 0, watchdog_s=30.0)
    server.start()
    try:
        with open_boards(server.url, "rig", ARM_BOARDS) as boards:
            both["servo"].set_input("count", 77, 1)
            boards.poll(0)
            assert boards["servo"].read("count", 1) == 77 and "gripper" not in boards
    finally:
        server.close()


def test_board_sim_finds_an_installed_stations_world_by_name(monkeypatch):
    """An entry point in pyrt.stations makes a station's world one board-sim serves by name; a
    station that declares no boards is refused, saying so; an unknown name lists the worlds."""
    from pyrt.cli.boardsim import build_world, find_world, worlds

    eps = [importlib.metadata.EntryPoint(n, v, ENTRY_POINT_GROUP) for n, v in (
        ("arm", "test_boards_generic:ArmStation"), ("counter", "_tiny_station:CounterFactory"),
        ("gripper", "pyrt.station.gripper:GRIPPER"))]
    monkeypatch.setattr(importlib.metadata, "entry_points",
                        lambda **kw: importlib.metadata.EntryPoints(eps))
    assert worlds() == ["arm", "gripper"]
    factory, preset = find_world("ARM")
    assert isinstance(factory, ArmStation) and preset == {}
    world = build_world(factory, argparse.Namespace(home=1))
    assert world.name == "arm" and world.registers("servo").snapshot() == [0, 0, 1]
    with pytest.raises(ConfigError, match="'counter' gives no world"):
        find_world("counter")
    with pytest.raises(ConfigError, match="stations: arm, gripper"):
        find_world("hexapod")
    factory, _ = find_world("test_boards_generic:ArmStation")  # MODULE:FACTORY too
    assert factory.board_kinds() == ARM_BOARDS
