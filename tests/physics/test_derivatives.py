"""The derivatives behind the inverse-dynamics residual (physics.locate): the Savitzky–Golay
window follows the motion's speed, checked against analytic derivatives of sinusoids; the
velocity's noise level against the spread of smoothed white noise."""

from __future__ import annotations

import numpy as np
import pytest

from kinemaforge_opt.io.recording import Recording
from kinemaforge_opt.nlp.joint_space import GAP_INTERVALS, stretches
from kinemaforge_opt.physics.locate import (
    DERIVATIVE_WINDOW_S, block_means, motion_window, smooth_derivatives, velocity_noise,
)


def _sine(freq_hz: float, rate_hz: float = 250.0, seconds: float = 4.0) -> tuple[Recording, np.ndarray]:
    """A joint swinging at ``freq_hz`` (1 rad amplitude) and its analytic acceleration."""
    t = np.arange(0.0, seconds, 1.0 / rate_hz)
    w = 2 * np.pi * freq_hz
    return Recording(t, ("j",), np.sin(w * t)[:, None]), -(w**2) * np.sin(w * t)


def _gain(a: np.ndarray, exact: np.ndarray, edge: int = 50) -> float:
    """Least-squares gain of an estimated acceleration against the exact one (edges left out)."""
    a, exact = a[edge:-edge, 0], exact[edge:-edge]
    return float(a @ exact / (exact @ exact))


def test_a_fast_swing_gets_a_window_short_enough_for_its_acceleration():
    rec, exact = _sine(2.5)
    window = motion_window(rec)
    assert window < DERIVATIVE_WINDOW_S
    assert _gain(smooth_derivatives(rec)[2], exact) < 0.95  # the default window: > 5 % low
    # ≈ 2 % low (DERIVATIVE_HALF_WINDOW_RAD; the window is rounded to whole samples)
    assert _gain(smooth_derivatives(rec, window)[2], exact) == pytest.approx(1.0, abs=0.025)


def test_a_slow_motion_keeps_the_default_window():
    rec, exact = _sine(0.2)
    assert motion_window(rec) == DERIVATIVE_WINDOW_S
    assert _gain(smooth_derivatives(rec)[2], exact) == pytest.approx(1.0, abs=0.01)


def test_block_means_average_whole_blocks():
    a = np.arange(14.0).reshape(7, 2)
    np.testing.assert_allclose(block_means(a, 3), [[2.0, 3.0], [8.0, 9.0]])
    assert block_means(a, 1) is a and block_means(None, 3) is None



def test_block_means_do_not_straddle_a_gap():
    """Samples 0–4 and 5–9 of a log that paused between them: blocks of 2 are taken within each
    stretch (the last incomplete one dropped); a block across the pause would be a sample of
    nothing recorded."""
    t = np.concatenate([np.arange(5.0), 20.0 + np.arange(5.0)])
    a = t[:, None] * 10.0
    np.testing.assert_allclose(block_means(t, 2, t), [0.5, 2.5, 20.5, 22.5])
    np.testing.assert_allclose(block_means(a, 2, t)[:, 0], [5.0, 25.0, 205.0, 225.0])


def test_a_gap_stays_a_gap_at_the_blocks_rate():
    """A hole of 7 sample intervals (a gap: more than GAP_INTERVALS) is 3.5 intervals of blocks
    of 2, no gap on their grid, whose fit would carry the dynamics across it: the first blocks
    after it are dropped until it is one again, so every stretch of the blocks is one of the
    samples."""
    t = np.concatenate([np.arange(30.0), 36.0 + np.arange(30.0)])
    blocks = block_means(t, 2, t)
    assert len(stretches(blocks)) == len(stretches(t)) == 2
    hole = np.diff(blocks).max()
    assert hole > GAP_INTERVALS * np.median(np.diff(blocks))
    assert blocks[np.argmax(np.diff(blocks)) + 1] == pytest.approx(36.0 + 2 * 2 + 0.5)  # two blocks dropped


@pytest.mark.parametrize("rate_hz, block", [(60.0, 1), (100.0, 3), (250.0, 1)])
def test_the_velocity_noise_level_is_the_spread_of_smoothed_white_noise(rate_hz, block):
    """``velocity_noise`` (the derivative filter's gain) against the standard deviation of the
    smoothed velocity of 20 000 samples of white noise, block-averaged as on a search grid."""
    sigma = 2e-3
    t = np.arange(20000) / rate_hz
    rec = Recording(t, ("j",), np.random.default_rng(3).normal(0.0, sigma, (t.size, 1)))
    v = smooth_derivatives(rec)[1][50:-50]
    measured = float(np.std(block_means(v, block)))
    assert velocity_noise(np.array([sigma]), 1.0 / rate_hz, block=block)[0] == pytest.approx(measured, rel=0.03)
