"""A lid opened and slammed shut within 12 camera samples (the quick benchmark's rate): the
slam inflates the smoother-based noise estimate above what the hinge fit leaves, which made
the lid's 80° turn look like noise ("no motion") or like a slide.  Truth by construction."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from kinemaforge_opt.graph import infer_tree
from kinemaforge_opt.io.tracks import PoseTracks
from kinemaforge_opt.spatial import axis_angle_error

HINGE_POINT = np.array([0.0, 0.24, 0.014])  # a laptop's hinge, along x [m]
LID_CENTRE = np.array([0.0, 0.0, 0.12])  # at the open pose (angle 0) [m]
ANGLES = np.radians([79.0, 60.0, 33.0, 0.0, 6.0, 79.0, 79.0, 79.0, 79.0, 79.0, 79.0, 79.0])


def _lid_pose(angle: float) -> np.ndarray:
    T = np.eye(4)
    R = Rotation.from_rotvec([-angle, 0.0, 0.0]).as_matrix()
    T[:3, :3] = R
    T[:3, 3] = HINGE_POINT + R @ (LID_CENTRE - HINGE_POINT)
    return T


@pytest.mark.parametrize("seed", range(4))
def test_a_lid_slammed_shut_within_twelve_samples_is_a_revolute_joint(seed):
    rng = np.random.default_rng(seed)
    poses = [_lid_pose(a) for a in ANGLES]
    P = np.array([T[:3, 3] for T in poses]) + rng.normal(0.0, 0.003, (len(poses), 3))
    R = np.array([Rotation.from_rotvec(rng.normal(0.0, 0.01, 3)).as_matrix() @ T[:3, :3] for T in poses])
    tracks = PoseTracks(np.arange(len(poses)) * 0.275, ("lid",), P[None], R[None])
    (joint,) = infer_tree(tracks).best.joints
    assert joint.type == "revolute"
    assert np.degrees(axis_angle_error(joint.hypothesis.axis_world, np.array([1.0, 0.0, 0.0]))) < 3.0
