"""The open-loop simulator behind every prediction (``physics.predict.simulate_recording``):
CVODES on the bridge's ABA, checked against MuJoCo (the synthetic world's independent simulator)
through a stop, and kept finite when a force law diverges."""

from __future__ import annotations

import numpy as np
import pytest

from kinemaforge_opt.calibration import apply_parameters
from kinemaforge_opt.io.recording import Recording
from kinemaforge_opt.nlp.joint_space import between_nominal_stops
from kinemaforge_opt.physics.predict import HeldOut, predict_before_after, simulate_recording
from kinemaforge_opt.synth.effects import ConcealedEffect as E
from kinemaforge_opt.synth.groundtruth import HandPlan, simulate
from kinemaforge_opt.synth.objects import make_object

NOISE = 2e-3
STOP, STIFFNESS = 0.45, 600.0  # [rad], [N·m/rad]


@pytest.fixture(scope="module")
def door_on_a_stop():
    """A MuJoCo door with damping 0.5 N·m·s/rad pushed towards 0.5 rad onto an upper stop at
    0.45 rad (600 N·m/rad), then towards 0.3 rad; 100 Hz, 2 mrad noise."""
    obj = make_object("cabinet", 0)
    j = obj.model.joint_names[0]
    effects = (E("viscous_damping", j, 0.5), E("limit_contact", j, STOP, (("stiffness", STIFFNESS), ("side", "upper"))))
    ep = simulate(obj.model, obj.handles, effects,
                  plan=HandPlan(goals=(0.5, 0.3), push_s=0.8, free_s=1.7, release_speed=0.15), record_hz=100)
    q = ep.q + np.random.default_rng(5).normal(0.0, NOISE, ep.q.shape)
    return obj.model, j, Recording(ep.t, ep.joint_names, q, tau=ep.tau)


def test_a_door_pressed_onto_its_stop_is_simulated_like_mujoco(door_on_a_stop):
    """The true model (damping + the stop) in 1-s pieces, each from its fitted state, stays within
    the noise of MuJoCo's motion through the contact; without the stop it does not."""
    model, j, rec = door_on_a_stop
    # up to where the stop throws the door back onto its closed end (a range limit MuJoCo
    # enforces and the model's dynamics do not hold)
    rec = between_nominal_stops(model, rec)
    assert rec.q[:, 0].max() > STOP + 0.01  # the hand does press the door into the stop
    damped = apply_parameters(model, {f"{j}.damping": np.array([0.5])})
    truth = apply_parameters(damped, {f"{j}.limit_stop": np.array([STOP]), f"{j}.limit_stiffness": np.array([STIFFNESS])})
    assert truth.joint(j).dynamics.limit_side == 1.0
    h = predict_before_after(damped, truth, rec, 1.0)
    assert h.rms_after < 1.5 * NOISE
    assert h.rms_before > 5 * NOISE


def test_pieces_simulated_side_by_side_give_the_same_prediction(door_on_a_stop):
    """The pieces of both models and both phases, simulated on two processes, give exactly the
    prediction simulated in this process, every sample in its place."""
    model, j, rec = door_on_a_stop
    rec = between_nominal_stops(model, rec)
    damped = apply_parameters(model, {f"{j}.damping": np.array([0.5])})
    alone = predict_before_after(model, damped, rec, 1.0, phases=2, workers=1)
    side_by_side = predict_before_after(model, damped, rec, 1.0, phases=2, workers=2)
    assert alone.t.size > rec.t.size  # two phases pooled
    for field in ("t", "q_rec", "q_before", "q_after"):
        np.testing.assert_array_equal(getattr(side_by_side, field), getattr(alone, field))
    assert alone.rms_after < alone.rms_before


def test_a_diverging_law_holds_the_last_state_it_reached(door_on_a_stop):
    """A law that drives the speed to infinity in finite time (f = 50 v^3) stops the integrator;
    the simulation keeps the longest prefix it integrated and holds its last state, finite."""
    model, j, rec = door_on_a_stop
    q = simulate_recording(model, rec, extra={j: lambda q, v: 50.0 * v**3})
    assert q.shape == rec.q.shape and np.isfinite(q).all()
    held = np.flatnonzero(np.abs(np.diff(q[:, 0])) > 0)[-1] + 1  # last sample that moved
    assert held < rec.t.size - 10  # it did give up early ...
    assert np.all(q[held:, 0] == q[held, 0])  # ... and holds from there
    # before giving up it followed the same law as the nominal model at first
    q_nominal = simulate_recording(model, rec)
    assert np.abs(q[:5, 0] - q_nominal[:5, 0]).max() < 1e-3


@pytest.mark.parametrize("gap", [0.12, 0.15, 0.18, 0.21, 0.24])
def test_a_door_coasting_below_a_stop_it_never_reaches_keeps_its_speed(gap):
    """No force but a stop ``gap`` rad beyond the end of the motion (its softplus force there:
    below 1e-100 N·m): a door about a plumb axis coasts at constant speed, q = 0.3 + 0.05 t.
    (CVODES's default dense QR gave up on the Jacobian's tiny entries at gaps 0.12-0.18.)"""
    obj = make_object("cabinet", 0)
    j = obj.model.joint_names[0]
    t = np.arange(0.0, 2.0 + 1e-9, 0.01)
    q_true = 0.3 + 0.05 * t
    rec = Recording(t, (j,), q_true[:, None], tau=np.zeros((t.size, 1)))
    m = apply_parameters(obj.model, {f"{j}.limit_stop": np.array([q_true[-1] + gap]),
                                     f"{j}.limit_stiffness": np.array([200.0])})
    np.testing.assert_allclose(simulate_recording(m, rec)[:, 0], q_true, atol=1e-5)

def test_a_gain_on_one_joint_is_not_diluted_by_another():
    """HeldOut's gain is the best joint's: one joint predicted 2σ better, one the same."""
    t = np.arange(10.0)
    rec = np.zeros((10, 2))
    before = np.column_stack([np.full(10, 3.0), np.ones(10)])
    after = np.column_stack([np.ones(10), np.ones(10)])
    h = HeldOut(t, rec, before, after)
    np.testing.assert_allclose(h.joint_gains_sigma(np.ones(2)), [2.0, 0.0])
    assert h.gain_sigma(np.ones(2)) == pytest.approx(2.0)


def test_a_short_misprediction_is_judged_where_it_is():
    """Before-model off by 10 noise sigmas for 0.2 s of a 10-s span (a stop's impact), after-model
    at the noise: pooled over the span the gain is below one sigma, judged where either model
    errs beyond 3 sigmas it is several."""
    rng = np.random.default_rng(0)
    t = np.arange(0.0, 10.0, 0.01)
    q_rec = rng.normal(0.0, 1.0, (t.size, 1))
    bump = ((t > 5.0) & (t < 5.2)).astype(float)[:, None] * 10.0
    h = HeldOut(t, q_rec, bump, np.zeros_like(q_rec))
    assert h.gain_sigma(np.ones(1)) < 1.0
    assert h.gain_sigma(np.ones(1), signal_sigma=3.0) > 3.0
    assert HeldOut(t, q_rec, np.zeros_like(q_rec), np.zeros_like(q_rec)).gain_sigma(np.ones(1), signal_sigma=3.0) == 0.0
