"""What a fit reads of a recording (``nlp.joint_space.fit_span``): isolated tracking glitches are
left out, real reversals are kept, and what was left out is said."""

from __future__ import annotations

import numpy as np
import pytest

from kinemaforge_opt.calibration import calibrate
from kinemaforge_opt.io.recording import Recording
from kinemaforge_opt.nlp.joint_space import without_spikes
from kinemaforge_opt.physics.diagnose import diagnose

from .test_other_simulator import _drake_recording
from .test_search_grid import _two_parts_diagnosed

GLITCHES = ((40, 0.15), (95, -0.2), (150, 0.1))  # (sample, jump [rad]): 50–100 noise sigmas


def _glitched(rec: Recording) -> Recording:
    q = rec.q.copy()
    for i, jump in GLITCHES:
        q[i] += jump
    return Recording(rec.t, rec.joint_names, q, tau=rec.tau)


def test_single_sample_glitches_are_left_out_and_said():
    """Three glitches in 210 samples of a damped Drake door: the fit was pulled to quadratic drag
    and Coulomb friction; without them the damping is found, and the summary names the samples."""
    model, rec = _drake_recording("cabinet", damping=0.4)
    glitched = _glitched(rec)
    _, left_out = without_spikes(glitched)
    assert left_out == {model.joint_names[0]: pytest.approx([rec.t[i] for i, _ in GLITCHES])}
    d = diagnose(model, glitched)
    assert {e.type: e.value for e in d.effects} == pytest.approx({"viscous_damping": 0.4}, rel=0.02), d.summary()
    assert "left out 3 isolated sample(s)" in d.summary()
    cal = calibrate(model, glitched, free=[f"{model.joint_names[0]}.damping"])
    assert cal.estimates[f"{model.joint_names[0]}.damping"].value[0] == pytest.approx(0.4, rel=0.02)
    assert cal.identifiability[0].startswith("left out 3 isolated sample(s)")


@pytest.mark.parametrize("speed_sigmas", [8.0, 12.0, 20.0, 60.0])
def test_an_instant_rebound_is_not_a_glitch(speed_sigmas):
    """A part that bounces straight back off a stop between two samples looks, at its peak, like a
    one-sample jump off its neighbours' line; but its neighbours stay on theirs."""
    sigma, dt = 1e-3, 0.01
    t = np.arange(0.0, 1.0, dt)
    peak = 50
    q = speed_sigmas * sigma * (1.0 - np.abs(np.arange(t.size) - peak) / 1.0) + np.random.default_rng(0).normal(0, sigma, t.size)
    rec = Recording(t, ("j",), q[:, None])
    assert without_spikes(rec)[1] == {}


@pytest.mark.parametrize("gap", [(2.0, 2.5), (2.0, 3.0), (1.0, 3.0)])
def test_a_gap_in_the_recording_is_not_bridged_by_the_dynamics(gap):
    """A log that lost 0.5–2 s of a damped Drake door: the fit carried the dynamics across the gap
    under a force only interpolated there (calibrate read damping 1.47 for 0.4), and the
    derivatives of the pre-screen read the gap's jump as motion (diagnose found nothing).  A gap
    of more than five median intervals now ends a segment, a prediction piece and a derivative
    window.  With 2 s of 7 lost the damping still ranked outside the pre-screen's five and
    quadratic drag was reported: a one-joint selection round is now fitted whole."""
    model, rec = _drake_recording("cabinet", damping=0.4)
    keep = (rec.t < gap[0]) | (rec.t > gap[1])
    gapped = Recording(rec.t[keep], rec.joint_names, rec.q[keep], tau=rec.tau[keep])
    name = f"{model.joint_names[0]}.damping"
    assert calibrate(model, gapped, free=[name]).estimates[name].value[0] == pytest.approx(0.4, rel=0.02)
    d = diagnose(model, gapped)
    assert {e.type: e.value for e in d.effects} == pytest.approx({"viscous_damping": 0.4}, rel=0.02), d.summary()


def test_two_doors_that_hit_their_stops_in_turn_are_read_between_every_contact():
    """A MuJoCo refrigerator: each door in turn is pushed open, runs into its open stop, is pushed
    shut and hits its closed stop (60 Hz, 2 mrad).  The freezer door has damping 0.5 N·m·s/rad,
    the fridge door Coulomb friction 0.3 N·m.  Read over the longest stretch clear of every stop
    alone (4.45–7.78 s of 12 s), damping 0.27 on the fridge door and an axis tilt on the freezer
    door were reported; read over every clear stretch, each a piece of its own, both are found."""
    d, freezer, fridge = _two_parts_diagnosed("refrigerator", 0, 0.5, 0.3, 60)
    found = {(e.joint, e.type): e.value for e in d.effects}
    assert found == pytest.approx({(freezer, "viscous_damping"): 0.5, (fridge, "coulomb_friction"): 0.3}, rel=0.05), \
        d.summary()
    assert "were fitted: the rest is a joint pressed on, or reaching, a stop" in d.summary()
    assert "without resting on it" not in d.summary()  # what is left out is each door's own contact
