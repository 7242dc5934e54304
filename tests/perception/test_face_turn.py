"""A small flat fragment put on another face (perception.track): a strip of a drawer's side wall
slides along itself, so when the drawer is pushed in fast its guesses are seen through and a wide
ICP pass lands it on the drawer's front, a quarter turn away but only a few centimetres from the
prediction (so small a patch moves little when it turns: its RMS displacement stays within ICP's
wide reach), and tracking goes on from there.  The turn is on no screw of the track and the next
pose does not continue it: the track ends at the turn.  The ICP results are scripted."""

from __future__ import annotations

import numpy as np

from factories import motion_about, scripted_tracker
from kinemaforge_opt.perception.track import ICP_COARSE_VOXELS, WIDE_FACTOR, displacement, jump

VOXEL = 0.0075  # [m] a 640x480 voxel at ~2 m
REACH = WIDE_FACTOR * ICP_COARSE_VOXELS * VOXEL  # [m] ICP's wide reach, as the tracker uses it
# (N, 3) a side-wall strip [m] in the y-z plane (normal x), 7 cm deep and 15 cm high: 210 points
STRIP = np.stack(np.meshgrid([0.0], np.arange(10) * VOXEL, np.arange(21) * VOXEL, indexing="ij"), axis=-1).reshape(-1, 3)
CENTRE = STRIP.mean(axis=0)


def _pose(rotvec=(0.0, 0.0, 0.0), t=(0.0, 0.0, 0.0), about=CENTRE) -> np.ndarray:
    """(4, 4) world motion: rotation ``rotvec`` [rad] about the point ``about`` [m] (the strip's
    centre unless given), then translation t [m]."""
    return motion_about(rotvec, t, about)


def _pushed(steps: int) -> list[np.ndarray]:
    """The strip's true motion from step 0: the drawer pushed in along +y, 1 cm per step."""
    return [_pose(t=(0.0, 0.01 * s, 0.0)) for s in range(steps)]


# at step 4 the strip lands on the front, turned 70 degrees about its long (z) axis and 2 cm off
# the constant-velocity prediction, and stays there
FLIPPED = _pose(rotvec=(0.0, 0.0, np.radians(70.0)), t=(0.02, 0.04, 0.0))
SLIPPED = _pushed(4) + [FLIPPED] * 4


def _scripted(poses: list[np.ndarray]):
    return scripted_tracker(poses, VOXEL)


def test_the_turn_stays_within_the_wide_reach_of_the_prediction():
    predicted = SLIPPED[3] @ np.linalg.inv(SLIPPED[2]) @ SLIPPED[3]
    assert displacement(FLIPPED, predicted, STRIP) < REACH  # displacement alone calls it no jump


def test_a_strip_turned_onto_another_face_ends_its_track():
    track = _scripted(SLIPPED).track("p0", 0, STRIP)
    observed = np.isfinite(track.Ts_delta[:, 0, 0])
    assert observed.tolist() == [True] * 4 + [False] * 4
    np.testing.assert_allclose(track.Ts_delta[:4], np.stack(SLIPPED[:4]))


def test_a_strip_that_slides_on_is_tracked_throughout():
    track = _scripted(_pushed(8)).track("p0", 0, STRIP)
    np.testing.assert_allclose(track.Ts_delta, np.stack(_pushed(8)))


def test_a_strip_turning_on_its_screw_is_kept():
    """A strip of a laptop lid slammed shut between two samples: 70 degrees on the screw of the
    hinge it was turning about (10 degrees per step), then at rest."""
    hinge = CENTRE + np.array([0.0, -0.05, 0.0])
    lid = [_pose(rotvec=(0.0, 0.0, np.radians(a)), about=hinge) for a in (0.0, 10.0, 20.0, 90.0, 90.0)]
    assert jump(lid[1:3], lid[3], lid[4], STRIP, REACH) is None
    track = _scripted(lid).track("p0", 0, STRIP)
    assert np.isfinite(track.Ts_delta[:, 0, 0]).all()
