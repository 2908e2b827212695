"""EPICS Channel Access (``--epics``): status PVs and the command PV, read with caproto's client.

Everything on 127.0.0.1 with ports of this test's own (EPICS_CA_SERVER_PORT
and the repeater port chosen free), so nothing else on the network is found
or disturbed.
"""

from __future__ import annotations

import re
import socket
import sys
import time
from contextlib import contextmanager

import pytest
from _server_rig import TOKEN, served

from pyrt.db import copy_station
from pyrt.errors import ConfigError
from pyrt.server import ServedStation, Server
from pyrt.station.manipulator import ManipulatorStation

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
        "EPICS_CAS_BEACON_PORT": str(repeater),
    }.items():
        monkeypatch.setenv(name, value)
    return port


@contextmanager
def epics_served(token: str | None = TOKEN):
    from pyrt.server.epics import EpicsService

    with served(token=token) as sv:
        ioc = EpicsService(sv.runner, sv.server.robot, sv.server, PREFIX, token=token,
                           interfaces=["127.0.0.1"], period_s=0.02, stats_period_s=0.2)
        ioc.start()
        try:
            yield sv, ioc
        finally:
            ioc.close()


@contextmanager
def epics_manipulator(tmp_path, token: str | None = TOKEN):
    """The prototype manipulator (SimClock, 5 ms tick) served over TCP and EPICS."""
    from pyrt.server.epics import EpicsService

    station = ManipulatorStation(copy_station("prototype", tmp_path / "prototype"),
                                 tick_ns=5_000_000)
    runner = station.runner
    robot = ServedStation(station)
    server = Server(runner, robot, token=token)
    runner.start()
    server.start()
    ioc = EpicsService(runner, robot, server, PREFIX, token=token, interfaces=["127.0.0.1"],
                       period_s=0.02, stats_period_s=0.2)
    ioc.start()
    runner.sleep(0.2)
    try:
        yield station, runner, ioc
    finally:
        ioc.close()
        server.close()
        runner.stop()
        station.close()


def _ca_read(name: str, **kw):
    """caproto's sync read, again on a stray UDP packet (another test's IOC or beacon on
    the loopback answering the search: RemoteProtocolError), at most three times."""
    from caproto import RemoteProtocolError
    from caproto.sync.client import read

    for attempt in range(3):
        try:
            return read(PREFIX + name, repeater=False, **kw)
        except RemoteProtocolError:
            if attempt == 2:
                raise
    raise AssertionError("unreachable")


def _meta(name: str, data_type):
    return _ca_read(name, data_type=data_type, timeout=2.0)


def _read(name: str, timeout: float = 2.0):
    return _ca_read(name, timeout=timeout).data


def _text(name: str) -> str:
    from caproto import ChannelType

    data = _ca_read(name, data_type=ChannelType.CHAR, timeout=2.0).data
    return bytes(data).rstrip(b"\0").decode()


def _string(name: str) -> str:
    return _read(name)[0].decode()


def _alarm(name: str):
    """``(status, severity)`` of a PV as the IOC computed them."""
    from caproto import ChannelType

    meta = _meta(name, ChannelType.STS_DOUBLE).metadata
    return meta.status, meta.severity


def _write(name: str, value: str) -> None:
    from caproto.sync.client import write

    write(PREFIX + name, value, notify=True, timeout=5.0, repeater=False)


def _until(fn, timeout_s: float = 30.0):
    """Poll ``fn`` until it is true; the bound catches a hang only (a loaded machine)."""
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
        # the IOC reads the robot every 0.02 s: a read of POSITION near the end may
        # come from a snapshot taken just before the move ended
        assert _until(lambda: _read("MOVING")[0] == b"no")
        assert _read("TARGET")[0] == -0x1B86
        assert _read("T")[0] > 1.0
        assert _until(lambda: _read("TICKS")[0] > 1000)
        assert _read("OVERRUNS")[0] == 0


def test_command_pv_needs_the_token_in_the_written_value(epics_env):
    """Writing 'TOKEN COMMAND' to CMD runs it and fills REPLY/RESULT; a wrong token runs nothing; CMD never shows the token."""
    with epics_served() as (sv, _ioc):
        _write("CMD", f"{TOKEN} X 33")
        assert _text("RESULT").startswith("OK speed 7F -> 33")
        _write("CMD", f"{TOKEN} T")
        assert _text("REPLY") == "OK 0000\n"
        assert TOKEN not in _text("CMD")
        _write("CMD", "wrong P E47A")
        assert _text("RESULT").startswith("ERR auth")
        _write("CMD", f"{TOKEN} W 1")
        assert _text("RESULT").startswith("ERR command")
        assert _text("RESULT") == _text("REPLY").splitlines()[-1]  # whole, not cut at 39
        assert len(_text("RESULT")) > 39
        sv.runner.sleep(0.5)
        assert sv.runner.call(sv.ctl.target) == 0  # the wrong token's P never ran
        assert sv.still_and_null()


def test_setpoint_pvs_set_parameters_with_the_token_rule(epics_env):
    """OBJECT:PARAM_SP takes 'TOKEN VALUE' and runs set OBJECT.PARAM VALUE (range checked,
    audited); a wrong token or a value out of range changes nothing."""
    with epics_served() as (sv, _ioc):
        assert f"{PREFIX}GRIPPER:SPEED_SP" in _ioc.pvdb
        _write("GRIPPER:SPEED_SP", f"{TOKEN} 33")
        assert _text("RESULT").startswith("OK"), _text("REPLY")
        assert sv.runner.call(lambda: sv.rig.controller.ram[0x51]) == 0x33
        _write("GRIPPER:SPEED_SP", f"{TOKEN} 99")
        assert _text("RESULT").startswith("ERR") and "01..7F" in _text("REPLY")
        _write("GRIPPER:SPEED_SP", "wrong 40")
        assert _text("RESULT").startswith("ERR auth")
        assert sv.runner.call(lambda: sv.rig.controller.ram[0x51]) == 0x33
        assert TOKEN not in _text("GRIPPER:SPEED_SP")
        assert any("set gripper.speed 33" in ln for ln in [str(m) for m in sv.runner.messages()])


def test_no_command_pv_without_a_token(epics_env):
    """Without a token there is no CMD or ACK (nobody is privileged); STOP is served all the same."""
    with epics_served(token=None) as (_sv, ioc):
        assert f"{PREFIX}CMD" not in ioc.pvdb and f"{PREFIX}ACK" not in ioc.pvdb
        assert not any(name.endswith("_SP") for name in ioc.pvdb)
        assert "no token" in ioc.summary and f"{PREFIX}STOP" in ioc.pvdb
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

    with epics_served(token=None) as (sv, ioc):
        pos = _meta("POSITION", ChannelType.CTRL_LONG)
        assert pos.metadata.units == b"counts"
        for name in ("MOVING", "FAULT", "BUSY"):
            ctrl = _meta(name, ChannelType.CTRL_ENUM)
            assert list(ctrl.metadata.enum_strings) == [b"no", b"yes"], name
        units = {name.upper(): sig.units for name, sig, _fmt in ServedStation(sv.rig).fields}
        assert {k for k in ioc.pvdb if k.startswith(PREFIX)} >= {PREFIX + k for k in units}
        sv.runner.call(sv.rig.trip, "epics test trip", "test")
        assert _until(lambda: _read("FAULT")[0] == b"yes")


# -- an IOC made from the records ---------------------------------------------------------


def test_manipulator_pvs_carry_units_precision_and_the_database_limits(epics_env, tmp_path):
    """TENSION0, AXIS0:LENGTH, X and NETFORCE carry EGU and PREC from their signals, display and alarm limits from the database (LOW_TENSION 2 N, MAX_TENSION 200 N, NET_FORCELIMIT 25 N, the vessel's 320 cm radius)."""
    from caproto import ChannelType

    with epics_manipulator(tmp_path) as (station, _runner, _ioc):
        pa = station.polyaxis
        t = _meta("TENSION0", ChannelType.CTRL_DOUBLE).metadata
        assert (t.units, t.precision) == (b"N", 2)
        assert (t.lower_alarm_limit, t.upper_alarm_limit) == (pa.low_tension, pa.max_tension)
        assert (t.lower_alarm_limit, t.upper_alarm_limit) == (2.0, 200.0)
        assert t.lower_alarm_limit < t.lower_warning_limit < t.upper_warning_limit < 200.0
        assert (t.lower_disp_limit, t.upper_disp_limit) == (0.0, 200.0)
        length = _meta("AXIS0:LENGTH", ChannelType.CTRL_DOUBLE).metadata
        assert length.units == b"cm" and length.upper_disp_limit > 300.0
        x = _meta("X", ChannelType.CTRL_DOUBLE).metadata
        assert (x.units, x.lower_disp_limit, x.upper_disp_limit) == (b"cm", -320.0, 320.0)
        nf = _meta("NETFORCE", ChannelType.CTRL_DOUBLE).metadata
        assert nf.upper_alarm_limit == pa.net_forcelimit == 25.0
        speed = _meta("AXIS0MOTOR:SPEED", ChannelType.CTRL_DOUBLE).metadata
        assert (speed.units, speed.upper_disp_limit) == (b"cm/s", 7.0)
        running = _meta("AXIS0MOTOR:RUNNING", ChannelType.CTRL_ENUM).metadata
        assert list(running.enum_strings) == [b"no", b"yes"]
        state = _meta("STATE", ChannelType.CTRL_ENUM).metadata
        assert list(state.enum_strings) == [b"idle", b"moving", b"fault"]


def test_a_slack_rope_is_a_major_alarm_computed_by_the_ioc(epics_env, tmp_path):
    """Tensions in range are NO_ALARM; a broken rope (below the 2 N low-tension stop) makes TENSION0 and AXIS0LOADCELL:TENSION LOLO / MAJOR."""
    from caproto import AlarmSeverity, AlarmStatus

    with epics_manipulator(tmp_path) as (station, runner, _ioc):
        assert _until(lambda: _read("TENSION0")[0] > 2.0)
        assert _alarm("TENSION0") == (AlarmStatus.NO_ALARM, AlarmSeverity.NO_ALARM)
        runner.call(station.plant.break_rope, 0, take_fault=False)
        runner.sleep(0.3)
        tension = runner.call(lambda: station.polyaxis.tensions[0], take_fault=False)
        assert tension < station.polyaxis.low_tension
        assert _until(lambda: _read("TENSION0")[0] < 2.0)
        assert _alarm("TENSION0") == (AlarmStatus.LOLO, AlarmSeverity.MAJOR_ALARM)
        assert _until(lambda: _alarm("AXIS0LOADCELL:TENSION")[1] == AlarmSeverity.MAJOR_ALARM)
        assert _alarm("TENSION1")[1] == AlarmSeverity.NO_ALARM


def test_per_rope_state_and_target_pvs_follow_a_move(epics_env, tmp_path):
    """During 'prototype to 10 0 100': STATE moving, TARGET_X 10, a motor RUNNING yes; after: STATE idle, STOP_REASON ENDPOINT_STOP, TARGET NaN, AXIS0:LENGTH and AXIS0ENCODER:LENGTH the ropes' lengths."""
    import math

    from pyrt.client import Client

    with epics_manipulator(tmp_path) as (station, runner, ioc):
        assert _until(lambda: math.isnan(_read("TARGET_X")[0]))
        assert _read("STATE")[0] == b"idle"
        op = Client(*ioc.server.address)
        op.auth(TOKEN)
        op.command("prototype to 10 0 100")
        runner.sleep(1.0)
        assert _until(lambda: _read("STATE")[0] == b"moving")
        assert _read("TARGET_X")[0] == pytest.approx(10.0)
        assert _read("TARGET_Z")[0] == pytest.approx(100.0)
        assert _until(lambda: b"yes" in {_read(f"AXIS{i}MOTOR:RUNNING")[0] for i in range(3)})
        (ended,) = op.command("wait")
        runner.sleep(0.3)
        assert ended.startswith("prototype stopped: ENDPOINT_STOP")
        assert _until(lambda: _read("STATE")[0] == b"idle")
        assert _until(lambda: _text("STOP_REASON").startswith("ENDPOINT_STOP"))
        assert math.isnan(_read("TARGET_X")[0])
        length = runner.call(station.axes[0].length)
        assert _read("AXIS0:LENGTH")[0] == pytest.approx(length, abs=0.05)  # last poll vs now
        enc = runner.call(station.axes[0].encoder.length)
        assert _read("AXIS0ENCODER:LENGTH")[0] == pytest.approx(enc, abs=0.01)
        assert {_read(f"AXIS{i}MOTOR:RUNNING")[0] for i in range(3)} == {b"no"}


def test_stop_pv_without_a_token_stops_a_move(epics_env):
    """Writing 'stop' to STOP (no token: a stop is for everyone) halts the operator's move at once; RESULT says so."""
    with epics_served() as (sv, _ioc):
        op = sv.operator()
        op.command("I")
        op.command("P E47A")
        sv.runner.sleep(0.2)
        assert sv.runner.call(lambda: sv.ctl.moving)
        _write("STOP", "stop")
        assert not sv.runner.call(lambda: sv.ctl.moving) and sv.still_and_null()
        assert _text("RESULT").startswith("OK gripper: every motor stopped; position ")
        assert _read("STOP")[0] == b"idle"  # a button: back to idle
        _write("STOP", "idle")  # nothing happens
        assert op.command("T") == ["E47A"]


def test_stop_pv_is_served_while_a_command_pv_holds_the_session(epics_env):
    """A CMD that runs long (its session busy) never holds up a STOP: the stop has a session of its own."""
    with epics_served() as (sv, ioc):
        op = sv.operator()
        op.command("I")
        op.command("P E47A")
        sv.runner.sleep(0.2)
        with ioc._shell_lock:  # as a 'TOKEN wait' written to CMD would hold it
            _write("STOP", "stop")
            assert not sv.runner.call(lambda: sv.ctl.moving) and sv.still_and_null()


def test_ack_pv_needs_the_token(epics_env):
    """A fault stays until ACK is written with the token: a wrong token acknowledges nothing."""
    with epics_served() as (sv, _ioc):
        sv.runner.call(sv.rig.trip, "epics test trip", "test")
        sv.runner.sleep(0.2)  # loop time for the 0.1 s sample of STATE
        assert _until(lambda: _read("FAULT")[0] == b"yes")
        assert _until(lambda: _read("STATE")[0] == b"fault")
        _write("ACK", "wrong")
        assert _text("RESULT").startswith("ERR auth")
        assert sv.rig.fault is not None
        _write("ACK", TOKEN)
        assert _text("RESULT").startswith("OK fault acknowledged")
        assert sv.rig.fault is None
        sv.runner.sleep(0.2)
        assert _until(lambda: _read("FAULT")[0] == b"no")
        assert TOKEN not in _text("ACK")


def test_a_200_character_fault_message_is_intact(epics_env):
    """FAULT_MSG is a char waveform: a 200-character cause reads back whole, not cut at 39."""
    cause = "rope axis1 " + "x" * 180 + " end of it"
    assert len(cause) == 201
    with epics_served() as (sv, _ioc):
        sv.runner.call(sv.rig.trip, cause, "test")
        assert _until(lambda: _text("FAULT_MSG") == cause)


def test_value_pvs_are_read_only_to_channel_access_clients(epics_env, caplog):
    """A client cannot write a value PV (POSITION, TARGET, MOVING): the IOC refuses and nothing
    changes; each refusal is one log line (no caproto traceback) and an audit line."""
    import logging

    caplog.set_level(logging.WARNING)
    with epics_served() as (sv, _ioc):
        for name, value in (("POSITION", 5), ("TARGET", -100), ("MOVING", "yes")):
            with pytest.raises(Exception):  # noqa: B017 - caproto's refusal
                _write(name, value)
        assert _read("TARGET")[0] == 0 and sv.runner.call(sv.ctl.target) == 0
        assert sv.still_and_null()
        refused = [r for r in caplog.records if "refused EPICS write" in r.getMessage()]
        assert len(refused) == 3 and all(r.exc_info is None for r in refused)
        assert not any("Forbidden" in (r.exc_text or "") for r in caplog.records)
        audit = [str(m) for m in sv.runner.messages()]
        assert sum("EPICS: refused EPICS write" in ln for ln in audit) == 3


def test_caproto_logs_at_warning_unless_verbose(epics_env, caplog):
    """caproto's logger is at WARNING (no INFO line per client connect), at INFO with verbose."""
    import logging

    from pyrt.server.epics import EpicsService

    with epics_served() as (sv, _ioc), caplog.at_level(logging.DEBUG, logger="pyrt"):
        assert logging.getLogger("caproto").getEffectiveLevel() == logging.WARNING
        _read("POSITION")
        assert not [r for r in caplog.records if r.name.startswith("caproto")
                    and r.levelno < logging.WARNING]
        EpicsService(sv.runner, sv.server.robot, sv.server, "V:", verbose=True)
        assert logging.getLogger("caproto").getEffectiveLevel() == logging.INFO


def test_epics_writes_that_act_are_shown_on_the_console(epics_env):
    """A CMD that changes the robot and a STOP are shown on the operator's console naming EPICS; a read is not."""
    import io

    from pyrt.commands import RobotShell

    with epics_served() as (sv, _ioc):
        console = RobotShell(sv.rig, io.StringIO())
        console.messages()
        _write("CMD", f"{TOKEN} X 33")
        _write("CMD", f"{TOKEN} T")
        _write("STOP", "stop")
        assert _text("RESULT").startswith("OK gripper: every motor stopped")
        audit = [m for m in console.messages() if m.startswith("remote: ")]
    assert audit == ["remote: EPICS CMD: X 33", "remote: EPICS STOP: stop"]


class _WordStation(ManipulatorStation):
    """The prototype with one more served value: a short text (a mode word, 12 characters at most)."""

    def served_signals(self):
        from pyrt.component import Signal

        return [*super().served_signals(),
                Signal.text("mode", lambda: "cruise", "the mode, a word", length=12)]


def test_the_robot_text_signals_are_string_pvs_that_read_what_the_station_says(
        epics_env, tmp_path):
    """After a move: PROTOTYPE:WHERE, LAST_STOP and STATUSLINE are char waveforms (unbounded text) holding the station's where, the move's stop reason and the status line; a text bounded to 39 characters (MODE) is a DBR_STRING PV."""
    from caproto import ChannelType

    from pyrt.client import Client
    from pyrt.server.epics import EpicsService

    station = _WordStation(copy_station("prototype", tmp_path / "prototype"),
                           tick_ns=5_000_000)
    runner = station.runner
    robot = ServedStation(station)
    server = Server(runner, robot, token=TOKEN)
    runner.start()
    server.start()
    ioc = EpicsService(runner, robot, server, PREFIX, token=TOKEN, interfaces=["127.0.0.1"],
                       period_s=0.02, stats_period_s=0.2)
    ioc.start()
    try:
        assert type(ioc.pvdb[PREFIX + "PROTOTYPE:WHERE"]).__mro__[1].__name__ == "ChannelChar"
        assert type(ioc.pvdb[PREFIX + "MODE"]).__mro__[1].__name__ == "ChannelString"
        assert _until(lambda: _string("MODE") == "cruise")
        assert _ca_read("MODE", timeout=2.0).data_type == ChannelType.STRING
        op = Client(*server.address)
        op.auth(TOKEN)
        op.command("prototype to 10 0 100")
        (ended,) = op.command("wait")
        assert ended.startswith("prototype stopped: ENDPOINT_STOP")
        runner.sleep(0.3)
        where = runner.call(station.where)
        status = runner.call(station.status)
        assert where and status
        assert _until(lambda: _text("PROTOTYPE:WHERE") == where), (_text("PROTOTYPE:WHERE"),
                                                                    where)
        assert _until(lambda: _text("PROTOTYPE:LAST_STOP").startswith("ENDPOINT_STOP"))
        assert _text("PROTOTYPE:LAST_STOP") == runner.call(station.last_stop)
        def untimed(line: str) -> str:  # the line's first field is the loop time
            return re.sub(r"^t=\s*[\d.]+ s\s+", "", line)

        assert status.startswith("t=") and untimed(status) != status
        assert _until(lambda: untimed(_text("PROTOTYPE:STATUSLINE")) == untimed(status))
    finally:
        ioc.close()
        server.close()
        runner.stop()
        station.close()


def test_a_text_pv_value_is_bounded_as_its_pv_holds_it():
    """A string PV's value is cut to 39 bytes (whole characters), a waveform's to 1023; a text of 40 characters or an unbounded one is a char waveform."""
    caproto = pytest.importorskip("caproto")
    from pyrt.server.epics import _pv_value, _value_pv

    assert _pv_value("string", "x" * 60) == "x" * 39
    assert _pv_value("string", "é" * 30) == "é" * 19  # 38 bytes: no half character
    assert _pv_value("text", "y" * 2000) == "y" * 1023
    assert _value_pv(caproto, "text", "s", kind="text", length=39)[0] == "string"
    assert _value_pv(caproto, "text", "s", kind="text", length=40)[0] == "text"
    assert _value_pv(caproto, "text", "s", kind="text")[0] == "text"
