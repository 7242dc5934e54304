"""calibrate(method="inverse_dynamics") on MuJoCo data of the 3-joint arm with known inertias
and joint friction: held-out torques vs IDIM-LS, physical consistency, friction recovery,
identifiability in words, bad input; the embedding callables."""

import time

import numpy as np
import pytest

from kinemaforge_opt.arm.control import inverse_dynamics
from kinemaforge_opt.arm.embedding import embed
from kinemaforge_opt.arm.excitation import design_excitation, excitation_plan, model_limits, random_fourier
from kinemaforge_opt.arm.idim import batched, fit_idim_ls, held_out_rms
from kinemaforge_opt.arm.mujoco_real import SensorNoise, arm_from_model, record_plan
from kinemaforge_opt.calibration import calibrate
from kinemaforge_opt.errors import DataError, UnknownNameError
from kinemaforge_opt.io.recording import Recording
from kinemaforge_opt.model import Inertial
from kinemaforge_opt.nlp.inverse_dynamics import (
    dynamic_from_log_cholesky,
    log_cholesky_from_dynamic,
)

from .conftest import small_arm

KP, KD = np.full(3, 400.0), np.full(3, 40.0)
NOISE = SensorNoise(q=1e-4, v=2e-3, tau=0.05)


@pytest.fixture(scope="module")
def experiment():
    """4 s designed excitation for fitting, 2 s of a different trajectory held out."""
    truth, nominal = small_arm(), small_arm(dynamics=False)
    limits = model_limits(nominal, a_max=20.0, velocity_fraction=0.9)
    exc = design_excitation(nominal, limits, base_frequency=0.25, samples=60, max_iterations=15).trajectory
    arm = arm_from_model(truth)
    fit = record_plan(arm, excitation_plan(nominal, exc, 4.0), KP, KD, NOISE, seed=1)
    test = record_plan(arm, excitation_plan(nominal, random_fourier(3, limits, 0.4, seed=5), 2.0), KP, KD, NOISE, seed=2)
    cal = calibrate(nominal, fit, method="inverse_dynamics", max_iter=500)
    return truth, nominal, fit, test, cal


def test_held_out_torque_at_most_idim_ls(experiment):
    _, nominal, fit, test, cal = experiment
    assert cal.success, cal.status
    ours = held_out_rms(batched(embed(cal).inverse_dynamics), test)
    idim = held_out_rms(fit_idim_ls(nominal, fit).predict, test)
    assert ours.mean() <= idim.mean(), (ours, idim)
    assert ours.mean() < 0.2 * held_out_rms(batched(inverse_dynamics(nominal)), test).mean()


def test_identified_inertias_are_physically_consistent(experiment):
    _, _, _, _, cal = experiment
    inertias = [n for n in cal.estimates if n.endswith(".inertia")]
    assert len(inertias) == 3
    for name in inertias:
        assert Inertial.from_dynamic_parameters(cal.estimates[name].value).is_physically_consistent(), name
        assert cal.model.link(name.split(".")[0]).inertial.is_physically_consistent()


def test_friction_recovered_within_tolerance_of_the_mujoco_truth(experiment):
    truth, _, _, _, cal = experiment
    for j in truth.movable_joints:
        for field in ("damping", "coulomb"):
            e = cal.estimates[f"{j.name}.{field}"]
            assert e.value[0] == pytest.approx(getattr(j.dynamics, field), rel=0.1), (j.name, field, e)
        assert cal.model.joint(j.name).dynamics.damping == pytest.approx(cal.estimates[f"{j.name}.damping"].value[0])


def test_unidentifiable_parameter_is_reported_in_words_and_stays_near_its_prior(experiment):
    # The first link turns about the vertical axis through its origin: its mass, first moments
    # along the axis and inertia about horizontal axes never enter the joint torques.
    _, nominal, _, _, cal = experiment
    text = "\n".join(cal.identifiability)
    assert "l1.inertia[m] has no effect on the joint torques" in text, text
    assert "base parameters" in cal.identifiability[0]
    e = cal.estimates["l1.inertia"]
    assert e.value[0] == pytest.approx(nominal.link("l1").inertial.mass, rel=0.1)
    assert e.ci95_high[0] - e.ci95_low[0] > 10 * e.value[0]  # the interval says "unknown"


def test_embedding_callables_invert_each_other_with_friction(experiment):
    _, _, _, _, cal = experiment
    dyn = embed(cal)
    rng = np.random.default_rng(0)
    q, v, a = rng.uniform(-1, 1, (3, 3))
    np.testing.assert_allclose(dyn.forward_dynamics(q, v, dyn.inverse_dynamics(q, v, a)), a, atol=1e-9)
    assert dyn.pin_model.nv == 3 and dyn.joint_names == ("j1", "j2", "j3")
    # friction is part of the callable: reversing v keeps the (quadratic) velocity-product terms
    # and flips viscous and Coulomb torques, 2 (damping + coulomb) at v = 1 rad/s
    friction = np.array([j.dynamics.damping + j.dynamics.coulomb for j in cal.model.movable_joints])
    zero, one = np.zeros(3), np.ones(3)
    diff = dyn.inverse_dynamics(q, one, zero) - dyn.inverse_dynamics(q, -one, zero)
    np.testing.assert_allclose(diff, 2 * friction, atol=1e-9)


def test_log_cholesky_is_physically_consistent_everywhere():
    rng = np.random.default_rng(3)
    for _ in range(200):
        pi = dynamic_from_log_cholesky(rng.normal(0, 1.5, 10))
        assert Inertial.from_dynamic_parameters(pi).is_physically_consistent(tol=1e-9)
    pi = small_arm().link("l2").inertial.dynamic_parameters()
    np.testing.assert_allclose(dynamic_from_log_cholesky(log_cholesky_from_dynamic(pi)), pi, atol=1e-12)


def test_bad_input_is_named(arm3):
    t = np.arange(400) * 1e-3
    q = np.sin(t)[:, None] * np.ones(3)
    with pytest.raises(DataError, match="tau"):
        calibrate(arm3, Recording(t, arm3.joint_names, q, q), method="inverse_dynamics")
    with pytest.raises(DataError, match="j3"):
        calibrate(arm3, Recording(t, ("j1", "j2"), q[:, :2], tau=q[:, :2]), method="inverse_dynamics")
    with pytest.raises(UnknownNameError, match="j1.axis"):
        calibrate(arm3, Recording(t, arm3.joint_names, q, tau=q), free=["j1.axis"], method="inverse_dynamics")
    with pytest.raises(DataError, match="tau:j2"):
        bad = q.copy()
        bad[10, 1] = np.nan
        Recording(t, arm3.joint_names, q, tau=bad)


@pytest.mark.slow
def test_benchmark_a_20_s_1_khz_recording_of_the_3_joint_arm(experiment):
    """Benchmark, not a check of correctness: 20 001 samples calibrate in seconds."""
    truth, nominal, fit, _, _ = experiment
    t = np.arange(20001) * 1e-3
    traj = random_fourier(3, model_limits(nominal, a_max=20.0, velocity_fraction=0.9), 0.25, seed=1)
    rec = record_plan(arm_from_model(truth), Recording(t, nominal.joint_names, *traj.evaluate(t)[:2],
                                                       tau=np.zeros((t.size, 3))), KP, KD, NOISE, seed=4)
    start = time.perf_counter()
    cal = calibrate(nominal, rec, method="inverse_dynamics", max_iter=500)
    assert cal.success and time.perf_counter() - start < 60.0
