"""Part mass properties from a contaminated cloud (perception/mass.py), against analytic answers:
a door slab of known size and density on a vertical hinge, observed on its front face at every
step, with a floor patch and a wall patch swept into its label (as perception did on
protocol_cabinet_0, where the whole-cloud hull weighed 30× the door)."""

from __future__ import annotations

import numpy as np
import pytest

from kinemaforge_opt.errors import DataError
from kinemaforge_opt.perception.mass import budget_subsample, moving_point_masks, part_mass_properties
from kinemaforge_opt.spatial import exp_so3, make_transform

W, H, T_SLAB, RHO = 0.45, 0.80, 0.018, 700.0  # door slab [m] and density [kg/m³]
HINGE = np.array([0.0, 0.0, 0.0])
SPACING, RADIUS = 0.01, 0.02


def _grid(ax_u, ax_w, lo, hi, const_axis, const):
    u = np.arange(lo[0], hi[0] + 1e-9, SPACING)
    w = np.arange(lo[1], hi[1] + 1e-9, SPACING)
    U, Wm = np.meshgrid(u, w, indexing="ij")
    p = np.zeros((U.size, 3))
    p[:, ax_u], p[:, ax_w], p[:, const_axis] = U.ravel(), Wm.ravel(), const
    return p


def _world(rng, qs):
    """Per step: the door's observed points (front face y = -T_SLAB, plus noise), a floor patch
    (z = 0) and a back-wall patch (y = 0.6) labelled as the door; the whole cloud; the door pose."""
    front = _grid(0, 2, (0.0, 0.05), (W, H), 1, -T_SLAB)  # door frame = world at q = 0
    floor = _grid(0, 1, (-0.3, -0.6), (0.6, -0.05), 2, 0.0)
    wall = _grid(0, 2, (-0.3, 0.0), (0.6, 0.9), 1, 0.6)
    labelled, clouds, poses = [], [], []
    for q in qs:
        T = make_transform(exp_so3(np.array([0.0, 0.0, -1.0]) * q), HINGE)
        door = front @ T[:3, :3].T + T[:3, 3] + rng.normal(0, 0.002, front.shape)
        lab = np.concatenate([door, floor, wall])
        labelled.append(lab)
        clouds.append(lab.copy())
        poses.append(T)
    return labelled, clouds, poses, len(front)


def _true_box():
    m = RHO * W * H * T_SLAB
    I_hinge_z = m / 12 * (W**2 + T_SLAB**2) + m * ((W / 2) ** 2 + (T_SLAB / 2) ** 2)
    return m, I_hinge_z


def test_background_swept_into_a_part_is_dropped_and_mass_is_near_the_truth():
    rng = np.random.default_rng(0)
    qs = np.linspace(0.0, 1.2, 10)
    labelled, clouds, poses, n_door = _world(rng, qs)
    masks = moving_point_masks(labelled, clouds, poses, RADIUS)
    # floor and wall are background in every step but the first (where they are also dropped)
    for m in masks:
        assert m[n_door:].mean() < 0.05
        assert m[:n_door].mean() > 0.9
    # link-frame fused cloud (door frame at q = 0)
    pts_link = np.concatenate([(x - T[:3, 3]) @ T[:3, :3] for x, T in zip(labelled, poses)])
    keep = np.concatenate(masks)
    m_true, I_true = _true_box()
    whole = part_mass_properties(pts_link, RHO, "door", voxel=SPACING)
    robust = part_mass_properties(pts_link, RHO, "door", voxel=SPACING, keep=keep)
    I_hinge = robust.inertia[2, 2] + robust.mass * (robust.com[0] ** 2 + robust.com[1] ** 2)
    # the front face alone does not show the 18 mm thickness; the volume model gives it one voxel
    # (10 mm) plus the noise: within a factor 2 of the slab's mass and hinge inertia
    assert 0.5 < robust.mass / m_true < 2.0
    assert 0.5 < I_hinge / I_true < 2.0
    assert whole.mass / m_true > 20  # what the hull of the labelled cloud would weigh
    assert robust.kept < robust.total


def test_a_flat_cloud_gets_a_slab_one_voxel_thick():
    pts = _grid(0, 2, (0.0, 0.0), (0.3, 0.5), 1, 0.0)
    mp = part_mass_properties(pts, 500.0, "panel", voxel=0.02)
    assert mp.method == "slab"
    # the outlier removal trims the outermost row of a regular grid (its neighbours are farther):
    # one grid spacing (10 mm) per side, 10 % of the area here
    assert mp.mass == pytest.approx(500.0 * 0.3 * 0.5 * 0.02, rel=0.12)
    np.testing.assert_allclose(mp.com, [0.15, 0.0, 0.25], atol=1e-6)
    assert mp.inertia[1, 1] == pytest.approx(mp.mass / 12 * (0.3**2 + 0.5**2), rel=0.12)


def test_a_budget_keeps_each_steps_share_and_the_mass_of_a_box():
    """30 noisy observations of a 0.4 × 0.6 × 0.1 m box's surface (uniform on its faces): the
    budget keeps the same share of every step, and the subsample's hull weighs what the box does."""
    rng = np.random.default_rng(1)
    ext = np.array([0.4, 0.6, 0.1])

    def surface(n):
        areas = np.array([ext[1] * ext[2], ext[0] * ext[2], ext[0] * ext[1]])
        axis = rng.choice(3, n, p=areas / areas.sum())
        p = rng.uniform(0, 1, (n, 3)) * ext
        p[np.arange(n), axis] = rng.integers(0, 2, n) * ext[axis]
        return p + rng.normal(0, 0.001, (n, 3))

    steps = [surface(n) for n in rng.integers(8000, 12000, 30)]
    total = sum(len(p) for p in steps)
    kept = budget_subsample(steps, budget=30_000)
    assert sum(len(p) for p in kept) == pytest.approx(30_000, abs=30)
    np.testing.assert_allclose([len(k) / len(p) for k, p in zip(kept, steps)], 30_000 / total, atol=1e-3)
    assert budget_subsample(steps, budget=total) is steps
    mp = part_mass_properties(np.concatenate(kept), 500.0, "box", voxel=0.01)
    # the 1 % trim per principal axis takes ~2 % of each extent
    assert mp.mass == pytest.approx(500.0 * np.prod(ext), rel=0.06)
    np.testing.assert_allclose(mp.com, ext / 2, atol=0.005)


def test_errors_name_the_part_and_the_count():
    with pytest.raises(DataError, match=r"part 'lid' has 3 points; its mass properties need at least 4"):
        part_mass_properties(np.zeros((3, 3)), 300.0, "lid", voxel=0.01)
    with pytest.raises(DataError, match=r"2 point sets, 1 clouds and 2 poses"):
        moving_point_masks([np.zeros((1, 3))] * 2, [np.zeros((1, 3))], [np.eye(4)] * 2, 0.01)


def test_stop_spans_find_an_abrupt_stop_and_not_a_smooth_one():
    """A door swinging at 1 rad/s into a stop at 1.0 rad (then at rest) against one that viscous
    damping brings to rest smoothly (q = 1 − e^{−2t}, same frames)."""
    from kinemaforge_opt.stops import stop_spans

    t = np.arange(0.0, 3.0, 0.1)
    q_hit = np.minimum(t, 1.0)[:, None] + np.random.default_rng(0).normal(0, 1e-3, (t.size, 1))
    assert stop_spans(t, q_hit) == [(9, t.size - 1)]
    q_smooth = (1 - np.exp(-2 * t))[:, None]
    assert stop_spans(t, q_smooth) == []
    # a joint that starts at rest on its lower end and leaves it is not an impact
    assert stop_spans(t, np.column_stack([q_smooth[:, 0], np.zeros(t.size)])) == []


def test_a_lid_that_falls_onto_a_compliant_stop_rests_there_to_the_end():
    """A lid lifted to -1.35 rad and let go falls back onto its stop at 0; the frame that catches
    the impact sees it pressed 0.035 rad into the stop (more than the band, 2 % of the range),
    then it rests at 0.  The stop holds it from the impact to the last frame, and its limit is
    where it rests; its other end is where it turned between the frames at -1.33, -1.35 and -1.0
    rad (the parabola's vertex); a door that stops at its limit keeps the observed range."""
    from kinemaforge_opt.stops import STOP_BAND, stop_limits, stop_spans

    t = np.arange(20) * 0.158
    lifted = [0.0, -0.11, -0.39, -0.74, -1.08, -1.33, -1.35, -1.0]
    rest = np.random.default_rng(2).normal(0.0, 1e-3, 11)
    q = np.array(lifted + [0.035] + list(rest))[:, None]
    assert 0.035 - rest.max() > STOP_BAND * np.ptp(q)  # at rest, outside the band of the extreme
    assert stop_spans(t, q) == [(7, 19)]
    a, top, c = lifted[5:8]  # equal frame steps: the vertex lies (c - a)² / (8 (a - 2 top + c)) past the top
    np.testing.assert_allclose(stop_limits(t, q), [[top - (c - a) ** 2 / (8 * (a - 2 * top + c)), rest.max()]])
    t_door = np.arange(0.0, 3.0, 0.1)
    q_door = np.minimum(t_door, 1.0)[:, None] + np.random.default_rng(0).normal(0, 1e-3, (t_door.size, 1))
    np.testing.assert_allclose(stop_limits(t_door, q_door), [[q_door.min(), q_door.max()]])
