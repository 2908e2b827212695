"""The pyrt manipulator console: object commands, words, faults, piped scripts, grammar properties."""

from __future__ import annotations

import io
import os
import subprocess
import sys

import pytest
from _manipulator_rig import make_station
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pyrt.commands import RobotShell
from pyrt.console import Console
from pyrt.db import load_station


@pytest.fixture
def shell(tmp_path):
    station, runner = make_station(tmp_path)
    out = io.StringIO()
    sh = RobotShell(station, out)
    yield sh, station, runner, out
    station.close()


def run_lines(sh, runner, lines: list[str]) -> str:
    """Feed lines through the console as a piped script; its transcript."""
    out = sh.stdout
    start = out.tell()
    Console(sh, io.StringIO("".join(ln + "\n" for ln in lines)), out,
            messages=runner.messages).run()
    return out.getvalue()[start:]


def test_object_commands_are_case_insensitive(shell):
    """'PROTOTYPE Tensions' and 'prototype tensions' are the same command."""
    sh, _, runner, _ = shell
    text = run_lines(sh, runner, ["PROTOTYPE Tensions", "prototype tensions"])
    lines = [ln for ln in text.splitlines() if "desired tensions" in ln]
    assert len(lines) == 2 and lines[0] == lines[1]


def test_move_and_wait_reports_the_stop(shell):
    """'prototype to' starts a move; 'wait' prints the stop reason and where."""
    sh, station, runner, _ = shell
    text = run_lines(sh, runner, ["prototype to 30 0 120", "wait", "status"])
    assert "prototype: to (30, 0, 120): 1 segment, " in text
    assert "ENDPOINT_STOP: within" in text
    assert "pos (" in text and "distErr" in text and "net" in text and "T [" in text
    assert not station.motors_running()


def test_moves_queue_on_the_motion_queue(shell):
    """A second 'to' waits on the motion queue and runs when the first ends; 'wait' waits for both."""
    sh, station, runner, _ = shell
    text = run_lines(sh, runner, ["prototype to 10 0 100", "prototype to 20 0 110",
                                  "prototype to 0 0 100", "wait"])
    assert "prototype: to (20, 0, 110) queued (1 waiting)" in text
    assert "prototype: to (0, 0, 100) queued (2 waiting)" in text
    assert text.count("prototype stopped: ENDPOINT_STOP") == 3
    assert len(station.motion) == 0 and not station.polyaxis.active
    x, _, z = station.polyaxis.position
    assert abs(x) < 1.0 and abs(z - 100.0) < 1.0


def test_stop_drops_queued_moves(shell):
    """'prototype stop' ends the move and empties the motion queue."""
    sh, station, runner, _ = shell
    text = run_lines(sh, runner, ["prototype to 30 0 100", "prototype to 0 0 120", "sleep 5",
                                  "prototype stop", "sleep 2", "status"])
    assert "1 queued move(s) dropped" in text
    assert len(station.motion) == 0 and not station.polyaxis.active
    assert not station.motors_running()


def test_axis_commands_during_a_move(shell):
    """Under PolyAxis control device commands are refused (reads allowed); 'axisN stop' stops all."""
    sh, station, runner, _ = shell
    text = run_lines(sh, runner, ["prototype to 40 0 130", "sleep 5", "axis1 up 3",
                                  "axis1Encoder reset", "axis1Motor maxspeed 2",
                                  "axis1Encoder read", "axis1 stop", "wait"])
    assert text.count("error:") == 3
    assert "under prototype control" in text
    assert "axis1Encoder: " in text
    assert "the prototype move is stopped with it" in text
    assert "STOP: axis1 stop command" in text
    assert not station.motors_running() and not station.polyaxis.active


def test_sub_object_commands(shell):
    """Compound names reach the devices: axis0Encoder read, axis0Motor maxspeed, axis1 up."""
    sh, station, runner, _ = shell
    text = run_lines(sh, runner, ["axis0Encoder read", "axis0Motor maxspeed 3", "axis1 up 0.5",
                                  "wait", "axis0Loadcell calibrate", "axis0Loadcell point 5 kg",
                                  "axis0Loadcell calibrate"])
    assert "axis0Encoder: " in text and " cm" in text
    assert "axis0Motor: maximum speed 3 cm/s" in text
    assert "axis1: moving to length" in text and "axis1: move ended at length" in text
    assert "axis0Loadcell: calibration mode" in text and "axis0Loadcell: point: ADC " in text
    assert "need at least two calibration points" in text
    assert station.axes[0].motor.cruise_speed == 3.0


def test_help_lists_objects_and_their_commands(shell):
    """'help' names every object; 'help axis0' lists Table 4; 'help prototype' Table 2."""
    sh, _, runner, _ = shell
    text = run_lines(sh, runner, ["help", "help axis0", "help prototype", "help axis2Encoder"])
    for name in ("prototype", "axis0Motor", "axis2Loadcell", "PROTOVESSEL"):
        assert name in text
    for cmd in ("up DIST", "calibrate", "tensionFind", "netForce", "pattern FILE",
                "setZeroLength"):
        assert cmd in text


def test_refusals_print_one_error_and_move_nothing(shell):
    """Bad objects, commands, arguments and unreachable targets: one error line each."""
    sh, station, runner, _ = shell
    bad = ["frob", "axis9 up 3", "axis0 fly", "axis0 up", "axis0 up -3", "axis0 up x",
           "prototype to 1 2", "prototype to 0 0 1000", "prototype to nan 0 0",
           "axis0Motor maxspeed 99", "prototype to 60 0 380", "sim fault axis7 dead"]
    text = run_lines(sh, runner, bad)
    assert text.count("error:") == len(bad)
    assert "outside the vessel" in text and "allowed radius" in text
    assert not station.motors_running() and not station.polyaxis.active


def test_fault_then_ack(shell):
    """A dead loadcell mid-move: 'wait' shows the tension stop; motion refused until 'ack'."""
    sh, station, runner, _ = shell
    text = run_lines(sh, runner, ["prototype to 60 0 140", "sleep 10", "sim fault axis2 dead",
                                  "wait", "prototype to 0 0 100", "ack", "sim fault axis2 none",
                                  "prototype to 0 0 110", "prototype stop"])
    assert "FAULT: LOW_TENSION_STOP: axis2 tension" in text
    assert "give 'ack' first; nothing moved" in text
    assert "fault acknowledged" in text
    assert "prototype: stopped" in text
    assert not station.motors_running()


def test_log_toggle_and_debug(shell, tmp_path):
    """'log FILE' records S/R lines each poll of a move; 'log' again closes it; 'debug' toggles."""
    sh, _, runner, _ = shell
    path = tmp_path / "m.log"
    text = run_lines(sh, runner, [f"log {path}", "prototype to 10 0 100", "wait", "log",
                                  "debug", "sleep 2", "debug"])
    assert f"logging on: {path}" in text and "logging off" in text
    assert "debugging on" in text and "debugging off" in text
    assert text.count("t=") >= 2  # status lines while debugging
    body = path.read_text().splitlines()
    assert sum(ln.startswith("S ") for ln in body) > 30
    assert sum(ln.startswith("R ") for ln in body) > 30


def test_pattern_from_the_console(shell, tmp_path):
    """'prototype pattern FILE' runs the pattern; 'wait' waits for all of it."""
    sh, _, runner, _ = shell
    pat = tmp_path / "p.pat"
    pat.write_text("p.log\n0 0 105\n8 0 105\n")
    text = run_lines(sh, runner, [f"prototype pattern {pat}", "wait"])
    assert "pattern finished: 2 endpoints" in text
    assert (tmp_path / "p.log").read_text().count("ENDPOINT_STOP") == 2


def test_pattern_excludes_other_moves_and_stop_ends_it(shell, tmp_path):
    """While a pattern runs 'to' is refused; 'prototype stop' ends the pattern; the log says so."""
    sh, station, runner, _ = shell
    pat = tmp_path / "q.pat"
    pat.write_text("q.log\n30 0 120\n0 0 100\n")
    text = run_lines(sh, runner, [f"prototype pattern {pat}", "sleep 5", "prototype to 0 0 110",
                                  f"prototype pattern {pat}", "prototype stop", "wait"])
    assert "a pattern is running" in text and "already running" in text
    log = (tmp_path / "q.log").read_text()
    assert " STOP at " in log and "pattern abandoned after endpoint 1: STOP" in log
    assert not station.motors_running() and not station.busy()


def test_stats_and_sim(shell):
    """'stats' shows the routines' timing; 'sim' the true position."""
    sh, _, runner, _ = shell
    text = run_lines(sh, runner, ["sleep 1", "stats", "sim"])
    assert "POLYAXIS" in text and "AXES" in text
    assert "true position" in text


def test_quit_stops_every_motor(shell):
    """'quit' stops all motors, then ends the session."""
    sh, station, runner, _ = shell
    text = run_lines(sh, runner, ["prototype to 40 0 130", "sleep 10", "quit", "status"])
    assert "pos (" not in text.split("quit")[-1]
    assert not station.motors_running() and not station.polyaxis.active


def test_piped_cli_transcript(tmp_path):
    """'pyrt manipulator --speed max' without --db copies the station, runs a script, writes back."""
    env = dict(os.environ, PYRT_HOME=str(tmp_path))
    script = "status\nprototype to 20 0 110\nwait\nquit\n"
    proc = subprocess.run([sys.executable, "-m", "pyrt", "manipulator", "--speed", "max"],
                          input=script, capture_output=True, text=True, env=env, timeout=120)
    assert proc.returncode == 0, proc.stderr
    work = tmp_path / "stations" / "prototype"
    assert f"working copy of the prototype station in {work}" in proc.stdout
    assert "ENDPOINT_STOP" in proc.stdout
    pos = load_station(work).polyaxis().position
    assert abs(pos[0] - 20.0) < 1.0 and abs(pos[2] - 110.0) < 1.0


def test_wall_clock_run(tmp_path):
    """On a wall clock (--speed 2) the loop runs in its own thread; a script still completes."""
    env = dict(os.environ, PYRT_HOME=str(tmp_path))
    # The move takes 16 s of loop time (8 s here); the wait's and the run's bounds catch a hang
    # only.  A slow speed: at 50x the 0.1 ms ticks of a loaded machine are mostly skipped.
    script = "prototype to 5 0 100\nwait 900\nquit\n"
    proc = subprocess.run([sys.executable, "-m", "pyrt", "manipulator", "--speed", "2"],
                          input=script, capture_output=True, text=True, env=env, timeout=600)
    assert proc.returncode == 0, proc.stderr
    assert "ENDPOINT_STOP" in proc.stdout
    pos = load_station(tmp_path / "stations" / "prototype").polyaxis().position
    assert abs(pos[0] - 5.0) < 1.0


# -- properties -----------------------------------------------------------------------

_OBJECTS = ["prototype", "axis0", "axis1", "axis2", "axis0Motor", "axis1Encoder",
            "axis2Loadcell", "protovessel", "nothing"]
_WORDS = sorted({"to", "tensionfind", "tensions", "netforce", "pattern", "stop", "tensionstop",
                 "errorsignalall", "up", "down", "calibrate", "point", "maxspeed", "zero",
                 "reset", "read", "readloop", "stoploop", "setzerolength", "show",
                 "fly", "", "tO"})
_NUMBERS = st.one_of(st.floats(allow_nan=True, allow_infinity=True).map(repr),
                     st.integers(-10**6, 10**6).map(str), st.sampled_from(["x", "1e999", "-0",
                                                                             "3 kg", "0x10"]))
_TOPLEVEL = ["help", "status", "stats", "sim", "ack", "debug", "sim fault axis1 dead",
             "sim fault 9 slip 2", "sim fault axis0 none"]


def _case(s: str, flips: list[bool]) -> str:
    return "".join(c.upper() if f else c.lower() for c, f in zip(s, flips + [False] * len(s),
                                                                  strict=False))


_LINE = st.one_of(
    st.tuples(st.sampled_from(_OBJECTS), st.sampled_from(_WORDS),
              st.lists(_NUMBERS, max_size=5), st.lists(st.booleans(), max_size=12)).map(
        lambda t: " ".join([_case(t[0], t[3]), _case(t[1], t[3][::-1]), *t[2]])),
    st.sampled_from(_TOPLEVEL),
    st.binary(max_size=40).map(lambda b: b.decode("utf-8", errors="replace")),
    st.text(max_size=30),
)


@settings(max_examples=int(os.environ.get("PYRT_GRAMMAR_EXAMPLES", "100")), deadline=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(line=_LINE)
def test_grammar_never_crashes_and_refusals_move_nothing(tmp_path_factory, line):
    """Any line on a fresh station: no exception escapes; after a refused command no motor moves."""
    words = line.split()
    if words and words[0].lower() in ("sleep", "wait", "log", "quit"):
        return
    station, runner = make_station(tmp_path_factory.mktemp("prop"))
    try:
        sh = RobotShell(station, io.StringIO())
        side = station.boards.simulated["tio10"]  # the world's TIO10: its outputs as they stand
        before = [side.values(r.name) for r in side.kind.outputs()]
        sh.onecmd(line)
        runner.sleep(0.05)
        out = sh.stdout.getvalue()
        if "error:" in out:
            assert not station.motors_running()
            assert not station.polyaxis.active
            if "nothing moved" in out:
                assert [side.values(r.name) for r in side.kind.outputs()] == before
    finally:
        station.close()


def test_nonsense_length_is_refused_and_nothing_written(shell):
    """A zero length set by hand is outside the rope's range: one error, nothing written."""
    sh, station, runner, _ = shell
    enc = station.directory / "ENCODER.dat"
    before = enc.read_text()
    text = run_lines(sh, runner, ["axis1Encoder setZeroLength 0", "sleep 12", "status"])
    assert text.count("error:") == 1
    assert "LEN 0 is out of range: LEN " in text and "nothing changed" in text
    assert "FAULT" not in text and station.fault is None
    assert enc.read_text() == before
    assert text.rstrip().splitlines()[-2].startswith("t=")


def test_stops_are_reported_as_they_happen(shell):
    """A move that ends while nobody waits is reported at the next prompt."""
    sh, _, runner, _ = shell
    text = run_lines(sh, runner, ["prototype to 5 0 100", "sleep 40", "status"])
    assert "prototype stopped: ENDPOINT_STOP" in text


def test_terminal_session_with_history(tmp_path):
    """On a terminal: prompt, an object command, the up arrow recalls it, quit exits cleanly."""
    pexpect = pytest.importorskip("pexpect")
    env = dict(os.environ, PROMPT_TOOLKIT_NO_CPR="1", TERM="xterm", PYRT_HOME=str(tmp_path))
    child = pexpect.spawn(sys.executable, ["-m", "pyrt", "manipulator", "--speed", "max"],
                          encoding="utf-8", timeout=30, dimensions=(24, 160), env=env)
    try:
        child.expect("prototype>")
        child.sendline("prototype tensions")
        child.expect("desired tensions axis0")
        child.expect("prototype>")
        child.send("\x1b[A")  # up arrow: the last command again
        child.send("\r")
        child.expect("desired tensions axis0")
        child.expect("prototype>")
        child.sendline("quit")
        child.expect(pexpect.EOF)
    finally:
        child.close()
    assert child.exitstatus == 0


def test_scope_captures_any_signal_by_object_name(shell):
    """'scope add prototype.x axis0.tension' captures the move: x climbs toward the target."""
    sh, _, runner, _ = shell
    text = run_lines(sh, runner, ["scope add prototype.x axis0.tension", "scope run roll",
                                  "prototype to 10 0 100", "sleep 20", "scope stop",
                                  "scope show 4000"])
    assert "scope channels: prototype.x, axis0.tension" in text
    rows = text.split("t_s prototype.x axis0.tension\n", 1)[1].splitlines()
    samples = [tuple(map(float, r.split())) for r in rows if r and r[0].isdigit()]
    assert len(samples) > 500
    xs = [x for _, x, _ in samples]
    assert xs[-1] - xs[0] > 8.0 and all(t > 2.0 for _, _, t in samples)


def test_completion_table_names_only_what_resolves(shell):
    """Every object verb, help topic and scope channel the completer offers is accepted."""
    from pyrt.console.base import complete

    sh, station, _, _ = shell
    table = sh.completions()
    for obj, verbs in table.items():
        for verb in verbs or {}:
            if obj in ("help", "status", "motion", "scope"):
                continue
            comp, rec, _, _ = sh.resolve(f"{obj} {verb}")
            assert comp.name == obj and rec.answers_to(verb)
    for channel in complete(table, "scope add "):
        station.resolve_signal(channel)
    assert complete(table, "PROTOTYPE T") == ["tensionFind", "tensionStop", "tensions", "to"]
    assert complete(table, "scope add prototype.x axis0.ten") == ["axis0.tension"]
    assert "prototype" in complete(table, "help p") and complete(table, "nosuch ") == []


def test_wait_prints_the_stop_reason_once_and_in_order(shell):
    """'wait' says why the move ended exactly once; stops of earlier queued moves come first."""
    sh, _, runner, _ = shell
    text = run_lines(sh, runner, ["prototype to 10 0 100", "wait"])
    assert text.count("ENDPOINT_STOP") == 1 and "prototype stopped: ENDPOINT_STOP" in text
    text = run_lines(sh, runner, ["prototype to 0 0 100", "prototype to 5 0 100", "wait"])
    stops = [ln for ln in text.splitlines() if "stopped: " in ln]
    assert len(stops) == 2 and "(0.0" in stops[0] and "(5.0" in stops[1]


def test_pattern_from_a_device_or_a_huge_file_is_refused(shell, tmp_path):
    """'prototype pattern /dev/zero' and a pattern over 1 MiB: one error each, read no further."""
    sh, station, runner, _ = shell
    big = tmp_path / "big.pat"
    big.write_bytes(b"log.txt\n" + b"0 0 100\n" * (1 << 17))
    text = run_lines(sh, runner, ["prototype pattern /dev/zero", f"prototype pattern {big}"])
    assert "error: pattern: '/dev/zero': not a regular file" in text
    assert "more than the 1048576 bytes allowed" in text
    assert text.count("error:") == 2
    assert not station.motors_running()


def test_a_fault_during_wait_is_shown_once_and_the_closing_line_says_what_was_kept(tmp_path):
    """pyrt manipulator: a slip during a move is printed once by wait (not again by the
    message pump); after ack, the closing line says POSITION, LENGTH and ZEROLENGTH kept
    their last trusted values."""

    script = "prototype to 0 0 40\nsleep 5\nsim fault 0 slip 1.0\nwait\nstatus\nack\n"
    done = subprocess.run([sys.executable, "-m", "pyrt", "manipulator", "--speed", "max",
                           "--init-db", str(tmp_path / "db"), "-k"], input=script,
                          capture_output=True, text=True, timeout=120)
    # the fault fails the piped script at its wait: status 1 (-k: it runs to its end)
    assert done.returncode == 1, done.stderr
    assert "stdin:4: 'wait' failed: FAULT" in done.stderr
    out = done.stdout
    assert out.count("position estimate lost") == 3  # wait, status, ack: once each
    assert out.count("nothing moves until you type ack") == 1
    assert out.rstrip().splitlines()[-1].endswith(
        "except POSITION, LENGTH and ZEROLENGTH (the position estimate is not trusted: they "
        "keep the values last written before it was lost)")


def test_stop_says_where_the_source_stopped_and_the_world_agrees(shell):
    """'stop' mid-move: every motor stopped, and the line gives the source's position, which
    is the estimate and within the endpoint tolerance of the simulated source."""
    import math
    import re

    sh, station, runner, _ = shell
    text = run_lines(sh, runner, ["prototype to 0 0 60", "sleep 6", "stop"])
    m = re.search(r"prototype: every motor stopped; source at \((\S+), (\S+), (\S+)\) cm\n", text)
    assert m, text
    said = tuple(float(v) for v in m.groups())
    assert not station.motors_running()
    assert math.dist(said, station.polyaxis.position) < 0.01
    assert math.dist(said, station.plant.position) <= station.polyaxis.end_error
    assert said[2] < 94.5  # it had moved down from 95.57 before the stop


def test_one_number_grammar_for_every_argument(shell):
    """'to 0 0 50mm' is 5 cm; '1_0' is refused alike by 'axis0 up' and 'netForce'; a load takes '30N'."""
    sh, station, runner, _ = shell
    pa = station.polyaxis
    text = run_lines(sh, runner, ["prototype netForce 0 0 1000mm", "prototype netForce 0 0 100"])
    said = [ln for ln in text.splitlines() if "net force" in ln]
    assert len(said) == 2 and said[0] == said[1]
    text = run_lines(sh, runner, ["axis0 up 1_0", "prototype netForce 1_0 0 5_0",
                                  "prototype to 0 0 5kg", "prototype to 0 0 1_000mm"])
    errors = [ln for ln in text.splitlines() if ln.startswith("error")]
    assert len(errors) == 4, text
    assert all("optional length unit (cm, ft, in, inch, m, mm)" in e for e in errors), errors
    assert not station.motors_running() and not pa.active
    x0 = pa.position
    text = run_lines(sh, runner, [f"prototype to {x0[0]:.3f} {x0[1]:.3f} {x0[2] * 10 - 5:.3f}mm",
                                  "wait"])
    assert "ENDPOINT_STOP" in text, text
    assert abs(pa.position[2] - (x0[2] - 0.5)) < 1.0
    text = run_lines(sh, runner, ["sim load axis0 30N", "sim unload axis0"])
    assert "error" not in text, text
