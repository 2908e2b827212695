"""A served gripper on 127.0.0.1 (ephemeral port), shared by the server tests."""

from __future__ import annotations

import socket
import time
from contextlib import contextmanager
from dataclasses import dataclass

from _gripper_rig import Rig, make_rig

from pyrt.boards.gripper import DAC_NULL
from pyrt.client import Client
from pyrt.scheduler import Loop, WallClock
from pyrt.scheduler.runner import Runner
from pyrt.server import GripperService, Server

TOKEN = "s3cret-token"


@dataclass
class Served:
    rig: Rig
    runner: Runner
    server: Server
    host: str
    port: int

    def client(self, timeout_s: float = 10.0) -> Client:
        return Client(self.host, self.port, timeout_s=timeout_s)

    def operator(self) -> Client:
        c = self.client()
        c.auth(TOKEN)
        return c

    def raw(self) -> socket.socket:
        """A bare socket, the greeting already read."""
        s = socket.create_connection((self.host, self.port), timeout=10)
        assert read_lines(s, 1)[0].startswith("OK pyrt")
        return s

    def still_and_null(self) -> bool:
        """No motor moving: drive bit clear and the DAC at null."""
        ctl = self.rig.ctl
        return self.runner.call(lambda: not ctl.moving and self.rig.board.dac == DAC_NULL)


def read_lines(sock: socket.socket, n: int, timeout_s: float = 10.0) -> list[str]:
    """Read ``n`` lines (or fewer, up to end of stream)."""
    sock.settimeout(timeout_s)
    buf = b""
    while buf.count(b"\n") < n:
        data = sock.recv(65536)
        if not data:
            break
        buf += data
    return buf.decode().splitlines()


def read_until_closed(sock: socket.socket, timeout_s: float = 10.0) -> str:
    """Everything until the server closes the connection."""
    sock.settimeout(timeout_s)
    buf = b""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            data = sock.recv(65536)
        except ConnectionResetError:
            break
        if not data:
            break
        buf += data
    return buf.decode(errors="replace")


@contextmanager
def served(token: str | None = TOKEN, wall: bool = False, **server_kw):
    """A gripper (SimClock unless ``wall``) served on an ephemeral loopback port."""
    rig = _wall_rig() if wall else make_rig()
    runner = Runner(rig.loop)
    server = Server(runner, GripperService(rig.ctl, rig.plant), "127.0.0.1", 0, token=token,
                    **server_kw)
    runner.start()
    host, port = server.start()
    try:
        runner.poll()  # a first tick: the status snapshot exists
        yield Served(rig, runner, server, host, port)
    finally:
        server.close()
        runner.stop()


def _wall_rig() -> Rig:
    from _gripper_rig import StallMonitor

    from pyrt.boards.gripper import SimGripperBoard
    from pyrt.boards.i8031 import I8031
    from pyrt.robots.gripper import GripperController
    from pyrt.sim.gripper import JawPlant

    cpu = I8031()
    board = SimGripperBoard(cpu)
    plant = JawPlant(board)
    ctl = GripperController(cpu)
    loop = Loop(WallClock())
    loop.attach(plant.step, name="jaws")
    ctl.attach(loop)
    stall = StallMonitor(board, plant)
    loop.attach(stall, name="stall monitor")
    ctl.power_up()
    return Rig(cpu, board, plant, ctl, loop, stall)
