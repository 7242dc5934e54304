"""The two baselines on MuJoCo episodes with known concealed effects."""

import warnings

import numpy as np
import pytest

from kinemaforge_opt.bench.baselines import idls, sindy, velocity_noise
from kinemaforge_opt.bench.recordings import stroke_plan
from kinemaforge_opt.io.recording import Recording
from kinemaforge_opt.synth.effects import ConcealedEffect
from kinemaforge_opt.synth.groundtruth import simulate
from kinemaforge_opt.synth.objects import make_object


def _door(effects, noise=0.0, hz=120):
    obj = make_object("cabinet", 0)
    joint = obj.model.movable_joints[0].name
    eff = tuple(ConcealedEffect(t, joint, v) for t, v in effects)
    ep = simulate(obj.model, obj.handles, eff, plan=stroke_plan(), record_hz=hz)
    q = ep.q + np.random.default_rng(0).normal(0.0, noise, ep.q.shape)
    return obj.model, Recording(ep.t, ep.joint_names, q, tau=ep.tau)


@pytest.mark.parametrize("method", [idls, sindy])
def test_exact_door_quadratic_drag_recovered(method):
    model, rec = _door([("quadratic_drag", 0.6)])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = method(model, rec)
    (e,) = res.effects
    assert e.type == "quadratic_drag" and e.value == pytest.approx(0.6, rel=0.05)


def test_idls_recovers_damping_in_noise():
    model, rec = _door([("viscous_damping", 0.8)], noise=2e-3, hz=30)
    (e,) = idls(model, rec).effects
    assert e.type == "viscous_damping" and e.value == pytest.approx(0.8, rel=0.1)
    assert e.unit == "N*m*s/rad"


@pytest.mark.parametrize("method", [idls, sindy])
def test_null_door_reports_nothing(method):
    model, rec = _door([], noise=2e-3, hz=30)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert method(model, rec).effects == ()


def test_velocity_noise_scales_with_encoder_noise():
    t = np.arange(300) / 30.0
    rng = np.random.default_rng(1)
    small = velocity_noise(Recording(t, ("j",), 1e-3 * rng.normal(size=(300, 1))))
    large = velocity_noise(Recording(t, ("j",), 1e-2 * rng.normal(size=(300, 1))))
    assert large[0] == pytest.approx(10 * small[0], rel=0.2)
