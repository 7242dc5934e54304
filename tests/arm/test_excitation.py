import numpy as np
import pytest

from kinemaforge_opt.arm.control import inverse_dynamics
from kinemaforge_opt.arm.excitation import (
    design_excitation,
    excitation_plan,
    limit_violation,
    model_limits,
    random_fourier,
    regressor_condition,
)
from kinemaforge_opt.errors import ModelError
from kinemaforge_opt.model import JointLimits


def test_designed_excitation_is_within_limits_and_better_conditioned_than_random(arm3):
    limits = model_limits(arm3, a_max=8.0)
    res = design_excitation(arm3, limits, base_frequency=0.5, samples=60, max_iterations=15)
    assert limit_violation(res.trajectory, limits) <= 0.0
    q, v, a = res.trajectory.evaluate(np.linspace(0, res.trajectory.period, 5000))
    assert np.all(q >= limits.q_lower) and np.all(q <= limits.q_upper)
    assert np.all(np.abs(v) <= limits.v_max) and np.all(np.abs(a) <= limits.a_max)
    random_conds = [regressor_condition(arm3, random_fourier(3, limits, 0.5, seed=s)) for s in range(1, 6)]
    assert res.condition < 0.5 * min(random_conds)


def test_fourier_derivatives_and_periodicity(arm3):
    traj = random_fourier(3, model_limits(arm3, a_max=8.0), base_frequency=0.5, seed=2)
    t = np.linspace(0.0, 2.0, 20001)
    q, v, a = traj.evaluate(t)
    np.testing.assert_allclose(np.gradient(q, t, axis=0)[1:-1], v[1:-1], atol=1e-6)
    np.testing.assert_allclose(np.gradient(v, t, axis=0)[1:-1], a[1:-1], atol=1e-5)
    np.testing.assert_allclose(q[0], q[-1], atol=1e-12)


def test_plan_carries_nominal_torque(arm3):
    traj = random_fourier(3, model_limits(arm3, a_max=8.0), base_frequency=0.5, seed=3)
    plan = excitation_plan(arm3, traj, 0.5)
    assert plan.q.shape == (501, 3) and plan.joint_names == arm3.joint_names
    q, v, a = traj.evaluate(plan.t)
    np.testing.assert_allclose(plan.tau[100], inverse_dynamics(arm3)(q[100], v[100], a[100]))


def test_limits_need_finite_ranges(arm3):
    bad = arm3.with_joint("j2", limits=JointLimits(-np.inf, np.inf, 10.0, 1.0))
    with pytest.raises(ModelError, match="j2"):
        model_limits(bad)
