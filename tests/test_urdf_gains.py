"""pyrt urdf: the servo's gains as run-time parameters (get/set, EPICS _SP), measured on the
simulated arm."""

from __future__ import annotations

import importlib.util
import math

import numpy as np
import pytest
from _urdf_rig import puma_station

from pyrt.errors import CommandError
from pyrt.scheduler import Loop, SimClock
from pyrt.station.urdf import build_urdf

#: The push the step response recovers from (deg): within the following-error limit.
PUSH_DEG = 1.0


@pytest.fixture(scope="module")
def puma():
    """One PUMA station on simulated time, holding its start pose."""
    yield from puma_station()


def _set(station, runner, name: str, text: str) -> str:
    """``set NAME TEXT`` as the console runs it: parsed against the range, then written."""
    comp, param = runner.call(station.param, name)
    value = param.parse(f"set {name}", text)
    return runner.call(station.set_param, comp, param, value)


def _step_response(station, runner, joint: int) -> tuple[float, float]:
    """Push joint ``joint`` of the held arm by PUSH_DEG in the world and let the servo bring it
    back: (the time until the truth is back within 10 % of the push and stays, s; the largest
    overshoot beyond the hold, deg)."""
    hold = runner.call(lambda: station.plant.truth().q.copy())

    def push():
        q = station.plant.truth().q
        q[joint] += math.radians(PUSH_DEG)
        station.plant.set_state(q)

    runner.call(push)
    trace: list[tuple[float, float]] = []
    t0 = runner.call(lambda: station.plant.truth().time)

    def watch() -> bool:
        tr = station.plant.truth()
        trace.append((tr.time - t0, math.degrees(tr.q[joint] - hold[joint])))
        return tr.time - t0 >= 1.0

    assert runner.wait_until(watch, 5.0)
    assert station.fault is None
    outside = [t for t, e in trace if abs(e) > 0.1 * PUSH_DEG]
    over = max(0.0, -min(e for _t, e in trace))
    return (outside[-1] if outside else 0.0), over


def test_set_bandwidth_and_kp_change_the_step_response_on_the_simulated_arm(puma):
    """set NAME.bandwidth 4 (every joint's kp ki kd retuned) makes the simulated joint's recovery from a 1 deg push slower than at 12 Hz; set JOINT.kp changes that joint alone and get reads it back; the gains set back restore the first response."""
    station, runner = puma
    fast, _ = _step_response(station, runner, 1)
    kp_before = runner.call(lambda: station.arm.servo.kp.copy())
    said = _set(station, runner, "puma560.bandwidth", "4")
    assert "12 -> 4 Hz" in said and "not written back" in said
    kp_slow = runner.call(lambda: station.arm.servo.kp.copy())
    assert np.allclose(kp_slow, kp_before * (4 / 12) ** 2)
    slow, _ = _step_response(station, runner, 1)
    assert slow > 2.0 * fast, (fast, slow)
    _set(station, runner, "puma560.bandwidth", "12")
    again, _ = _step_response(station, runner, 1)
    assert again == pytest.approx(fast, abs=0.01)
    # one joint's kp alone: a tenth of it and no integral makes its recovery slower still
    ki = runner.call(lambda: float(station.arm.servo.ki[1]))
    kp = runner.call(lambda: float(station.arm.servo.kp[1]))
    _set(station, runner, "joint2.kp", f"{kp / 10:.6g}")
    _set(station, runner, "joint2.ki", "0")
    _comp, param = runner.call(station.param, "joint2.kp")
    assert runner.call(param.read) == pytest.approx(kp / 10, rel=1e-5)
    assert runner.call(lambda: float(station.arm.servo.kp[0])) == pytest.approx(kp_before[0])
    soft, _ = _step_response(station, runner, 1)
    assert soft > 2.0 * fast, (fast, soft)
    _set(station, runner, "joint2.kp", repr(kp))
    _set(station, runner, "joint2.ki", repr(ki))


@pytest.mark.parametrize(("name", "text", "why"), [
    ("joint2.kp", "1e9", "out of range"),
    ("joint2.kp", "-1", "out of range"),
    ("joint2.kff", "1.5", "out of range"),
    ("joint3.kd", "fast", "not a number"),
    ("puma560.bandwidth", "80", "out of range"),
    ("puma560.bandwidth", "0", "out of range"),
    ("joint2.ilim", "nan", "not a"),
])
def test_a_gain_outside_its_safe_range_is_refused_and_nothing_changes(puma, name, text, why):
    """A gain outside its safe range (or not a number) is refused with the range; every gain of every joint stays as it was."""
    station, runner = puma
    before = runner.call(lambda: station.arm.servo.gains.copy())
    with pytest.raises(CommandError, match=why) as info:
        _set(station, runner, name, text)
    assert "nothing changed" in str(info.value)
    if "range" in why:
        assert ".." in str(info.value)  # the range is named
    assert np.array_equal(runner.call(lambda: station.arm.servo.gains.copy()), before)


def test_a_write_past_the_console_check_is_still_refused_by_the_servo(puma):
    """A value that reaches a gain's write without the console's range check (a negative kp) is refused by the servo's own ranges: CommandError, nothing changed."""
    station, runner = puma
    before = runner.call(lambda: station.arm.servo.gains.copy())
    _comp, param = runner.call(station.param, "joint1.kp")
    with pytest.raises(CommandError, match=r"safe range.*nothing changed"):
        runner.call(param.write, -5.0)
    assert np.array_equal(runner.call(lambda: station.arm.servo.gains.copy()), before)


def test_get_lists_every_joint_s_gains_with_units_and_ranges(puma):
    """get JOINT lists kp ki kd ilim kv ka kff with the joint's units and safe ranges; the arm lists bandwidth and kff (every joint's at once; nan when they differ); all writable, not written back."""
    station, runner = puma
    joint = station.component("joint2")
    params = runner.call(station.params_of, joint)
    assert [p.name for p in params] == ["kp", "ki", "kd", "ilim", "kv", "ka", "kff"]
    kp = params[0]
    assert kp.units == "N m/rad" and kp.lo == 0.0 and kp.hi > kp.read() > 0
    assert all(p.writable and not p.written_back for p in params)
    arm = runner.call(station.params_of, station.arm)
    assert [p.name for p in arm] == ["bandwidth", "kff"]
    assert arm[0].read() == 12.0 and arm[0].hi == pytest.approx(50.0)
    _set(station, runner, "puma560.kff", "0.5")
    assert runner.call(lambda: station.arm.servo.kff.tolist()) == [0.5] * 6
    _set(station, runner, "joint3.kff", "1")
    assert math.isnan(runner.call(arm[1].read))  # the joints differ
    _set(station, runner, "puma560.kff", "1")
    assert runner.call(arm[1].read) == 1.0


@pytest.mark.skipif(importlib.util.find_spec("caproto") is None, reason="caproto not installed")
def test_epics_serves_a_setpoint_pv_for_every_gain(puma):
    """--epics with a token: every gain is a NAME:PARAM_SP setpoint PV (JOINT2:KP_SP, PUMA560:BANDWIDTH_SP ...), as every writable parameter is."""
    from pyrt.server import ServedStation, Server
    from pyrt.server.epics import EpicsService

    station, runner = puma
    served = ServedStation(station)
    token = "gains-token-0123456789"
    server = Server(runner, served, "127.0.0.1", 0, token=token)
    epics = EpicsService(runner, served, server, "PUMA:", token=token)
    try:
        for j in range(1, 7):
            for gain in ("KP", "KI", "KD", "ILIM", "KV", "KA", "KFF"):
                assert f"PUMA:JOINT{j}:{gain}_SP" in epics.pvdb
        assert "PUMA:PUMA560:BANDWIDTH_SP" in epics.pvdb
        assert "PUMA:PUMA560:KFF_SP" in epics.pvdb
    finally:
        epics.close()
        server.close()


def test_on_hardware_a_the_host_servo_s_gains_are_not_offered():
    """On hardware (a) the board servos with the gains it was built with: get lists no host gain and set refuses one, so nothing tunes a servo that does not run."""
    station = build_urdf(Loop(SimClock(), period_ns=10_000_000), hardware="a")
    try:
        runner = station.start()
        names = [f"{c.name}.{p.name}" for c in station.components() for p in c.params()]
        assert not [n for n in names if n.rsplit(".", 1)[1] in
                    ("kp", "ki", "kd", "ilim", "kv", "ka", "kff", "bandwidth")]
        with pytest.raises(CommandError):
            runner.call(station.param, f"{station.arm.name}.bandwidth")
    finally:
        station.close()
