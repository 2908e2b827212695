"""Both stations on the tcp:// board back end: ``pyrt board-sim`` in a subprocess (or a
BoardServer in a thread where only the greeting matters), the console's commands through
RobotShell at real time, the board process or the controller killed, refusals."""

from __future__ import annotations

import io
import queue
import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator

import pytest

from pyrt.boards import open_boards
from pyrt.boards.gripper import DAC_NULL
from pyrt.cli import main
from pyrt.commands import RobotShell
from pyrt.db import copy_station, load_station, station_directory
from pyrt.errors import BoardError, ConfigError
from pyrt.scheduler import Loop, SimClock, WallClock
from pyrt.sim.boardsim import BoardServer
from pyrt.sim.world import GRIPPER_BOARDS, MANIPULATOR_BOARDS, GripperWorld, ManipulatorWorld
from pyrt.station.base import BoardWorld
from pyrt.station.gripper import GripperStation, build_gripper
from pyrt.station.manipulator import ManipulatorStation

pytestmark = pytest.mark.wallclock

#: Generous: a loaded two-core machine may be slow to start a Python process.
START_S = 60.0
#: Only a hang takes this long: a bound that catches one, never a measure of speed.
HANG_S = 30.0


class _Proc:
    """A child Python process whose stdout lines a thread collects."""

    def __init__(self, args: list[str], stdin: str | None = None):
        self.proc = subprocess.Popen([sys.executable, *args],
                                     stdin=subprocess.PIPE if stdin is not None
                                     else subprocess.DEVNULL,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        if stdin is not None:
            self.proc.stdin.write(stdin)
            self.proc.stdin.flush()
        self.lines: queue.Queue[str | None] = queue.Queue()
        self.seen: list[str] = []
        threading.Thread(target=self._pump, daemon=True).start()

    def send(self, line: str) -> None:
        """One more line on the child's stdin."""
        self.proc.stdin.write(line + "\n")
        self.proc.stdin.flush()

    def _pump(self) -> None:
        for line in self.proc.stdout:
            self.lines.put(line.rstrip("\n"))
        self.lines.put(None)

    def expect(self, pattern: str, seconds: float = START_S) -> re.Match:
        """The first line from here on that matches ``pattern``."""
        deadline = time.monotonic() + seconds
        while True:
            try:
                line = self.lines.get(timeout=max(0.01, deadline - time.monotonic()))
            except queue.Empty:
                line = None
            if line is not None:
                self.seen.append(line)
                m = re.search(pattern, line)
                if m:
                    return m
            if time.monotonic() > deadline or (line is None and self.proc.poll() is not None):
                self.kill()
                raise AssertionError(f"no line matching {pattern!r}; got {self.seen[-20:]}, "
                                     f"stderr {self.proc.stderr.read()[-2000:]!r}")

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait(10)


def _board_sim(world: str, *extra: str, watchdog: float = 2.0) -> tuple[_Proc, str]:
    """``pyrt board-sim WORLD`` on a free loopback port; its URL from its first line."""
    p = _Proc(["-m", "pyrt", "board-sim", world, "--listen", "127.0.0.1:0",
               "--watchdog", str(watchdog), *extra])
    m = p.expect(r"^pyrt board-sim: \w+ \w+ on (tcp://127\.0\.0\.1:\d+) ")
    assert len(p.seen) == 1  # the first line names the URL
    return p, m.group(1)


@pytest.fixture
def gripper_sim() -> Iterator[tuple[_Proc, str]]:
    """A gripper board-sim subprocess, jaws near wide open."""
    sim, url = _board_sim("gripper", "--start", "-0100")
    yield sim, url
    sim.kill()


def _until(predicate: Callable[[], bool], seconds: float) -> bool:
    deadline = time.monotonic() + seconds
    while not predicate():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.01)
    return True


def _info(url: str, robot: str, seconds: float = HANG_S) -> dict[str, str]:
    """The world's INFO through a fresh connection (retrying while board-sim is still busy
    with the old one)."""
    deadline = time.monotonic() + seconds
    while True:
        try:
            kinds = GRIPPER_BOARDS if robot == "gripper" else MANIPULATOR_BOARDS
            with open_boards(url, robot, kinds, max_age=0) as b:
                return b.info()
        except BoardError as exc:
            if "busy" not in str(exc) or time.monotonic() > deadline:
                raise
            time.sleep(0.005)


def _gripper(url: str) -> tuple[GripperStation, RobotShell, io.StringIO]:
    station = build_gripper(Loop(WallClock()), boards=url)
    out = io.StringIO()
    return station, RobotShell(station, out), out


# -- (a) the gripper over tcp at real time ----------------------------------------------------


def test_gripper_init_move_and_wait_over_tcp_reach_the_target(gripper_sim):
    """I, P-1B86 and wait through RobotShell against board-sim gripper: the jaws in the other
    process reach the target, the controller's encoder agrees, and close leaves the DAC null."""
    _, url = gripper_sim
    # a fixed, patient link timeout: the claim here is the move over the link, and a loaded
    # machine can starve board-sim past the timeout derived from the tick (0.1 s)
    station, shell, out = _gripper(url + "?timeout=5")
    reports: list[str] = []
    station.close_report = reports.append
    try:
        assert station.plant is None and station.boards.url.startswith(url)
        assert isinstance(station.find("sim"), BoardWorld)
        station.start()
        for line in ("I", "P-1B86", "wait"):
            shell.onecmd(line)
        text = out.getvalue()
        assert "jaws wide open (limit sensor on), encoder 0000" in text, text
        m = re.search(r"at target: position ([0-9A-F]{4}) \([0-9.]+ mm\), target E47A "
                      r"\([0-9.]+ mm\), error ([-+]\d+)", text)
        assert m, text
        assert abs(int(m.group(2))) <= 20
        world = station.boards.info()  # the other process's truth, not a register access
        assert abs(float(world["x"]) - (-0x1B86)) <= 40, world
        assert station.fault is None and station.loop.clock.speed == 1.0
    finally:
        station.close()
    assert reports == []
    assert _info(url, "gripper")["dac"] == str(DAC_NULL)


# -- (b) the board process killed ----------------------------------------------------------------


def test_killed_board_sim_faults_the_gripper_within_three_ticks_naming_the_url(gripper_sim):
    """SIGKILL of board-sim during a P move: the robot is faulted within 3 ticks of the first
    register access that failed, the fault names the URL, every actuator is left stopped,
    the next command reports the fault once, and close does not raise but says so once."""
    sim, url = gripper_sim
    station, shell, out = _gripper(url)
    reports: list[str] = []
    station.close_report = reports.append
    ctl = station.controller
    link = station.board.registers.link
    failed: list[int] = []

    def recording(fn):
        def access(*line: str):
            try:
                return fn(*line)
            except BoardError:
                if not failed:
                    failed.append(station.loop.tick_index)
                raise
        return access

    link.request = recording(link.request)
    link.request_ints = recording(link.request_ints)
    link.collect = recording(link.collect)
    link.send = recording(link.send)
    link.newest = recording(link.newest)  # the stream's read phase
    try:
        station.start()
        shell.onecmd("I")
        shell.onecmd("P-1B86")
        assert _until(lambda: ctl.moving and ctl.dac != DAC_NULL, HANG_S), out.getvalue()
        sim.kill()
        assert _until(lambda: station.fault is not None, HANG_S), out.getvalue()
        fault = station.fault
        assert failed, "no register access failed"
        assert 0 <= fault.tick - failed[0] <= 3, (fault.tick, failed)
        assert url in fault.cause and fault.cause.startswith(f"board {url}: ")
        assert ctl.dac == DAC_NULL and not ctl.moving and ctl.job is None
        assert not station.busy() and len(station.motion) == 0
        shell.onecmd("W")
        shell.onecmd("W")
        text = out.getvalue()
        assert text.count(url) == 1 and "fault" in text.lower(), text
    finally:
        station.close()
    assert len(reports) == 1 and url in reports[0], reports


# -- (c) the controller killed ---------------------------------------------------------------------


def test_killed_controller_process_leaves_the_outputs_off_on_the_disconnect():
    """SIGKILL of a 'pyrt gripper --boards tcp://...' that is driving the jaws: a fresh
    connection finds board-sim's DAC null, turned off for the lost connection, not by the
    watchdog (60 s: it cannot have run out)."""
    sim, url = _board_sim("gripper", "--start", "-0100", watchdog=60.0)
    ctl = _Proc(["-m", "pyrt", "gripper", "--boards", url], stdin="P-1B86\n")
    try:
        ctl.expect(r"^CMD: P-1B86$")
        for _ in range(500):  # W until the encoder moves: current is applied
            ctl.send("W")
            if ctl.expect(r"^([0-9A-F]{4})$").group(1) != "0000":
                break
        else:
            raise AssertionError(f"the jaws did not move: {ctl.seen[-10:]}")
        sim.expect(r"^controller \S+ owns the outputs$", HANG_S)
        ctl.proc.send_signal(signal.SIGKILL)
        ctl.kill()
        info = _info(url, "gripper", HANG_S)
        assert info["dac"] == str(DAC_NULL), info
        sim.expect(r"^controller \S+ (disconnected|lost \(.*\)): outputs off$", HANG_S)
        assert not any("watchdog:" in line for line in sim.seen)
    finally:
        ctl.kill()
        sim.kill()


def test_controller_that_closes_its_socket_without_a_stop_leaves_the_outputs_off():
    """A driving station whose connection is cut under it (no stop, no QUIT): board-sim's DAC is
    null, turned off for the lost connection, not by the watchdog (60 s: it cannot have run
    out), and the station faults naming the URL."""
    sim, url = _board_sim("gripper", "--start", "-0100", watchdog=60.0)
    station, shell, out = _gripper(url)
    try:
        station.start()
        shell.onecmd("I")
        shell.onecmd("P-1B86")
        assert _until(lambda: station.controller.dac != DAC_NULL, HANG_S), out.getvalue()
        station.board.registers.link._sock.shutdown(2)  # the socket closes, nothing said
        info = _info(url, "gripper", HANG_S)
        assert info["dac"] == str(DAC_NULL), info
        sim.expect(r"^controller \S+ (disconnected|lost \(.*\)): outputs off$", HANG_S)
        assert not any("watchdog:" in line for line in sim.seen)
        assert _until(lambda: station.fault is not None, HANG_S)
        assert url in station.fault.cause
    finally:
        station.close()
        sim.kill()


# -- (d) the manipulator over tcp ----------------------------------------------------------------


@pytest.fixture
def prototype_sim(tmp_path) -> Iterator[tuple[_Proc, str, object]]:
    """A prototype board-sim subprocess built from a copy of the packaged station."""
    db = copy_station("prototype", tmp_path / "db")
    sim, url = _board_sim("prototype", "--db", str(db), "--ideal-sensors", watchdog=2.0)
    yield sim, url, db
    sim.kill()


def _manipulator(db, url: str) -> ManipulatorStation:
    return ManipulatorStation(db, loop=Loop(WallClock(), period_ns=5_000_000), boards=url)


def test_manipulator_over_tcp_moves_and_closes_cleanly(prototype_sim):
    """The prototype against board-sim prototype: it starts where the world holds the source,
    a short 'prototype to' makes progress in the other process, and close stops every motor,
    reports nothing and leaves the outputs off."""
    _, url, db = prototype_sim
    station = _manipulator(db, url)
    reports: list[str] = []
    station.close_report = reports.append
    out = io.StringIO()
    shell = RobotShell(station, out)
    pa = station.polyaxis
    try:
        assert station.plant is None and isinstance(station.find("sim"), BoardWorld)
        x0, y0, z0 = pa.position
        assert z0 == pytest.approx(95.57, abs=0.5)
        station.start()
        shell.onecmd(f"prototype to {x0:.2f} {y0:.2f} {z0 - 3:.2f}")
        assert "error" not in out.getvalue(), out.getvalue()
        assert _until(lambda: pa.position[2] < z0 - 0.5, 30.0), (pa.position, out.getvalue())
        world = station.boards.info()
        assert float(world["z"]) < z0 - 0.3, world  # the world moved, not only the estimate
        assert station.fault is None, station.fault
    finally:
        station.close()
    assert reports == []
    info = _info(url, "manipulator")
    assert info["armed"] == "none" and info["windings_off"] == "1", info


def test_manipulator_close_with_board_sim_gone_does_not_raise_and_says_so_once(prototype_sim):
    """board-sim killed under a running manipulator: the station faults naming the URL; close
    does not raise, stops what it can and reports the lost boards in one line."""
    sim, url, db = prototype_sim
    station = _manipulator(db, url)
    reports: list[str] = []
    station.close_report = reports.append
    try:
        station.start()
        sim.kill()
        assert _until(lambda: station.fault is not None, HANG_S)
        assert station.fault.cause.startswith(f"board {url}: ")
        assert station.motors_running() == []
    finally:
        station.close()
    assert len(reports) == 1 and url in reports[0], reports


# -- (e) refusals ------------------------------------------------------------------------------------


@pytest.fixture
def gripper_server() -> Iterator[BoardServer]:
    """A gripper board-sim in a thread (only its greeting and a few accesses matter here)."""
    server = BoardServer(GripperWorld(), "127.0.0.1", 0, watchdog_s=30.0)
    server.start()
    yield server
    server.close()


@pytest.mark.parametrize(("clock", "word"), [
    (SimClock, "virtual time (--speed max)"),
    (lambda: WallClock(speed=2.0), "--speed 2"),
])
def test_gripper_over_tcp_refuses_a_loop_not_at_real_time(gripper_server, clock, word):
    """--speed max or N with tcp:// boards is a ConfigError naming the URL and the speed."""
    with pytest.raises(ConfigError) as err:
        build_gripper(Loop(clock()), boards=gripper_server.url)
    assert gripper_server.url in str(err.value) and word in str(err.value)
    assert "real time" in str(err.value)


@pytest.mark.parametrize(("kw", "word"), [
    ({"start": -0x100}, "--start"), ({"object_mm": 20.0}, "--object"),
    ({"faults": ["jam"]}, "--fault"),
])
def test_gripper_over_tcp_refuses_the_simulations_options(gripper_server, kw, word):
    """A jaw start position, an object or a fault with tcp:// boards: a ConfigError saying they
    are board-sim's; the connection is given back (board-sim serves the next one)."""
    with pytest.raises(ConfigError) as err:
        build_gripper(Loop(WallClock()), boards=gripper_server.url, **kw)
    assert word in str(err.value) and "pyrt board-sim" in str(err.value)
    _info(gripper_server.url, "gripper")  # free again


def test_cli_refuses_speed_max_with_tcp_boards_in_one_line(gripper_server, capsys):
    """pyrt gripper --boards tcp://... --speed max ends with exit 1 and one line, no traceback."""
    assert main(["gripper", "--boards", gripper_server.url, "--speed", "max"]) == 1
    err = capsys.readouterr().err
    assert "virtual time (--speed max)" in err and err.count("\n") == 1
    assert "Traceback" not in err


def test_manipulator_refuses_a_world_that_is_not_its_station(tmp_path):
    """A tcp:// board-sim serving another world (sno) than the station (prototype): ConfigError
    naming the URL and both worlds; --ideal-sensors with tcp:// boards is refused too."""
    plant = ManipulatorWorld.from_station(load_station(station_directory("prototype"))).plant
    server = BoardServer(ManipulatorWorld(plant, "sno"), "127.0.0.1", 0, watchdog_s=30.0)
    server.start()
    db = copy_station("prototype", tmp_path / "db")
    try:
        with pytest.raises(ConfigError) as err:
            _manipulator(db, server.url)
        text = str(err.value)
        assert server.url in text and "'sno'" in text and "'prototype'" in text
        assert main(["manipulator", "--db", str(db), "--boards", server.url,
                     "--ideal-sensors"]) == 1
    finally:
        server.close()


def test_help_names_the_boards_option_and_board_sim():
    """pyrt gripper --help and pyrt manipulator --help say what --boards does and name board-sim."""
    for robot in ("gripper", "manipulator"):
        text = subprocess.run([sys.executable, "-m", "pyrt", robot, "--help"],
                              capture_output=True, text=True, timeout=START_S).stdout
        flat = " ".join(text.split())
        assert "--boards URL" in flat and "pyrt board-sim" in flat and "tcp://HOST:PORT" in flat


class _JumpClock:
    """The monotonic clock, which the test can move forward at once: board-sim's watchdog
    trips when the test says, never because a loaded machine made a tick late."""

    def __init__(self) -> None:
        self.offset = 0

    def __call__(self) -> int:
        return time.monotonic_ns() + self.offset

    def jump(self, ns: int) -> None:
        self.offset += ns


def test_watchdog_trips_before_the_loop_starts_are_not_a_fault():
    """A station built longer than board-sim's watchdog before it starts (nothing driven yet):
    the trip while nothing polled is not a fault; I then runs; a later stall would be."""
    clock = _JumpClock()
    server = BoardServer(GripperWorld(start=-0x100), "127.0.0.1", 0, watchdog_s=5.0,
                         clock=clock)
    server.start()
    station, shell, out = _gripper(server.url)
    try:
        clock.jump(6_000_000_000)  # idle while being set up, past the watchdog time
        assert _until(lambda: server.watchdog_trips >= 1, HANG_S)
        station.start()
        shell.onecmd("I")
        assert "jaws wide open" in out.getvalue(), out.getvalue()
        assert station.fault is None, station.fault
    finally:
        station.close()
        server.close()


def test_a_down_link_answers_only_what_the_drop_did(gripper_server):
    """After the link fails, the outputs-off writes a reflex makes succeed without a round trip
    (DAC null; disarm, windings off) and channels read disarmed; anything else raises BoardError."""
    from pyrt.boards.gripper import DAC, LED_LO
    from pyrt.boards.tio10 import AWO_BITS, DIR_BITS

    with open_boards(gripper_server.url, "gripper", GRIPPER_BOARDS, max_age=0) as b:
        assert b.down is None and b.has_info
        gripper_server.close()
        with pytest.raises(BoardError):
            b.poll(0)
        assert b.down is not None
        b["gripper"].write(DAC, DAC_NULL)
        for write in ((DAC, 0x90), (LED_LO, 0)):
            with pytest.raises(BoardError, match="link is down"):
                b["gripper"].write(*write)
    world = ManipulatorWorld.from_station(load_station(station_directory("prototype")))
    server = BoardServer(world, "127.0.0.1", 0, watchdog_s=30.0)
    server.start()
    with open_boards(server.url, "prototype", MANIPULATOR_BOARDS) as b:
        server.close()
        with pytest.raises(BoardError):
            b.poll(0)
        tio = b["tio10"]
        tio.disarm(7)
        tio.set_bit(*AWO_BITS[7], True)
        assert not tio.armed(7)
        with pytest.raises(BoardError):
            tio.set_bit(*DIR_BITS[7], True)
        with pytest.raises(BoardError):
            tio.arm(7)
    with open_boards("sim:", "gripper", GRIPPER_BOARDS) as b:  # in process: nothing to lose, nothing to tell
        assert b.down is None and not b.has_info
        with pytest.raises(ConfigError):
            b.info()
