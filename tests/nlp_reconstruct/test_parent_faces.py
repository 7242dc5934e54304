"""The face directions a reconstruction hands the NLP for its square-slide hypothesis
(perception.reconstruct.parent_faces): measured on the fused cloud of each part that carries a
joint, from a box's surface points alone (no normals given), and left out (without an error) for
a part too small for a surface."""

from __future__ import annotations

import numpy as np

from kinemaforge_opt.model import ArticulatedModel, Joint, Link
from kinemaforge_opt.perception.reconstruct import parent_faces
from kinemaforge_opt.spatial import exp_so3

from .worlds import box_surface


def test_a_carcass_turned_25_degrees_gives_its_depth_and_width_directions():
    yaw = np.radians(25.0)
    R = exp_so3(np.array([0.0, 0.0, yaw]))
    pts, _ = box_surface(np.array([0.6, 0.5, 0.8]), np.zeros(3), 0.01)
    rng = np.random.default_rng(0)
    carcass = pts @ R.T + rng.normal(0.0, 0.001, pts.shape)
    drawer = carcass[:30] * 0.1  # too few points for a surface: no faces
    tray = rng.normal(0.0, 1e-4, (60, 3))  # enough points, but all in one voxel: no faces, no error
    model = ArticulatedModel("chest", (Link("base"), Link("drawer"), Link("tray"), Link("box")), (
        Joint("slide", "prismatic", "base", "drawer", axis=[0, -1, 0]),
        Joint("tray_slide", "prismatic", "drawer", "tray", axis=[0, -1, 0]),
        Joint("box_slide", "prismatic", "tray", "box", axis=[0, -1, 0])))
    faces = parent_faces(model, {"base": carcass, "drawer": drawer, "tray": tray}, 0.01)
    assert set(faces) == {"base"}
    truth = np.array([R[:, 0], R[:, 1]])
    # each found direction lies along one of the carcass's, within 0.2°
    angles = np.degrees(np.arccos(np.clip(np.max(np.abs(faces["base"] @ truth.T), axis=1), -1.0, 1.0)))
    assert np.all(angles < 0.2), angles
