"""The DAQ server with the rope manipulator (SimClock, 5 ms tick) on loopback."""

from __future__ import annotations

import io
import itertools
from contextlib import contextmanager

import pytest
from _server_rig import read_only_lines

from pyrt.client import Client, ServerError
from pyrt.db import copy_station
from pyrt.server import ServedStation, Server
from pyrt.station.manipulator import ManipulatorStation

TOKEN = "rope-token"


@contextmanager
def served_manipulator(tmp_path):
    station = ManipulatorStation(copy_station("prototype", tmp_path / "prototype"),
                                 tick_ns=5_000_000)
    runner = station.runner
    robot = ServedStation(station)
    server = Server(runner, robot, token=TOKEN)
    runner.start()
    host, port = server.start()
    runner.sleep(0.2)
    try:
        yield station, runner, robot, host, port
    finally:
        server.close()
        runner.stop()
        station.close()


def test_full_move_commanded_by_a_client_and_reported_to_a_subscriber(tmp_path):
    """'prototype to 10 0 100' from the privileged client ends at the endpoint; a subscriber sees x go from 0 to 10."""
    with served_manipulator(tmp_path) as (station, _runner, _robot, host, port):
        sub = Client(host, port)
        sub.command("SUBSCRIBE 5")
        op = Client(host, port)
        op.auth(TOKEN)
        assert op.command("prototype to 10 0 100") == ["prototype: to (10, 0, 100): 1 segment, "
                                                       "11.1 cm"]
        (ended,) = op.command("wait")
        assert ended.startswith("prototype stopped: ENDPOINT_STOP")
        pushed = list(itertools.islice(sub.statuses(0.5), 1000))
        samples = [s for s in pushed if s.time_s is not None]
        stops = [s.stop for s in pushed if s.stop is not None]
        assert len(stops) == 1 and stops[0].startswith("ENDPOINT_STOP")  # once
        xs = [s.fields["x"] for s in samples if s.fields["moving"] == 1]
        assert len(xs) > 10 and xs[0] < 1.0 and xs[-1] > 8.0
        assert {f"tension{i}" for i in range(3)} <= samples[0].fields.keys()
        final = sub.status().fields
        assert final["moving"] == 0 and final["fault"] == 0
        assert abs(final["x"] - 10.0) < 0.2 and abs(final["z"] - 100.0) < 0.2
        assert not station.motors_running()


READ_ONLY = ["status", "stats", "help", "help axis0", "sim", "prototype tensions",
             "prototype netForce", "axis0Encoder read", "protovessel show", "axis0",
             "prototype tensionFind", "status axis0"]
#: Not reads, but every client may give them: a stop is the DAQ's right (000).
ANYONE = ["stop", "prototype stop", "axis0 stop"]
PRIVILEGED = ["prototype to 0 0 100", "axis0 up 1", "axis0Motor maxspeed 3",
              "axis1Loadcell calibrate", "ack", "log", "debug", "wait", "sleep 1",
              "sim fault axis0 break", "prototype tensionStop", "axis0Encoder reset", "quit",
              "nosuchobject read"]


@pytest.fixture(scope="module")
def robot(tmp_path_factory):
    station = ManipulatorStation(copy_station("prototype", tmp_path_factory.mktemp("m") / "p"),
                                 tick_ns=5_000_000)
    yield ServedStation(station)
    station.close()


@pytest.mark.parametrize("line", READ_ONLY)
def test_manipulator_reads_are_read_only(robot, line):
    """Status, statistics, help, tensions, netForce, encoder reads and the AV's show are served without AUTH."""
    assert robot.is_read_only(line)


@pytest.mark.parametrize("line", ANYONE)
def test_any_client_may_stop_the_manipulator(robot, line):
    """Every stop is served without AUTH: any client can halt a move."""
    assert robot.is_read_only(line)


@pytest.mark.parametrize("line", PRIVILEGED)
def test_manipulator_commands_that_act_need_privilege(robot, line):
    """Moves, stops, speeds, calibration, ack, logs, waits and simulated faults need AUTH."""
    assert not robot.is_read_only(line)


def test_denied_without_the_token_and_nothing_moves(tmp_path):
    """Without AUTH 'prototype to' is ERR denied and no motor runs; with a wrong token too."""
    with served_manipulator(tmp_path) as (station, runner, _robot, host, port):
        c = Client(host, port)
        with pytest.raises(ServerError) as exc:
            c.auth("nope")
        assert exc.value.code == "auth"
        for line in PRIVILEGED[:4]:
            assert c.request(line).code == "denied"
        runner.sleep(1.0)
        assert not station.motors_running() and not station.busy()
        assert c.command("prototype tensions")[0].startswith("prototype: desired tensions")


def test_device_reads_answer_with_their_values_over_the_network(tmp_path):
    """An unprivileged 'axis0Encoder read', 'axis0' and 'prototype tensionFind' reply with values, not a bare OK."""
    with served_manipulator(tmp_path) as (station, runner, _robot, host, port):
        c = Client(host, port)
        (line,) = c.command("axis0Encoder read")
        assert line.startswith("axis0Encoder: ") and line.endswith(" cm")
        length = runner.call(station.axes[0].encoder.length)
        assert float(line.split()[1]) == pytest.approx(length, abs=1e-3)
        assert "axis0.tension = " in "\n".join(c.command("axis0"))
        assert c.command("prototype tensionFind")[0].startswith("prototype: position from tensions")


def test_every_read_only_manipulator_command_returns_its_value_over_the_network(tmp_path):
    """Each read-only command record (no argument) of every object, sent by an unprivileged client, answers OK with its value, not a bare OK."""
    with served_manipulator(tmp_path) as (station, runner, robot, host, port):
        c = Client(host, port)
        lines = read_only_lines(station, robot.make_shell(runner, io.StringIO()))
        assert {"status", "stats", "axis0Encoder read", "prototype tensions",
                "prototype tensionFind", "sim show"} <= set(lines)
        for line in lines:
            reply = c.request(line)
            assert reply.ok and reply.lines and reply.lines[0], (line, reply)
