"""The refinement pass (perception.track.refine): a part's ICP targets are the step's non-static
points plus every point on a tracked part; a union's leftover, whose track followed no one part,
is passed through as tracked and adds no target."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from kinemaforge_opt.perception.change import MOVING, STATIC
from kinemaforge_opt.perception.track import ICP_FINE_VOXELS, Proposal, Tracker, refine

STEPS = 3
VOXEL = 0.01  # [m]


def _plane(y: float) -> np.ndarray:
    """(N, 3) points [m] on a 0.3 × 0.3 m square in the plane y = ``y``, 1 cm apart."""
    x, z = np.meshgrid(np.arange(0.0, 0.3, VOXEL), np.arange(0.0, 0.3, VOXEL), indexing="ij")
    return np.stack([x.ravel(), np.full(x.size, y), z.ravel()], axis=1)


class _Stub(Tracker):
    """Every step: a moving front at y = 0 and a static wall at y = 0.5 m; every pose accepted."""

    def __init__(self):
        front, wall = _plane(0.0), _plane(0.5)
        cloud = SimpleNamespace(points=np.concatenate([front, wall]))
        self.clouds = [cloud] * STEPS
        self.status = [np.r_[np.full(len(front), MOVING), np.full(len(wall), STATIC)]] * STEPS
        self.voxel = VOXEL

    def verify(self, points, s):
        return 1.0, 0.0


def test_a_leftover_is_passed_through_and_its_points_are_no_target():
    tracker = _Stub()
    rest = np.tile(np.eye(4), (STEPS, 1, 1))
    front = Proposal("front", 0, _plane(0.0), rest)
    leftover = Proposal("u", 0, _plane(0.5), rest.copy())  # passes by the static wall at every step
    out = refine(tracker, [front, leftover], frozenset({"u"}))
    assert [p.name for p in out] == ["front", "u"] and out[1] is leftover
    assert all(len(t) == len(front.points) for t in tracker.targets)  # the wall is no target
    np.testing.assert_allclose(out[0].Ts_delta, rest, atol=ICP_FINE_VOXELS * VOXEL)
    # named a part, the same proposal makes the wall a target
    refine(tracker, [front, leftover])
    assert all(len(t) == len(tracker.clouds[0].points) for t in tracker.targets)
