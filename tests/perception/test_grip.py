"""A recorded push's grip as a tracking guess (perception.grip, Tracker.grip_guess): a drawer
pulled from rest further between two samples than ICP reaches is found where the hand moved it.
The images are an exact oracle of the true front at each step: a point on it is confirmed, any
other seen through."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
from scipy.spatial import cKDTree

from kinemaforge_opt.io.sequence import Wrenches
from kinemaforge_opt.perception.grip import GripPath
from kinemaforge_opt.perception.track import ICP_COARSE_VOXELS, WIDE_FACTOR, Tracker

VOXEL = 0.01  # [m]
ON_SURFACE = 0.002  # [m]
SPEED = 0.30  # [m/s] along -y from rest at 0 s: 2.5x ICP's widest reach between two samples
TIMES = (0.0, 1.0, 2.0, 3.0)  # [s]
# a 0.38 x 0.15 m drawer front in the plane y = 0, on a 1-cm grid
FRONT = np.stack(np.meshgrid(np.arange(-0.19, 0.19 + 1e-9, VOXEL), [0.0], np.arange(0.0, 0.15 + 1e-9, VOXEL),
                             indexing="ij"), axis=-1).reshape(-1, 3)
HANDLE = np.array([0.0, -0.03, 0.075])  # [m] 3 cm in front of the front's centre


def _pulled(s: int) -> np.ndarray:
    """(4, 4) the front's true motion at step s: pulled at SPEED from rest at step 0."""
    T = np.eye(4)
    T[1, 3] = -SPEED * TIMES[s]
    return T


class _Oracle(Tracker):
    """The front alone at every step; verdicts against its true pose; no re-detection, no growth."""

    def __init__(self, grip: GripPath | None, moves: bool = True):
        surfaces = [FRONT + (_pulled(s)[:3, 3] if moves else 0.0) for s in range(len(TIMES))]
        self.voxel, self.grip = VOXEL, grip
        self.clouds = [SimpleNamespace(t=t) for t in TIMES]
        self._trees = [cKDTree(x) for x in surfaces]
        self.set_targets(surfaces)

    def full_tree(self, s):
        return self._trees[s]

    def verdicts(self, points, s):
        on = self._trees[s].query(points, distance_upper_bound=ON_SURFACE)[0] < np.inf
        return on.astype(int), (~on).astype(int)

    def moving_clusters(self, s):
        return []

    def grow(self, ref, points, Ts):
        return points

    def grow_far(self, ref, points, Ts):
        return points


def _wrenches(handle: np.ndarray) -> Wrenches:
    """A hand holding ``handle`` from 0 to 3 s, pulling it along -y at SPEED (rows at 100 Hz),
    then letting go."""
    t = np.arange(0.0, 4.0, 0.01)
    points = handle + np.outer(np.minimum(t, 3.0), [0.0, -SPEED, 0.0])
    forces = np.where((t <= 3.0)[:, None], [0.0, -20.0, 0.0], 0.0)
    return Wrenches(t, points, forces)


def test_the_grip_path_moves_over_the_overlap_of_a_contact_with_a_span():
    grip = GripPath.of(_wrenches(HANDLE))
    point, shift = grip.move(0.0, 1.0)
    np.testing.assert_allclose(point, HANDLE, atol=1e-12)
    np.testing.assert_allclose(shift, [0.0, -SPEED, 0.0], atol=1e-12)
    point, shift = grip.move(1.5, 0.5)  # backwards
    np.testing.assert_allclose(point, HANDLE + [0.0, -1.5 * SPEED, 0.0], atol=1e-12)
    np.testing.assert_allclose(shift, [0.0, SPEED, 0.0], atol=1e-12)
    point, shift = grip.move(3.5, 2.5)  # from after the hand let go at 3 s: from where it let go
    np.testing.assert_allclose(point, HANDLE + [0.0, -3.0 * SPEED, 0.0], atol=1e-12)
    np.testing.assert_allclose(shift, [0.0, 0.5 * SPEED, 0.0], atol=1e-12)
    assert grip.move(3.5, 3.9) is None
    assert GripPath.of(None) is None
    quiet = Wrenches(np.arange(3.0), np.zeros((3, 3)), np.zeros((3, 3)))
    assert GripPath.of(quiet) is None  # no force, no contact


def test_a_drawer_pulled_beyond_icp_reach_is_tracked_where_the_grip_moved_it():
    assert SPEED * (TIMES[1] - TIMES[0]) > WIDE_FACTOR * ICP_COARSE_VOXELS * VOXEL
    without = _Oracle(None).track("p0", 0, FRONT)
    assert not np.all(np.isfinite(without.Ts_delta[1]))  # from rest nothing verifies: lost
    held = _Oracle(GripPath.of(_wrenches(HANDLE))).track("p0", 0, FRONT)
    for s in range(len(TIMES)):
        np.testing.assert_allclose(held.Ts_delta[s], _pulled(s), atol=1e-6)


def test_a_grip_on_another_part_gives_no_guess():
    """A hand on a drawer half a metre below (farther than ICP reaches from this front) moves
    nothing of it."""
    far = HANDLE - [0.0, 0.0, 0.5]
    tracker = _Oracle(GripPath.of(_wrenches(far)))
    assert tracker.grip_guess(FRONT, np.eye(4), 0, 1) is None
    assert tracker.grip_guess(FRONT, np.eye(4), 1, 2) is None
    near = _Oracle(GripPath.of(_wrenches(HANDLE)))
    np.testing.assert_allclose(near.grip_guess(FRONT, np.eye(4), 0, 1), _pulled(1), atol=1e-12)


def test_a_hand_sliding_along_a_front_at_rest_moves_nothing():
    """A hand that slides along the front (its point moves, the front stays): the at-rest guess
    verifies, and the front stays where the images put it."""
    still = _Oracle(GripPath.of(_wrenches(HANDLE)), moves=False).track("p0", 0, FRONT)
    for s in range(len(TIMES)):
        np.testing.assert_allclose(still.Ts_delta[s], np.eye(4), atol=1e-6)
