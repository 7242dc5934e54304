"""The benchmark's drift against the true model continued past the recording
(bench.reconstruction.drift_vs_true_model), on a damped slider with a closed-form motion:
m ẍ = −b ẋ from x = 0, ẋ = v0 gives x(t) = v0 m/b (1 − e^{−b t/m}), still moving when the
3-s recording ends.  The "reconstruction" is the same slider with its axis reversed and its
joint renamed (q_reco = −x), replayed by the closed form itself: against the true model continued
it drifts ~0 at every horizon, while the tool's definition (last pose held) would score the
distance still travelled.  A slider with the wrong damping drifts by the closed-form difference."""

from __future__ import annotations

import json

import numpy as np
import pytest

from kinemaforge_opt.bench.metrics import JointRecord, JointScore
from kinemaforge_opt.bench.reconstruction import drift_vs_true_model
from kinemaforge_opt.io.recording import Recording, write_recording
from kinemaforge_opt.model import ArticulatedModel, Inertial, Joint, JointDynamics, Link, write_urdf

M, B, V0, T_REC = 2.0, 1.0, 0.5, 3.0


def _slider(name: str, axis, damping: float) -> ArticulatedModel:
    cart = Link("cart", Inertial(M, [0.0, 0.0, 0.0], np.diag([0.01, 0.02, 0.02])))
    j = Joint(name, "prismatic", "base", "cart", axis=axis, dynamics=JointDynamics(damping=damping))
    return ArticulatedModel("slider", (Link("base"), cart), (j,))


def _x(t, b=B):
    return V0 * M / b * (1 - np.exp(-b * t / M))


def _v(t, b=B):
    return V0 * np.exp(-b * t / M)


def _case(tmp_path, b_reco: float):
    root, out = tmp_path / "case", tmp_path / "out"
    (root / "ground_truth").mkdir(parents=True)
    out.mkdir()
    write_urdf(_slider("x", [1.0, 0.0, 0.0], B), root / "ground_truth" / "true_model.urdf")
    t120 = np.arange(0.0, T_REC, 1 / 120)
    write_recording(root / "recording.csv", Recording(t120, ("x",), _x(t120)[:, None], _v(t120)[:, None],
                                                      np.zeros((t120.size, 1))))
    write_urdf(_slider("j0", [-1.0, 0.0, 0.0], b_reco), out / "model.urdf")
    t10 = np.arange(0.0, T_REC, 0.1)
    write_recording(out / "recording.csv", Recording(t10, ("j0",), -_x(t10)[:, None]))
    t_rep = np.concatenate([t10, np.arange(T_REC, 50.0 + 1e-9, 0.1)])
    write_recording(out / "replay.csv", Recording(t_rep, ("j0",), -_x(t_rep, b_reco)[:, None], -_v(t_rep, b_reco)[:, None]))
    (out / "reconstruction.json").write_text(json.dumps({"verification": {"zero_step_t_s": 0.0}}))
    scores = [JointScore("x", "prismatic", "j0", "prismatic", 0.0, None, True, "parts")]
    est = [JointRecord("j0", "prismatic", "base", "cart", np.array([-1.0, 0.0, 0.0]), np.zeros(3))]
    true = [JointRecord("x", "prismatic", "base", "cart", np.array([1.0, 0.0, 0.0]), np.zeros(3))]
    return root, out, scores, est, true


def test_the_true_model_replayed_drifts_nothing_against_itself_continued(tmp_path):
    root, out, scores, est, true = _case(tmp_path, B)
    d = drift_vs_true_model(root, out, scores, est, true)["truth_continued_drift_m"]
    assert set(d) == {"1", "5", "10", "20", "50"}
    # Drake's 1-ms discrete plant against the closed form
    assert max(d.values()) < 2e-3
    # the tool's definition would have scored the distance travelled after the recording
    assert _x(50.0) - _x(T_REC - 0.1) > 0.2


def test_a_wrong_damping_drifts_by_the_closed_form_difference(tmp_path):
    root, out, scores, est, true = _case(tmp_path, 2 * B)
    d = drift_vs_true_model(root, out, scores, est, true)["truth_continued_drift_m"]
    for h in (5.0, 50.0):
        assert d[str(int(h))] == pytest.approx(abs(_x(h) - _x(h, 2 * B)), abs=2e-3)


def test_an_unmatched_joint_is_reported_not_scored(tmp_path):
    root, out, _, est, true = _case(tmp_path, B)
    unmatched = [JointScore("x", "prismatic", None, None, None, None, False, None)]
    assert drift_vs_true_model(root, out, unmatched, est, true) == {
        "truth_continued_drift_error": "joint 'j0' has no matched true joint"}
