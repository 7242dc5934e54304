"""Choosing a tracked pose among ICP results (perception.track.Tracker.solve_step): the free-space
test confirms a point anywhere within its depth tolerance τ of a surface, so a drawer front left
short and tilted by a coarse ICP pass from rest verifies as well as the true pose; the pose kept
is the one with more points on the observed surface.  The images are an oracle of one flat front
with a lenient τ; the ICP passes are scripted."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from kinemaforge_opt.perception.track import Tracker

VOXEL = 0.008  # [m]
TAU = 0.05  # [m] the free-space tolerance at ~2 m range (3√2·σ_z)
# (N, 3) a drawer front [m] in the x-z plane, 40 cm wide and 15 cm high
FRONT = np.stack(np.meshgrid(np.linspace(-0.2, 0.2, 41), [0.0], np.linspace(0.0, 0.15, 16), indexing="ij"), axis=-1).reshape(-1, 3)


def _pose(rotvec=(0.0, 0.0, 0.0), t=(0.0, 0.0, 0.0), about=np.zeros(3)) -> np.ndarray:
    """(4, 4) rotation by ``rotvec`` [rad] about the point ``about`` [m], then translation ``t`` [m]."""
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    T[:3, 3] = np.asarray(t) + about - T[:3, :3] @ about
    return T


TRUE = _pose(t=(0.0, -0.08, 0.0))  # pulled 8 cm in one step, from rest
# a coarse pass from rest: left 2 cm short and tilted 20° about the front's long axis
SHORT = _pose(rotvec=(np.radians(20.0), 0.0, 0.0), t=(0.0, -0.06, 0.0), about=FRONT.mean(axis=0))


class _Scripted(Tracker):
    """One step (s = 1) whose observed surface is the front at TRUE; the images confirm a point
    within TAU of it and see through it otherwise.  ``coarse`` maps (wide) to the coarse pose; the
    fine pass keeps its start; ``fine_starts`` records them."""

    def __init__(self, coarse: dict[bool, np.ndarray]):
        surface = FRONT @ TRUE[:3, :3].T + TRUE[:3, 3]
        self.voxel, self.coarse, self.fine_starts = VOXEL, coarse, []
        self.targets, self.trees = [surface] * 2, [cKDTree(surface)] * 2

    def full_tree(self, s):
        return self.trees[s]

    def verdicts(self, points, s):
        near = self.trees[s].query(points, distance_upper_bound=TAU)[0] < np.inf
        return near.astype(int), (~near).astype(int)

    def verify(self, points, s):
        cons, viol = self.verdicts(points, s)
        return float(cons.mean()), float(viol.mean())

    def _coarse(self, points, s, T0, wide=False):
        return self.coarse[wide]

    def _fine(self, points, s, T0):
        self.fine_starts.append(T0)
        return T0


def test_the_pose_on_the_surface_wins_over_one_the_images_merely_accept():
    tracker = _Scripted({False: SHORT, True: TRUE})
    assert tracker.verify(FRONT @ SHORT[:3, :3].T + SHORT[:3, 3], 1) == (1.0, 0.0)  # both verify
    T, _ = tracker.solve_step(FRONT, 1, [np.eye(4)])
    np.testing.assert_allclose(T, TRUE)


def test_coarse_poses_in_one_basin_get_one_fine_pass():
    near = TRUE @ _pose(t=(0.002, 0.0, 0.0))
    tracker = _Scripted({False: near, True: TRUE})
    # at rest the constant-velocity guess is the last pose: one start, one basin
    T, _ = tracker.solve_step(FRONT, 1, [_pose(t=(0.001, 0.0, 0.0)), np.eye(4)])
    assert len(tracker.fine_starts) == 1
    np.testing.assert_allclose(T, near)
