"""A part's surface model at q = 0 from points seen where its joint is not at zero (a part whose
zero pose was taken at another step than the step the NLP's surfaces come from)."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from kinemaforge_opt.perception.reconstruct import _surface_at_zero

from .worlds import door_model, door_surface_world, moved


def test_points_seen_at_an_open_angle_are_moved_back_to_the_closed_door():
    model = door_model([0.0, 0.0, 1.0], [0.2, 0.5, 0.0])
    zero_pts, _ = door_surface_world(model, 0.01)
    front = zero_pts[np.isclose(zero_pts[:, 1], zero_pts[:, 1].min())]  # the face towards a camera at −y
    camera = np.array([0.4, -2.0, 0.3])
    q = 0.7  # rad, where the points were seen
    seen, _ = moved(model, q, front)
    sight = (camera - seen) / np.linalg.norm(camera - seen, axis=1, keepdims=True)  # towards the camera
    surface = _surface_at_zero(model, "door", np.array([q]), seen, sight, 0.01)
    gap = cKDTree(zero_pts).query(surface.points)[0]
    assert gap.max() < 0.01  # on the closed door's faces (its resolution: the 1-cm grid)
    np.testing.assert_allclose(surface.normals[:, 1], -1.0, atol=0.05)  # out of the front face, towards the camera
    kept = _surface_at_zero(model, "door", np.zeros(1), seen, sight, 0.01)  # told it is at zero
    assert np.median(cKDTree(zero_pts).query(kept.points)[0]) > 0.05
