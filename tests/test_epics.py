"""EPICS Channel Access (``--epics``): status PVs and the command PV, read with caproto's client.

Everything on 127.0.0.1 with ports of this test's own (EPICS_CA_SERVER_PORT
and the repeater port chosen free), so nothing else on the network is found
or disturbed.
"""

from __future__ import annotations

import socket
import sys
import time
from contextlib import contextmanager

import pytest
from _server_rig import TOKEN, served

from pyrt.errors import ConfigError
from pyrt.server import ServedStation

PREFIX = "PYRTTEST:"


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
    """EPICS environment confined to loopback and ports of this test."""
    pytest.importorskip("caproto")
    port, repeater = _free_port(), _free_port()
    for name, value in {
        "EPICS_CA_ADDR_LIST": "127.0.0.1",
        "EPICS_CA_AUTO_ADDR_LIST": "NO",
        "EPICS_CAS_INTF_ADDR_LIST": "127.0.0.1",
        "EPICS_CAS_AUTO_BEACON_ADDR_LIST": "NO",
        "EPICS_CAS_BEACON_ADDR_LIST": "127.0.0.1",
        "EPICS_CA_SERVER_PORT": str(port),
        "EPICS_CAS_SERVER_PORT": str(port),
        "EPICS_CA_REPEATER_PORT": str(repeater),
    }.items():
        monkeypatch.setenv(name, value)
    return port


@contextmanager
def epics_served(token: str | None = TOKEN):
    from pyrt.server.epics import EpicsService

    with served(token=token) as sv:
        robot = ServedStation(sv.rig)
        ioc = EpicsService(sv.runner, robot, sv.server, PREFIX, token=token,
                           interfaces=["127.0.0.1"], period_s=0.02, stats_period_s=0.2)
        ioc.start()
        try:
            yield sv, ioc
        finally:
            ioc.close()


def _read(name: str, timeout: float = 2.0):
    from caproto.sync.client import read

    return read(PREFIX + name, timeout=timeout, repeater=False).data


def _text(name: str) -> str:
    from caproto import ChannelType
    from caproto.sync.client import read

    data = read(PREFIX + name, data_type=ChannelType.CHAR, timeout=2.0, repeater=False).data
    return bytes(data).rstrip(b"\0").decode()


def _string(name: str) -> str:
    return _read(name)[0].decode()


def _write(name: str, value: str) -> None:
    from caproto.sync.client import write

    write(PREFIX + name, value, notify=True, timeout=5.0, repeater=False)


def _until(fn, timeout_s: float = 5.0):
    deadline = time.monotonic() + timeout_s
    while True:
        value = fn()
        if value or time.monotonic() > deadline:
            return value
        time.sleep(0.05)


def test_status_pvs_follow_the_robot(epics_env):
    """POSITION, MOVING, FAULT, T and the tick statistics read through caproto follow a move commanded over TCP."""
    with epics_served() as (sv, ioc):
        assert ioc.summary.startswith(f"{len(ioc.pvdb)} PVs")
        assert _read("POSITION")[0] == 0 and _read("FAULT")[0] == b"no"  # FAULT: enum no/yes
        op = sv.operator()
        op.command("I")
        op.command("P E47A")
        op.command("wait")
        assert _until(lambda: abs(_read("POSITION")[0] + 0x1B86) <= 16)
        assert _read("MOVING")[0] == b"no"
        assert _read("TARGET")[0] == -0x1B86
        assert _read("T")[0] > 1.0
        assert _until(lambda: _read("TICKS")[0] > 1000)
        assert _read("OVERRUNS")[0] == 0


def test_command_pv_needs_the_token_in_the_written_value(epics_env):
    """Writing 'TOKEN COMMAND' to CMD runs it and fills REPLY/RESULT; a wrong token runs nothing; CMD never shows the token."""
    with epics_served() as (sv, _ioc):
        _write("CMD", f"{TOKEN} X 33")
        assert _string("RESULT").startswith("OK speed 7F -> 33")
        _write("CMD", f"{TOKEN} T")
        assert _text("REPLY") == "OK 0000\n"
        assert TOKEN not in _text("CMD")
        _write("CMD", "wrong P E47A")
        assert _string("RESULT").startswith("ERR auth")
        _write("CMD", f"{TOKEN} W 1")
        assert _string("RESULT").startswith("ERR command")
        sv.runner.sleep(0.5)
        assert sv.runner.call(sv.ctl.target) == 0  # the wrong token's P never ran
        assert sv.still_and_null()


def test_no_command_pv_without_a_token(epics_env):
    """Without a token only status PVs exist: CMD is not served."""
    with epics_served(token=None) as (_sv, ioc):
        assert f"{PREFIX}CMD" not in ioc.pvdb and "status only" in ioc.summary
        assert _read("FAULT")[0] == b"no"
        with pytest.raises(Exception, match=r"(?i)time"):
            _read("CMD", timeout=0.5)


def test_a_clear_message_when_caproto_is_missing(monkeypatch):
    """--epics without caproto installed is a ConfigError naming the extra."""
    from pyrt.server import epics

    monkeypatch.setitem(sys.modules, "caproto", None)
    assert not epics.caproto_available()
    with served() as sv, pytest.raises(ConfigError, match=r"pyrt\[epics\]"):
        epics.EpicsService(sv.runner, ServedStation(sv.rig), sv.server, PREFIX)


def test_status_pvs_carry_the_signals_units_and_booleans_are_enums(epics_env):
    """Each status PV is made from its signal record: counts as EGU of POSITION, MOVING and FAULT enum PVs with states no/yes."""
    from caproto import ChannelType
    from caproto.sync.client import read

    with epics_served(token=None) as (sv, ioc):
        pos = read(PREFIX + "POSITION", data_type=ChannelType.CTRL_LONG, timeout=2.0,
                   repeater=False)
        assert pos.metadata.units == b"counts"
        for name in ("MOVING", "FAULT", "BUSY"):
            ctrl = read(PREFIX + name, data_type=ChannelType.CTRL_ENUM, timeout=2.0,
                        repeater=False)
            assert list(ctrl.metadata.enum_strings) == [b"no", b"yes"], name
        units = {name.upper(): sig.units for name, sig, _fmt in ServedStation(sv.rig).fields}
        assert {k for k in ioc.pvdb if k.startswith(PREFIX)} >= {PREFIX + k for k in units}
        sv.runner.call(sv.rig.trip, "epics test trip", "test")
        assert _until(lambda: _read("FAULT")[0] == b"yes")
