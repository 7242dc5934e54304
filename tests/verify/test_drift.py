"""Drift and energy residual of models replaying closed-form recordings."""

from __future__ import annotations

import numpy as np
import pytest
from verify_models import oscillator_recording, slider

from kinemaforge_opt.errors import DataError
from kinemaforge_opt.io.recording import Recording
from kinemaforge_opt.verify import drift, energy_residual

M, K, B, REST = 2.0, 50.0, 2.0, 0.1


def _model(b=B, k=K):
    return slider(M, damping=b, spring_stiffness=k, spring_rest=REST)


@pytest.fixture(scope="module")
def settled():
    """20 s of exact damped oscillation (settles to 1e-6 m), 100 Hz."""
    return oscillator_recording(M, K, B, REST, x0=0.3, duration=20.0)


def test_consistent_model_does_not_drift(settled):
    report = drift(_model(), settled, discrete=False)
    assert list(report.horizons_s) == [1, 5, 10, 20, 50]
    assert report.beyond_recording.tolist() == [False, False, False, True, True]
    assert np.all(report.drift_m < 1e-5)
    assert np.all(report.joint_rms < 1e-5)


def test_discrete_replay_drifts_by_its_time_step_only(settled):
    report = drift(_model(), settled, horizons_s=(1, 5, 30))
    assert np.all(report.max_drift_m < 5e-3)


def test_wrong_damping_drifts(settled):
    good = drift(_model(), settled, horizons_s=(1, 5), discrete=False)
    bad = drift(_model(b=0.5 * B), settled, horizons_s=(1, 5), discrete=False)
    assert bad.drift_m[1] > 0.01 > 1e3 * good.drift_m[1]
    assert np.all(bad.max_drift_m > good.max_drift_m)


def test_beyond_the_recording_the_reference_is_its_last_pose():
    short = oscillator_recording(M, K, B, REST, x0=0.3, duration=3.0)  # ends at 0.3·e^-1.5 swing
    report = drift(_model(), short, horizons_s=(50,), discrete=False)
    assert report.drift_m[0] == pytest.approx(abs(short.q[-1, 0] - REST), abs=1e-5)


def test_recorded_force_is_replayed():
    tau = 5.0  # constant push: equilibrium moves to rest + tau/k
    rec = oscillator_recording(M, K, B, REST, x0=REST, duration=8.0, tau=tau)
    assert drift(_model(), rec, horizons_s=(2, 7.5), discrete=False).drift_m.max() < 1e-5
    unforced = Recording(rec.t, rec.joint_names, rec.q, rec.v, None)
    assert drift(_model(), unforced, horizons_s=(2,), discrete=False).drift_m[0] > 0.05


def test_energy_residual_is_zero_for_the_true_model_and_large_otherwise(settled):
    assert energy_residual(_model(), settled) < 1e-3
    assert energy_residual(_model(b=0.5 * B), settled) > 0.3
    assert energy_residual(_model(k=2 * K), settled) > 0.3


def test_recording_joint_not_in_model_is_named(settled):
    rec = Recording(settled.t, ("drawer",), settled.q, settled.v)
    with pytest.raises(DataError, match="'drawer' are not movable joints of model 'slider'"):
        drift(_model(), rec)
    with pytest.raises(DataError, match="'drawer'"):
        energy_residual(_model(), rec)


def test_model_joint_missing_from_recording_is_named(settled):
    two = Recording(settled.t, ("x", "y"), np.hstack([settled.q, settled.q]))
    with pytest.raises(DataError, match="'y'"):
        drift(_model(), two)


def test_bad_horizons(settled):
    with pytest.raises(DataError, match="horizons_s"):
        drift(_model(), settled, horizons_s=(1, -5))


def test_initial_velocity_never_points_into_the_stop_the_joint_starts_on():
    # a 4 kg slider pushed by 8 N from rest on its lower stop (x = a t²/2, a = 2 m/s²), seen at
    # 4 Hz; the model is half as heavy, so it runs ahead, and a v0 into the stop (a bounce that
    # wastes time) would fit the first frames better.  The truth, v0 = 0, is the only start
    # that does not move into the stop.
    from verify_models import JointLimits

    from kinemaforge_opt.verify.drift import fit_initial_velocity

    t = np.arange(0.0, 1.5, 0.25)
    x = 0.5 * 2.0 * t**2
    rec = Recording(t, ("x",), x[:, None], tau=np.full((t.size, 1), 8.0))
    model = slider(2.0, limits=JointLimits(0.0, 5.0))
    assert fit_initial_velocity(model, rec)[0] == pytest.approx(0.0, abs=1e-9)


def test_initial_velocity_from_rest_is_found_past_a_stop_in_the_window():
    # a 4 kg slider pulled from rest by 8 N for 0.4 s (x = a t²/2, a = 2 m/s², then 0.8 m/s)
    # onto a stop at 0.35 m, seen at ~2 Hz.  The first finite difference (0.46 m/s) replays it
    # into the stop inside the window, where more speed only means an earlier rebound: a false
    # minimum.  The truth, the model itself, started at rest, replays it exactly.
    from verify_models import JointLimits

    from kinemaforge_opt.verify.drift import fit_initial_velocity

    m, force, push_s, stop = 4.0, 8.0, 0.4, 0.35
    a = force / m
    t = np.arange(0.0, 2.0, 0.475)
    x = np.minimum(np.where(t < push_s, 0.5 * a * t**2, 0.5 * a * push_s**2 + a * push_s * (t - push_s)), stop)
    tf = np.arange(0.0, 2.0, 0.01)
    forcing = Recording(tf, ("x",), np.zeros((tf.size, 1)), tau=np.where(tf < push_s, force, 0.0)[:, None])
    model = slider(m, limits=JointLimits(0.0, stop))
    assert fit_initial_velocity(model, Recording(t, ("x",), x[:, None]), forcing)[0] == pytest.approx(0.0, abs=0.01)
