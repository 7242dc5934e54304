"""Growing where a part lies farthest from its reference pose (perception.track.Tracker.grow_far):
what it adds, carried back to the reference step, may not lie where the images there see through.
A door's inner face, hidden behind its outer face at the reference, is kept; points the far step's
growth took from a wrong pose (a drawer's track slid into the body at its shut steps) are not.
The images are an exact oracle at the reference step."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from kinemaforge_opt.perception.track import Tracker

VOXEL = 0.01  # [m]
# a 0.3 x 0.3 m panel in the plane y = 0 at the reference step (0), seen from y < 0
PANEL = np.stack(np.meshgrid(np.arange(0.0, 0.3, VOXEL), [0.0], np.arange(0.0, 0.3, VOXEL), indexing="ij"),
                 axis=-1).reshape(-1, 3)
INNER = PANEL + [0.0, 0.02, 0.0]  # its hidden far side, 2 cm behind it (occluded at step 0)
AIR = PANEL[:100] + [0.0, -0.2, 0.0]  # 20 cm in front of it: the cameras see through there
FAR = np.eye(4)
FAR[:3, 3] = [0.0, -0.3, 0.0]  # the track's pose at the far step (1)


class _Oracle(Tracker):
    """Two steps; growth at the far step adds ``found`` (given at the reference, carried to the far
    pose); verdicts at the reference: seen through in front of the panel, hidden behind it."""

    def __init__(self, found: np.ndarray):
        self.voxel, self.found = VOXEL, found
        self.clouds = [SimpleNamespace(points=PANEL)] * 2

    def grow(self, ref, points, Ts):
        assert ref == 1
        return np.concatenate([points, self.found @ FAR[:3, :3].T + FAR[:3, 3]])

    def verdicts(self, points, s):
        assert s == 0
        on = np.abs(points[:, 1]) < 1e-6
        return on.astype(int), (points[:, 1] < -1e-6).astype(int)


def test_far_side_growth_keeps_hidden_faces_and_drops_points_seen_through_at_the_reference():
    grown = _Oracle(np.concatenate([INNER, AIR])).grow_far(0, PANEL, np.array([np.eye(4), FAR]))
    np.testing.assert_allclose(grown, np.concatenate([PANEL, INNER]), atol=1e-12)
