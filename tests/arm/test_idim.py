"""IDIM-LS on MuJoCo data of the 3-joint arm with known inertia and joint dynamics."""

import dataclasses

import numpy as np
import pytest

from kinemaforge_opt.arm.control import inverse_dynamics
from kinemaforge_opt.arm.excitation import design_excitation, excitation_plan, model_limits, random_fourier
from kinemaforge_opt.arm.idim import (
    base_columns,
    batched,
    fit_idim_ls,
    held_out_rms,
    identification_regressor,
)
from kinemaforge_opt.arm.mujoco_real import SensorNoise, arm_from_model, record_plan
from kinemaforge_opt.errors import DataError
from kinemaforge_opt.io.recording import Recording
from kinemaforge_opt.model.pinocchio import build_pin_model

from .conftest import small_arm

KP, KD = np.full(3, 400.0), np.full(3, 40.0)
NOISE = SensorNoise(q=1e-4, v=2e-3, tau=0.05)


def _without_coulomb(model):
    for j in model.movable_joints:
        model = model.with_joint(j.name, dynamics=dataclasses.replace(j.dynamics, coulomb=0.0))
    return model


def _experiment(truth):
    """Fit on a 4 s designed excitation, hold out 2 s of a different trajectory."""
    nominal = small_arm(dynamics=False)
    limits = model_limits(nominal, a_max=20.0, velocity_fraction=0.9)
    exc = design_excitation(nominal, limits, base_frequency=0.25, samples=60, max_iterations=15).trajectory
    arm = arm_from_model(truth)
    fit = record_plan(arm, excitation_plan(nominal, exc, 4.0), KP, KD, NOISE, seed=1)
    test = record_plan(arm, excitation_plan(nominal, random_fourier(3, limits, 0.4, seed=5), 2.0), KP, KD, NOISE, seed=2)
    res = fit_idim_ls(nominal, fit)
    return res, test, batched(inverse_dynamics(truth))


@pytest.fixture(scope="module")
def with_friction():
    return _experiment(small_arm())


def test_friction_coefficients_recovered(with_friction):
    res, _, _ = with_friction
    truth = small_arm()
    damping = np.array([j.dynamics.damping for j in truth.movable_joints])
    coulomb = np.array([j.dynamics.coulomb for j in truth.movable_joints])
    np.testing.assert_allclose(res.viscous, damping, rtol=0.1)
    np.testing.assert_allclose(res.coulomb, coulomb, rtol=0.1)


def test_held_out_prediction_as_good_as_the_true_parameters(with_friction):
    # With Coulomb friction the irreducible error (MuJoCo's soft frictionloss near v = 0,
    # filtered accelerations at sign changes) is what the true parameters achieve.
    res, test, truth_id = with_friction
    rms_idim, rms_truth = held_out_rms(res.predict, test), held_out_rms(truth_id, test)
    assert np.all(rms_idim <= 1.1 * rms_truth + 0.01), (rms_idim, rms_truth)


def test_held_out_prediction_at_noise_level_without_coulomb():
    res, test, truth_id = _experiment(_without_coulomb(small_arm()))
    # Raw torque: sensor noise plus the PD's reaction to measurement noise (kd·σ_v ≈ 0.08 N·m),
    # which filtered accelerations cannot follow; the filtered torque leaves only model error.
    rms_raw, rms_truth = held_out_rms(res.predict, test), held_out_rms(truth_id, test)
    assert np.all(rms_raw <= 1.1 * rms_truth + 0.005) and np.all(rms_raw < 3 * NOISE.tau), rms_raw
    assert np.all(held_out_rms(res.predict, test, filtered_torque=True) < 0.5 * NOISE.tau)
    np.testing.assert_allclose(res.viscous, [1.2, 0.9, 0.4], rtol=0.05)
    np.testing.assert_allclose(res.coulomb, 0.0, atol=0.05)


def test_base_columns_span_the_regressor(arm3):
    rng = np.random.default_rng(0)
    q, v, a = (rng.uniform(-1, 1, (50, 3)) for _ in range(3))
    W = identification_regressor(build_pin_model(arm3), q, v, a)
    base = base_columns(W)
    assert np.linalg.matrix_rank(W) == base.size == np.linalg.matrix_rank(W[:, base])


def test_recording_without_torque_is_rejected(arm3):
    t = np.arange(100) * 1e-3
    rec = Recording(t, arm3.joint_names, np.zeros((100, 3)), np.zeros((100, 3)))
    with pytest.raises(DataError, match="tau"):
        fit_idim_ls(arm3, rec)
