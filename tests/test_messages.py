"""Operator messages are events, and a component fails the same way adopted or not."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import pyrt
from pyrt import Component, Station
from pyrt.component import Message
from pyrt.errors import FaultError
from pyrt.scheduler import Loop, SimClock

PACKAGE = Path(pyrt.__file__).parent
#: The packages below pyrt.commands (the layers of pyproject.toml).
BELOW_COMMANDS = ("station", "robots", "tasks", "devices", "sim", "boards", "component.py",
                  "db", "scope", "client", "scheduler", "journal", "native", "units.py",
                  "fileio.py", "errors.py", "_version.py")


class Winch(Component):
    """A component with an actuator whose reflex is recorded."""

    name = "winch"

    def __init__(self) -> None:
        self.stopped = 0
        self.drum = Drum()

    def children(self) -> list[Component]:
        return [self.drum]

    def reflex(self) -> None:
        self.stopped += 1


class Drum(Component):
    name = "drum"

    def __init__(self) -> None:
        self.stopped = 0

    def reflex(self) -> None:
        self.stopped += 1


def _station(root: Component) -> Station:
    st = Station(Loop(SimClock(), period_ns=1_000_000))
    st.name = "rig"
    st.adopt(root)
    return st


def test_a_message_carries_its_source_level_and_text():
    """say() makes one Message (source = the component, a level, the text); a bad level is refused."""
    w = Winch()
    w.say("drum full", "warning")
    (m,) = w.held_messages()
    assert m == Message("winch", "warning", "drum full") and str(m) == "drum full"
    with pytest.raises(ValueError, match="level"):
        w.say("x", "loud")


def test_the_station_publishes_messages_to_subscribers_the_console_and_the_log(caplog):
    """A message said before and after adoption reaches a subscriber, the runner's lines and the log."""
    w = Winch()
    w.drum.say("said while being built")
    st = _station(w)
    heard: list[Message] = []
    unsubscribe = st.subscribe(heard.append)
    with caplog.at_level("INFO", logger="pyrt.messages"):
        w.say("hello", "error")
    assert heard == [Message("winch", "error", "hello")]
    assert st.runner is not None
    assert st.runner.messages() == ["said while being built", "hello"]
    assert ("pyrt.messages", 40, "winch: hello") in caplog.record_tuples
    unsubscribe()
    w.say("again")
    assert heard == [Message("winch", "error", "hello")]


def test_a_failing_subscriber_is_dropped_and_the_others_still_hear():
    """A subscriber that raises is dropped; the console's lines still come."""
    w = Winch()
    st = _station(w)

    def broken(_m: Message) -> None:
        raise RuntimeError("gone")

    st.subscribe(broken)
    w.say("one")
    w.say("two")
    assert st.runner is not None
    assert st.runner.messages() == ["one", "two"]


def test_fail_before_adoption_runs_the_reflex_and_raises_to_the_builder():
    """Not adopted: fail() stops every actuator below the component and raises FaultError."""
    w = Winch()
    with pytest.raises(FaultError, match="rope jammed") as info:
        w.fail("rope jammed")
    assert info.value.fault.source == "winch"
    assert (w.stopped, w.drum.stopped) == (1, 1)


def test_fail_after_adoption_trips_the_station_once():
    """Adopted: fail() is the station's trip (every reflex in this tick); no exception at the component."""
    w = Winch()
    st = _station(w)
    w.drum.fail("drum slipped")
    assert st.fault is not None and st.fault.cause == "drum slipped"
    assert st.fault.source == "drum"
    assert (w.stopped, w.drum.stopped) == (1, 1)


def _modules_below_commands() -> list[Path]:
    out: list[Path] = []
    for part in BELOW_COMMANDS:
        path = PACKAGE / part
        out += [path] if path.suffix == ".py" else sorted(path.rglob("*.py"))
    return out


def test_no_module_below_the_commands_takes_or_writes_a_stdout():
    """No function below pyrt.commands takes a stdout, and none reads or writes one (.stdout, sys.stdout)."""
    found = []
    modules = _modules_below_commands()
    assert len(modules) > 50  # the walk found the packages
    for path in modules:
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        rel = path.relative_to(PACKAGE.parent)
        for node in ast.walk(tree):
            if isinstance(node, ast.arg) and node.arg == "stdout":
                found.append(f"{rel}:{node.lineno}: parameter stdout")
            elif isinstance(node, ast.Attribute) and node.attr == "stdout":
                found.append(f"{rel}:{node.lineno}: .stdout")
            elif isinstance(node, ast.Name) and node.id == "stdout":
                found.append(f"{rel}:{node.lineno}: stdout")
    assert found == []
