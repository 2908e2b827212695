"""The tcp:// back end against a board-sim server in this process (loopback only): registers
both ways, encoder interrupts at poll, the per-tick copy, refusals, bad input, failures."""

from __future__ import annotations

import socket
import struct
import threading
import time

import pytest

from pyrt.boards import open_boards
from pyrt.boards.dataconcentrator import DataConcentrator
from pyrt.boards.gripper import (
    DAC,
    DAC_NULL,
    LED_LO,
    P8155_CMD,
    P8155_PA,
    P8155_PB,
    REGISTERS,
    GripperBoard,
)
from pyrt.boards.i8031 import ENCODER_CNT, I8031, LIMIT, OTHER, VECTOR_EXT0, VECTOR_EXT1
from pyrt.boards.kinds import GRIPPER_CAGE
from pyrt.boards.registers import OUTPUT, BoardKind, Register, RegisterBoard
from pyrt.boards.registry import Boards
from pyrt.boards.tio10 import AWO_BITS, DIR_BITS, TIO10
from pyrt.boards.wire import MAX_LINE
from pyrt.db import load_station, station_directory
from pyrt.errors import BoardError, ConfigError
from pyrt.robots.gripper import GripperController
from pyrt.scheduler import Loop, WallClock
from pyrt.sim.boardsim import BoardServer
from pyrt.sim.sensors import Imperfections
from pyrt.sim.world import GRIPPER_BOARDS, MANIPULATOR_BOARDS, GripperWorld, ManipulatorWorld, World

#: prototype rope 0: motor channel 7, encoder address 168, loadcell ADC 3.
CH, ENC, ADC = 7, 168, 3


def _serve(world, **kw) -> BoardServer:
    server = BoardServer(world, "127.0.0.1", 0, **{"watchdog_s": 30.0, **kw})
    server.start()
    return server


@pytest.fixture
def gripper_sim():
    """A gripper board-sim, jaws near wide open, on a free loopback port."""
    server = _serve(GripperWorld(start=-0x0100))
    yield server
    server.close()


@pytest.fixture
def manipulator_sim():
    """A prototype-station board-sim with ideal sensors, on a free loopback port."""
    world = ManipulatorWorld.from_station(load_station(station_directory("prototype")),
                                          imperfections=Imperfections.ideal())
    server = _serve(world)
    yield server
    server.close()


def _info(link) -> dict[str, str]:
    return dict(kv.split("=", 1) for kv in link.request("INFO"))


#: Only a hang takes this long: a bound that catches one, never a measure of speed.
HANG_S = 30.0


def _until(predicate, seconds: float = HANG_S) -> bool:
    """Poll ``predicate`` until it holds or the deadline (a bound for a hang) passes."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.01)
    return predicate()


class _Raw:
    """A bare protocol client: send bytes, read one reply line."""

    def __init__(self, server: BoardServer):
        self.sock = socket.create_connection(("127.0.0.1", server.port), timeout=5)
        self.file = self.sock.makefile("rb")
        self.greeting = self.line()

    def line(self) -> str:
        return self.file.readline().decode("ascii").rstrip("\n")

    def ask(self, data: bytes) -> str:
        self.sock.sendall(data)
        return self.line()

    def close(self) -> None:
        self.file.close()
        self.sock.close()


# -- the greeting and the wire --------------------------------------------------------------


def test_greeting_names_protocol_station_watchdog_and_boards(gripper_sim):
    """The server speaks first: OK pyrt-board-sim 2 gripper 30000 gripper=gripper-cage@FP."""
    raw = _Raw(gripper_sim)
    try:
        assert raw.greeting == f"OK pyrt-board-sim 2 gripper 30000 gripper={GRIPPER_CAGE.tag}"
        assert raw.ask(b"QUIT\n") == "OK bye"
        assert raw.file.readline() == b""  # the server closed the connection
    finally:
        raw.close()


def test_bad_input_gets_error_replies_and_the_server_keeps_serving(gripper_sim):
    """Garbage, unknown verbs, wrong arity, bad numbers, non-ASCII, over-long and empty lines,
    refused values: each gets one ERR reply, nothing changes, and the next request is served."""
    raw = _Raw(gripper_sim)
    try:
        cases = [
            (b"\n", "ERR syntax empty request"),
            (b"HELLO\n", "ERR syntax unknown request"),
            (b"R\n", "ERR syntax R takes 2 or 3 arguments"),
            (b"R gripper\n", "ERR syntax R takes 2 or 3 arguments"),
            (b"W gripper dac\n", "ERR syntax W takes 3 or 4"),
            (b"R gripper dac -1\n", "ERR range gripper: dac: index must be 0..0"),
            (b"R gripper dac 0x\n", "ERR syntax"),
            (b"R gripper dac 12ab\n", "ERR syntax"),
            (b"R gripper dac \xff\n", "ERR ascii"),
            (b"\x00\x01\x02\n", "ERR syntax"),
            (b"R gripper adc\n", "ERR range gripper: a gripper-cage board has no register 'adc'"),
            (b"R cage dac\n", "ERR range no board 'cage'; boards: gripper"),
            (b"W gripper pa 0\n", "ERR range gripper: pa is an input"),
            (b"W gripper dac 256\n", "ERR range gripper: dac: value must be an integer 0..255"),
            (b"W gripper dac -1\n", "ERR range gripper: dac: value must be an integer 0..255"),
            (b"W gripper dac 99999999999999999999999\n", "ERR syntax"),
            (b"W gripper led_lo 1; R gripper dac\n", "ERR syntax only writes"),
            (b"W gripper led_lo 1;\n", "ERR syntax only writes"),
            (b"X" * (MAX_LINE + 10) + b"\n", "ERR too-long"),
            (b"SNAP 1\n", "ERR range no board '1'"),
            (b"SNAP gripper gripper\n", "ERR syntax SNAP names a board twice"),
            (b"INFO 1\n", "ERR syntax INFO takes no arguments"),
        ]
        for data, want in cases:
            assert raw.ask(data).startswith(want), data[:40]
        assert raw.ask(b"r GRIPPER Dac\r\n") == f"OK {DAC_NULL}"  # any case, CR LF accepted
        assert raw.ask(b"W gripper dac 0 0x90\n") == "OK"
        assert raw.ask(b"R gripper dac\n") == "OK 144"
        assert raw.ask(b"W gripper led_lo 0x5A; W gripper led_hi 0 0xA5\n") == "OK"
        assert raw.ask(b"R gripper led_lo\nR gripper led_hi 0\n") == "OK 90"  # pipelined
        assert raw.line() == "OK 165"
        assert raw.ask(b"SNAP\n") == "OK 0 255 255 255 0 0"  # trips, pa pb pc, up down
        assert raw.ask(b"snap gripper\n") == "OK 0 255 255 255 0 0"
        assert gripper_sim.errors == len(cases)
    finally:
        raw.close()


def test_an_over_long_line_in_pieces_is_refused_once_and_its_tail_dropped(gripper_sim):
    """A line longer than MAX_LINE sent in pieces gets one ERR too-long; what follows it is served."""
    raw = _Raw(gripper_sim)
    try:
        raw.sock.sendall(b"R " + b"1" * MAX_LINE)
        assert raw.line().startswith("ERR too-long")
        raw.sock.sendall(b"1" * 100 + b"\nR gripper dac\n")
        assert raw.line() == f"OK {DAC_NULL}"
    finally:
        raw.close()


def test_a_second_controller_is_refused_busy(gripper_sim):
    """While one controller is connected a second gets ERR busy (naming the first) and is closed."""
    boards = open_boards(gripper_sim.url, "gripper", GRIPPER_BOARDS)
    try:
        with pytest.raises(BoardError) as err:
            open_boards(gripper_sim.url, "gripper", GRIPPER_BOARDS)
        assert gripper_sim.url in str(err.value) and "busy" in str(err.value)
        assert gripper_sim.refused == 1
        assert boards["gripper"].read(DAC) == DAC_NULL  # the first is still served
    finally:
        boards.close()
    with open_boards(gripper_sim.url, "gripper", GRIPPER_BOARDS) as again:  # free again after QUIT
        assert again.world == "gripper"


def test_wrong_kind_of_board_is_a_config_error(gripper_sim):
    """Opening a gripper board-sim as a manipulator is a ConfigError naming the URL, the station
    served and the declared boards that are missing."""
    with pytest.raises(ConfigError) as err:
        open_boards(gripper_sim.url, "prototype", MANIPULATOR_BOARDS)
    text = str(err.value)
    assert gripper_sim.url in text and "serves the gripper station" in text
    assert "missing: tio10 (tio10), dc (dataconcentrator)" in text


# -- the gripper -------------------------------------------------------------------------------


@pytest.mark.parametrize("url", ["sim:", "tcp"])
def test_gripper_board_interface_is_the_same_in_process_and_over_tcp(gripper_sim, url):
    """The cage over sim: and over tcp:// reads, writes and refuses alike, through MOVX too
    (one typed board over the process image, whatever the back end)."""
    cpu = I8031()
    boards = open_boards(gripper_sim.url if url == "tcp" else url, "gripper", GRIPPER_BOARDS, cpu=cpu)
    try:
        board = boards["gripper"]
        assert isinstance(board, GripperBoard)
        assert {a: board.read(a) for a in REGISTERS} == {
            P8155_CMD: 0, P8155_PA: 0xFF, P8155_PB: 0xFF, 0x0103: 0xFF, LED_LO: 0xFF,
            0x0201: 0xFF, DAC: DAC_NULL}
        cpu.movx_write(LED_LO, 0x5A)
        cpu.movx_write(P8155_PA, 0x00)  # an input port: ignored, as the 8155 does
        assert cpu.movx_read(LED_LO) == 0x5A and board.read(LED_LO) == 0x5A
        assert cpu.movx_read(P8155_PA) == 0xFF
        with pytest.raises(ValueError, match="input port"):
            board.write(P8155_PA, 0)
        with pytest.raises(ValueError, match="no gripper cage register"):
            board.read(0x1234)
        with pytest.raises(ValueError, match=r"0\.\.255"):
            board.write(DAC, 0x100)
        assert board.pulse_counts() == (0, 0)
    finally:
        boards.close()


def test_gripper_register_written_over_tcp_is_seen_by_the_plant_and_back(gripper_sim):
    """A DAC write over TCP drives the jaws in the other world; the plant's limit sensor and
    encoder pulses come back: PB shows the limit, poll raises EXT0 once per count."""
    cpu = I8031()
    hits = [0, 0]
    cpu.set_vector(VECTOR_EXT0, lambda: hits.__setitem__(0, hits[0] + 1))
    cpu.set_vector(VECTOR_EXT1, lambda: hits.__setitem__(1, hits[1] + 1))
    with open_boards(gripper_sim.url, "gripper", GRIPPER_BOARDS, cpu=cpu) as boards:
        link = boards["gripper"].registers.link
        assert cpu.movx_read(P8155_PB) & (1 << LIMIT)  # 0100 counts in: limit off
        cpu.movx_write(DAC, 0xA0)  # open at +32
        assert _info(link)["dac"] == "160"
        assert _until(lambda: not cpu.movx_read(P8155_PB) & (1 << LIMIT))  # reached the stop
        cpu.movx_write(DAC, DAC_NULL)
        assert _until(lambda: float(_info(link)["v"]) == 0.0)  # the motor lag has run out
        boards.poll(0)
        info = _info(link)
        assert info["current"] == "0"
        assert hits == [int(info["up"]), int(info["down"])] == list(boards["gripper"].pulse_counts())
        assert hits[0] >= 0x100 - 20 and hits[1] == 0


def test_poll_copy_serves_the_reads_of_a_tick_and_sees_its_own_writes(gripper_sim):
    """In a tick (poll .. flush) reads and writes make no round trip and a read sees the tick's
    write; flush sends the changed outputs in one request; outside a tick a write goes out at
    once, and with max_age=0 a read outside a tick reads the inputs again (prefetch off: every
    read phase is one round trip, so the exchanges can be counted)."""
    url = gripper_sim.url + "?prefetch=0"
    with open_boards(url, "gripper", GRIPPER_BOARDS, max_age=60) as boards:
        board = boards["gripper"]
        link = board.registers.link
        boards.set_tick(0.001)  # a station runs the phases
        boards.poll(0)
        n, sends = link.requests, link.sends
        assert [board.read(a) for a in REGISTERS] and link.requests == n
        board.write(DAC, 0x81)
        board.write(LED_LO, 0x01)
        assert link.requests == n and board.read(DAC) == 0x81 and link.requests == n
        assert link.sends == sends
        boards.flush(0)  # sent, its reply read with the next exchange
        assert link.sends == sends + 1 and link.requests == n
        boards.poll(0)
        assert link.requests == n + 2 and link.sends == sends + 2
        board.write(DAC, 0x81)  # unchanged: nothing to send
        boards.flush(0)
        assert link.requests == n + 2 and link.sends == sends + 2
        board.write(DAC, 0x80)  # outside a tick: at once
        assert link.requests == n + 3
    with open_boards(gripper_sim.url, "gripper", GRIPPER_BOARDS, max_age=0) as boards:
        link = boards["gripper"].registers.link
        n = link.requests
        boards["gripper"].read(P8155_PA)
        assert link.requests == n + 1


def test_the_inputs_stream_and_a_tick_sends_at_most_once(gripper_sim):
    """With prefetch (the default) board-sim pushes the inputs after every world step: a read
    phase sends nothing and takes the newest push; a write phase sends its writes, the request
    for the inputs they leave and (the first time) the stream's request in one system call."""
    with open_boards(gripper_sim.url, "gripper", GRIPPER_BOARDS) as boards:
        board = boards["gripper"]
        client = board.registers.client
        link = client.link
        assert client.streaming and client.step_us == 1000
        boards.set_tick(10.0)  # a long tick: no push is too old for a read phase here
        boards.poll(0)
        board.write(DAC, 0x70)
        sends = link.sends
        boards.flush(0)
        assert link.sends == sends + 1
        boards.poll(0)  # the write's reply and the inputs after it come first
        assert link.latest is not None
        pushes = link.snapshots
        # a bound for a hang only: board-sim pushes after its next step
        assert _until(lambda: (boards.poll(0), link.snapshots)[1] > pushes + 2)
        assert link.sends == sends + 1  # the reads came without asking
        assert _info(link)["dac"] == str(0x70)


@pytest.mark.wallclock
def test_gripper_controller_runs_init_over_tcp_unchanged(gripper_sim):
    """The 002 controller, unchanged, runs I (fullopen to the limit, zero) on a wall-clock loop
    through the GripperBoard view, its encoder counts delivered by poll before the ready queue and its
    DAC writes sent by flush after it."""
    cpu = I8031()
    boards = open_boards(gripper_sim.url, "gripper", GRIPPER_BOARDS, cpu=cpu)
    try:
        ctl = GripperController(cpu)
        loop = Loop(WallClock(), period_ns=1_000_000)
        loop.attach(boards.poll, name="board")
        ctl.attach(loop)
        ctl.power_up()
        job = ctl.start_init()
        # a bound for a hang only: the init takes well under a second of a quiet machine
        loop.run(until=lambda: job.done, duration_ns=60_000_000_000)
        assert job.done and job.value().ok, job.value()
        assert not ctl.ram[OTHER] & (1 << LIMIT)  # the limit sensor, read over TCP
        assert ctl.word(ENCODER_CNT) == 0
        assert _info(boards["gripper"].registers.link)["dac"] == str(DAC_NULL)
    finally:
        boards.close()


# -- the manipulator -----------------------------------------------------------------------------


def test_manipulator_cards_over_tcp_read_back_and_refuse_like_the_sim(manipulator_sim):
    """The TIO10 and dataConcentrator views over tcp://: writes read back, the world sees them;
    refusals are ValueError, made before anything is sent."""
    with open_boards(manipulator_sim.url, "prototype", MANIPULATOR_BOARDS) as boards:
        tio, dc = boards["tio10"], boards["dc"]
        assert isinstance(tio, TIO10) and isinstance(dc, DataConcentrator)
        assert boards.world == "prototype"
        world = manipulator_sim.world
        tio.select_source(CH, 3)
        tio.load_period(CH, 1234)
        tio.write_port(2, 0xA5)
        assert (tio.source(CH), tio.period(CH), tio.read_port(2)) == (3, 1234, 0xA5)
        assert (world.tio10.source(CH), world.tio10.period(CH)) == (3, 1234)
        assert tio.source(4) == 1 and tio.rtc_ticks() > 0
        assert dc.read_adc(ADC) == world.dc.read_adc(ADC) > 0
        with pytest.raises(ValueError, match="no period loaded"):  # the period reads back 0
            tio.arm(0)
        with pytest.raises(ValueError, match="real-time clock"):  # refused before sending
            tio.arm(4)
        with pytest.raises(ValueError, match="16-bit"):
            tio.load_period(CH, 1)
        with pytest.raises(ValueError, match=r"0\.\.255"):
            dc.read_counter(256)
        assert not tio.armed(0)


_PAIR = BoardKind("pair", (Register("a", width=8, direction=OUTPUT),
                           Register("b", width=8, direction=OUTPUT)))


class _RefusesSeven(RegisterBoard):
    """A board whose far side refuses b = 7 (what the controller's image cannot know)."""

    def write(self, name: str, value: int, index: int = 0) -> None:
        if name == "b" and value == 7:
            raise ValueError("b: this board refuses 7")
        super().write(name, value, index)


def test_a_refused_write_leaves_the_image_holding_what_board_sim_holds():
    """A batch that board-sim refuses part of, written at once (a reflex's write): the writes
    before the refused one stand and read back as written, the refused one reads back as it was
    (not 0)."""
    side = Boards("sim:", "pair", {"x": _RefusesSeven(_PAIR)}, {"x": _PAIR}, in_process=True)
    server = _serve(World("pair", side))
    try:
        with open_boards(server.url, "pair", {"x": _PAIR}) as boards:
            x = boards["x"]
            x.write("a", 1)
            x.write("b", 3)
            with pytest.raises(ValueError, match="refuses 7"):
                boards.backend.write_many([("x", "a", 0, 5), ("x", "b", 0, 7)])
            assert (x.read("a"), x.read("b")) == (5, 3)
            assert side["x"].output("a") == 5 and side["x"].output("b") == 3
    finally:
        server.close()


@pytest.mark.wallclock
def test_manipulator_motor_driven_over_tcp_moves_the_world_and_counts_come_back(manipulator_sim):
    """A motor armed over TCP pays rope out in the other world; pulses, encoder counts and the
    loadcell come back, through one SNAP per poll."""
    with open_boards(manipulator_sim.url, "prototype", MANIPULATOR_BOARDS) as boards:
        tio, dc = boards["tio10"], boards["dc"]
        link = tio.registers.link
        before = float(_info(link)["payout0"])
        dc.clear_counter(ENC)
        tio.select_source(CH, 3)  # F3: 50 kHz
        tio.load_period(CH, 100)  # 500 half-steps/s
        tio.set_bit(*DIR_BITS[CH], True)  # pay out
        tio.set_bit(*AWO_BITS[CH], False)  # windings on
        tio.arm(CH)
        assert _until(lambda: (boards.poll(0), dc.read_counter(ENC))[1] >= 5)
        tio.disarm(CH)
        tio.set_bit(*AWO_BITS[CH], True)
        boards.poll(0)
        n = link.requests
        assert tio.pulses(CH) > 0 and not tio.armed(CH) and link.requests == n
        assert float(_info(link)["payout0"]) > before


class _MovedClock:
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


def test_the_world_steps_on_board_sims_clock():
    """The world's clock (the TIO10's 5 MHz RTC, set by each step) advances as board-sim's
    monotonic clock does: 0.3 s of it, 1,500,000 RTC ticks."""
    world = ManipulatorWorld.from_station(load_station(station_directory("prototype")),
                                          imperfections=Imperfections.ideal())
    clock = _MovedClock()
    server = _serve(world, clock=clock)
    try:
        with open_boards(server.url, "prototype", MANIPULATOR_BOARDS, max_age=0) as boards:
            tio = boards["tio10"]
            r0 = tio.rtc_ticks()
            clock.advance(300_000_000)
            # a bound for a hang only: board-sim steps at its next pass
            assert _until(lambda: tio.rtc_ticks() != r0, HANG_S)
            assert tio.rtc_ticks() - r0 == 1_500_000
    finally:
        server.close()


def _packed(*values: int) -> str:
    """The hexadecimal a packed snapshot of ``values`` (TRIPS first) carries."""
    return struct.pack(f"<{len(values)}I", *values).hex()


def _stepped(server: BoardServer, clock: _MovedClock, ns: int) -> None:
    """Move board-sim's clock by ``ns`` and wait until it has stepped its world there
    (a bound for a hang only)."""
    steps = server.steps
    clock.advance(ns)
    assert _until(lambda: server.steps > steps)


def test_a_stream_pushes_the_inputs_after_every_step_until_its_time_is_up():
    """STREAM MS answers the world's step and pushes ``S HEX`` (SNAPX's inputs) after every
    step of board-sim's clock until MS have passed; STREAM 0 stops it; any connection may
    stream, and a push never comes between a reply's bytes."""
    clock = _MovedClock()
    server = _serve(GripperWorld(), clock=clock)
    raw = _Raw(server)
    try:
        snap = _packed(0, 0xFF, 0xFF, 0xFF, 0, 0)  # trips, pa pb pc, up down
        assert raw.ask(b"SNAPX\n") == f"OK {snap}"
        assert raw.ask(b"snapx gripper\n") == f"OK {snap}"
        assert raw.ask(b"STREAM 3\n") == "OK 1000"
        _stepped(server, clock, 1_000_000)
        assert raw.line() == f"S {snap}"
        _stepped(server, clock, 1_000_000)
        assert raw.line() == f"S {snap}"
        _stepped(server, clock, 2_000_000)  # the 3 ms are up: no more
        assert raw.ask(b"R gripper dac\n") == f"OK {DAC_NULL}"
        assert raw.ask(b"STREAM 100 gripper\n") == "OK 1000"
        _stepped(server, clock, 1_000_000)
        assert raw.line() == f"S {snap}"
        assert raw.ask(b"STREAM 0\n") == "OK 1000"
        _stepped(server, clock, 1_000_000)
        assert raw.ask(b"R gripper dac\n") == f"OK {DAC_NULL}"
        assert server.owner is None  # streaming claims nothing
    finally:
        raw.close()
        server.close()


class _OlderBoardSim(BoardServer):
    """A board-sim from before the packed form: SNAPX and STREAM are unknown requests."""

    def _answer(self, conn, line):
        if line.split()[:1] in ([b"SNAPX"], [b"STREAM"]):
            return b"ERR syntax unknown request; known: R W SNAP OWN INFO QUIT\n"
        return super()._answer(conn, line)


def test_an_older_board_sim_is_read_with_snap_one_send_a_tick():
    """A board-sim that does not know SNAPX and STREAM is read with text SNAP: the write phase
    sends its writes and the next tick's SNAP in one system call, the read phase sends nothing
    and reads both replies, and the writes reach the board."""
    server = _OlderBoardSim(GripperWorld(), "127.0.0.1", 0, watchdog_s=30.0)
    server.start()
    try:
        with open_boards(server.url, "gripper", GRIPPER_BOARDS) as boards:
            board = boards["gripper"]
            client = board.registers.client
            link = client.link
            assert client.step_us is None and not client.streaming
            boards.set_tick(10.0)  # a long tick: no prefetched SNAP is too old here
            boards.poll(0)
            board.write(DAC, 0x70)
            sends, n = link.sends, link.requests
            boards.flush(0)
            assert link.sends == sends + 1
            boards.poll(0)
            assert link.sends == sends + 1 and link.requests == n + 2
            assert board.read(P8155_PA) == 0xFF and _info(link)["dac"] == str(0x70)
    finally:
        server.close()


def test_a_request_of_another_thread_gets_its_own_reply_while_the_inputs_stream(gripper_sim):
    """While the loop's phases stream the inputs and send writes, INFO asked from another
    thread (a console) always gets INFO's reply, and the phases never take it for theirs."""
    with open_boards(gripper_sim.url, "gripper", GRIPPER_BOARDS) as boards:
        board = boards["gripper"]
        link = board.registers.link
        boards.set_tick(0.001)
        infos: list[dict[str, str]] = []
        failures: list[BaseException] = []

        def console() -> None:
            try:
                for _ in range(150):
                    infos.append(_info(link))
            except BaseException as exc:  # the test says what it was
                failures.append(exc)

        t = threading.Thread(target=console)
        t.start()
        k = 0
        while t.is_alive():
            boards.poll(0)
            board.write(LED_LO, k & 0xFF)  # a write, its SNAPX behind it, every tick
            boards.flush(0)
            k += 1
        t.join()
        assert failures == [] and len(infos) == 150
        assert all("dac" in info and "x" in info for info in infos), infos[:3]
        boards.poll(0)
        assert boards.down is None


@pytest.mark.parametrize("lose", [True, False])
def test_the_receiving_thread_ends_with_the_link_and_a_lost_board_sim_is_named(lose):
    """While the inputs stream a thread of the link's own receives them; when board-sim goes
    the next read phase raises BoardError naming the URL, and the thread has ended; closing
    the link ends it too."""
    server = _serve(GripperWorld())
    boards = open_boards(server.url, "gripper", GRIPPER_BOARDS)
    try:
        link = boards["gripper"].registers.link
        boards.set_tick(0.001)
        boards.poll(0)
        boards.flush(0)  # the stream is asked for: the thread receives from here on
        receiver = link._receiver
        assert receiver is not None and receiver.is_alive()
        if lose:
            server.close()
            with pytest.raises(BoardError) as err:
                # a bound for a hang only: the loss shows at a read phase after it
                assert not _until(lambda: boards.poll(0) and False)
            assert err.value.url == server.url and server.url in str(err.value)
            receiver.join(HANG_S)
            assert not receiver.is_alive()
        boards.close()
        receiver.join(HANG_S)
        assert not receiver.is_alive() and boards.down is not None
    finally:
        boards.close()
        server.close()


# -- failures -------------------------------------------------------------------------------------


def test_board_sim_gone_makes_the_next_access_raise_board_error_naming_the_url():
    """When board-sim closes, the next access raises BoardError naming the URL, and so does every
    later one, at once (for the closed connection, not after the reply timeout)."""
    server = _serve(GripperWorld())
    boards = open_boards(server.url, "gripper", GRIPPER_BOARDS, max_age=0)
    url = server.url
    server.close()
    with pytest.raises(BoardError) as err:
        boards["gripper"].read(P8155_PA)  # outside a tick, max_age=0: the inputs are read
    assert str(err.value).startswith(f"board {url}: SNAP: ") and err.value.url == url
    assert "no reply within" not in str(err.value)
    with pytest.raises(BoardError, match="link is down"):
        boards.poll(0)
    boards.close()


def test_connection_refused_is_a_board_error_naming_the_url():
    """Opening a tcp:// URL where nothing listens raises BoardError naming it."""
    probe = socket.create_server(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()
    url = f"tcp://127.0.0.1:{port}"
    with pytest.raises(BoardError) as err:
        open_boards(url, "prototype", MANIPULATOR_BOARDS)
    assert str(err.value).startswith(f"board {url}: cannot connect") and "refused" in str(err.value)


def test_a_board_that_stops_answering_times_out_with_a_board_error():
    """A board that greets and then never replies: the access fails after the timeout, naming the URL."""
    listener = socket.create_server(("127.0.0.1", 0))
    port = listener.getsockname()[1]
    held: list[socket.socket] = []

    def accept() -> None:
        conn, _ = listener.accept()
        conn.sendall(f"OK pyrt-board-sim 2 mute 500 gripper={GRIPPER_CAGE.tag}\n".encode())
        held.append(conn)

    t = threading.Thread(target=accept, daemon=True)
    t.start()
    url = f"tcp://127.0.0.1:{port}?timeout=0.1"
    try:
        boards = open_boards(url, "gripper", GRIPPER_BOARDS, max_age=0)
    except BoardError as exc:  # the first SNAP already times out: that is the case too
        assert "no reply within 0.1 s" in str(exc)
    else:  # pragma: no cover - the SNAP at open cannot be answered
        boards.close()
        raise AssertionError("a mute board was opened")
    finally:
        t.join(5)
        for c in held:
            c.close()
        listener.close()


def test_a_peer_that_is_not_board_sim_is_refused():
    """A server that greets with something else is refused as not a pyrt board-sim."""
    listener = socket.create_server(("127.0.0.1", 0))

    def accept() -> None:
        conn, _ = listener.accept()
        conn.sendall(b"SSH-2.0-OpenSSH_9.6\r\n")
        conn.close()

    t = threading.Thread(target=accept, daemon=True)
    t.start()
    url = f"tcp://127.0.0.1:{listener.getsockname()[1]}"
    try:
        with pytest.raises(BoardError, match="not a pyrt board-sim"):
            open_boards(url, "gripper", GRIPPER_BOARDS)
    finally:
        t.join(5)
        listener.close()


def test_a_silent_controller_trips_the_watchdog_in_process():
    """No register access for the watchdog time (0.1 s of board-sim's clock): the DAC goes to
    null while still connected, and the controller's next poll raises BoardError saying so (once)."""
    clock = _MovedClock()
    server = _serve(GripperWorld(), watchdog_s=0.1, clock=clock)
    try:
        with open_boards(server.url, "gripper", GRIPPER_BOARDS) as boards:
            boards["gripper"].write(DAC, 0x70)
            clock.advance(150_000_000)
            # a bound for a hang only: board-sim keeps the watchdog at its next pass
            assert _until(lambda: server.watchdog_trips == 1, HANG_S)
            with pytest.raises(BoardError) as err:  # the controller is told, once
                boards.poll(0)
            assert str(err.value) == (f"board {server.url}: the board's watchdog turned the "
                                      "outputs off (no register access for 0.1 s)")
            boards.poll(0)
            assert boards["gripper"].read(DAC) == DAC_NULL
    finally:
        server.close()
