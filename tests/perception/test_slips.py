"""Track slips (perception.track.jump): a one-step spike in a track's velocity is an outlier or a
slip, a part that starts or stops moving between two samples is neither."""

from __future__ import annotations

import numpy as np

from factories import motion_about as _pose
from factories import scripted_tracker
from kinemaforge_opt.perception.track import Proposal, _comoving, displacement, join, jump, symmetries

RNG = np.random.default_rng(0)
# a drawer-sized box surface: 40 x 30 x 15 cm, points on its faces
BOX = RNG.uniform([-0.2, -0.15, 0.0], [0.2, 0.15, 0.15], (600, 3))
TOL = 0.07  # [m] the wide ICP reach of a ~6 mm voxel (3 x 4 voxels)


def _drawer(stroke_per_step: list[float]) -> list[np.ndarray]:
    """Poses of a drawer pulled along -y by the given stroke [m] per step, from the reference."""
    y = np.concatenate([[0.0], np.cumsum(stroke_per_step)])
    return [_pose(t=(0.0, -v, 0.0)) for v in y]


def test_displacement_is_the_rms_point_distance():
    A, B = _pose(t=(0.03, 0.0, 0.0)), np.eye(4)
    assert abs(displacement(A, B, BOX) - 0.03) < 1e-12


def test_a_fragment_that_jumps_onto_another_face_and_stays_is_a_slip():
    poses = _drawer([0.02, 0.03, 0.04])
    # the fragment lands on a face 90 degrees away and 29 cm off, and tracking goes on from there
    slipped = poses[-1] @ _pose(rotvec=(0.0, 0.0, np.pi / 2), t=(0.11, -0.08, -0.26))
    after = slipped @ _pose(t=(0.0, -0.002, 0.0))
    assert jump(poses[-2:], slipped, after, BOX, TOL) == "slip"
    # the true pull for comparison: on the prediction
    assert jump(poses[-2:], _pose(t=(0.0, -0.14, 0.0)), _pose(t=(0.0, -0.19, 0.0)), BOX, TOL) is None


def test_a_half_turn_flip_between_true_poses_is_an_outlier():
    about = np.array([0.2, 0.0, 0.0])  # a door hinged at its edge, 7.7 degrees per step
    door = [_pose(rotvec=(0.0, 0.0, 0.134 * i), about=about) for i in range(8)]
    flipped = door[6] @ _pose(rotvec=(np.pi, 0.0, 0.0))  # the flat door registered upside down
    assert jump(door[4:6], flipped, door[7], BOX, TOL) == "outlier"
    assert jump(door[4:6], door[6], door[7], BOX, TOL) is None


def test_smooth_and_sudden_motions_are_neither():
    about = np.array([0.2, 0.0, 0.0])
    door = [_pose(rotvec=(0.0, 0.0, 0.02 * i * i), about=about) for i in range(12)]  # accelerating swing
    assert all(jump(door[k - 2:k], door[k], door[k + 1], BOX, TOL) is None for k in range(2, 11))
    # a drawer at rest yanked 20 cm per step between two samples (a velocity change, once), then
    # stopped at once
    d = _drawer([0.0, 0.0, 0.2, 0.2, 0.2, 0.0, 0.0])
    assert all(jump(d[max(k - 2, 0):k], d[k], d[k + 1], BOX, TOL) is None for k in range(1, 7))


def test_a_part_reseeded_where_its_track_was_cut_rejoins_and_fills_the_gap():
    """A drawer pulled 3 cm per step over 8 steps; its first track (reference step 5) was cut at
    steps 0-2; a second proposal of the same drawer seeded at step 1 is tracked over steps 0-6."""
    truth = [_pose(t=(0.0, -0.03 * s, 0.0)) for s in range(8)]  # world motion from step 0
    rel = lambda ref: np.stack([T @ np.linalg.inv(truth[ref]) for T in truth])  # motion from ref
    first = rel(5)
    first[:3] = np.nan
    p = Proposal("p0", 5, BOX[:300] @ truth[5][:3, :3].T + truth[5][:3, 3], first)
    second = rel(1)
    second[7] = np.nan
    new = Proposal("p1", 1, BOX[300:] @ truth[1][:3, :3].T + truth[1][:3, 3], second)
    k, anchor = _comoving(new, [p], 0.01)
    assert k == 0 and anchor == 3  # the common step nearest the new reference
    joined = join(p, new, anchor)
    assert np.all(np.isfinite(joined.Ts_delta))
    np.testing.assert_allclose(joined.Ts_delta, rel(5), atol=1e-12)
    # both pieces at the reference step of p: the whole box at step 5
    np.testing.assert_allclose(joined.points, BOX @ truth[5][:3, :3].T + truth[5][:3, 3], atol=1e-12)
    # a piece moving otherwise (a second drawer, still) does not join
    still = Proposal("p2", 1, new.points, np.stack([np.eye(4)] * 8))
    assert _comoving(still, [p], 0.01) == (None, None)


def test_a_proposal_seen_only_at_the_new_ones_reference_does_not_swallow_it():
    """A drawer pulled 3 cm per step, tracked from step 4 over all 8 steps, beside an earlier
    proposal seeded at step 4 whose track failed everywhere else: the one step both observe is
    the anchor, where any two tracks agree by construction, so the drawer is no piece of it (it
    was joined into it, and its track was dropped with it: a pulled drawer lost)."""
    truth = [_pose(t=(0.0, -0.03 * s, 0.0)) for s in range(8)]
    drawer = Proposal("p1", 4, BOX @ truth[4][:3, :3].T + truth[4][:3, 3],
                      np.stack([T @ np.linalg.inv(truth[4]) for T in truth]))
    lost = np.full((8, 4, 4), np.nan)
    lost[4] = np.eye(4)
    failed = Proposal("p0", 4, drawer.points[:100] + [0.0, 0.0, 0.5], lost)
    assert _comoving(drawer, [failed], 0.01) == (None, None)


def test_a_lid_slammed_shut_is_no_slip():
    """A lid turning 15 degrees per step about its hinge, then 54 degrees in one step onto its
    base, where it stops: a speed change along the same screw."""
    about = np.array([0.0, 0.15, 0.0])
    angles = np.radians([0.0, 15.0, 30.0, 45.0, 99.0, 99.0])
    lid = [_pose(rotvec=(a, 0.0, 0.0), about=about) for a in angles]
    assert jump(lid[2:4], lid[4], lid[5], BOX, TOL) is None
    assert jump(lid[2:4], lid[4], None, BOX, TOL) is None  # the slam as the last tracked step
    # the same jump turned about another axis is a slip
    off = _pose(rotvec=(0.0, np.radians(54.0), 0.0), about=about) @ lid[3]
    assert jump(lid[2:4], off, off, BOX, TOL) == "slip"


def _scripted(poses: list[np.ndarray], voxel: float = 0.006):
    return scripted_tracker(poses, voxel)


def _relative(world: list[np.ndarray], ref: int) -> list[np.ndarray]:
    return [T @ np.linalg.inv(world[ref]) for T in world]


def test_tracking_ends_a_side_at_a_slip_and_drops_a_flip():
    world = _drawer([0.03] * 9)  # 10 steps of a drawer pulled 3 cm per step
    truth = _relative(world, 6)
    script = list(truth)
    slipped = truth[2] @ _pose(rotvec=(0.0, 0.0, np.pi / 2), t=(0.11, -0.08, -0.26))
    script[2] = script[1] = script[0] = slipped  # the backward side slips at step 2 and stays
    script[8] = truth[8] @ _pose(rotvec=(np.pi, 0.0, 0.0))  # a half-turn flip at step 8 alone
    Ts = _scripted(script).track("p0", 6, BOX).Ts_delta
    assert np.isnan(Ts[[0, 1, 2, 8]]).all()
    for s in (3, 4, 5, 6, 7, 9):
        np.testing.assert_allclose(Ts[s], truth[s], atol=1e-12)


def test_tracking_keeps_a_lid_that_turns_back_at_the_reference_and_slams_shut():
    about = np.array([0.0, 0.15, 0.0])
    angles = np.radians([0.0, 20.0, 40.0, 60.0, 80.0, 55.0, 8.0, 0.0, 0.0])  # opened, then slammed
    truth = _relative([_pose(rotvec=(a, 0.0, 0.0), about=about) for a in angles], 4)
    Ts = _scripted(truth).track("p0", 4, BOX).Ts_delta
    np.testing.assert_allclose(Ts, np.stack(truth), atol=1e-12)


def test_a_lid_slammed_shut_and_then_seen_turned_over_every_other_step_keeps_its_rest_pose():
    """A lid slammed shut onto its base, then at rest; the flat lid registers turned over about
    its own long axis at every other step (a constant half-turn "velocity" that each next pose
    continues).  The turned-over steps are unobserved, the rest pose kept."""
    about = np.array([0.0, 0.15, 0.0])
    angles = np.radians([60.0, 45.0, 30.0, 15.0, 0.0, 79.0, 79.0, 79.0, 79.0, 79.0, 79.0, 79.0])
    truth = _relative([_pose(rotvec=(a, 0.0, 0.0), about=about) for a in angles], 3)
    script = list(truth)
    centre = truth[5][:3, :3] @ BOX.mean(axis=0) + truth[5][:3, 3]
    for s in (6, 8, 10):
        script[s] = _pose(rotvec=(np.pi, 0.0, 0.0), about=centre) @ truth[s]
    Ts = _scripted(script).track("p0", 3, BOX).Ts_delta
    assert np.isnan(Ts[[6, 8, 10]]).all()
    for s in (0, 1, 2, 3, 4, 5, 7, 9, 11):
        np.testing.assert_allclose(Ts[s], truth[s], atol=1e-12)


def _plate(flange: bool = False) -> np.ndarray:
    """A 24 x 18 cm plate sampled on a 6 mm grid (a voxelised lid, fewer points than the tracker
    samples), optionally with a 6 cm
    flange along one long edge (a drawer front with its side wall: no half-turn maps it onto
    itself)."""
    g = np.arange(0.0, 0.24, 0.006)
    x, y = np.meshgrid(g, g[g < 0.18])
    pts = np.c_[x.ravel(), y.ravel(), np.zeros(x.size)]
    if flange:
        fx, fz = np.meshgrid(g, np.arange(0.006, 0.06, 0.006))
        pts = np.vstack([pts, np.c_[fx.ravel(), np.zeros(fx.size), fz.ravel()]])
    return pts


def test_a_plate_has_three_half_turn_symmetries_a_plate_with_a_flange_none():
    plate = _plate()
    syms = symmetries(plate, 1.5 * 0.006)
    assert len(syms) == 3
    tree_check = plate.mean(axis=0)
    for S in syms:  # each is a half-turn about an axis through the centre
        assert abs(np.trace(S[:3, :3]) + 1.0) < 1e-9
        np.testing.assert_allclose(S[:3, :3] @ tree_check + S[:3, 3], tree_check, atol=1e-12)
    assert symmetries(_plate(flange=True), 1.5 * 0.006) == []


def test_tracking_keeps_the_twin_of_a_symmetric_part_nearest_the_motion():
    """A flat lid opened and slammed shut, registered turned over (a symmetry of the plate) at
    every other step while it rests: the track keeps the pose that continues the motion."""
    lid = _plate()
    about = np.array([0.0, 0.2, 0.0])
    angles = np.radians([60.0, 45.0, 30.0, 15.0, 0.0, 79.0, 79.0, 79.0, 79.0, 79.0, 79.0, 79.0])
    truth = _relative([_pose(rotvec=(a, 0.0, 0.0), about=about) for a in angles], 3)
    flip = symmetries(lid, 1.5 * 0.006)[0]
    script = [T @ flip if s in (6, 8, 10) else T for s, T in enumerate(truth)]
    Ts = _scripted(script).track("p0", 3, lid).Ts_delta
    np.testing.assert_allclose(Ts, np.stack(truth), atol=1e-9)


def test_a_part_still_moving_at_the_reference_is_tracked_on_from_the_other_sides_velocity():
    """A drawer pulled 3 cm per step up to its reference step 4, then 5 cm per step, stopped at
    step 8.  ICP reaches 4 cm from a guess: from rest the first forward step lands elsewhere (a
    pose on another surface, where tracking would go on), which the backward side's increment
    exposes as a slip.  The forward side is then tracked from the velocity through the reference:
    every step is the true pose (before, steps 5-11 were all unobserved)."""
    world = _drawer([0.03] * 4 + [0.05] * 4 + [0.0] * 3)  # steps 0-11
    truth = _relative(world, 4)
    elsewhere = _pose(rotvec=(0.0, 0.0, np.pi / 2), t=(0.3, 0.2, 0.0))  # a static surface far off
    reach = 0.04

    class Basin(type(_scripted(truth))):
        def solve_step(self, points, s, guesses):
            if any(displacement(g, truth[s], points) <= reach for g in guesses):
                return truth[s], 1.0
            return elsewhere, 1.0

    tracker = Basin.__new__(Basin)
    tracker.poses, tracker.voxel, tracker.clouds = truth, 0.006, [None] * len(truth)
    Ts = tracker.track("p0", 4, BOX).Ts_delta
    np.testing.assert_allclose(Ts, np.stack(truth), atol=1e-12)
