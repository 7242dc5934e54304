"""One part tracked twice (perception.track.coincident_with, union_fit, without_contradicted,
merge_fragments): a
second proposal on the same surface whose track slides along it (a flat door front gives ICP no
grip in its own plane), carrying points no motion explains, is merged into one part with the
motion that puts both point sets on the true surface; a drawer next to it is not a duplicate.
The images are an exact oracle of the true scene (confirmed on a true surface; seen through
in front of the carcass, off them)."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from kinemaforge_opt.perception.track import (ICP_FINE_VOXELS, Proposal, Tracker, coincident_with,
                                              merge_fragments, union_fit)

STEPS = 10
REF = 4
ON_SURFACE = 0.002  # [m] a point this close to a true surface point is confirmed
SPACING = 0.01  # [m] between the fronts' points


def _front(z0: float) -> np.ndarray:
    """(N, 3) points [m] of a drawer front 0.38 × 0.15 m in the plane y = 0, bottom at z0."""
    x, z = np.meshgrid(np.arange(-0.19, 0.19 + 1e-9, SPACING), np.arange(z0, z0 + 0.15 + 1e-9, SPACING), indexing="ij")
    return np.stack([x.ravel(), np.zeros(x.size), z.ravel()], axis=1)


def _motion(shift: np.ndarray) -> np.ndarray:
    """(STEPS, 4, 4) world translations by (STEPS, 3) ``shift`` [m], relative to step REF."""
    Ts = np.tile(np.eye(4), (STEPS, 1, 1))
    Ts[:, :3, 3] = shift - shift[REF]
    return Ts


PULL = np.outer(0.03 * np.arange(STEPS), [0.0, -1.0, 0.0])  # 3 cm a step along -y
# the second drawer pushed shut over the first two steps (a part at rest throughout is the base's)
SHUT = np.outer(0.03 * np.clip(2 - np.arange(STEPS), 0, None), [0.0, -1.0, 0.0])
# the same, sliding along the front 1 cm a step in +x after the reference step
SLIDE = PULL + np.outer(0.01 * np.clip(np.arange(STEPS) - REF, 0, None), [1.0, 0.0, 0.0])


class _Oracle(Tracker):
    """verdicts()/verify()/fit() against the true surfaces at each step (module doc)."""

    def __init__(self, surfaces: list[np.ndarray]):
        self.trees = [cKDTree(s) for s in surfaces]
        self.voxel = ON_SURFACE / ICP_FINE_VOXELS * 2.5  # the fine ICP radius: half the fronts' spacing
        self.min_points = 100  # the smallest part

    def _verdicts(self, points, s):
        on = self.trees[s].query(points, distance_upper_bound=ON_SURFACE)[0] < np.inf
        return on, ~on & (points[:, 1] < -1e-3)  # the carcass (y >= 0) hides what is inside it

    def verdicts(self, points, s):
        on, seen_through = self._verdicts(points, s)
        return on.astype(int), seen_through.astype(int)

    def verify(self, points, s):
        on, seen_through = self._verdicts(points, s)
        return float(np.mean(on)), float(np.mean(seen_through))

    def fit(self, points, s, verdicts=None, held=None):
        on, seen_through = self._verdicts(points, s)
        if held is not None:
            on = on & ~held
        return float(np.mean(on) - np.mean(seen_through))


def _air(points: np.ndarray, share: float) -> np.ndarray:
    """``share`` of (N, 3) front points [m] moved 5 cm out into the air in front of the front."""
    return points[: int(share * len(points))] + np.array([0.0, -0.05, 0.0])


def _scene():
    """The front pulled out along -y, a second drawer's front above it (shut, then at rest), the front's true
    track, and a duplicate: the front's middle (|x| <= 0.1 m) plus 12 % as many points in the air
    in front of it (seen through at every step), tracked sliding along the front."""
    front, other = _front(0.05), _front(0.3)
    surfaces = [np.concatenate([front + PULL[s], other + SHUT[s]]) for s in range(STEPS)]
    at_ref = front + PULL[REF]
    middle = at_ref[np.abs(at_ref[:, 0]) <= 0.1 + 1e-9]
    true = Proposal("true", REF, at_ref, _motion(PULL))
    dup = Proposal("dup", REF, np.concatenate([middle, _air(middle, 0.12)]), _motion(SLIDE))
    rest = Proposal("other", REF, other, _motion(SHUT))
    return _Oracle(surfaces), true, dup, rest


def test_a_duplicate_sliding_along_the_part_is_merged_into_it_with_the_true_motion():
    oracle, true, dup, rest = _scene()
    assert coincident_with(oracle, dup, [true, rest, dup]) == (0, REF)
    assert union_fit(oracle, true, dup, true, REF) > union_fit(oracle, true, dup, dup, REF)
    merged = merge_fragments(oracle, [true, rest, dup])
    assert [p.name for p in merged] == ["true", "other"]
    np.testing.assert_allclose(merged[0].Ts_delta, true.Ts_delta)  # the true track, not the slide
    np.testing.assert_array_equal(merged[0].points, true.points)  # the duplicate's points lie on it, or in the air


def test_the_true_track_wins_when_it_is_the_smaller_proposal():
    oracle, true, dup, rest = _scene()
    # the true track on the front's right end alone (its slide would carry it off the edge); the
    # whole front plus points in the air tracked sliding
    end = true.points[true.points[:, 0] >= 0.05]
    small = Proposal("small", REF, end, true.Ts_delta)
    big = Proposal("big", REF, np.concatenate([true.points, _air(true.points, 0.12)]), dup.Ts_delta)
    assert coincident_with(oracle, small, [big, small, rest]) == (0, REF)
    assert union_fit(oracle, big, small, small, REF) > union_fit(oracle, big, small, big, REF)
    merged = merge_fragments(oracle, [big, small, rest])
    assert len(merged) == 2
    np.testing.assert_allclose(merged[0].Ts_delta, true.Ts_delta)
    # the end's points and the big one's front; its points in the air, seen through under the
    # true motion, are left out
    np.testing.assert_allclose(merged[0].points, np.concatenate([small.points, true.points]))


def test_a_neighbouring_drawer_is_no_duplicate():
    oracle, true, dup, rest = _scene()
    assert coincident_with(oracle, rest, [true, rest]) == (None, None)
    assert coincident_with(oracle, true, [true, rest]) == (None, None)
    assert [p.name for p in merge_fragments(oracle, [true, rest])] == ["true", "other"]


def test_the_surface_test_carries_points_back_along_the_part_s_motion():
    """`_Surfaces.on` (points carried back to the proposal's reference pose against one tree) says
    what a KD-tree of the proposal's moved points says at every step: on a door turning about a
    hinge, points just off its moved face are on it, points a few radii off are not, and none is
    on it where it is unobserved."""
    from kinemaforge_opt.perception.track import _Surfaces
    from kinemaforge_opt.spatial import screw_motion

    voxel = 0.01
    radius = ICP_FINE_VOXELS * voxel
    # 6 degrees a step about the vertical hinge line x = -0.19, y = 0
    Ts = np.stack([screw_motion(np.array([0.0, 0.0, 1.0]), np.array([-0.19, 0.0, 0.0]), np.radians(6.0 * (s - REF)))
                   for s in range(STEPS)])
    Ts[7] = np.nan
    door = Proposal("door", REF, _front(0.0), Ts)
    rng = np.random.default_rng(3)
    surfaces = _Surfaces(voxel, subset=False)
    for s in range(STEPS):
        moved = door.points_at(s)
        if moved is None:
            assert not surfaces.on(_front(0.0), door, s).any()
            continue
        probe = moved[rng.choice(len(moved), 200)] + rng.normal(0.0, 2.0 * radius / 3.0, (200, 3))
        truth = cKDTree(moved).query(probe, distance_upper_bound=radius)[0] < np.inf
        assert 0 < truth.sum() < len(probe)  # both kinds of point are probed
        np.testing.assert_array_equal(surfaces.on(probe, door, s), truth)
