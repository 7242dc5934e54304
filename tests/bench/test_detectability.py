"""The oracle ΔBIC on MuJoCo recordings of the concealed-effects set (the truth is the
catalogue's; the recording is the independent simulator's)."""

from kinemaforge_opt.bench.detectability import oracle_delta_bic
from kinemaforge_opt.bench.recordings import effect_recording
from kinemaforge_opt.physics.diagnose import DELTA_BIC


def test_a_visible_damping_is_supported_far_beyond_the_selection_margin():
    assert oracle_delta_bic(effect_recording("effect_door_viscous_damping")) < 10 * DELTA_BIC


def test_stribeck_excess_on_quick_strokes_does_not_show_in_the_recording():
    # two 0.8-s pushes pass through the Stribeck regime (|v| < 0.1 rad/s) in a fraction of a
    # second: even the true law, fitted from its true values, gains less than the margin
    assert oracle_delta_bic(effect_recording("effect_door_stribeck_friction")) >= DELTA_BIC


def test_null_case_has_no_oracle():
    assert oracle_delta_bic(effect_recording("null_door")) is None
