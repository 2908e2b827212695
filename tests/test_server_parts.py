"""The server's parts: the loop hub, loopback detection, token reading, service options."""

from __future__ import annotations

import argparse
import logging

import pytest

from pyrt.cli._serve import add_serve_options, prepare_service, read_token
from pyrt.errors import ConfigError, Fault
from pyrt.scheduler import Loop, SimClock
from pyrt.scope import Source
from pyrt.server import StatusHub, is_loopback


class _Thing:
    x = 0.0


def _hub(every: int = 1) -> tuple[StatusHub, _Thing, Loop]:
    thing = _Thing()
    hub = StatusHub(["x"], [Source.attr(thing, "x")], snapshot_every=every)
    loop = Loop(SimClock())
    loop.attach(lambda now: setattr(thing, "x", now / 1e6), name="ramp")
    loop.attach(hub, name="server")
    loop.fault_listeners.append(hub.on_fault)
    return hub, thing, loop


def test_hub_publishes_a_snapshot_every_n_ticks():
    """The snapshot is (time, tick, values) of the latest Nth tick."""
    hub, _thing, loop = _hub(every=5)
    assert hub.snapshot == (0, -1, None)
    loop.run(12)
    t_ns, tick, values = hub.snapshot
    assert tick == 9 and t_ns == 10_000_000 and values == (10.0,)


def test_hub_spews_per_subscriber_and_stops_on_unsubscribe():
    """A subscription at 100 Hz on a 1 ms loop hands on every 10th tick; unsubscribing stops it."""
    hub, _thing, loop = _hub()
    hub.subscribe("a", 100.0)
    loop.run(50)
    events = hub.drain()
    assert [e[0] for e in events] == ["sample"] * 5 and {e[1] for e in events} == {"a"}
    assert [e[3][0] for e in events] == [1.0, 11.0, 21.0, 31.0, 41.0]
    assert hub.unsubscribe("a") and not hub.unsubscribe("a") and hub.subscribers == 0
    loop.run(50)
    assert hub.drain() == []


def test_hub_pushes_faults_at_once():
    """A fault recorded by the loop is an event and the hub's last fault."""
    hub, _thing, _loop = _hub()
    fault = Fault(robot="r", cause="boom", tick=3, time_ns=3_000_000)
    hub.on_fault(fault)
    assert hub.drain() == [("fault", None, 3_000_000, fault)] and hub.last_fault is fault


def test_hub_refuses_bad_settings():
    """Mismatched names and sources or snapshot_every < 1 are ValueErrors."""
    with pytest.raises(ValueError):
        StatusHub(["a", "b"], [Source.call(lambda: 1.0)])
    with pytest.raises(ValueError):
        StatusHub(["a"], [Source.call(lambda: 1.0)], snapshot_every=0)


@pytest.mark.parametrize(("host", "loopback"), [
    ("127.0.0.1", True), ("localhost", True), ("::1", True), ("127.1.2.3", True),
    ("0.0.0.0", False), ("", False), ("::", False), ("192.0.2.1", False),
    ("no-such-host.invalid", False),
])
def test_is_loopback(host, loopback):
    """Only names that resolve to loopback addresses alone count as loopback."""
    assert is_loopback(host) is loopback


def test_read_token_from_file_or_environment(tmp_path, monkeypatch):
    """The token file's first line wins over PYRT_TOKEN; neither means no token."""
    monkeypatch.delenv("PYRT_TOKEN", raising=False)
    assert read_token(None) is None
    monkeypatch.setenv("PYRT_TOKEN", "  env-token-0123456789 \n")
    assert read_token(None) == "env-token-0123456789"
    f = tmp_path / "t"
    f.write_text("file-token-0123456789\nsecond line\n")
    f.chmod(0o600)
    assert read_token(str(f)) == "file-token-0123456789"


@pytest.mark.parametrize("content", ["", "\n", "two words\n", "x" * 300 + "\n"])
def test_read_token_refuses_bad_files(tmp_path, content):
    """An empty first line, a token with spaces or an over-long one is a ConfigError."""
    f = tmp_path / "t"
    f.write_text(content)
    f.chmod(0o600)
    with pytest.raises(ConfigError):
        read_token(str(f))
    with pytest.raises(ConfigError, match="cannot read"):
        read_token(str(tmp_path / "missing"))


def _args(*argv: str) -> argparse.Namespace:
    p = argparse.ArgumentParser()
    add_serve_options(p)
    return p.parse_args(list(argv))


def test_service_options_are_checked_before_anything_starts(monkeypatch):
    """--headless without --serve, --token-file alone, a bad address: ConfigError; no options: no service."""
    monkeypatch.delenv("PYRT_TOKEN", raising=False)
    assert prepare_service(_args(), None, None) is None
    for argv in (["--headless"], ["--token-file", "x"], ["--serve", "host:port"]):
        with pytest.raises(ConfigError):
            prepare_service(_args(*argv), None, None)


@pytest.mark.parametrize(("argv", "level"), [([], logging.WARNING), (["--verbose"], logging.INFO)])
def test_epics_option_sets_caprotos_logger_by_verbose(monkeypatch, argv, level):
    """--epics keeps caproto's per-connect INFO lines out of the log unless --verbose."""
    pytest.importorskip("caproto")
    from _gripper_rig import make_rig

    from pyrt.server import ServedStation

    monkeypatch.delenv("PYRT_TOKEN", raising=False)
    logging.getLogger("caproto").setLevel(logging.NOTSET)
    rig = make_rig()
    service = prepare_service(_args("--epics", "T:", *argv), rig.runner,
                              ServedStation(rig.station))
    assert service is not None and service.epics is not None
    assert logging.getLogger("caproto").getEffectiveLevel() == level
    assert "T:STOP" in service.epics.pvdb
