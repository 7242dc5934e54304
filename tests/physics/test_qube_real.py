"""diagnose on the real Quanser Qube (../shared/data/real/qube): the nominal Furuta model from the
published parameters against a recording, with three other recordings of the same device."""

from __future__ import annotations

from pathlib import Path

from factories import shared_data_dir
from kinemaforge_opt.io.qube import read_qube_csv
from kinemaforge_opt.model import read_urdf
from kinemaforge_opt.physics.diagnose import diagnose

DATA = shared_data_dir() / "real" / "qube" / "QQS2_data_diffx0"
URDF = Path(__file__).resolve().parents[2] / "models" / "furuta" / "furuta.urdf"
PUBLISHED_PENDULUM_DAMPING = 5e-5  # N·m·s/rad, the URDF's value


def test_the_pendulums_damping_is_corrected_and_independent_recordings_are_predicted_better():
    """Fitted on fin4 with fin6 judging acceptance (the same split as the README's): the pendulum's
    published damping is reported as a wrong value, smaller, and the two recordings no step saw
    (fin7, fin8) are predicted better than by the nominal model, in 1-s pieces."""
    rec, *others = (read_qube_csv(DATA / f"example_csv_fin{k}.csv", decimate=8) for k in (4, 6, 7, 8))
    d = diagnose(read_urdf(URDF), rec, segment_s=1.0, other_recordings=tuple(others))
    damping = [e for e in d.effects if e.joint == "alpha" and e.type == "viscous_damping"]
    assert damping, d.summary()
    e = damping[0]
    assert e.params["nominal"] == PUBLISHED_PENDULUM_DAMPING
    assert 0 < e.ci95[0] and e.ci95[1] < PUBLISHED_PENDULUM_DAMPING
    independent = [h for k, h in enumerate(d.held_out_others) if k != d.other_used_for_selection]
    assert len(independent) == 2
    for h in independent:
        assert h.rms_after < 0.9 * h.rms_before, d.summary()


def _diagnosed(fit: int, others: tuple[int, ...]):
    rec, *rest = (read_qube_csv(DATA / f"example_csv_fin{k}.csv", decimate=8) for k in (fit, *others))
    return diagnose(read_urdf(URDF), rec, segment_s=1.0, other_recordings=tuple(rest))


def _pendulum_damping_corrected(d) -> None:
    damping = [e for e in d.effects if e.joint == "alpha" and e.type == "viscous_damping"]
    assert damping and damping[0].ci95[1] < PUBLISHED_PENDULUM_DAMPING, d.summary()


def test_an_arm_standing_still_at_encoder_resolution_is_not_called_noiseless():
    """fin12's arm stands still for most of the recording: its quantised angle's third
    differences are mostly exactly 0, the noise estimate read 1e-9 rad, every misfit counted as
    1e8 sigma and nothing was reported.  With the encoder's rounding error as the floor the
    pendulum's damping is corrected, as on the other recordings, and all three others are
    predicted better."""
    d = _diagnosed(12, (1, 4, 7))
    _pendulum_damping_corrected(d)
    for h in d.held_out_others:
        assert h.rms_after < 0.9 * h.rms_before, d.summary()


def test_when_another_recording_refutes_the_best_ranked_hypotheses_the_others_are_fitted():
    """fin11: the pre-screen's best five were the arm's inertia and a pendulum tilt, each below
    the model-form floor, and both predicted fin12 worse; the pendulum's damping, ranked below
    them, was never fitted and nothing was reported.  Refuted, the ranking's best give way to
    the rest."""
    d = _diagnosed(11, (12, 3, 6))
    _pendulum_damping_corrected(d)
    independent = [h for k, h in enumerate(d.held_out_others) if k != d.other_used_for_selection]
    assert len(independent) == 2
    for h in independent:
        assert h.rms_after < h.rms_before, d.summary()
