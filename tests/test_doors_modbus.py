"""board-sim --modbus under abuse, over loopback: a watchdog only the owning controller feeds,
exception 03 for an illegal value, pipelined requests, idle and half-open connections, a
bounded number of connections, and a bounded fuzz of Modbus frames."""

from __future__ import annotations

import contextlib
import random
import signal
import socket
import struct
import threading
import time
from collections.abc import Iterator

import pytest
from test_board_sim import START_S, _Proc

from pyrt.boards.gripper import DAC_NULL
from pyrt.boards.modbus import builtin_map
from pyrt.boards.modbusmap import load_map
from pyrt.sim.modbusserver import ModbusBoardServer
from pyrt.sim.world import GRIPPER_BOARDS, GripperWorld

#: Where the shipped gripper map puts things (unit 1): input registers 0..6, holding 0..3.
UNIT, DAC_AT, CMD_AT = 1, 3, 0

#: Generous bounds for a loaded two-core machine; what is asserted is that it happens.
BOUND_S = 15.0


def _frame(tid: int, pdu: bytes, unit: int = UNIT) -> bytes:
    return struct.pack(">HHHB", tid, 0, len(pdu) + 1, unit) + pdu


class _Raw:
    """A Modbus TCP client on a bare socket: frames in, frames out, nothing hidden."""

    def __init__(self, port: int):
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=5)
        self.tid = 0
        self.buf = b""

    def send(self, pdu: bytes, unit: int = UNIT) -> int:
        self.tid = (self.tid + 1) & 0xFFFF
        self.sock.sendall(_frame(self.tid, pdu, unit))
        return self.tid

    def frame(self) -> tuple[int, bytes]:
        """The next reply: (transaction id, PDU); EOFError when the server closed."""
        while True:
            if len(self.buf) >= 6:
                length = struct.unpack(">H", self.buf[4:6])[0]
                if len(self.buf) >= 6 + length:
                    tid = struct.unpack(">H", self.buf[:2])[0]
                    pdu = self.buf[7:6 + length]
                    self.buf = self.buf[6 + length:]
                    return tid, pdu
            data = self.sock.recv(4096)
            if not data:
                raise EOFError
            self.buf += data

    def ask(self, pdu: bytes, unit: int = UNIT) -> bytes:
        tid = self.send(pdu, unit)
        got, reply = self.frame()
        assert got == tid
        return reply

    def read_holding(self, address: int, count: int = 1) -> list[int]:
        reply = self.ask(struct.pack(">BHH", 3, address, count))
        assert reply[0] == 3, reply
        return list(struct.unpack(f">{count}H", reply[2:]))

    def read_inputs(self) -> bytes:
        return self.ask(struct.pack(">BHH", 4, 0, 7))

    def write(self, address: int, value: int) -> bytes:
        return self.ask(struct.pack(">BHH", 6, address, value))

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
        self.sock.close()


def _until(predicate, seconds: float = BOUND_S) -> bool:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.01)
    return predicate()


def _serve(**kw) -> tuple[ModbusBoardServer, GripperWorld]:
    world = GripperWorld(start=-0x100)
    server = ModbusBoardServer(world, load_map(builtin_map("gripper"), GRIPPER_BOARDS),
                               **{"watchdog_s": 30.0, **kw})
    server.start()
    return server, world


@pytest.fixture
def served() -> Iterator[tuple[ModbusBoardServer, GripperWorld]]:
    server, world = _serve()
    yield server, world
    server.close()


def _dac(world: GripperWorld) -> int:
    return world.registers("gripper").read("dac")


# -- Modbus like a device ----------------------------------------------------------------


def test_an_illegal_value_gets_exception_03_and_changes_nothing(served):
    """0x0100 and 0x7FFF to the 8-bit DAC (function 6 and 16), and a block write whose last
    value is illegal: exception 03 (illegal data value), nothing written; 0x90 is then taken."""
    server, world = served
    c = _Raw(server.port)
    try:
        before = [world.registers("gripper").read(r) for r in ("cmd", "led_lo", "led_hi", "dac")]
        assert c.write(DAC_AT, 0x0100) == bytes([0x86, 0x03])
        assert c.ask(struct.pack(">BHHBH", 16, DAC_AT, 1, 2, 0x7FFF)) == bytes([0x90, 0x03])
        block = struct.pack(">BHHB4H", 16, CMD_AT, 4, 8, 0x12, 0x34, 0x56, 0x100)
        assert c.ask(block) == bytes([0x90, 0x03])
        assert [world.registers("gripper").read(r)
                for r in ("cmd", "led_lo", "led_hi", "dac")] == before
        assert c.write(DAC_AT, 0x90) == struct.pack(">BHH", 6, DAC_AT, 0x90)
        assert _dac(world) == 0x90
    finally:
        c.close()


def test_malformed_requests_get_the_exception_the_protocol_names(served):
    """Unknown function: 01; an address the map does not place: 02; a count beyond the
    protocol's limit, a byte count that disagrees, a coil value not 0/FF00: 03; a write to an
    input register: 02.  The connection stays usable."""
    server, _world = served
    c = _Raw(server.port)
    try:
        assert c.ask(bytes([0x2B, 0x0E, 0x01, 0x00])) == bytes([0xAB, 0x01])
        assert c.ask(struct.pack(">BHH", 4, 100, 1)) == bytes([0x84, 0x02])
        assert c.ask(struct.pack(">BHH", 4, 0, 126)) == bytes([0x84, 0x03])
        assert c.ask(struct.pack(">BHH", 3, 0, 0)) == bytes([0x83, 0x03])
        assert c.ask(struct.pack(">BHHBH", 16, 0, 2, 2, 0)) == bytes([0x90, 0x03])
        assert c.ask(struct.pack(">BHH", 6, 200, 1)) == bytes([0x86, 0x02])
        assert c.ask(struct.pack(">BHH", 5, 0, 0x1234))[:1] == bytes([0x85])
        assert c.read_holding(DAC_AT) == [DAC_NULL]
    finally:
        c.close()


def test_pipelined_requests_all_get_replies_in_order(served):
    """Five requests in one TCP segment: five replies, their transaction ids in order."""
    server, _world = served
    c = _Raw(server.port)
    try:
        c.sock.sendall(b"".join(_frame(tid, struct.pack(">BHH", 4, 0, 7))
                                for tid in range(10, 15)))
        got = [c.frame() for _ in range(5)]
        assert [tid for tid, _ in got] == list(range(10, 15))
        assert all(pdu[:2] == bytes([4, 14]) for _, pdu in got)
    finally:
        c.close()


@pytest.mark.wallclock
def test_idle_and_half_open_connections_are_closed_and_the_server_keeps_serving():
    """A connection that sends nothing and one that stops mid-frame are closed after the idle
    time (0.3 s); a fresh connection is still served."""
    server, _world = _serve(idle_s=0.3)
    idle, half = _Raw(server.port), _Raw(server.port)
    try:
        half.sock.sendall(_frame(1, struct.pack(">BHH", 4, 0, 7))[:5])
        assert _until(idle.closed_by_server), "an idle connection stayed open"
        assert _until(half.closed_by_server), "a half-sent frame kept its connection open"
        fresh = _Raw(server.port)
        assert fresh.read_inputs()[:2] == bytes([4, 14])
        fresh.close()
    finally:
        idle.close()
        half.close()
        server.close()


def test_connections_are_bounded_and_a_controller_always_gets_in():
    """max_clients 4 and twelve readers: the server holds at most 4 connections (the longest
    idle reader makes room), and a controller that comes last connects, writes and owns."""
    server, world = _serve(max_clients=4)
    readers = [_Raw(server.port) for _ in range(12)]
    ctl = None
    try:
        for r in readers:
            with contextlib.suppress(EOFError, OSError):
                r.read_inputs()
        ctl = _Raw(server.port)
        assert ctl.write(DAC_AT, 0x90) == struct.pack(">BHH", 6, DAC_AT, 0x90)
        assert _dac(world) == 0x90
        open_ = [r for r in readers if not r.closed_by_server()]
        assert len(open_) <= 3, f"{len(open_)} readers still connected besides the controller"
    finally:
        for r in readers:
            r.close()
        if ctl is not None:
            ctl.close()
        server.close()


def test_250_half_open_connections_neither_exhaust_the_server_nor_keep_a_controller_out(served):
    """250 connections each stopped in the middle of a frame (the default bounds): the server
    holds at most max_clients of them, and a controller still reads the inputs and drives the
    DAC at once."""
    server, world = served
    held: list[_Raw] = []
    try:
        for n in range(250):
            c = _Raw(server.port)
            c.sock.sendall(_frame(n, struct.pack(">BHH", 4, 0, 7))[:9])
            held.append(c)
        assert _until(lambda: server.clients <= server.max_clients)
        ctl = _Raw(server.port)
        assert ctl.read_inputs()[:2] == bytes([4, 14])
        assert ctl.write(DAC_AT, 0x90)[:1] == b"\x06" and _dac(world) == 0x90
        assert server.clients <= server.max_clients and server.evicted >= 250 - server.max_clients
        ctl.close()
    finally:
        for c in held:
            c.close()


@pytest.mark.wallclock
def test_a_reader_neither_writes_nor_feeds_the_watchdog_while_the_controller_owns():
    """The controller writes the DAC and owns the outputs; a second client's write gets
    exception 06 (busy) and changes nothing; the controller falls silent while the reader keeps
    polling every 50 ms: the watchdog (0.3 s) turns the DAC off all the same."""
    server, world = _serve(watchdog_s=0.3)
    ctl, reader = _Raw(server.port), _Raw(server.port)
    stop = threading.Event()
    try:
        assert ctl.write(DAC_AT, 0x90)[:1] == b"\x06"
        assert reader.write(DAC_AT, 0x10) == bytes([0x86, 0x06])
        assert _dac(world) == 0x90

        def poll() -> None:
            while not stop.wait(0.05):
                reader.read_inputs()
                reader.read_holding(DAC_AT)

        t = threading.Thread(target=poll, daemon=True)
        t.start()
        assert _until(lambda: _dac(world) == DAC_NULL), "the reader kept the outputs on"
        assert server.watchdog_trips >= 1
        stop.set()
        t.join(5)
    finally:
        stop.set()
        ctl.close()
        reader.close()
        server.close()


def test_a_second_pyrt_controller_is_told_the_outputs_are_owned(served):
    """Two pyrt controllers on one board-sim --modbus: the second opens (reading is open to
    all) but its write fails with a BoardError naming exception 06 and the owner's claim, and
    changes nothing; once the first has closed, the second's write is taken."""
    from pyrt.boards import open_boards
    from pyrt.boards.gripper import DAC
    from pyrt.errors import BoardError

    server, world = served
    url = f"{server.url}?map=builtin:gripper"
    first = open_boards(url, "gripper", GRIPPER_BOARDS, max_age=0)
    second = open_boards(url, "gripper", GRIPPER_BOARDS, max_age=0)
    try:
        first["gripper"].write(DAC, 0x90)
        with pytest.raises(BoardError, match=r"exception 06 \(server device busy"):
            second["gripper"].write(DAC, 0x10)
        assert _dac(world) == 0x90
        first.close()
        assert _until(lambda: server.owner is None)
        second["gripper"].write(DAC, 0x70)
        assert _dac(world) == 0x70
    finally:
        first.close()
        second.close()


# -- the controller killed while an HMI polls (board-sim and the controller in subprocesses) ---

#: A pyrt controller that drives the DAC to 1 (near full drive), says 'driving', then polls.
CONTROLLER = """
import sys, time
from pyrt.boards import open_boards
from pyrt.boards.gripper import DAC
from pyrt.sim.world import GRIPPER_BOARDS
b = open_boards(sys.argv[1], "gripper", GRIPPER_BOARDS)
b["gripper"].write(DAC, 1)
print("driving", flush=True)
while True:
    b.poll(0)
    time.sleep(0.01)
"""


def _board_sim(scheme: str) -> tuple[_Proc, str]:
    args = ["-m", "pyrt", "board-sim", "gripper", "--watchdog", "1"]
    if scheme == "modbus":
        args += ["--modbus", "127.0.0.1:0"]
    else:
        args += ["--listen", "127.0.0.1:0"]
    p = _Proc(args)
    _, m = p.expect(r"^pyrt board-sim: gripper gripper on ((tcp|modbus)://127\.0\.0\.1:\d+\S*) ")
    return p, m.group(1)


class _Poller:
    """An HMI: reads the inputs and the DAC every 100 ms over its own connection."""

    def __init__(self, scheme: str, url: str):
        port = int(url.split(":")[2].split("?")[0])
        self.scheme = scheme
        self.dac: int | None = None
        self.errors: list[str] = []
        self.reads = 0
        self._stop = threading.Event()
        if scheme == "modbus":
            self.raw = _Raw(port)
        else:
            self.sock = socket.create_connection(("127.0.0.1", port), timeout=5)
            self.f = self.sock.makefile("rb")
            self.f.readline()  # the greeting
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _once(self) -> int:
        if self.scheme == "modbus":
            assert self.raw.read_inputs()[:1] == b"\x04"
            return self.raw.read_holding(DAC_AT)[0]
        self.sock.sendall(b"SNAP\nR gripper dac\n")
        snap, dac = self.f.readline().split(), self.f.readline().split()
        assert snap[:1] == [b"OK"] and dac[:1] == [b"OK"], (snap, dac)
        return int(dac[1])

    def _run(self) -> None:
        while not self._stop.wait(0.1):
            try:
                self.dac = self._once()
                self.reads += 1
            except Exception as exc:
                self.errors.append(f"{type(exc).__name__}: {exc}")
                return

    def close(self) -> None:
        self._stop.set()
        self.thread.join(5)
        if self.scheme == "modbus":
            self.raw.close()
        else:
            self.f.close()
            self.sock.close()


@pytest.mark.wallclock
@pytest.mark.parametrize("scheme", ["modbus", "tcp"])
def test_a_killed_controller_leaves_the_outputs_off_while_a_reader_polls(scheme):
    """board-sim (watchdog 1 s), a pyrt controller driving the DAC to 1, an HMI polling the
    inputs every 100 ms on its own connection; kill -9 the controller: the DAC goes back to
    null (80) while the HMI keeps polling, and the HMI is served throughout."""
    sim, url = _board_sim(scheme)
    ctl = poller = None
    try:
        ctl = _Proc(["-c", CONTROLLER, url])
        ctl.expect("^driving$", START_S)
        poller = _Poller(scheme, url)
        assert _until(lambda: poller.dac == 1 or poller.errors), poller.errors
        assert poller.dac == 1, poller.errors
        ctl.proc.send_signal(signal.SIGKILL)
        ctl.proc.wait(10)
        reads = poller.reads
        assert _until(lambda: poller.dac == DAC_NULL or bool(poller.errors)), \
            f"DAC still {poller.dac} after {BOUND_S} s of polling"
        assert not poller.errors, poller.errors
        assert poller.dac == DAC_NULL
        assert _until(lambda: poller.reads >= reads + 3)  # and the HMI is still served
    finally:
        if poller is not None:
            poller.close()
        if ctl is not None:
            ctl.kill()
        sim.kill()


# -- a bounded fuzz of Modbus frames ---------------------------------------------------------

_FUNCTIONS = (1, 2, 3, 4, 5, 6, 15, 16, 23, 0, 7, 8, 0x2B, 0x80, 0x86, 0xFF)


def _random_pdu(rng: random.Random) -> bytes:
    kind = rng.random()
    if kind < 0.15:  # any bytes at all
        return bytes(rng.randrange(256) for _ in range(rng.randrange(1, 40)))
    fc = rng.choice(_FUNCTIONS)
    address = rng.choice([0, 1, 2, 3, 4, 5, 6, 7, 100, 0xFFFF, rng.randrange(0x10000)])
    count = rng.choice([0, 1, 2, 4, 7, 125, 126, 2000, 2001, rng.randrange(0x10000)])
    value = rng.choice([0, 1, 0x7F, 0x80, 0xFF, 0x100, 0x7FFF, 0xFF00, 0xFFFF,
                        rng.randrange(0x10000)])
    if fc in (1, 2, 3, 4, 5, 6):
        pdu = struct.pack(">BHH", fc, address, count if fc < 5 else value)
    elif fc in (15, 16):
        n = rng.randrange(0, 6)
        data = bytes(rng.randrange(256) for _ in range(n * 2))
        byte_count = rng.choice([len(data), len(data) + 1, rng.randrange(256)])
        pdu = struct.pack(">BHHB", fc, address, rng.choice([n, count]), byte_count & 0xFF) + data
    elif fc == 23:
        n = rng.randrange(0, 4)
        data = b"".join(struct.pack(">H", rng.choice([value, 0x90])) for _ in range(n))
        pdu = struct.pack(">BHHHHB", fc, rng.randrange(8), rng.randrange(8), address,
                          rng.choice([n, count]), len(data) & 0xFF) + data
    else:
        pdu = bytes([fc]) + bytes(rng.randrange(256) for _ in range(rng.randrange(0, 8)))
    if rng.random() < 0.1:  # truncated or padded
        pdu = pdu[:rng.randrange(len(pdu) + 1)] + bytes(rng.randrange(3))
    return pdu


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


#: The fuzz's bounds: frames sent, and a wall-time bound on the whole run that only a
#: hang reaches (the run takes seconds, on a loaded machine too).
FUZZ_FRAMES = 1500
FUZZ_S = 120.0


def test_fuzzed_modbus_frames_never_crash_the_server_nor_write_an_illegal_value(served):
    """1500 random, malformed and hostile frames (seeded; bad headers too): the server never
    dies, every exception reply changes no output, every output always holds a legal value,
    and a well-formed request is answered afterwards."""
    server, world = served
    rng = random.Random(20261126)
    c = _Raw(server.port)
    t_end = time.monotonic() + FUZZ_S
    replies = exceptions = reconnects = 0
    try:
        for n in range(FUZZ_FRAMES):
            assert time.monotonic() < t_end, f"fuzz too slow: {n} frames"
            before = _outputs(world)
            pdu = _random_pdu(rng)
            unit = rng.choice([UNIT, UNIT, UNIT, 0, 2, 255])
            tid = n & 0xFFFF
            if not pdu or rng.random() < 0.05:  # a broken header: protocol id or length field
                head = struct.pack(">HHHB", tid, rng.choice([0, 1, 0xFFFF]),
                                   rng.choice([0, 1, 255, 0xFFFF, len(pdu) + 1]), unit)
                c.sock.sendall(head + pdu)
                c.sock.settimeout(0.5)
                with contextlib.suppress(EOFError, OSError):
                    c.frame()
                c.close()
                c = _Raw(server.port)
                reconnects += 1
                # the old connection's close turns the outputs off if it owned them: wait
                assert _until(lambda: server.owner is None)
                continue
            c.sock.sendall(_frame(tid, pdu, unit))
            try:
                got, reply = c.frame()
            except (EOFError, OSError):
                raise AssertionError(f"no reply to {pdu.hex()} for unit {unit}") from None
            replies += 1
            assert got == tid
            after = _outputs(world)
            if reply[:1] and reply[0] & 0x80:
                exceptions += 1
                assert after == before, (pdu.hex(), reply.hex(), before, after)
            assert _legal(world, after), (pdu.hex(), after)
            assert server.alive
        assert replies > FUZZ_FRAMES // 2 and exceptions > 100, (replies, exceptions)
        fresh = _Raw(server.port)
        assert fresh.read_inputs()[:2] == bytes([4, 14])
        assert fresh.read_holding(DAC_AT) == [_dac(world)]
        fresh.close()
    finally:
        c.close()


# -- the closing message, true to the link's settings ------------------------------------------


@pytest.mark.wallclock
@pytest.mark.parametrize("off_on_loss", ["0", "1"])
def test_the_closing_message_says_what_the_link_promises_about_the_outputs(off_on_loss):
    """A gripper over modbus:// whose server dies: closing reports the lost boards in one line
    that says the device turns its outputs off only when the URL says so (off_on_loss=1), and
    otherwise that they may still be driven."""
    from pyrt.scheduler import Loop, WallClock
    from pyrt.station.gripper import build_gripper

    server, _world = _serve()
    url = f"{server.url}?map=builtin:gripper&off_on_loss={off_on_loss}"
    station = build_gripper(Loop(WallClock()), boards=url)
    reports: list[str] = []
    station.close_report = reports.append
    try:
        station.start()
        server.close()
        assert _until(lambda: station.fault is not None), "no fault"
    finally:
        station.close()
        server.close()
    assert len(reports) == 1, reports
    if off_on_loss == "1":
        assert reports[0].endswith("the board turns its outputs off when its link drops")
    else:
        assert "the board turns its outputs off" not in reports[0]
        assert "not known to turn its outputs off" in reports[0]
        assert "off_on_loss=0" in reports[0] and "may still be driven" in reports[0]


def test_random_byte_streams_on_many_connections_leave_the_server_serving(served):
    """Fifty connections (seeded) each blast 4 kB of random bytes, or random frames with a good
    header, and close at once: the server keeps running, every output holds a legal value,
    and a well-formed request is answered afterwards."""
    server, world = served
    rng = random.Random(37)
    for n in range(50):
        c = _Raw(server.port)
        if n % 2:
            data = bytes(rng.randrange(256) for _ in range(4096))
        else:
            data = b"".join(_frame(k, _random_pdu(rng) or b"\x03") for k in range(100))
        with contextlib.suppress(OSError):
            c.sock.sendall(data)
        c.close()
        assert server.alive and _legal(world, _outputs(world))
    fresh = _Raw(server.port)
    try:
        assert fresh.read_inputs()[:2] == bytes([4, 14])
        assert fresh.read_holding(DAC_AT) == [_dac(world)]
    finally:
        fresh.close()
