"""A served gripper on 127.0.0.1 (ephemeral port), shared by the server tests."""

from __future__ import annotations

import socket
import time
from contextlib import contextmanager
from dataclasses import dataclass

from pyrt.boards.gripper import DAC_NULL
from pyrt.client import Client
from pyrt.scheduler import Loop, SimClock, WallClock
from pyrt.scheduler.runner import Runner
from pyrt.server import ServedStation, Server
from pyrt.station.gripper import GripperStation, build_gripper

TOKEN = "s3cret-token-of-the-rig"


@dataclass
class Served:
    rig: GripperStation
    runner: Runner
    server: Server
    host: str
    port: int

    @property
    def ctl(self):
        return self.rig.controller

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
        ctl = self.ctl
        return self.runner.call(lambda: not ctl.moving and self.rig.board.dac == DAC_NULL,
                                take_fault=False)


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


def read_only_lines(station, shell) -> list[str]:
    """A line for every read-only command record that needs no argument and
    that the console resolves at its top level (derived from the records)."""
    from pyrt.errors import CommandError

    lines = []
    for comp, rec in [(None, w) for w in shell.words()] + station.all_commands():
        if not rec.reads_only or any(not a.optional for a in rec.args):
            continue
        if rec.name == "clear":  # clears the terminal: it has no value to return
            continue
        line = rec.name if comp is None or comp is shell.level else f"{comp.name} {rec.name}"
        try:
            if shell.resolve(line)[1] == rec:
                lines.append(line)
        except CommandError:  # a level the console is not at (the monitor's letters)
            continue
    return lines


@contextmanager
def served(token: str | None = TOKEN, wall: bool = False, speed: float = 1.0, **server_kw):
    """The gripper station (SimClock unless ``wall``; the wall clock at ``speed``) served on an
    ephemeral loopback port."""
    station = build_gripper(Loop(WallClock(speed) if wall else SimClock()))
    runner = station.runner
    server = Server(runner, ServedStation(station), "127.0.0.1", 0, token=token,
                    **server_kw)
    runner.start()
    host, port = server.start()
    try:
        runner.poll()  # a first tick: the status snapshot exists
        yield Served(station, runner, server, host, port)
    finally:
        server.close()
        station.shutdown()


# -- load: clients in processes of their own (the server's GIL stays the server's) ----------

# The clients stand for a DAQ on another computer: they run at the lowest
# priority, so that on a shared two-core machine what the loop feels is the
# server's work, not the load generator's.
_LOAD = r'''
import json, os, selectors, socket, sys, time
os.nice(19)
host, port, n, seconds = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4])
line = sys.argv[5].encode() + b"\n"
at_least, hang = int(sys.argv[6]), float(sys.argv[7])
sel = selectors.DefaultSelector()
for _ in range(n):
    s = socket.create_connection((host, port))
    s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    greeting = b""
    while not greeting.endswith(b"\n"):
        greeting += s.recv(4096)
    s.setblocking(False)
    sel.register(s, selectors.EVENT_READ, [b""])
sys.stdout.write("ready\n"); sys.stdout.flush()
sys.stdin.readline()
start = time.perf_counter()
end = start + seconds
give_up = end + hang
for key in list(sel.get_map().values()):
    key.fileobj.send(line)
count = errors = 0
while sel.get_map() and (time.perf_counter() < end
                         or (count < at_least and time.perf_counter() < give_up)):
    for key, _ in sel.select(0.05):
        s, st = key.fileobj, key.data
        try:
            data = s.recv(65536)
        except BlockingIOError:
            continue
        if not data:
            errors += 1
            sel.unregister(s)
            continue
        buf = st[0] + data
        cut = buf.rfind(b"\n") + 1
        lines = buf[:cut].split(b"\n")[:-1]
        st[0] = buf[cut:]
        count += len(lines)
        errors += sum(1 for x in lines if not x.startswith(b"OK"))
        if lines:
            s.send(line * len(lines))
print(json.dumps({"requests": count, "seconds": time.perf_counter() - start,
                  "errors": errors}))
'''


#: How long past its ``seconds`` a load with ``at_least`` keeps on for its replies:
#: only a hang takes this long, however loaded the machine is.
LOAD_HANG_S = 60.0


def run_load(host: str, port: int, clients: int, seconds: float, line: str = "STATUS",
             procs: int = 2, during=None, at_least: int = 0) -> dict:
    """``clients`` connections (spread over ``procs`` processes), each with one
    request in flight for ``seconds``, and on until each process has had
    ``at_least`` replies (a count that does not depend on the machine's speed;
    bounded by :data:`LOAD_HANG_S`); ``during()`` runs while they do.
    Returns requests, requests per second and errors."""
    import json
    import os
    import subprocess
    import sys

    per = [clients // procs + (1 if i < clients % procs else 0) for i in range(procs)]
    children = [
        subprocess.Popen([sys.executable, "-c", _LOAD, host, str(port), str(n), str(seconds),
                          line, str(at_least), str(LOAD_HANG_S)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                         preexec_fn=lambda: os.nice(19))  # nice from the interpreter's start
        for n in per if n
    ]
    try:
        for child in children:
            assert child.stdout.readline().strip() == "ready"
        for child in children:
            child.stdin.write("go\n")
            child.stdin.flush()
        result = during() if during is not None else None
        outs = [json.loads(child.communicate(timeout=seconds + LOAD_HANG_S + 30)[0]) for child in children]
    finally:
        for child in children:
            if child.poll() is None:
                child.kill()
    total = sum(o["requests"] for o in outs)
    secs = max(o["seconds"] for o in outs)
    return {"requests": total, "per_s": total / secs, "errors": sum(o["errors"] for o in outs),
            "during": result}
