"""A joint that turned between two frames (a lid lifted and let fall, seen at a few frames a
second) gets the end of its range where it turned, not at the frame nearest the turn
(stop_limits / apex_reach).  The truth is analytic: under a constant deceleration the turn is
at v0² / (2a)."""

import numpy as np
import pytest

from kinemaforge_opt.stops import STOP_BAND, apex_reach, stop_impacts, stop_limits

FRAME_S = 0.158  # 6.3 frames a second, as the benchmark's lids
V0, DECEL = 4.0, 5.8  # [rad/s], [rad/s²]: turns at V0² / (2 DECEL) = 1.379 rad, at 0.690 s
TOP = V0**2 / (2 * DECEL)


def lifted(t: np.ndarray) -> np.ndarray:
    """A lid sent up at V0 that slows at DECEL, turns at TOP and falls back as fast, shut (q = 0)
    on its stop from then on [rad]."""
    return np.maximum(V0 * t - 0.5 * DECEL * t**2, 0.0)


def frames(phase: float) -> np.ndarray:
    return phase + FRAME_S * np.arange(16)


@pytest.mark.parametrize("phase", [0.0, 0.03, 0.07, 0.12, 0.14])
def test_the_upper_limit_is_where_a_lid_turned_between_frames(phase):
    t = frames(phase)
    q = lifted(t)
    lower, upper = stop_limits(t, q[:, None])[0]
    assert upper == pytest.approx(TOP, abs=1e-9)  # the nearest frame is 0.4-17 mrad short
    assert lower == pytest.approx(0.0, abs=1e-12)  # shut on its stop: the frames say where
    # the lower end of a joint turning the other way
    assert stop_limits(t, -q[:, None])[0, 0] == pytest.approx(-TOP, abs=1e-9)


def test_noisy_frames_put_the_turn_nearer_the_truth_than_the_nearest_frame():
    rng = np.random.default_rng(7)
    vertex_err, frame_err = [], []
    for phase in rng.uniform(0.0, FRAME_S, 40):
        t = frames(phase)
        q = lifted(t) + rng.normal(0.0, 0.003, t.size)  # 3 mrad of tracking noise
        vertex_err.append(abs(q.max() + apex_reach(t, q, 1) - TOP))
        frame_err.append(abs(q.max() - TOP))
    assert np.mean(frame_err) > 0.005
    assert np.mean(vertex_err) < 0.5 * np.mean(frame_err)
    assert np.max(vertex_err) < 0.02


def test_a_joint_resting_at_an_end_before_or_after_keeps_the_frame():
    t = np.arange(20) * 0.1
    pushed = np.clip(1.5 * t, 0.0, 1.2)  # pushed open onto its stop at 1.2 rad and held there
    assert apex_reach(t, pushed, 1) == 0.0
    assert stop_limits(t, pushed[:, None])[0, 1] == pytest.approx(1.2)
    leaves = pushed[::-1].copy()  # rests at 1.2 rad, then pushed shut: leaves the end from rest
    assert apex_reach(t, leaves, 1) == 0.0
    # one rest frame of noise above the stop does not make a turn either
    bump = pushed.copy()
    bump[10] += 1e-4
    assert apex_reach(t, bump, 1) == 0.0


def test_an_end_at_the_first_or_last_frame_or_a_stop_impact_is_left_to_its_own_rules():
    t = frames(0.05)
    q = lifted(t)
    assert apex_reach(t[:5], q[:5], 1) == 0.0  # still rising at the last frame
    assert apex_reach(t[3:], q[3:], 0) == 0.0  # the stop end: the lid rests shut, no turn
    # a door slammed onto its stop that rests there: the impact end keeps its frame
    slam = np.minimum(3.0 * t, 1.5)
    assert stop_limits(t, slam[:, None])[0, 1] == pytest.approx(1.5)


def test_a_turn_whose_top_two_frames_lie_in_the_stop_band_is_no_stop_impact():
    t = frames(0.12)  # frames at 1.353 and 1.368 rad, both within 2 % of the range of the top
    q = lifted(t)
    assert np.ptp(q) * STOP_BAND > TOP - q[3]
    assert [e.end for e in stop_impacts(t, q[:, None])] == [0.0]  # only the fall onto the shut stop
    assert [e.end for e in stop_impacts(t, -q[:, None])] == [0.0]  # turning at the lower end
    # a door that hits its stop, rests there three frames and is pulled back fast: still an impact
    door = np.array([0.0, 0.3, 0.7, 1.1, 1.5, 1.498, 1.499, 1.497, 1.1, 0.6, 0.2, 0.0, 0.0])
    first = stop_impacts(np.arange(door.size) * 0.1, door[:, None])[0]
    assert (first.i, first.end) == (4, 1.5)
