"""The discovery bench's second recording: MuJoCo's true system, predicted by Pinocchio."""

import numpy as np

from kinemaforge_opt.bench.discovery import segment_rms
from kinemaforge_opt.bench.recordings import NOISE, other_recording
from kinemaforge_opt.nlp.joint_space import between_nominal_stops
from kinemaforge_opt.synth.effects import true_model


def test_the_true_model_predicts_the_second_recording_to_the_encoder_noise():
    # MuJoCo (the ground truth) pushes a damped door three times; Pinocchio with the true damping
    # predicts each 2-s piece from its own fitted start to within the 2-mrad noise, and the
    # nominal (undamped) model misses it by far more.  The pushes come after free coasts: an
    # integrator that steps over them (as LSODA did without a bounded step) fails this.
    er = other_recording("effect_door_viscous_damping")
    rec = between_nominal_stops(er.model, er.recording.select(er.model.joint_names))
    assert rec.t[-1] > 6.0  # the hand plan keeps the door off its own stops
    assert np.any(np.abs(rec.tau) > 1.0) and np.any(rec.tau == 0.0)  # pushed and free
    truth = segment_rms(true_model(er.model, er.effects), rec)
    assert truth < 2 * NOISE
    assert segment_rms(er.model, rec) > 20 * truth
