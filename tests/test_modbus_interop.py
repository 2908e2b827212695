"""modbus:// both ways: pyrt drives a plain pymodbus server, a plain pymodbus client reads board-sim
--modbus; the 002 transcript over modbus://; killing the Modbus server mid-move."""

from __future__ import annotations

import asyncio
import io
import re
import sys
import threading
import time
import tomllib
from collections.abc import Iterator
from pathlib import Path

import pytest
from pymodbus.client import ModbusTcpClient
from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import SimData, SimDevice
from pymodbus.simulator.simdata import DataType
from test_gripper_transcript import SCRIPT, answers, hexword
from test_station_boards import _Proc

from pyrt.boards import open_boards
from pyrt.boards.gripper import DAC_NULL
from pyrt.boards.modbus import builtin_map
from pyrt.boards.registers import OUTPUT, BoardKind, Register
from pyrt.cli import main
from pyrt.commands import RobotShell
from pyrt.scheduler import Loop, WallClock
from pyrt.station.gripper import build_gripper

START_S = 60.0

SERVO = BoardKind("arm-servo", (
    Register("drive", count=2, width=16, signed=True, direction=OUTPUT, off=0),
    Register("enable", direction=OUTPUT, off=0),
    Register("count", count=2, width=32, signed=True),
    Register("status", width=8),
))

SERVO_MAP = """\
unit = 5
[servo.count]          # the test plays the world: it writes these holding registers
table = "holding"
address = 0
width = 32
[servo.drive]
table = "holding"
address = 10
[servo.enable]
table = "coil"
address = 0
[servo.status]         # a read-only input register the server was given
table = "input"
address = 0
"""


# -- a plain pymodbus server that knows nothing of pyrt ------------------------------------


class _PlainServer:
    """A pymodbus ModbusTcpServer holding registers (SimDevice 5), in a thread of its own;
    ``received`` counts the requests it got."""

    def __init__(self, port: int):
        self.port = port
        self.received = 0
        dev = SimDevice(5, simdata=(
            [SimData(0, count=8, values=False, datatype=DataType.BITS)],
            [SimData(0, count=8, values=False, datatype=DataType.BITS)],
            [SimData(0, count=20, values=0, datatype=DataType.REGISTERS)],
            [SimData(0, count=4, values=[42, 0, 0, 0], datatype=DataType.REGISTERS)]))
        self._loop = asyncio.new_event_loop()
        self._ready = threading.Event()

        def trace(sending: bool, pdu):
            if not sending:
                self.received += 1
            return pdu

        async def run() -> None:
            self.server = ModbusTcpServer(dev, address=("127.0.0.1", port), trace_pdu=trace)
            await self.server.serve_forever(background=True)
            self._ready.set()
            self._stop = asyncio.Event()
            await self._stop.wait()
            await self.server.shutdown()

        self._thread = threading.Thread(target=lambda: self._loop.run_until_complete(run()),
                                        daemon=True)
        self._thread.start()
        assert self._ready.wait(10)

    def close(self) -> None:
        self._loop.call_soon_threadsafe(self._stop.set)
        self._thread.join(5)


def _free_port() -> int:
    import socket
    with socket.create_server(("127.0.0.1", 0)) as s:
        return s.getsockname()[1]


def test_pyrt_drives_a_plain_pymodbus_server_through_a_map(tmp_path):
    """A plain pymodbus server holding registers: pyrt reads the counts the test's own client
    wrote (32-bit signed, two holding registers each) and the server's input register; its
    writes of a tick arrive at the end of the tick, one request per contiguous group."""
    path = tmp_path / "servo.toml"
    path.write_text(SERVO_MAP)
    port = _free_port()
    server = _PlainServer(port)
    world = ModbusTcpClient("127.0.0.1", port=port)
    assert world.connect()
    boards = open_boards(f"modbus://127.0.0.1:{port}?map={path}", "arm", {"servo": SERVO})
    try:
        view = boards.registers("servo")
        boards.set_tick(1.0)  # a long tick: the prefetched reads are never stale here
        world.write_registers(0, [0xFFFF, 0xFFFB, 0x0001, 0x1170], device_id=5)  # -5, 70000
        n = server.received
        boards.poll(0)
        assert server.received == n + 2  # holding 0..3 and input 0: two tables, two requests
        assert (view.read("count", 0), view.read("count", 1), view.read("status")) == \
            (-5, 70000, 42)
        view.write("drive", -300, 1)
        view.write("drive", 25, 0)
        view.write("enable", 1)
        assert world.read_holding_registers(10, count=2, device_id=5).registers == [0, 0]
        n = server.received
        boards.flush(0)
        assert server.received == n + 2  # holding 10..11 in one request, coil 0 in another
        assert world.read_holding_registers(10, count=2, device_id=5).registers == \
            [25, -300 & 0xFFFF]
        assert world.read_coils(0, count=1, device_id=5).bits[0] is True
    finally:
        boards.close()
        world.close()
        server.close()


# -- board-sim --modbus in a subprocess ----------------------------------------------------


def _board_sim(*extra: str, listen: str = "127.0.0.1:0") -> tuple[_Proc, str]:
    p = _Proc(["-m", "pyrt", "board-sim", "gripper", "--modbus", listen, *extra])
    m = p.expect(r"^pyrt board-sim: gripper gripper on (modbus://127\.0\.0\.1:\d+\?map=\S+) ")
    return p, m.group(1)


@pytest.fixture
def modbus_sim() -> Iterator[tuple[_Proc, str]]:
    sim, url = _board_sim("--start", "-0100", "--watchdog", "2")
    yield sim, url
    sim.kill()


def _place(name: str) -> dict:
    """Where the shipped map puts the gripper's register ``name`` (the map alone is known)."""
    doc = tomllib.loads(Path(builtin_map("gripper")).read_text())
    return {"unit": doc.get("unit", 1), "width": 16, **doc["gripper"][name]}


def _read(client: ModbusTcpClient, name: str) -> int:
    p = _place(name)
    assert p["table"] == "input"
    words = client.read_input_registers(p["address"], count=p["width"] // 16,
                                        device_id=p["unit"]).registers
    return words[0] if p["width"] == 16 else (words[0] << 16) | words[1]


@pytest.mark.wallclock
def test_a_plain_client_reads_the_encoder_and_sensors_change_during_a_move(modbus_sim):
    """A plain pymodbus client that knows only the shipped map reads board-sim gripper --modbus
    while pyrt drives it over modbus://: the encoder counters grow during I and P-1B86 and the
    limit sensor's bit of PB changes."""
    _, url = modbus_sim
    port = int(re.search(r":(\d+)\?", url).group(1))
    tool = ModbusTcpClient("127.0.0.1", port=port)
    assert tool.connect()
    try:
        for _ in range(3):
            station = build_gripper(Loop(WallClock()), boards=url)
            out = io.StringIO()
            shell = RobotShell(station, out)
            try:
                before = {n: _read(tool, n) for n in ("up", "down", "pb")}
                station.start()
                # read where the state is known (a sampling thread could miss a short state
                # when the machine is loaded): at the limit after I, away from it after the move
                shell.onecmd("I")
                at_limit = _read(tool, "pb")
                for line in ("P-1B86", "wait"):
                    shell.onecmd(line)
                away = _read(tool, "pb")
                after = {n: _read(tool, n) for n in ("up", "down")}
                stats = station.loop.statistics()
                fault = station.fault
            finally:
                station.close()
            if not (fault is not None and stats.overruns + stats.missed > 0):
                break
            # a loop this machine starved (its ticks overran) faults its move safely: the
            # jaws are stopped and the fault said; the claim here needs a run that was not
            assert "every motor stopped" in out.getvalue(), out.getvalue()
        else:
            pytest.skip("the machine starved the real-time loop in 3 runs (each faulted safely)")
    finally:
        tool.close()
    assert "at target" in out.getvalue(), out.getvalue()
    assert after["up"] - before["up"] > 0x80  # opened to the limit
    assert after["down"] - before["down"] > 0x1800  # closed to E47A
    assert {at_limit & 0x04, away & 0x04} == {0, 0x04}, (at_limit, away)  # on, then off
    assert fault is None


def _modbus_script() -> str:
    """The 002 transcript without the simulated object (a world setting of the sim: back end)."""
    lines = SCRIPT.splitlines()
    cut = lines.index("sim object 30")
    resume = lines.index("X 33")
    end = lines.index("sim object none")
    return "\n".join([*lines[:cut], *lines[resume:end], "quit"]) + "\n"


@pytest.mark.wallclock
def test_gripper_transcript_over_modbus_against_board_sim(monkeypatch, capsys):
    """The 002 command set piped through 'pyrt gripper --boards modbus://...' at real time
    against 'pyrt board-sim gripper --modbus': the same answers as in process."""
    sim, url = _board_sim()
    try:
        monkeypatch.setattr(sys, "stdin", io.StringIO(_modbus_script()))
        # the transcript refuses some lines on purpose: -k runs it to its end, status 1
        assert main(["gripper", "--boards", url, "-k"]) == 1
        out = capsys.readouterr().out
    finally:
        sim.kill()
    text = "\n".join(line for line in out.splitlines() if not line.startswith("overrun:"))
    assert "jaws wide open (limit sensor on), encoder 0000" in text.splitlines()[1], text
    got = iter(answers(text))

    def nxt(cmd: str) -> list[str]:
        c, lines = next(got)
        assert c == cmd, (c, cmd)
        return lines

    assert nxt("W") == ["0000"]
    assert nxt("T") == ["0000"]
    assert nxt("E") == ["0080"]
    assert nxt("P-1B86") == []
    assert nxt("wait")[0].startswith("at target: position")
    assert abs(hexword(nxt("W")[0]) + 0x1B86) <= 16
    assert nxt("T") == ["E47A"]
    assert abs(int(nxt("E")[0], 16) - 0x80) <= 16
    assert nxt("P 0800")[0].startswith("error: target 0800 refused")
    assert nxt("PE47A") == []
    nxt("wait")
    assert nxt("T") == ["E47A"]
    assert nxt("p -0800") == []
    nxt("wait")
    assert abs(hexword(nxt("W")[0]) + 0x0800) <= 16
    nxt("P D800")
    nxt("wait")
    assert abs(hexword(nxt("W")[0]) - hexword("D800")) <= 16
    nxt("P0")
    nxt("wait")
    assert nxt("X 33") == [
        "speed 7F -> 33: JSPEED 33, MXPJSPD B3, MXNJSPD 4D (up to 860 counts/s)"]
    assert nxt("T") == ["0000"]
    assert nxt("M") == []
    assert nxt("D 43") == ["43 0C"]
    assert nxt("C 43 20")[0] == "43 20"
    assert nxt("N") == ["44 0A"]
    assert nxt("S") == ["SP 57"]
    assert nxt("I") == ["clock interrupt OFF (ready queue frozen)"]
    assert nxt("L FBFE") == ["2D FE"]
    assert nxt("N")[0].startswith("2E ")
    nxt("D 2E")
    assert nxt("I") == ["clock interrupt ON"]
    assert nxt("C 80 00")[0].startswith("error: address 80")
    assert nxt("Q") == []
    assert nxt("quit")[0].startswith("pyrt gripper: quit: every motor stopped; jaws at ")


@pytest.mark.wallclock
def test_killing_the_modbus_server_mid_move_trips_within_the_timeout_naming_the_url():
    """SIGKILL of board-sim --modbus during a P move: the robot trips within the timeout
    (N x M ticks), the fault names the URL, the controller's outputs are off, and the server
    started again on the same port holds its outputs off."""
    sim, url = _board_sim("--start", "-0100", "--watchdog", "2")
    port = int(re.search(r":(\d+)\?", url).group(1))
    station = build_gripper(Loop(WallClock()), boards=url)
    station.close_report = lambda line: None
    shell = RobotShell(station, io.StringIO())
    ctl = station.controller
    again = None
    try:
        station.start()
        shell.onecmd("P-1B86")
        deadline = time.monotonic() + 30  # a bound for a hang only
        while not (ctl.moving and ctl.dac != DAC_NULL):
            assert time.monotonic() < deadline
            time.sleep(0.01)
        backend = station.boards.registers("gripper").client
        timeout_ticks = round(backend.timeout_s * 1e9 / station.loop.period_ns)
        sim.proc.kill()
        sim.proc.wait(10)
        killed_at = station.loop.tick_index
        deadline = time.monotonic() + 30  # a bound for a hang only
        while station.fault is None:
            assert time.monotonic() < deadline, "no fault"
            time.sleep(0.01)
        fault = station.fault
        assert fault.tick - killed_at <= timeout_ticks, (fault.tick, killed_at, timeout_ticks)
        assert fault.cause.startswith(f"board {url}: ")
        assert ctl.dac == DAC_NULL and not ctl.moving and ctl.job is None
        again, _ = _board_sim(listen=f"127.0.0.1:{port}")
        tool = ModbusTcpClient("127.0.0.1", port=port)
        assert tool.connect()
        dac = _place("dac")
        assert tool.read_holding_registers(dac["address"], count=1,
                                           device_id=dac["unit"]).registers == [DAC_NULL]
        tool.close()
    finally:
        station.close()
        sim.kill()
        if again is not None:
            again.kill()
