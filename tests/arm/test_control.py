"""Computed-torque control and the dynamics callables against MuJoCo."""

import dataclasses

import numpy as np
import pytest

from kinemaforge_opt.arm.control import forward_dynamics, inverse_dynamics, track
from kinemaforge_opt.arm.excitation import model_limits, random_fourier
from kinemaforge_opt.arm.mujoco_real import arm_from_model
from kinemaforge_opt.errors import DataError

from .conftest import small_arm


def _no_coulomb(model):
    for j in model.movable_joints:
        model = model.with_joint(j.name, dynamics=dataclasses.replace(j.dynamics, coulomb=0.0))
    return model


@pytest.fixture(scope="module")
def reference():
    traj = random_fourier(3, model_limits(small_arm(), a_max=15.0), 0.4, seed=4)
    t = np.arange(2001) * 1e-3
    return (t, *traj.evaluate(t))


def test_exact_model_tracks_to_near_zero_error(reference):
    # MuJoCo's frictionloss is a soft constraint, not sign(v): the exact model here has inertia,
    # armature and damping (all of which MuJoCo reproduces exactly).
    truth = _no_coulomb(small_arm())
    res = track(arm_from_model(truth), *reference, inverse_dynamics(truth), kp=100.0, kd=20.0)
    assert np.all(res.max_abs < 1e-3), res.max_abs
    nominal = track(arm_from_model(truth), *reference, inverse_dynamics(small_arm(dynamics=False)), 100.0, 20.0)
    assert np.all(nominal.rms > 10 * res.rms)


def test_forward_dynamics_inverts_inverse_dynamics(arm3):
    rng = np.random.default_rng(0)
    q, v, a = rng.uniform(-1, 1, (3, 3))
    id_fn, fd_fn = inverse_dynamics(arm3), forward_dynamics(arm3)
    np.testing.assert_allclose(fd_fn(q, v, id_fn(q, v, a)), a, atol=1e-10)


def test_gains_must_be_positive(reference, arm3):
    with pytest.raises(DataError, match="gains"):
        track(arm_from_model(arm3), *reference, inverse_dynamics(arm3), kp=0.0)
