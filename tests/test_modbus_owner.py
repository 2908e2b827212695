"""One board, one controller on modbus://: a second connection that writes is refused with
exception 06 and changes nothing (reads stay open), and a map may name the outputs' owner.
The server is driven in process (its request handler, two connections, a clock of its own),
deterministically; test_doors_modbus has the same over sockets."""

from __future__ import annotations

import socket
import struct
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pyrt.boards.modbus import builtin_map
from pyrt.boards.modbusmap import parse_map
from pyrt.errors import ConfigError
from pyrt.sim.boardsim import Connection
from pyrt.sim.modbusserver import SERVER_BUSY, ModbusBoardServer
from pyrt.sim.world import GRIPPER_BOARDS, GripperWorld

UNIT = 1
#: The shipped gripper map: holding 0..3 are cmd, led_lo, led_hi, dac.
HOLDING = ("cmd", "led_lo", "led_hi", "dac")
GRIPPER_MAP = Path(builtin_map("gripper")).read_text(encoding="utf-8")


class _Clock:
    def __init__(self) -> None:
        self.ns = 0

    def __call__(self) -> int:
        return self.ns


def _server(owner: str | None = None):
    text = GRIPPER_MAP if owner is None else f"owner = {owner}\n" + GRIPPER_MAP
    clock = _Clock()
    world = GripperWorld(start=-0x100)
    lines: list[str] = []
    server = ModbusBoardServer(world, parse_map(text, GRIPPER_BOARDS, "gripper.toml"),
                               watchdog_s=0.5, clock=clock, say=lines.append)
    _SERVERS.append(server)
    return server, world, clock, lines


_SOCKETS: list[socket.socket] = []
_SERVERS: list[ModbusBoardServer] = []


def _conn(addr: str) -> Connection:
    """A connection as the server holds it (a socket it may close; nothing is sent on it)."""
    a, b = socket.socketpair()
    _SOCKETS.extend((a, b))
    return Connection(a, addr, 0)


@pytest.fixture(autouse=True)
def _close_sockets_and_servers():
    yield
    while _SOCKETS:
        _SOCKETS.pop().close()
    while _SERVERS:
        _SERVERS.pop().close()


def _outputs(world: GripperWorld) -> list[int]:
    regs = world.registers("gripper")
    return [regs.read(name) for name in HOLDING]


def _write_single(address: int, value: int) -> bytes:
    return struct.pack(">BHH", 6, address, value)


# the writing functions: 6 (one register), 16 (several), 23 (read/write); 5 and 15 have
# no coil to write in this map (02), which changes nothing either
def _writes():
    return st.one_of(
        st.builds(lambda a, v: _write_single(a, v), st.integers(0, 3), st.integers(0, 0xFF)),
        st.builds(lambda a, vs: struct.pack(">BHHB", 16, a, len(vs), 2 * len(vs))
                  + struct.pack(f">{len(vs)}H", *vs),
                  st.integers(0, 1), st.lists(st.integers(0, 0xFF), min_size=1, max_size=3)),
        st.builds(lambda v: struct.pack(">BHHHHB", 23, 0, 4, 3, 1, 2) + struct.pack(">H", v),
                  st.integers(0, 0xFF)),
    )


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(first=st.integers(0x81, 0xFF), pdus=st.lists(_writes(), min_size=1, max_size=6))
def test_a_second_writer_gets_exception_06_and_changes_nothing_while_reads_are_answered(
        first, pdus):
    """The first connection that writes owns the outputs; every write of a second connection (functions 6, 16, 23, any place, any value) is answered with exception 06 and leaves every output as it was; the second's reads are answered, and the owner's next write is taken."""
    server, world, clock, lines = _server()
    owner, other = _conn("127.0.0.1:5000"), _conn("127.0.0.1:5001")
    assert server.answer(owner, UNIT, _write_single(3, first)) == _write_single(3, first)
    assert server.owner == "127.0.0.1:5000"
    before = _outputs(world)
    for pdu in pdus:
        clock.ns += 1_000_000
        reply = server.answer(other, UNIT, pdu)
        assert reply == bytes([pdu[0] | 0x80, SERVER_BUSY]), (pdu, reply)
        assert _outputs(world) == before
        server.answer(owner, UNIT, struct.pack(">BHH", 4, 0, 7))  # the owner keeps polling
    read = server.answer(other, UNIT, struct.pack(">BHH", 3, 0, 4))
    assert read[:2] == bytes([3, 8]) and list(struct.unpack(">4H", read[2:])) == before
    assert server.answer(owner, UNIT, _write_single(3, 0x90)) == _write_single(3, 0x90)
    assert _outputs(world)[3] == 0x90
    assert server.refused == len(pdus)
    assert any("refused 127.0.0.1:5001" in line for line in lines)


def test_a_silent_owner_is_displaced_by_the_next_writer_after_the_watchdog():
    """The owner falls silent beyond the watchdog (its outputs are off): the next connection that writes owns the outputs and the old owner's connection is closed; before that, its write is refused."""
    server, world, clock, _lines = _server()
    a, b = _conn("127.0.0.1:6000"), _conn("127.0.0.1:6001")
    server.answer(a, UNIT, _write_single(3, 0x90))
    clock.ns += 400_000_000
    assert server.answer(b, UNIT, _write_single(3, 0x10))[0] == 0x86
    clock.ns += 200_000_000  # 0.6 s since a's last access: beyond the 0.5 s watchdog
    assert server.answer(b, UNIT, _write_single(3, 0x10)) == _write_single(3, 0x10)
    assert server.owner == "127.0.0.1:6001" and a.gone  # the silent owner's link closed
    assert _outputs(world)[3] == 0x10


def test_a_map_that_names_its_owner_refuses_writes_from_anywhere_else():
    """owner = "127.0.0.1" in the map: a connection from 127.0.0.2 is refused (06, nothing changed) even while nobody owns the outputs, and may read; one from 127.0.0.1 owns them; a list and localhost are accepted."""
    server, world, _clock, lines = _server('"127.0.0.1"')
    stranger, controller = _conn("127.0.0.2:7000"), _conn("127.0.0.1:7001")
    before = _outputs(world)
    assert server.answer(stranger, UNIT, _write_single(3, 0x90)) == bytes([0x86, SERVER_BUSY])
    assert _outputs(world) == before and server.owner is None
    assert server.answer(stranger, UNIT, struct.pack(">BHH", 3, 0, 4))[0] == 3
    assert server.answer(controller, UNIT, _write_single(3, 0x90)) == _write_single(3, 0x90)
    assert server.owner == "127.0.0.1:7001" and _outputs(world)[3] == 0x90
    assert any("the map names 127.0.0.1" in line for line in lines)
    for text, host, ok in (('["10.0.0.5", "127.0.0.1"]', "127.0.0.1", True),
                           ('"localhost"', "::1", True), ('"10.0.0.5"', "127.0.0.1", False)):
        regmap = parse_map(f"owner = {text}\n" + GRIPPER_MAP, GRIPPER_BOARDS)
        assert regmap.may_own(host) is ok
    assert parse_map(GRIPPER_MAP, GRIPPER_BOARDS).may_own("192.0.2.1")


@pytest.mark.parametrize("text", ['"controller.lab"', "5", '["127.0.0.1", 7]'])
def test_a_bad_owner_is_refused_with_its_line(text):
    """An owner that is not an IP address (or localhost), or a list of them: ConfigError naming the map's line."""
    with pytest.raises(ConfigError, match=r"gripper\.toml:2: owner"):
        parse_map(f"unit = 1\nowner = {text}\n" + GRIPPER_MAP.replace("unit = 1\n", ""),
                  GRIPPER_BOARDS, "gripper.toml")
