"""diagnose on robot joints: the 3-joint arm tracking a random Fourier trajectory under PD +
feed-forward control in MuJoCo (1 kHz, its friction a `frictionloss` constraint, not this
project's smooth law; armature; encoder, velocity and torque noise), recorded with the
commanded torques.  The nominal model is the truth with one joint effect left out."""

import dataclasses

import numpy as np
import pytest

from kinemaforge_opt.arm.excitation import excitation_plan, model_limits, random_fourier
from kinemaforge_opt.arm.mujoco_real import SensorNoise, arm_from_model, record_plan
from kinemaforge_opt.physics.diagnose import diagnose

from .conftest import small_arm

KP, KD = np.full(3, 400.0), np.full(3, 40.0)
NOISE = SensorNoise(q=1e-4, v=2e-3, tau=0.05)


def _recording(truth, nominal):
    limits = model_limits(nominal, a_max=20.0, velocity_fraction=0.9)
    plan = excitation_plan(nominal, random_fourier(3, limits, 0.25, seed=3), 4.0)
    rec = record_plan(arm_from_model(truth), plan, KP, KD, NOISE, seed=1)
    return rec.rows(np.arange(rec.t.size) % 4 == 0)  # logged at 250 Hz


def _without(model, joint, **zeroed):
    return model.with_joint(joint, dynamics=dataclasses.replace(model.joint(joint).dynamics, **zeroed))


@pytest.mark.parametrize("joint, field, effect", [
    pytest.param("j2", "damping", "viscous_damping", marks=pytest.mark.slow),  # damping alone: also the doors'
    ("j3", "coulomb", "coulomb_friction"),
])
def test_a_joint_effect_left_out_of_an_arm_model_is_the_only_one_found(joint, field, effect):
    truth = small_arm()
    nominal = _without(truth, joint, **{field: 0.0})
    d = diagnose(nominal, _recording(truth, nominal))
    assert [(e.joint, e.type) for e in d.effects] == [(joint, effect)], d.summary()
    assert d.effects[0].value == pytest.approx(getattr(truth.joint(joint).dynamics, field), rel=0.03)
    assert d.held_out.rms_after < d.held_out.rms_before / 20


def test_the_true_arm_model_shows_no_effect():
    """The truth's own model fits to ~14 noise sigmas (MuJoCo's exact stiction against the smooth
    sign, the torque's sample-and-hold), and that model-form error is not taken for an effect."""
    truth = small_arm()
    d = diagnose(truth, _recording(truth, truth))
    assert d.effects == (), d.summary()
