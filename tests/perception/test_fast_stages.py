"""The fast perception stages on exact inputs: per-pixel free-space status, the voxel grid, ICP,
and one full-size synthetic door (slow)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from kinemaforge_opt.perception.change import MOVING, STATIC, UNKNOWN, pixel_status
from kinemaforge_opt.io.sequence import Frame
from kinemaforge_opt.perception.clouds import DepthNoise, FrameCloud, downsample, fuse
from kinemaforge_opt.perception.track import icp, kabsch


def test_pixel_status_of_a_box_that_leaves():
    """A wall at 2 m; a 6×6-pixel box at 1 m in front of it at steps 0–1, gone at steps 2–4."""
    T, h, w = 5, 20, 30
    D = np.full((T, h, w), 2.0)
    D[:2, 5:11, 8:14] = 1.0
    D[3, 0, 0] = np.nan  # a dropout
    st = pixel_status(D, DepthNoise(0.002, 0.001))
    assert np.all(st[:2, 5:11, 8:14] == MOVING)  # seen through at steps 2–4
    assert np.all(st[2:, 5:11, 8:14] == STATIC)  # the wall behind, uncovered
    box = np.zeros((h, w), bool)
    box[5:11, 8:14] = True
    assert np.all(st[:, ~box][np.isfinite(D[:, ~box])] == STATIC)
    assert st[3, 0, 0] == UNKNOWN


def test_pixel_status_ignores_an_isolated_noisy_reading():
    D = np.full((6, 12, 12), 2.0)
    D[2, 6, 6] = 1.8  # one reading 20 cm short: violated by all other steps, but a lone pixel
    st = pixel_status(D, DepthNoise(0.002, 0.001))
    assert st[2, 6, 6] == UNKNOWN and not np.any(st == MOVING)


def test_voxel_grid_gives_the_centroid_of_each_occupied_cell():
    rng = np.random.default_rng(0)
    P = rng.uniform(-1, 1, (3000, 3))
    size = 0.2
    cells: dict = {}
    for p in P:  # reference: cells at integer multiples of the edge, a plain loop
        cells.setdefault(tuple(int(np.floor(x / size)) for x in p), []).append(p)
    ref = np.array([np.mean(v, axis=0) for v in cells.values()])
    ours = downsample(P, size)
    assert len(ours) == len(ref)
    d, _ = cKDTree(ref).query(ours)
    assert d.max() < 1e-9
    # isolated points go with ``outliers``: a dense patch plus three far strays
    patch = rng.uniform(0, 0.1, (2000, 3)) * [1, 1, 0]
    strays = np.array([[5.0, 5, 5], [-5.0, 5, 5], [5.0, -5, 5]])
    kept = downsample(np.concatenate([patch, strays]), 0.01, outliers=True)
    assert kept.max() < 0.2 and len(kept) > 50


def test_fused_points_carry_their_sightlines():
    """Two cameras 2 m above a floor, 2 m apart; each sees its own half and both see a strip in
    the middle.  A fused point's sightline is the unit vector towards its camera, or the mean of
    both where both saw it (voxel centroids sit within a voxel of the readings: < 0.5°)."""
    cams = np.array([[-1.0, 0.0, 2.0], [1.0, 0.0, 2.0]])
    g = np.arange(-0.5, 0.5, 0.01)
    floor = np.column_stack([np.repeat(g, g.size), np.tile(g, g.size), np.zeros(g.size**2)])
    views = []
    for i, (c, half) in enumerate(zip(cams, (floor[:, 0] < 0.1, floor[:, 0] > -0.1))):
        T = np.eye(4)
        T[:3, 3] = c
        views.append(FrameCloud(Frame(i, 0.0, f"cam{i}", T, "", ""), np.zeros((half.sum(), 2), int), floor[half], np.zeros((1, 1))))
    cloud, _ = fuse(0.0, views, 0.02)
    assert cloud.sightlines.shape == cloud.points.shape
    to = [(c - cloud.points) / np.linalg.norm(c - cloud.points, axis=1, keepdims=True) for c in cams]
    expect = np.where((cloud.points[:, 0] < -0.1)[:, None], to[0], to[1])
    both = np.abs(cloud.points[:, 0]) < 0.09
    mean = to[0][both] + to[1][both]
    expect[both] = mean / np.linalg.norm(mean, axis=1, keepdims=True)
    clear = np.abs(np.abs(cloud.points[:, 0]) - 0.1) > 0.02  # voxels on the strip's edge mix both
    angle = np.degrees(np.arccos(np.clip(np.sum(cloud.sightlines * expect, axis=1), -1, 1)))
    assert both.sum() > 50 and angle[clear].max() < 0.5


def test_fused_points_carry_the_variance_share_of_their_readings():
    """Two static cameras over one floor: camera 0's depths are means of 12 readings, camera 1's
    of 3 on the half x > 0 (hidden at 9 steps) and single readings on the other.  A fused
    point's variance share is the mean of 1/readings over what was fused into it; a view without
    counts (a moving camera) fuses as single readings."""
    g = np.arange(-0.5, 0.5, 0.01)
    floor = np.column_stack([np.repeat(g, g.size), np.tile(g, g.size), np.zeros(g.size**2)])
    counts = [np.full(len(floor), 12), np.where(floor[:, 0] > 0, 3, 1)]
    views = [FrameCloud(Frame(i, 0.0, f"cam{i}", np.eye(4), "", ""), np.zeros((len(floor), 2), int), floor,
                        np.zeros((1, 1)), status=np.full(len(floor), STATIC, dtype=np.int8), readings=n)
             for i, n in enumerate(counts)]
    cloud, _ = fuse(0.0, views, 0.02)
    inner = np.abs(cloud.points[:, 0]) > 0.02  # voxels off the line x = 0 hold one kind of reading
    expect = np.where(cloud.points[:, 0] > 0, (1 / 12 + 1 / 3) / 2, (1 / 12 + 1) / 2)
    np.testing.assert_allclose(cloud.variance_share[inner], expect[inner], rtol=1e-9)
    once, _ = fuse(0.0, [FrameCloud(views[0].frame, views[0].pixels, floor, np.zeros((1, 1)))], 0.02)
    np.testing.assert_allclose(once.variance_share, 1.0)


def test_kabsch_and_icp_recover_a_rigid_motion():
    rng = np.random.default_rng(1)
    # an L-shaped bracket (two perpendicular plates): every motion is observable
    a = np.column_stack([rng.uniform(0, 0.4, 800), rng.uniform(0, 0.3, 800), np.zeros(800)])
    b = np.column_stack([np.zeros(800), rng.uniform(0, 0.3, 800), rng.uniform(0, 0.2, 800)])
    X = np.concatenate([a, b])
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec([0.0, 0.0, 0.15]).as_matrix()
    T[:3, 3] = [0.02, -0.01, 0.015]
    Y = X @ T[:3, :3].T + T[:3, 3]
    np.testing.assert_allclose(kabsch(X, Y), T, atol=1e-12)
    found = icp(X[::3], cKDTree(Y), Y, np.eye(4), (0.06, 0.015), iterations=60)
    c = X.mean(axis=0)
    assert np.linalg.norm(found[:3, :3] @ c + found[:3, 3] - (T[:3, :3] @ c + T[:3, 3])) < 2e-3
    assert np.degrees(np.linalg.norm(Rotation.from_matrix(found[:3, :3] @ T[:3, :3].T).as_rotvec())) < 0.5


@pytest.mark.slow
def test_full_size_door_is_fast_and_right(tmp_path):
    """30 steps, 4 views, 640×480, D435 noise: the issue's timing case, scored on ground truth."""
    from problems.eval_perception import evaluate, instance_case

    r = evaluate(instance_case("cabinet", 0), tmp_path)
    assert "error" not in r, r.get("error")
    assert r["topology_ok"] and r["type_accuracy"] == 1.0
    assert all(j["axis_error_deg"] < 3.0 for j in r["joints"])
    assert min(r["iou_moving"].values()) > 0.9
    # the benchmark's part IoU: the floor and wall must not be counted as the cabinet's body
    assert r["part_iou"] > 0.9
    assert sum(r["cpu_s"].values()) < 30.0  # CPU seconds (10 s is the goal on an idle machine)
