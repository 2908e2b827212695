"""EPICS Channel Access under abuse: closed by default, escaped names, back-off, one master, fuzz.

Everything on 127.0.0.1 with ports of each test's own (the ``epics_env``
fixture of test_epics); the Channel Access clients that flood or forge run
in a subprocess.  Skipped when caproto is not installed.
"""

from __future__ import annotations

import asyncio
import json
import os
import random
import subprocess
import sys
import time
from pathlib import Path

import pytest
from _server_rig import TOKEN, served
from test_epics import PREFIX, _read, _text, _until, _write, epics_env, epics_served

from pyrt.errors import ConfigError

__all__ = ["epics_env"]  # the fixture, imported for these tests

pytest.importorskip("caproto")

#: A Channel Access client in a process of its own: writes ``[pv, value, wait]`` in
#: order (a value is text, or a list of numbers), claiming host and user names;
#: prints one JSON list: after each write, "ok" or the exception's name, and
#: RESULT's text when ``read_result``.
_CLIENT = r'''
import json, sys
from caproto.threading.client import Context
host, user, prefix, read_result = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4] == "1"
writes = json.loads(sys.stdin.read())
ctx = Context(host_name=host, client_name=user)
names = sorted({w[0] for w in writes} | {"RESULT"})
pvs = dict(zip(names, ctx.get_pvs(*[prefix + n for n in names], timeout=10)))
for pv in pvs.values():
    pv.wait_for_connection(timeout=10)
out = []
for name, value, wait in writes:
    data = value.encode("utf-8", "surrogateescape") if isinstance(value, str) else value
    try:
        pvs[name].write(data, wait=wait, timeout=5)
        got = "ok"
    except Exception as exc:
        got = type(exc).__name__
    if read_result:
        got += " " + bytes(pvs["RESULT"].read(timeout=5).data).rstrip(b"\0").decode("utf-8", "replace")
    out.append(got)
ctx.disconnect()
print(json.dumps(out))
'''


def _ca_client(writes: list, host: str = "pyrt-test", user: str = "pyrt-test",
               read_result: bool = False, timeout_s: float = 240) -> list[str]:
    proc = subprocess.run([sys.executable, "-c", _CLIENT, host, user, PREFIX,
                           "1" if read_result else "0"], input=json.dumps(writes),
                          capture_output=True, text=True, timeout=timeout_s,
                          env={**os.environ, "PYTHONIOENCODING": "utf-8"})
    assert proc.returncode == 0, proc.stderr[-2000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _tcp_listeners(port: int) -> set[str]:
    """The local addresses with a TCP socket listening on ``port`` (Linux /proc)."""
    found = set()
    for table, width in (("/proc/net/tcp", 8), ("/proc/net/tcp6", 32)):
        if not Path(table).exists():
            continue
        for line in Path(table).read_text().splitlines()[1:]:
            fields = line.split()
            local, state = fields[1], fields[3]
            addr_hex, port_hex = local.split(":")
            if state != "0A" or int(port_hex, 16) != port:
                continue
            raw = bytes.fromhex(addr_hex)
            if width == 8:
                found.add(".".join(str(b) for b in raw[::-1]))
            else:
                found.add("::" if not any(raw) else "::1" if raw == bytes(15) + b"\1"
                          else raw.hex())
    return found


# -- closed by default ------------------------------------------------------------------------

@pytest.mark.skipif(not Path("/proc/net/tcp").exists(), reason="reads /proc/net/tcp (Linux)")
def test_epics_listens_on_loopback_unless_an_interface_is_named(epics_env, monkeypatch):
    """No interface named (and no EPICS_CAS_INTF_ADDR_LIST): the IOC listens on 127.0.0.1
    only, not on every interface as caproto would; it serves there."""
    from pyrt.server.epics import EpicsService

    monkeypatch.delenv("EPICS_CAS_INTF_ADDR_LIST")
    with served() as sv:
        ioc = EpicsService(sv.runner, sv.server.robot, sv.server, PREFIX, token=TOKEN,
                           period_s=0.02, stats_period_s=0.2)
        assert ioc.interfaces == ["127.0.0.1"] and ioc.summary.endswith("on 127.0.0.1")
        ioc.start()
        try:
            assert _tcp_listeners(epics_env) == {"127.0.0.1"}
            assert _read("FAULT")[0] == b"no"
        finally:
            ioc.close()


def test_epics_beyond_loopback_needs_a_token_and_a_long_one(epics_env):
    """An interface beyond loopback without a token is refused at construction, with the
    reason; with a short token too; loopback without a token is allowed (STOP only)."""
    from pyrt.server.epics import EpicsService

    with served(token=None) as sv:
        for where in (["0.0.0.0"], ["127.0.0.1", "192.0.2.1"]):
            with pytest.raises(ConfigError, match="without a token"):
                EpicsService(sv.runner, sv.server.robot, sv.server, PREFIX, interfaces=where)
        with pytest.raises(ConfigError, match="at least 16"):
            EpicsService(sv.runner, sv.server.robot, sv.server, PREFIX, token="short",
                         interfaces=["0.0.0.0"])
        ioc = EpicsService(sv.runner, sv.server.robot, sv.server, PREFIX)
        assert "no token" in ioc.summary


@pytest.mark.parametrize("how", ["option", "environment"])
def test_pyrt_epics_beyond_loopback_without_a_token_exits_with_the_reason(tmp_path, how):
    """pyrt gripper --epics P: --epics-interface 0.0.0.0 (or EPICS_CAS_INTF_ADDR_LIST=0.0.0.0)
    without a token: exit 1 naming the reason, nothing served."""
    env = {k: v for k, v in os.environ.items() if k != "PYRT_TOKEN"}
    args = ["gripper", "--epics", "PYRTDOORS:", "--headless", "--speed", "max"]
    if how == "option":
        args += ["--epics-interface", "0.0.0.0"]
    else:
        env["EPICS_CAS_INTF_ADDR_LIST"] = "0.0.0.0"
    proc = subprocess.run([sys.executable, "-m", "pyrt", *args], stdin=subprocess.DEVNULL,
                          capture_output=True, text=True, env=env, cwd=tmp_path, timeout=120)
    assert proc.returncode == 1, proc
    assert "without a token" in proc.stderr and "Traceback" not in proc.stderr


def test_a_dead_epics_thread_is_a_fault_the_operator_sees(epics_env, monkeypatch):
    """The IOC's thread fails while serving: the station is tripped naming EPICS (every motor
    stopped), and the service records the error."""
    from pyrt.server.epics import EpicsService

    async def broken(self: EpicsService) -> None:
        await asyncio.sleep(0.3)  # serving, then failing
        raise RuntimeError("the IOC's update loop is broken")

    monkeypatch.setattr(EpicsService, "_update", broken)
    with served() as sv:
        ioc = EpicsService(sv.runner, sv.server.robot, sv.server, PREFIX, token=TOKEN,
                           period_s=0.02)
        ioc.start()
        try:
            fault = _until(lambda: sv.runner.call(lambda: sv.rig.fault, take_fault=False), 10)
            assert fault is not None and "EPICS server has stopped" in fault.cause
            assert isinstance(ioc.error, RuntimeError) and sv.still_and_null()
        finally:
            ioc.close()


# -- an audit trail that holds ------------------------------------------------------------------


def _audit_lines(sv) -> list[str]:
    """The served station's audit lines said since the last call (the runner's messages)."""
    return [str(m) for m in sv.runner.messages() if str(m).startswith("remote: ")]


EVIL_HOST = "ops\n2026-01-01 00:00:00,000 EPICS CMD: P 0000\x1b[2J\x1b]0;owned\x07"
EVIL_USER = "root\r\x1b[31mforged"


def test_claimed_host_and_user_names_reach_the_audit_trail_escaped(epics_env, caplog):
    """A client claiming a host name with a line end and terminal escapes writes a read-only
    PV and CMD with a wrong token: each refusal is one audit line naming its real address,
    the names escaped (no line end, no ESC) in the audit lines and in every log record."""
    import logging

    caplog.set_level(logging.INFO)
    with epics_served() as (sv, _ioc):
        _audit_lines(sv)  # what came before
        _ca_client([["POSITION", [5.0], False], ["CMD", "wrong P E47A", True]],
                   host=EVIL_HOST, user=EVIL_USER)
        audit: list[str] = []
        deadline = time.monotonic() + 10
        while len(audit) < 2 and time.monotonic() < deadline:  # both refusals, in any order
            audit += [ln for ln in _audit_lines(sv) if "refused" in ln]
            time.sleep(0.05)
        assert len(audit) == 2, audit
        for ln in audit:
            assert "\n" not in ln and "\r" not in ln and "\x1b" not in ln and "\x07" not in ln
            assert "127.0.0.1:" in ln and "\\x0a2026-01-01" in ln and "\\x1b[2J" in ln
        assert any("to PYRTTEST:POSITION" in ln for ln in audit)
        assert sv.runner.call(sv.ctl.target) == 0
        for rec in caplog.records:
            msg = rec.getMessage()
            assert "\x1b" not in msg and "\n2026-01-01" not in msg, msg


WRONG_WRITES = 300


def test_wrong_token_writes_back_off_and_are_summarised(epics_env):
    """300 CMD writes with wrong tokens from one client: a few audit lines, then the address
    backs off (even the right token is refused unread), one summary names the count and the
    address, and nothing ever ran."""
    with epics_served() as (sv, _ioc):
        _audit_lines(sv)  # what came before
        writes = [["CMD", f"guess-{i:04d}-abcdefghijkl P E47A", True] for i in range(WRONG_WRITES)]
        writes.append(["CMD", f"{TOKEN} X 33", True])
        results = _ca_client(writes, read_result=True)
        assert len(results) == WRONG_WRITES + 1
        assert all(r.startswith("ok ERR auth") for r in results), set(results)
        compared = [r for r in results if "wrong token" in r]
        assert len(compared) <= 12, len(compared)  # the rest refused unread
        assert "too many refused writes from 127.0.0.1" in results[-1]  # the right token too
        sv.server.guard.flush(force=True)
        audit = [ln for ln in _audit_lines(sv) if "refused" in ln or "failures" in ln]
        assert len(audit) <= 6, audit
        summary = [ln for ln in audit if "failures from 127.0.0.1" in ln]
        assert len(summary) == 1 and "EPICS write refused while backing off" in summary[0]
        assert int(summary[0].split("audit: ")[1].split()[0]) >= WRONG_WRITES - 12
        assert sv.runner.call(lambda: sv.rig.controller.ram[0x51]) != 0x33
        assert sv.runner.call(sv.ctl.target) == 0 and sv.still_and_null()


# -- one master ---------------------------------------------------------------------------------

def test_epics_cmd_and_the_daq_link_never_have_two_masters(epics_env):
    """While a DAQ client is privileged, CMD is ERR busy and runs nothing; once it leaves, CMD
    runs and then holds the privilege for its lease: a DAQ AUTH is ERR busy until it ends."""
    from pyrt.server.epics import EpicsService

    with served() as sv:
        ioc = EpicsService(sv.runner, sv.server.robot, sv.server, PREFIX, token=TOKEN,
                           interfaces=["127.0.0.1"], period_s=0.02, stats_period_s=0.2,
                           lease_s=3.0)
        ioc.start()
        try:
            op = sv.operator()
            _write("CMD", f"{TOKEN} X 33")
            assert _text("RESULT").startswith("ERR busy DAQ client")
            assert sv.runner.call(lambda: sv.rig.controller.ram[0x51]) == 0x7F  # unchanged
            _write("ACK", TOKEN)
            assert _text("RESULT").startswith("ERR busy")
            op.close()
            assert _until(lambda: sv.server.privileged_client is None)
            _write("CMD", f"{TOKEN} X 33")
            assert _text("RESULT").startswith("OK speed 7F -> 33")
            with sv.client() as second:
                reply = second.request(f"AUTH {TOKEN}")
                assert reply.code == "busy" and "EPICS CMD holds the privilege" in reply.text
                deadline = time.monotonic() + 20  # the lease is 3 s
                while reply.code == "busy" and time.monotonic() < deadline:
                    time.sleep(0.1)
                    reply = second.request(f"AUTH {TOKEN}")
                assert reply.ok
                _write("CMD", f"{TOKEN} X 34")
                assert _text("RESULT").startswith("ERR busy")
        finally:
            ioc.close()


# -- fuzz ---------------------------------------------------------------------------------------

_JUNK = ["\x00", "\n", "\r", "\x1b[2J", "\u2028", "\u202e", "\udcff", "é", "\\", "'", ";",
         "$(id)", "%s%n", "../..", "ack", "stop", "1e308", "nan", "-1", " "]
FUZZ_WRITES = 240


def _fuzz_writes(rng: random.Random) -> list:
    writes: list = []
    for _ in range(FUZZ_WRITES):
        pv = rng.choice(["CMD", "CMD", "ACK", "GRIPPER:SPEED_SP", "STOP", "POSITION", "TARGET",
                         "MOVING", "RESULT", "REPLY", "FAULT_MSG"])
        if pv == "STOP":
            value: object = [rng.choice([0, 1, 2, 7, 255, 65535])]
        elif pv in ("POSITION", "TARGET", "MOVING"):
            value = [rng.choice([0.0, -1e308, 1e308, 5.0, 1])]
        else:
            words = [rng.choice(_JUNK) for _ in range(rng.randint(0, 6))]
            if pv != "RESULT" and rng.random() < 0.5:
                words.insert(0, TOKEN if rng.random() < 0.5 else "wrong" * rng.randint(0, 4))
            value = " ".join(words)[:250]
            if rng.random() < 0.1:
                value = "".join(chr(rng.randrange(1, 256)) for _ in range(rng.randint(1, 250)))
        # a refused write (read-only, an enum index out of range, not text) gets an error
        # response that caproto's threading client leaves unmatched: not waited for
        text = (isinstance(value, str) and value[:1] not in ("", "\x00")
                and not any("\udc80" <= c <= "\udcff" for c in value))
        answered = (pv in ("CMD", "ACK", "GRIPPER:SPEED_SP") and text) or (
            pv == "STOP" and value in ([0], [1]))
        writes.append([pv, value, answered])
    return writes


def test_fuzzed_epics_puts_never_meet_a_bug_or_move_the_robot(epics_env):
    """240 generated puts to CMD, ACK, a setpoint, STOP and read-only PVs (garbage, control and
    format characters, invalid UTF-8, with and without the token): RESULT never says ERR
    internal, the IOC and the DAQ server serve on, nothing moves and no fault is raised."""
    from pyrt.server.epics import EpicsService
    from pyrt.server.guard import FailureGuard

    rng = random.Random(37)
    # no back-off here, so that the writes with the token reach the console every time
    lenient = FailureGuard(lambda who, line: None, per_address=10**6, overall=10**6)
    with served(guard=lenient) as sv:
        ioc = EpicsService(sv.runner, sv.server.robot, sv.server, PREFIX, token=TOKEN,
                           interfaces=["127.0.0.1"], period_s=0.02, stats_period_s=0.2)
        ioc.start()
        try:
            results = _ca_client(_fuzz_writes(rng), read_result=True)
            assert len(results) == FUZZ_WRITES
            assert not [r for r in results if "ERR internal" in r]
            assert any(r.startswith("ok ERR command") for r in results)  # the console was reached
            assert _read("FAULT")[0] == b"no" and ioc.error is None
            assert sv.server.alive
            assert sv.runner.call(lambda: sv.rig.fault, take_fault=False) is None
            assert sv.runner.call(sv.ctl.target) == 0 and sv.still_and_null()
        finally:
            ioc.close()
