"""``pyrt board-sim`` in a subprocess on 127.0.0.1: its first line, the watchdog when the
controller dies or hangs, the controller's BoardError when board-sim dies, SIGTERM, options."""

from __future__ import annotations

import importlib.util
import os
import queue
import re
import signal
import subprocess
import sys
import threading
import time

import pytest

from pyrt.boards import open_boards
from pyrt.boards.gripper import DAC, DAC_NULL, P8155_PB
from pyrt.cli import main
from pyrt.db import copy_station
from pyrt.errors import BoardError
from pyrt.sim.world import GRIPPER_BOARDS, MANIPULATOR_BOARDS

pytestmark = pytest.mark.wallclock

#: Generous: a loaded two-core machine may be slow to start a Python process.
START_S = 60.0
#: Only a hang takes this long: a bound that catches one, never a measure of speed.
HANG_S = 30.0

#: The stations board-sim serves: the built-in ones, and the arm of examples/arm if installed.
STATIONS = ", ".join(sorted(["gripper", "manipulator", "prototype", "sno"]
                            + (["arm"] if importlib.util.find_spec("pyrt_arm") else [])))


class _Proc:
    """A child process whose stdout lines are collected, with their arrival times, by a thread."""

    def __init__(self, args: list[str], env: dict[str, str] | None = None,
                 preexec: object = None):
        self.proc = subprocess.Popen([sys.executable, *args], stdin=subprocess.DEVNULL,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                     env=env, preexec_fn=preexec)  # type: ignore[arg-type]
        self.lines: queue.Queue[tuple[float, str]] = queue.Queue()
        self.seen: list[str] = []
        threading.Thread(target=self._pump, daemon=True).start()

    def _pump(self) -> None:
        for line in self.proc.stdout:
            self.lines.put((time.monotonic(), line.rstrip("\n")))
        self.lines.put((time.monotonic(), ""))

    def expect(self, pattern: str, seconds: float = START_S) -> tuple[float, re.Match]:
        """The first line (from here on) matching ``pattern``, and when it came."""
        deadline = time.monotonic() + seconds
        while True:
            try:
                at, line = self.lines.get(timeout=max(0.01, deadline - time.monotonic()))
            except queue.Empty:
                line, at = None, 0.0
            if line is not None:
                self.seen.append(line)
                m = re.search(pattern, line)
                if m:
                    return at, m
            if (line == "" and self.proc.poll() is not None) or time.monotonic() > deadline:
                self.kill()
                raise AssertionError(f"no line matching {pattern!r}; got {self.seen}, "
                                     f"stderr {self.proc.stderr.read()[-2000:]!r}")

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait(10)


def _board_sim(world: str, *extra: str, watchdog: float = 1.0,
               env: dict[str, str] | None = None) -> tuple[_Proc, str]:
    p = _Proc(["-m", "pyrt", "board-sim", world, "--listen", "127.0.0.1:0",
               "--watchdog", str(watchdog), *extra], env=env)
    _, m = p.expect(r"^pyrt board-sim: \w+ \w+ on (tcp://127\.0\.0\.1:\d+) ")
    assert p.seen == [m.group(0) + p.seen[0][len(m.group(0)):]]  # it was the first line
    return p, m.group(1)


#: A controller that drives the outputs, prints 'driving', then keeps polling.
CONTROLLER = """
import sys, time
from pyrt.boards import open_boards
from pyrt.boards.gripper import DAC
from pyrt.boards.tio10 import AWO_BITS, DIR_BITS
from pyrt.sim.world import GRIPPER_BOARDS, MANIPULATOR_BOARDS
kinds = GRIPPER_BOARDS if sys.argv[2] == "gripper" else MANIPULATOR_BOARDS
b = open_boards(sys.argv[1], sys.argv[2], kinds)
if sys.argv[2] == "gripper":
    b["gripper"].write(DAC, 0xC0)
else:
    tio = b["tio10"]
    tio.select_source(7, 3)
    tio.load_period(7, 5000)
    tio.set_bit(*DIR_BITS[7], True)
    tio.set_bit(*AWO_BITS[7], False)
    tio.arm(7)
b.poll(0)  # the first look takes the watchdog's count: done before any test stops us
print("driving", flush=True)
while True:
    try:
        b.poll(0)
    except Exception as exc:
        print(exc, flush=True)
    time.sleep(0.01)
"""


def _robot(world: str) -> str:
    return "gripper" if world == "gripper" else "manipulator"


def _outputs(url: str, world: str, deadline_s: float) -> dict[str, str]:
    """The world's INFO through a fresh connection (retrying while board-sim is busy)."""
    deadline = time.monotonic() + deadline_s
    while True:
        try:
            kinds = GRIPPER_BOARDS if world == "gripper" else MANIPULATOR_BOARDS
            with open_boards(url, _robot(world), kinds, max_age=0) as b:
                return b.info()
        except BoardError as exc:
            if "busy" not in str(exc) or time.monotonic() > deadline:
                raise
            time.sleep(0.005)


def _off(info: dict[str, str]) -> bool:
    if "dac" in info:
        return info["dac"] == str(DAC_NULL)
    return info["armed"] == "none" and info["windings_off"] == "1"


def _driving_controller(url: str, world: str) -> _Proc:
    c = _Proc(["-c", CONTROLLER, url, _robot(world)])
    c.expect("^driving$")
    return c


@pytest.mark.parametrize("world", ["gripper", "prototype"])
def test_killed_controller_leaves_the_outputs_off_on_the_disconnect(world):
    """SIGKILL of a controller that is driving: a fresh connection finds the outputs off
    (DAC null; every channel disarmed, windings off), turned off for the lost connection,
    not by the watchdog (60 s: it cannot have run out)."""
    sim, url = _board_sim(world, watchdog=60.0)
    try:
        ctl = _driving_controller(url, world)
        ctl.proc.send_signal(signal.SIGKILL)
        ctl.kill()
        info = _outputs(url, world, HANG_S)
        assert _off(info), info
        sim.expect(r"^controller \S+ (disconnected|lost \(.*\)): outputs off$", HANG_S)
        assert not any("watchdog:" in line for line in sim.seen)
    finally:
        sim.kill()


@pytest.mark.parametrize("world", ["gripper", "prototype"])
def test_hung_controller_trips_the_watchdog(world):
    """SIGSTOP of a controller that is driving (connected, silent): board-sim turns the outputs
    off after the watchdog time (0.3 s), not before; the controller, resumed, is told by a
    BoardError at its next poll; killed, it leaves the outputs off.  (How soon after the
    watchdog time it trips is a property of board-sim's clock: test_boards_generic.py.)"""
    sim, url = _board_sim(world, watchdog=0.3)
    ctl = _driving_controller(url, world)
    try:
        ctl.proc.send_signal(signal.SIGSTOP)
        _at, m = sim.expect(r"watchdog: no register access for ([0-9.]+) s: outputs off",
                            HANG_S)
        assert float(m.group(1)) >= 0.3  # never before its time, however late the check
        ctl.proc.send_signal(signal.SIGCONT)  # it wakes up and is told
        ctl.expect(re.escape(f"board {url}: the board's watchdog turned the outputs off"), HANG_S)
        ctl.proc.send_signal(signal.SIGKILL)
        ctl.kill()
        info = _outputs(url, world, HANG_S)
        assert _off(info), info
    finally:
        ctl.kill()
        sim.kill()


def test_killed_board_sim_makes_the_next_access_raise_board_error_naming_the_url():
    """SIGKILL of board-sim: the controller's next register access raises BoardError naming the
    URL (the link's own timeout bounds the wait), and so does every later one."""
    sim, url = _board_sim("gripper")
    boards = open_boards(url, "gripper", GRIPPER_BOARDS, max_age=0)
    try:
        boards["gripper"].write(DAC, 0x90)
        sim.kill()
        with pytest.raises(BoardError) as err:
            boards.poll(0)
        assert str(err.value).startswith(f"board {url}: SNAP: ")
        with pytest.raises(BoardError, match=re.escape(url)):
            boards["gripper"].read(P8155_PB)  # an input: nothing to answer it with
        with pytest.raises(BoardError, match=re.escape(url)):
            boards["gripper"].write(DAC, 0x90)  # driving again: refused
        boards["gripper"].write(DAC, DAC_NULL)  # the reflex's null: what the drop did
        assert boards["gripper"].read(DAC) == DAC_NULL
    finally:
        boards.close()
        sim.kill()


def test_manipulator_world_is_the_stations_and_sigterm_ends_it_with_outputs_off(tmp_path):
    """board-sim prototype --db DIR holds the world a controller on DIR expects (the same rope
    payouts as the in-process station); SIGTERM exits 0 saying the outputs are off."""
    from pyrt.station.manipulator import ManipulatorStation

    db = copy_station("prototype", tmp_path / "db")
    sim, url = _board_sim("prototype", "--db", str(db), "--ideal-sensors")
    try:
        info = _outputs(url, "prototype", HANG_S)
        local = ManipulatorStation(db, writer="sync").plant
        for i in range(len(local.ropes)):
            assert float(info[f"payout{i}"]) == pytest.approx(local.payout(i), abs=1e-4)
        sim.proc.send_signal(signal.SIGTERM)
        sim.expect(r"^pyrt board-sim: stopped, outputs off", HANG_S)
        assert sim.proc.wait(HANG_S) == 0
    finally:
        sim.kill()


def _term_ignored() -> None:
    signal.signal(signal.SIGTERM, signal.SIG_IGN)


@pytest.mark.parametrize("world", ["gripper", "prototype"])
def test_sigterm_sent_on_reading_the_address_stops_it_even_if_it_started_ignoring_sigterm(world):
    """A board-sim whose parent ignored SIGTERM (the ignore is inherited) takes the signal
    before it names its address: a SIGTERM sent the moment the first line is read is the
    orderly stop (outputs off, exit 0), never lost."""
    sim = _Proc(["-m", "pyrt", "board-sim", world, "--listen", "127.0.0.1:0"],
                preexec=_term_ignored)
    try:
        sim.expect(r"^pyrt board-sim: .* on tcp://")
        sim.proc.send_signal(signal.SIGTERM)
        sim.expect(r"^pyrt board-sim: stopped, outputs off", HANG_S)
        assert sim.proc.wait(HANG_S) == 0
    finally:
        sim.kill()


def test_help_tells_the_options_and_the_url():
    """pyrt board-sim --help names the stations, --listen, --watchdog, the tcp:// URL; with a
    station's name it adds that world's options; pyrt --help lists board-sim."""
    env = {**os.environ, "COLUMNS": "100"}

    def helps(*argv: str) -> str:
        return subprocess.run([sys.executable, "-m", "pyrt", "board-sim", *argv], env=env,
                              capture_output=True, text=True, timeout=START_S).stdout

    out = helps("--help")
    for word in (f"stations: {STATIONS}", "--listen HOST:PORT",
                 "--watchdog S", "tcp://HOST:PORT", "pyrt.boards.wire", "WorldFactory"):
        assert word in out, word
    out = helps("gripper", "--help")
    for word in ("--listen HOST:PORT", "--start HEX", "--object MM", "--fault"):
        assert word in out, word
    out = helps("sno", "--help")
    for word in ("--listen HOST:PORT", "--db DIR", "--station", "--ideal-sensors"):
        assert word in out, word
    top = subprocess.run([sys.executable, "-m", "pyrt", "--help"], env=env, capture_output=True,
                         text=True, timeout=START_S).stdout
    assert "board-sim" in top


@pytest.mark.parametrize(("argv", "message", "status"), [
    (["board-sim", "gripper", "--db", "somewhere"], "unrecognized arguments: --db somewhere", 2),
    (["board-sim", "sno", "--start", "F400"], "unrecognized arguments: --start F400", 2),
    (["board-sim", "hexapod"], "no station named 'hexapod' gives a world to serve; stations: "
                               + STATIONS, 2),
    (["board-sim"], "pyrt board-sim: error: name the station whose world to serve", 2),
    (["board-sim", "manipulator", "--station", "sno", "--db", "/nonexistent/db"],
     "/nonexistent/db", 1),
    (["board-sim", "gripper", "--object", "99"], "object width must be between 0 and 76 mm", 1),
    (["board-sim", "prototype", "--db", "/nonexistent/db"], "/nonexistent/db", 1),
])
def test_bad_options_end_with_one_line(capsys, argv, message, status):
    """Options of the other world, a bad object, a missing database: one line, no traceback;
    exit 2 for a command line that cannot be used, 1 for a world that cannot be made."""
    assert main(argv) == status
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err and err.count("\n") == 1


def test_a_station_of_ones_own_is_served_and_driven_over_tcp():
    """pyrt board-sim MODULE:FACTORY serves a two-joint arm's servo board (a plain kind) with
    its world's own option; a controller drives it over tcp:// and its counts come back; the
    first line names the station and its boards; SIGTERM turns the outputs off."""
    tests = os.path.dirname(os.path.abspath(__file__))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [tests, *filter(None, [os.environ.get("PYTHONPATH")])])}
    sys.path.insert(0, tests)
    try:
        from test_boards_generic import ARM_BOARDS
    finally:
        sys.path.remove(tests)
    sim, url = _board_sim("test_boards_generic:ArmStation", "--home", "1", env=env)
    try:
        assert "arm arm on " in sim.seen[0] and "(boards servo=arm-servo;" in sim.seen[0]
        with open_boards(url, "arm", ARM_BOARDS, max_age=0) as b:
            servo = b["servo"]
            assert servo.read("home") == 1
            servo.write("drive", 1000, 0)
            servo.write("enable", 1)
            deadline = time.monotonic() + HANG_S  # a bound for a hang only
            while servo.read("count", 0) < 50 and time.monotonic() < deadline:
                b.poll(0)
                time.sleep(0.005)
            assert servo.read("count", 0) >= 50 and servo.read("count", 1) == 0
        sim.expect(r"^controller \S+ said QUIT: outputs off$", HANG_S)
        sim.proc.send_signal(signal.SIGTERM)
        sim.expect(r"^pyrt board-sim: stopped, outputs off", HANG_S)
        assert sim.proc.wait(HANG_S) == 0
    finally:
        sim.kill()
