"""Calibration models: corrections applied to a chain both ways, and identified from measured poses."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pyrt.kinematics.calibration import (
    CalibrationModel,
    correction,
    observations,
    pose_error,
)
from pyrt.kinematics.chain import Chain
from pyrt.kinematics.puma import LOWER_DEG, UPPER_DEG, puma560

LOWER = np.radians(LOWER_DEG)
UPPER = np.radians(UPPER_DEG)


@pytest.fixture(scope="module")
def puma():
    return puma560()


def random_q(rng, n=20) -> list[np.ndarray]:
    """Joint vectors spread over the middle of the PUMA's range."""
    mid, half = (LOWER + UPPER) / 2, (UPPER - LOWER) / 2
    return [mid + 0.7 * half * rng.uniform(-1, 1, 6) for _ in range(n)]


def test_a_known_error_is_identified_from_20_measured_poses(puma):
    """0.5 deg on joint 2's offset, 1 mm and 0.2 deg on the base: identified from 20 measured poses to within 0.01 deg and 0.05 mm."""
    truth = CalibrationModel.for_chains(puma)
    base_t = np.array([0.6, -0.48, 0.64]) * 1e-3  # 1 mm
    base_t *= 1e-3 / np.linalg.norm(base_t)
    base_r = np.radians(0.2) * np.array([0.6, 0.8, 0.0])  # 0.2 deg, about a horizontal axis
    truth.update({"offset.joint2": math.radians(0.5),
                  **{f"base.{a}": v for a, v in zip(("x", "y", "z"), base_t, strict=True)},
                  **{f"base.{a}": v for a, v in zip(("rx", "ry", "rz"), base_r, strict=True)}})
    real = truth.apply(puma)
    qs = random_q(np.random.default_rng(7))
    measured = [real.fk(q) for q in qs]

    model = CalibrationModel.for_chains(puma)
    free = ["offset.joint2", "offset.joint3", "offset.joint4", "offset.joint5", "offset.joint6", "base"]
    fit = model.identify(observations(puma, qs, measured), free)
    assert fit.converged and fit.unobservable == ()
    assert fit.rms_position_before > 1e-3 and fit.rms_position < 1e-9
    for k in ("joint2", "joint3", "joint4", "joint5", "joint6"):
        assert abs(math.degrees(model[f"offset.{k}"] - truth[f"offset.{k}"])) < 0.01
    got_t = np.array([model[f"base.{a}"] for a in ("x", "y", "z")])
    assert np.linalg.norm(got_t - base_t) < 0.05e-3
    got_r = np.array([model[f"base.{a}"] for a in ("rx", "ry", "rz")])
    assert math.degrees(np.linalg.norm(got_r - base_r)) < 0.01
    # the calibrated chain now puts the tool where the real arm does
    cal = model.apply(puma)
    for q in random_q(np.random.default_rng(8), 5):
        assert np.max(np.abs(cal.fk(q) - real.fk(q))) < 1e-6


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_identification_from_noisy_measurements_stays_within_tolerance(puma, seed):
    """Poses measured with 10 um and 0.002 deg of noise still give the 0.5 deg offset and the 1 mm / 0.2 deg base error to within 0.01 deg and 0.05 mm."""
    truth = CalibrationModel.for_chains(puma)
    truth.update({"offset.joint2": math.radians(0.5), "base.x": 0.6e-3, "base.y": -0.48e-3,
                  "base.z": 0.64e-3, "base.rx": math.radians(0.12), "base.ry": math.radians(0.16)})
    real = truth.apply(puma)
    rng = np.random.default_rng(seed)
    qs = random_q(rng)
    measured = [real.fk(q) @ correction([*rng.normal(0, 10e-6, 3),
                                         *rng.normal(0, math.radians(0.002), 3)]) for q in qs]
    model = CalibrationModel.for_chains(puma)
    free = [f"offset.joint{k}" for k in range(2, 7)] + ["base"]
    fit = model.identify(observations(puma, qs, measured), free)
    assert fit.converged and fit.rms_position < 30e-6
    for k in range(2, 7):
        assert abs(math.degrees(model[f"offset.joint{k}"] - truth[f"offset.joint{k}"])) < 0.01
    err = [model[f"base.{a}"] - truth[f"base.{a}"] for a in ("x", "y", "z")]
    assert np.linalg.norm(err) < 0.05e-3
    rot = [model[f"base.{a}"] - truth[f"base.{a}"] for a in ("rx", "ry", "rz")]
    assert math.degrees(np.linalg.norm(rot)) < 0.01


@settings(max_examples=15, deadline=None)
@given(st.lists(st.floats(-0.02, 0.02), min_size=5, max_size=5),
       st.lists(st.floats(-2e-3, 2e-3), min_size=3, max_size=3),
       st.lists(st.floats(-0.01, 0.01), min_size=3, max_size=3),
       st.integers(0, 2**32 - 1))
def test_any_small_error_of_offsets_and_base_is_identified(puma, offsets, shift, turn, seed):
    """Random offsets on joints 2-6 (up to 1.1 deg) and a random base error (2 mm, 0.6 deg) are identified from 20 exact poses to 1e-8."""
    truth = CalibrationModel.for_chains(puma)
    truth.update({f"offset.joint{k}": v for k, v in zip(range(2, 7), offsets, strict=True)})
    truth.update({f"base.{a}": v for a, v in zip(("x", "y", "z", "rx", "ry", "rz"), [*shift, *turn],
                                                 strict=True)})
    real = truth.apply(puma)
    qs = random_q(np.random.default_rng(seed))
    model = CalibrationModel.for_chains(puma)
    fit = model.identify(observations(puma, qs, [real.fk(q) for q in qs]),
                         [f"offset.joint{k}" for k in range(2, 7)] + ["base"])
    assert fit.converged and fit.unobservable == ()
    for name in fit.params:
        assert model[name] == pytest.approx(truth[name], abs=1e-8), name


def test_parameters_the_data_cannot_separate_are_named_and_left_alone(puma):
    """Joint 1's offset and a base rotation about joint 1's axis are one error to the data: the fit names both unobservable and still matches the poses."""
    truth = CalibrationModel.for_chains(puma)
    truth.update({"offset.joint1": math.radians(0.3), "base.z": 0.5e-3})
    real = truth.apply(puma)
    qs = random_q(np.random.default_rng(3), 12)
    model = CalibrationModel.for_chains(puma)
    fit = model.identify(observations(puma, qs, [real.fk(q) for q in qs]), ["offset.joint1", "base"])
    assert fit.converged and fit.rank == 6
    assert set(fit.unobservable) == {"offset.joint1", "base.rz"}
    assert fit.rms_position < 1e-9 and fit.rms_rotation < 1e-9
    assert model["offset.joint1"] + model["base.rz"] == pytest.approx(math.radians(0.3), abs=1e-9)
    assert model["base.z"] == pytest.approx(0.5e-3, abs=1e-9)


def two_chains(puma):
    """An RCM-like pair: the whole arm, and its first three joints with an instrument of their own."""
    instrument = correction([0.1, 0.0, 0.05, 0.0, 0.0, 0.0])
    short = Chain("puma-positioner", puma.joints[:3], tool=instrument)
    return puma.replace(closed_form=None), short


def test_a_shared_model_couples_two_chains(puma):
    """One model over two chains: identified from the first chain's poses alone, it corrects the second chain's shared base and joints too."""
    arm, positioner = two_chains(puma)
    truth = CalibrationModel.for_chains(arm, positioner)
    truth.update({"offset.joint2": math.radians(0.4), "base.x": 0.8e-3, "base.ry": math.radians(0.1),
                  "origin.joint3.y": 0.3e-3})
    real_arm, real_pos = truth.apply(arm), truth.apply(positioner)

    model = CalibrationModel.for_chains(arm, positioner)
    assert model.joints == arm.joint_names
    qs = random_q(np.random.default_rng(11))
    fit = model.identify(observations(arm, qs, [real_arm.fk(q) for q in qs]),
                         ["offset.joint2", "base", "origin.joint3.y"])
    assert fit.converged
    cal_pos = model.apply(positioner)
    for q in random_q(np.random.default_rng(12), 5):
        assert np.max(np.abs(cal_pos.fk(q[:3]) - real_pos.fk(q[:3]))) < 1e-7
        assert np.max(np.abs(positioner.fk(q[:3]) - real_pos.fk(q[:3]))) > 1e-4


def test_two_chains_identified_together(puma):
    """Observations of both chains fit one shared model at once."""
    arm, positioner = two_chains(puma)
    truth = CalibrationModel.for_chains(arm)
    truth.update({"offset.joint3": math.radians(-0.3), "base.y": -0.7e-3, "tool.z": 2e-3})
    real_arm, real_pos = truth.apply(arm), truth.apply(positioner)
    rng = np.random.default_rng(5)
    qa, qp = random_q(rng, 10), [q[:3] for q in random_q(rng, 10)]
    data = observations(arm, qa, [real_arm.fk(q) for q in qa])
    data += observations(positioner, qp, [real_pos.fk(q) for q in qp])
    model = CalibrationModel.for_chains(arm)
    fit = model.identify(data, ["offset.joint3", "base.x", "base.y", "base.z", "tool.z"])
    assert fit.converged
    assert model["offset.joint3"] == pytest.approx(math.radians(-0.3), abs=1e-9)
    assert model["base.y"] == pytest.approx(-0.7e-3, abs=1e-10)
    assert model["tool.z"] == pytest.approx(2e-3, abs=1e-10)


@settings(max_examples=25, deadline=None)
@given(st.lists(st.floats(-1e-3, 1e-3), min_size=4, max_size=4),
       st.lists(st.floats(-0.01, 0.01), min_size=4, max_size=4),
       st.integers(0, 2**32 - 1))
def test_the_calibrated_chain_is_consistent_forward_and_inverse(puma, lengths, angles, seed):
    """A calibrated PUMA (offsets, base, tool and a joint origin corrected): each configuration its closed form returns maps back through its own fk."""
    model = CalibrationModel.for_chains(puma)
    model.update({"offset.joint2": angles[0], "base.x": lengths[0], "base.rx": angles[1],
                  "tool.z": lengths[1], "tool.ry": angles[2],
                  "origin.joint3.x": lengths[2], "origin.joint4.rz": angles[3]})
    cal = model.apply(puma)
    q = random_q(np.random.default_rng(seed), 1)[0]
    pose = cal.fk(q)
    cf = cal.closed_form
    assert cf.config_of(q) in cf.configurations
    sol = cf.solve(pose, cf.config_of(q))
    assert sol is not None
    assert np.max(np.abs(cal.fk(sol) - pose)) < 1e-9
    found = 0
    for cfg in cf.configurations:
        s = cf.solve(pose, cfg)
        if s is not None:
            found += 1
            assert np.max(np.abs(cal.fk(s) - pose)) < 1e-9
    assert found >= 1
    res = cal.ik(pose, q + 0.05)
    assert res.ok and np.max(np.abs(cal.fk(res.q) - pose)) < 1e-8


def test_the_calibrated_closed_form_refuses_with_a_reason(puma):
    """With joint origins corrected, an unreachable pose or a configuration beyond a limit is refused with the reason; a bad configuration name is an error."""
    model = CalibrationModel.for_chains(puma)
    model.update({"origin.joint3.x": 0.5e-3, "base.z": 1e-3})
    cf = model.apply(puma).closed_form
    far = np.eye(4)
    far[:3, 3] = (1.5, 0.0, 0.8)
    assert cf.solve(far, "righty-above-noflip") is None
    assert "beyond the arm's reach" in cf.reason(far, "righty-above-noflip")
    assert cf.solve_all(far) == {}
    q = np.radians([150.0, 30.0, -60.0, 10.0, 40.0, 0.0])
    pose = model.apply(puma).fk(q)
    assert cf.reason(pose, cf.config_of(q)) is None
    refused = [c for c in cf.configurations if cf.solve(pose, c) is None]
    assert refused and all("joint4" in cf.reason(pose, c) for c in refused)
    with pytest.raises(ValueError, match="righty/lefty"):
        cf.solve(pose, "sideways")


def test_offsets_base_and_tool_alone_keep_the_exact_closed_form(puma):
    """Without origin corrections the calibrated PUMA keeps Paul's inverse, rebuilt for the corrected base, tool and offsets."""
    from pyrt.kinematics.puma import PaulInverse

    model = CalibrationModel.for_chains(puma)
    model.update({"offset.joint5": 0.01, "base.z": 1e-3, "tool.rz": 0.02})
    cal = model.apply(puma)
    assert isinstance(cal.closed_form, PaulInverse)
    q = np.radians([10.0, 40.0, -100.0, 20.0, 30.0, 40.0])
    np.testing.assert_allclose(cal.closed_form.solve(cal.fk(q), cal.closed_form.config_of(q)), q, atol=1e-9)
    np.testing.assert_allclose(cal.offsets[4], 0.01)


def test_bad_input_is_refused_and_changes_nothing(puma):
    """An unknown parameter, a non-finite value, mismatched observations or a chain with none of the model's joints is refused; the model is unchanged."""
    model = CalibrationModel.for_chains(puma)
    model.update({"base.x": 1e-3})
    before = model.params
    with pytest.raises(ValueError, match=r"no parameter 'base\.w'"):
        model.update({"base.y": 2e-3, "base.w": 1.0})
    with pytest.raises(ValueError, match="not a finite"):
        model.update({"base.y": math.nan})
    with pytest.raises(ValueError, match="names no parameter"):
        model.select(["elbow"])
    with pytest.raises(ValueError, match="2 joint vectors but 1 poses"):
        observations(puma, [np.zeros(6), np.zeros(6)], [np.eye(4)])
    with pytest.raises(ValueError, match="expected 6 finite joint values"):
        observations(puma, [np.zeros(5)], [np.eye(4)])
    with pytest.raises(ValueError, match="none of its joints"):
        CalibrationModel(["a", "b"]).apply(puma)
    with pytest.raises(ValueError, match="no observations"):
        model.identify([])
    assert model.params == before


def test_pose_error_is_position_and_rotation_vector():
    """pose_error gives the position difference and the rotation vector from the model's orientation to the measured one."""
    a = correction([0.1, 0.2, 0.3, 0.0, 0.0, 0.0])
    b = correction([0.1, 0.2, 0.25, 0.0, 0.0, 0.3]) @ np.eye(4)
    err = pose_error(b, a)
    np.testing.assert_allclose(err, [0, 0, -0.05, 0, 0, 0.3], atol=1e-12)
    np.testing.assert_allclose(pose_error(a, a), np.zeros(6), atol=1e-15)
