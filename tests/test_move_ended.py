"""The end of a move is one event: wait takes it in one mailbox call, and the console,
a subscribed DAQ client and EPICS each report it exactly once (a move that reaches
its target, one that is stopped, one that faults; on each station)."""

from __future__ import annotations

import io
import socket
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import pytest

from pyrt.client import Client
from pyrt.commands import RobotShell
from pyrt.db import copy_station
from pyrt.scheduler import Loop, SimClock
from pyrt.server import ServedStation, Server
from pyrt.station.gripper import build_gripper
from pyrt.station.manipulator import ManipulatorStation

PREFIX = "MOVE:"
TOKEN = "move-token"


def _free_port() -> int:
    """A port free for both UDP and TCP on 127.0.0.1."""
    for _ in range(50):
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as u:
            u.bind(("127.0.0.1", 0))
            port = u.getsockname()[1]
            with socket.socket() as t:
                try:
                    t.bind(("127.0.0.1", port))
                except OSError:
                    continue
            return port
    raise RuntimeError("no free port")


@pytest.fixture
def epics_env(monkeypatch):
    """EPICS confined to loopback and ports of this test."""
    pytest.importorskip("caproto")
    port, repeater = _free_port(), _free_port()
    for name, value in {
        "EPICS_CA_ADDR_LIST": "127.0.0.1", "EPICS_CA_AUTO_ADDR_LIST": "NO",
        "EPICS_CAS_INTF_ADDR_LIST": "127.0.0.1", "EPICS_CAS_AUTO_BEACON_ADDR_LIST": "NO",
        "EPICS_CAS_BEACON_ADDR_LIST": "127.0.0.1", "EPICS_CA_SERVER_PORT": str(port),
        "EPICS_CAS_SERVER_PORT": str(port), "EPICS_CA_REPEATER_PORT": str(repeater),
        "EPICS_CAS_BEACON_PORT": str(repeater),
    }.items():
        monkeypatch.setenv(name, value)


@dataclass(frozen=True)
class Case:
    """A station, the line that moves it, and what it runs first."""

    name: str
    build: Callable[[Any], Any]
    move: str
    first: tuple[str, ...] = ()


def _gripper(_tmp: Any) -> Any:
    return build_gripper(Loop(SimClock()))


def _manipulator(tmp: Any) -> Any:
    return ManipulatorStation(copy_station("prototype", tmp / "prototype"), tick_ns=5_000_000)


def _arm(_tmp: Any) -> Any:
    arm = pytest.importorskip("pyrt_arm.station")
    return arm.build_arm(Loop(SimClock()))


CASES = [
    Case("gripper", _gripper, "P-1B86", ("I", "wait")),
    Case("manipulator", _manipulator, "prototype to 10 0 100"),
    Case("arm", _arm, "arm to 45 30"),
]
#: How each move ends: at its target, stopped by the operator, by a fault.
ENDINGS = ["target", "stopped", "fault"]


@contextmanager
def _served(case: Case, tmp: Any) -> Iterator[tuple[Any, Server, Any]]:
    from pyrt.server.epics import EpicsService

    station = case.build(tmp)
    runner = station.runner
    robot = ServedStation(station)
    server = Server(runner, robot, "127.0.0.1", 0, token=TOKEN)
    runner.start()
    server.start()
    ioc = EpicsService(runner, robot, server, PREFIX, token=TOKEN, interfaces=["127.0.0.1"],
                       period_s=0.02, stats_period_s=3600.0)
    ioc.start()
    try:
        runner.poll()
        yield station, server, ioc
    finally:
        ioc.close()
        server.close()
        station.close()


def _after(station: Any, seconds: float, act: Callable[[], Any]) -> None:
    """Run ``act`` once in the loop, ``seconds`` of loop time from now (mid-move)."""
    loop = station.loop
    at = loop.now_ns + int(seconds * 1e9)

    def job() -> Iterator[None]:
        while loop.now_ns < at:
            yield
        act()

    station.runner.spawn("test-act", job())


def _text(value: Any) -> str:
    return value.decode() if isinstance(value, bytes) else str(value)


def _poll(what: str, ok: Callable[[], bool], bound_s: float = 20.0) -> None:
    deadline = time.monotonic() + bound_s
    while not ok():
        assert time.monotonic() < deadline, f"{what} within {bound_s:g} s"
        time.sleep(0.01)


@pytest.mark.parametrize("ending", ENDINGS)
@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_the_end_of_a_move_is_reported_once_on_every_door(case, ending, tmp_path, epics_env):
    """wait costs one mailbox call; the console, a subscribed DAQ client and EPICS each report the end once."""
    with _served(case, tmp_path) as (station, server, ioc):
        runner = station.runner
        out = io.StringIO()
        shell = RobotShell(station, out)
        for line in case.first:
            shell.onecmd(line)
        shell.messages()
        # EPICS: every write of STOP_REASON from here on (the first's written already)
        pv = ioc.pvdb[PREFIX + "STOP_REASON"]
        if station.last_move is not None:
            reason = station.last_move.reason
            _poll("the first move's STOP_REASON", lambda: _text(pv.value) == reason)
        written: list[Any] = []
        plain_write = pv.write

        async def counting(value: Any, *a: Any, **kw: Any) -> Any:
            written.append(value)
            return await plain_write(value, *a, **kw)

        pv.write = counting
        sub = Client(*server.address, timeout_s=10.0)
        sub.command("SUBSCRIBE 2")
        seen = station.last_move.seq if station.last_move is not None else 0
        out.seek(0)
        out.truncate()

        shell.onecmd(case.move)
        if ending == "stopped":
            _after(station, 0.3, station.stop)
        elif ending == "fault":
            _after(station, 0.3, lambda: station.root.fail("injected fault", "test"))
        requests: list[str] = []
        runner.request_tap = lambda name, *_a: requests.append(name)
        shell.onecmd("wait")
        runner.request_tap = None
        # one mailbox call (EPICS's own reads of the loop's statistics aside)
        assert [name for name in requests if name != "stats"] == ["wait"]

        runner.sleep(0.05)  # the ticks after: whatever else is said comes too
        for line in shell.messages():
            out.write(line + "\n")
        text = out.getvalue()
        event = station.last_move
        assert event is not None and event.seq == seen + 1  # one event for one move
        if ending == "fault":
            assert event.fault_id == station.fault.id
            assert text.count("injected fault") == 1  # the fault said once, by the wait
            assert not any(line in text for line in event.report)
        else:
            assert event.fault_id == 0
            for line in event.report:
                assert text.count(line) == 1, (line, text)
            if ending == "target":
                assert "target" in event.reason or "ENDPOINT" in event.reason
            else:
                assert "stop" in event.reason.lower() or "brak" in event.reason.lower()

        # EPICS: STOP_REASON written once, with the event's reason; and not again
        # after the IOC has served later snapshots
        _poll("STOP_REASON written", lambda: len(written) >= 1)
        runner.sleep(0.2)
        t_now = runner.loop.now_ns / 1e9
        _poll("EPICS serving later ticks",
              lambda: ioc.pvdb[PREFIX + "T"].value >= t_now - 1e-9)
        assert len(written) == 1 and _text(written[0]) == event.reason

        # DAQ: one STATUS STOP line for the move, among the samples
        stops: list[str] = []
        for status in sub.statuses(1.0):
            if status.stop is not None:
                stops.append(status.stop)
        assert stops == [event.reason]
        sub.close()
