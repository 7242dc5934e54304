"""Several recordings of the same system fitted together (``nlp.joint_space.join_recordings``):
one model for all, each recording followed from its own state.  The truth is Drake's (its own
joint damping and integrator; the fits use Pinocchio's ABA)."""

from __future__ import annotations

import numpy as np
import pytest

from kinemaforge_opt.calibration import calibrate
from kinemaforge_opt.cli import main
from kinemaforge_opt.errors import DataError
from kinemaforge_opt.io.recording import Recording, write_recording
from kinemaforge_opt.model import write_urdf
from kinemaforge_opt.nlp.joint_space import GAP_INTERVALS, JOIN_GAP_S, join_recordings, recording_gaps
from kinemaforge_opt.physics.diagnose import diagnose

from .test_other_simulator import RECORD_HZ, _pendulum, _swing

TRUTH = dict(damping=0.03, scale=1.5)  # the rod 1.5 times heavier, three times the model's damping


def _free_and_pushed(push_s: float = 1.0) -> tuple[Recording, Recording]:
    """A free swing of the true rod released at 1 rad (no force recorded, 6 s) and ``push_s`` of
    it pushed by a recorded torque from the same release."""
    t = np.arange(0.0, 6.0 + 0.5 / RECORD_HZ, 1.0 / RECORD_HZ)
    tau = (0.3 * np.sin(2 * np.pi * 0.7 * t) * (t < 3.0))[:, None]
    truth = _pendulum(**TRUTH)
    return _swing(truth), _swing(truth, tau).window(0.0, push_s)


def test_a_free_swing_and_a_second_of_pushing_together_fix_the_inertia_and_the_damping():
    """A free swing fixes the damping only relative to the rod's inertia (0.020 in the model's
    units for 0.03 on a rod 1.5 times heavier), and one second of pushing alone was read as a
    constant bias.  Fitted together, the push fixes the scale and the swing the damping."""
    free, pushed = _free_and_pushed()
    alone = diagnose(_pendulum(0.01), free)
    assert "inertia_error" not in {e.type for e in alone.effects}
    assert "no applied force was recorded" in alone.summary()
    d = diagnose(_pendulum(0.01), [free, pushed])
    assert {e.type: e.value for e in d.effects} == pytest.approx({"viscous_damping": 0.03, "inertia_error": 1.5},
                                                                 rel=0.02), d.summary()
    assert "2 recordings fitted together" in d.summary() and "no applied force" not in d.summary()
    # the fit reads the first three quarters of each, one after the other; the last ones are held out
    assert recording_gaps(d.nominal_fit.recording.t).size == 1
    assert d.held_out.rms_after < 0.5 * d.held_out.rms_before


def test_calibrate_fits_several_recordings_with_one_model():
    free, pushed = _free_and_pushed()
    names = ["hinge.damping", "rod.inertia_ratio"]
    cal = calibrate(_pendulum(0.01), [free, pushed], free=names)
    assert {n: float(e.value[0]) for n, e in cal.estimates.items()} == pytest.approx(
        {"hinge.damping": 0.03, "rod.inertia_ratio": 1.5}, rel=0.02)
    assert any("2 recordings fitted together" in w for w in cal.identifiability)
    assert not any("cannot determine" in w for w in cal.identifiability)
    # the fit does not carry the first recording's end state into the second one's start
    assert cal.recording.t.size == free.t.size + pushed.t.size
    assert cal.q_fit[free.t.size, 0] == pytest.approx(pushed.q[0, 0], abs=0.01)


def test_recordings_are_joined_with_a_gap_between_them():
    free, pushed = _free_and_pushed()
    joined = join_recordings([free, pushed])
    (gap,) = recording_gaps(joined.t)
    assert gap == free.t.size - 1
    assert joined.t[gap + 1] - joined.t[gap] == pytest.approx(max(JOIN_GAP_S, 2 * GAP_INTERVALS * free.dt))
    # the free swing recorded no force: beside a pushed one it is driven by nothing
    np.testing.assert_array_equal(joined.tau[: free.t.size], 0.0)
    np.testing.assert_array_equal(joined.tau[free.t.size:], pushed.tau)
    assert join_recordings([free]) is free


def test_recordings_that_cannot_be_fitted_together_are_named():
    free, pushed = _free_and_pushed()
    other_joint = Recording(pushed.t, ("elbow",), pushed.q, tau=pushed.tau)
    with pytest.raises(DataError, match=r"recording 2 has joints \['elbow'\], recording 1 \['hinge'\]"):
        join_recordings([free, other_joint])
    with_v = Recording(pushed.t, pushed.joint_names, pushed.q, v=np.zeros_like(pushed.q), tau=pushed.tau)
    with pytest.raises(DataError, match="recording 2 has velocities v:<joint> and recording 1 has none"):
        join_recordings([free, with_v])
    fast = Recording(free.t[0] + (free.t - free.t[0]) / 4, free.joint_names, free.q)
    with pytest.raises(DataError, match=r"recording 2 is sampled at 120 Hz and recording 1 at 30 Hz"):
        join_recordings([free, fast])


def test_the_cli_fits_recordings_given_with_also(tmp_path, capsys):
    free, pushed = _free_and_pushed()
    urdf = write_urdf(_pendulum(0.01), tmp_path / "rod.urdf")
    paths = [write_recording(tmp_path / f"{k}.csv", r) for k, r in enumerate((free, pushed))]
    assert main(["calibrate", str(urdf), str(paths[0]), "--also", str(paths[1]), "-o", str(tmp_path / "cal"),
                 "--free", "hinge.damping,rod.inertia_ratio"]) == 0
    out = capsys.readouterr().out
    assert "from 2 recordings" in out and "2 recordings fitted together" in out
    assert main(["diagnose", str(urdf), str(paths[0]), "--also", str(paths[1]), "-o", str(tmp_path / "diag"),
                 "--no-drift", "--workers", "1"]) == 0
    assert "missing physics on hinge: inertia error" in capsys.readouterr().out
    fast = write_recording(tmp_path / "fast.csv", Recording(free.t / 4, free.joint_names, free.q))
    assert main(["diagnose", str(urdf), str(paths[0]), "--also", str(fast), "-o", str(tmp_path / "bad")]) == 2
    assert "recording 2 is sampled at 120 Hz and recording 1 at 30 Hz" in capsys.readouterr().err
    assert not (tmp_path / "bad" / "model.urdf").exists()


def test_inverse_dynamics_calibration_filters_each_recording_on_its_own():
    """The torque-error method low-passes q, v and tau: across the pause between joined
    recordings that filter would smear one recording into the next.  Each is filtered and trimmed
    on its own, and a stretch too short for the filter's edge padding is left out."""
    from kinemaforge_opt.nlp.inverse_dynamics import filtered_states

    t = np.arange(0.0, 6.0 + 0.5 / RECORD_HZ, 1.0 / RECORD_HZ)
    truth = _pendulum(**TRUTH)
    recs = [_swing(truth, (a * np.sin(2 * np.pi * f * t))[:, None]) for a, f in ((0.3, 0.7), (0.5, 0.3))]
    short = recs[0].window(0.0, 0.4)  # 13 samples
    joined = join_recordings([*recs, short])
    q = filtered_states(joined, 3.0)[0]
    assert np.isnan(q[-short.t.size:]).all() and np.isfinite(q[: -short.t.size]).all()
    cal = calibrate(_pendulum(0.01), [*recs, short], free=["hinge.damping", "rod.inertia"], method="inverse_dynamics")
    m_cz = float(cal.estimates["rod.inertia"].value[3])  # the rod's first moment along its length [kg·m]
    assert m_cz == pytest.approx(-TRUTH["scale"] * 0.2, rel=0.02)
    assert float(cal.estimates["hinge.damping"].value[0]) == pytest.approx(TRUTH["damping"], rel=0.1)
