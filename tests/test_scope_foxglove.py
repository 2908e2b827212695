"""scope foxglove: the scope's channels, and an arm's joint states and URDF, live on a Foxglove server on loopback."""

from __future__ import annotations

import io
import json
import math
import re
import struct
import threading

import pytest

pytest.importorskip("foxglove", reason="the Foxglove SDK (pyrt[foxglove]) is not installed")

from _wsclient import FoxgloveClient

from pyrt.errors import CommandError
from pyrt.scheduler import Loop, SimClock
from pyrt.scope.foxglove import FoxgloveServer
from pyrt.scope.joints import JointStates
from pyrt.scope.stream import Layout

JOINTS = JointStates(names=("shoulder", "elbow"), position=("q0", "q1"),
                     velocity=("shoulder.velocity", "elbow.velocity"), urdf="<robot name='r'/>")
TOPICS = ["/scope", "/scope/sim", "/joint_states", "/robot_description"]


def _feed(server: FoxgloveServer, layout: Layout, stop: threading.Event) -> None:
    """Offer a sample every 10 ms of loop time, as the scope would, until ``stop``."""
    k = 0
    while not stop.wait(0.005):
        server.offer(layout, layout.packer.pack(k * 10_000_000, 90.0, -45.0, 9.0, 0.0, 2.5))
        k += 1


def test_a_client_gets_the_channels_with_schemas_and_joint_states_in_si():
    """A client on loopback is advertised one JSON channel per object and the joint
    channels, and receives each: values as sampled, joints in rad and rad/s, the URDF."""
    server = FoxgloveServer(0, 100, units={"q0": "deg", "sim.x": "mm"},
                            joints=(JOINTS, ["deg", "deg", "deg/s", "deg/s"]))
    assert server.url.startswith("ws://127.0.0.1:")
    layout = Layout(struct.Struct("<q" + "d" * 5),
                    ("q0", "q1", "shoulder.velocity", "elbow.velocity", "sim.x"))
    stop = threading.Event()
    feeder = threading.Thread(target=_feed, args=(server, layout, stop))
    client = FoxgloveClient("127.0.0.1", server.port)
    feeder.start()
    try:
        client.until(lambda c: all(c.messages.get(t) for t in TOPICS), subscribe=TOPICS)
    finally:
        stop.set()
        feeder.join()
        client.close()
        server.close()
    by_topic = {ch["topic"]: ch for ch in client.channels.values()}
    assert by_topic["/joint_states"]["schemaName"] == "sensor_msgs/msg/JointState"
    assert all(by_topic[t]["encoding"] == "json" for t in TOPICS)
    assert json.loads(by_topic["/scope/sim"]["schema"])["properties"]["x"]["description"] == "mm"
    t_ns, body = client.messages["/joint_states"][-1]
    js = json.loads(body)
    assert js["name"] == ["shoulder", "elbow"]
    assert js["position"] == pytest.approx([math.pi / 2, -math.pi / 4])
    assert js["velocity"] == pytest.approx([math.radians(9.0), 0.0])
    assert js["header"]["stamp"] == {"sec": t_ns // 10**9, "nsec": t_ns % 10**9}
    assert t_ns % 10_000_000 == 0  # the loop's time, as offered
    assert json.loads(client.messages["/scope"][-1][1]) == {"q0": 90, "q1": -45}
    assert json.loads(client.messages["/scope/sim"][-1][1]) == {"x": 2.5}
    assert json.loads(client.messages["/robot_description"][-1][1]) == {"data": "<robot name='r'/>"}


def test_offer_only_queues_and_counts_what_a_full_queue_drops():
    """The loop's side appends to a bounded queue; past its bound a sample is dropped
    and counted, and nothing waits for a client (none is connected)."""
    from pyrt.scope import foxglove as fx

    server = FoxgloveServer(0, 100)
    layout = Layout(struct.Struct("<qd"), ("x",))
    server._stop.set()  # the thread stops draining: the queue only fills
    server._thread.join(timeout=5)
    try:
        for k in range(fx.QUEUE + 7):
            server.offer(layout, layout.packer.pack(k, 1.0))
        assert server.dropped == 7
        assert "7 dropped" in server.describe()
    finally:
        server.close()
    assert server.sent == fx.QUEUE


def test_a_taken_port_and_bad_words_are_refused_with_a_sentence():
    """A port already served, a port that is no number and a rate out of range are
    refused with what was wrong."""
    first = FoxgloveServer(0, 50)
    try:
        with pytest.raises(CommandError, match=f"cannot serve on 127.0.0.1:{first.port}"):
            FoxgloveServer(first.port, 50)
    finally:
        first.close()
    with pytest.raises(CommandError, match="rate must be"):
        FoxgloveServer(0, 5000)


def test_the_arm_moving_is_seen_as_joint_states_and_its_urdf():
    """scope foxglove on the example arm serves /joint_states and /robot_description
    (the arm's declaration): during 'arm to 30 60' a client on loopback sees the joints
    go to 30 and 60 deg (in rad), with the URDF's joint names."""
    pytest.importorskip("pyrt_arm", reason="the example arm is not installed")
    from pyrt_arm.station import build_arm

    from pyrt.commands.robot import RobotShell

    station = build_arm(Loop(SimClock()))
    runner = station.start()
    out = io.StringIO()
    shell = RobotShell(station, out, runner=runner)
    client = None
    try:
        shell.onecmd("scope foxglove 0 20")
        said = out.getvalue()
        port = int(re.search(r"ws://127\.0\.0\.1:(\d+)", said).group(1))
        assert "added q0, q1, shoulder.velocity, elbow.velocity for /joint_states" in said
        client = FoxgloveClient("127.0.0.1", port)
        client.until(lambda c: c.messages.get("/joint_states")
                     and c.messages.get("/robot_description"),
                     subscribe=["/joint_states", "/robot_description"])
        shell.onecmd("scope foxglove 1 2 3")
        assert "scope foxglove: [PORT [HZ]]" in out.getvalue()
        shell.onecmd("arm to 30 60")
        shell.onecmd("wait")

        def arrived(c: FoxgloveClient) -> bool:
            last = json.loads(c.messages["/joint_states"][-1][1])
            return last["position"] == pytest.approx([math.radians(30), math.radians(60)],
                                                     abs=1e-3)

        client.until(arrived)
        urdf = json.loads(client.messages["/robot_description"][-1][1])["data"]
        assert '<joint name="shoulder"' in urdf and '<joint name="elbow"' in urdf
        names = json.loads(client.messages["/joint_states"][-1][1])["name"]
        assert names == ["shoulder", "elbow"]
        out.seek(0)
        out.truncate()
        shell.onecmd("scope foxglove off")
        assert "Foxglove server off" in out.getvalue() and "sent" in out.getvalue()
    finally:
        if client is not None:
            client.close()
        station.close()


def test_a_piped_arm_serves_foxglove_to_a_client_in_another_process():
    """pyrt arm --speed max with its script on a pipe: 'scope foxglove 0' says where it
    serves (loopback); a client in this process sees /joint_states follow 'arm to 30 60'
    and the station ends cleanly after 'scope foxglove off'."""
    import os
    import subprocess
    import sys

    pytest.importorskip("pyrt_arm", reason="the example arm is not installed")
    env = {k: v for k, v in os.environ.items() if k != "PYRT_TOKEN"}
    proc = subprocess.Popen([sys.executable, "-m", "pyrt", "arm", "--speed", "max"],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env)
    client = None
    try:
        proc.stdin.write("scope foxglove 0 20\n")
        proc.stdin.flush()
        port = None
        for _ in range(200):  # a bound: the banner and the answer are a few lines
            line = proc.stdout.readline()
            m = re.search(r"Foxglove server on ws://127\.0\.0\.1:(\d+)", line)
            if m or not line:
                port = m and int(m.group(1))
                break
        assert port, "the arm did not say where it serves Foxglove"
        client = FoxgloveClient("127.0.0.1", port)
        client.until(lambda c: "/joint_states" in c.subscribed.values(),
                     subscribe=["/joint_states"])
        # on virtual time the loop runs while a command does: a sleep until the
        # subscription is seen to carry samples, then the move
        for _ in range(50):
            proc.stdin.write("sleep 0.2\n")
            proc.stdin.flush()
            try:
                client.until(lambda c: c.messages.get("/joint_states"), timeout_s=0.5)
                break
            except (TimeoutError, OSError):
                continue
        proc.stdin.write("arm to 30 60\nwait\nsleep 1\n")
        proc.stdin.flush()
        client.until(lambda c: json.loads(c.messages["/joint_states"][-1][1])["position"]
                     == pytest.approx([math.radians(30), math.radians(60)], abs=1e-3))
        proc.stdin.write("scope foxglove off\nquit\n")
        proc.stdin.flush()
        out, err = proc.communicate(timeout=60)
    finally:
        if client is not None:
            client.close()
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, err
    assert "Foxglove server off" in out
