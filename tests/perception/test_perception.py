"""Perception stages on exact inputs, and the RGB-D reconstruction on tiny synthetic cases."""

from __future__ import annotations

import dataclasses
import json
import shutil

import numpy as np
import pytest

from kinemaforge_opt.errors import DataError
from kinemaforge_opt.io.sequence import CameraInfo, Frame, load_sequence, depth_to_png, write_png, write_sequence_json
from kinemaforge_opt.perception import backproject, estimate_depth_noise, free_space_test, reconstruct_sequence
from kinemaforge_opt.perception.change import padded_depth
from kinemaforge_opt.perception.clouds import DepthNoise
from kinemaforge_opt.perception.segment import clusters, environment_planes
from kinemaforge_opt.perception.track import pca_alignments

CAM = CameraInfo("cam0", 40, 30, 35.0, 35.0, 19.5, 14.5)


def _plane_depth(n_camera: np.ndarray, d: float) -> np.ndarray:
    """Exact z-depth of the plane n·p = d (camera frame) for CAM."""
    v, u = np.mgrid[0 : CAM.height, 0 : CAM.width].astype(float)
    rays = np.stack([(u - CAM.cx) / CAM.fx, (v - CAM.cy) / CAM.fy, np.ones_like(u)], axis=-1)
    return d / (rays @ n_camera)


def test_backprojection_of_a_known_plane_lies_on_it():
    n = np.array([0.2, -0.1, 1.0])
    n /= np.linalg.norm(n)
    depth = _plane_depth(n, 1.5)
    T = np.eye(4)
    T[:3, :3] = np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]], dtype=float)  # camera looking along world +y
    T[:3, 3] = [0.3, -2.0, 0.8]
    pts = backproject(depth, CAM, T).reshape(-1, 3)
    n_world = T[:3, :3] @ n
    np.testing.assert_allclose((pts - T[:3, 3]) @ n_world, 1.5, atol=1e-12)


def test_noise_estimate_recovers_inverse_depth_noise():
    rng = np.random.default_rng(0)
    z = _plane_depth(np.array([0.0, 0.3, 1.0]) / np.hypot(0.3, 1.0), 1.2)
    k = 0.004
    depths = [z + rng.standard_normal(z.shape) * k * z**2 for _ in range(5)]
    est = estimate_depth_noise(depths, depth_scale=1e9)
    assert est.k == pytest.approx(k, rel=0.1)


def test_free_space_test_verdicts():
    depth = np.full((CAM.height, CAM.width), 2.0)
    noise = DepthNoise(0.001, 0.001)
    pts = np.array([[0.0, 0.0, 2.0], [0.0, 0.0, 1.0], [0.0, 0.0, 3.0], [100.0, 0.0, 1.0]])
    verdict = free_space_test(pts, CAM, np.eye(4), padded_depth(depth), noise)
    assert verdict.tolist() == [1, -1, 0, 0]  # on surface, seen through, occluded, out of view


def test_pca_alignment_recovers_a_rigid_motion():
    rng = np.random.default_rng(1)
    X = rng.standard_normal((200, 3)) * [0.4, 0.2, 0.05]
    angle = 0.7
    T = np.eye(4)
    T[:3, :3] = [[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]]
    T[:3, 3] = [0.1, -0.2, 0.3]
    Y = X @ T[:3, :3].T + T[:3, 3]
    errors = [np.abs(X @ C[:3, :3].T + C[:3, 3] - Y).max() for C in pca_alignments(X, Y)]
    assert min(errors) < 1e-9


def test_clusters_split_separate_parts_and_planes_find_the_floor():
    rng = np.random.default_rng(2)
    a = rng.uniform([0, 0, 0.5], [0.3, 0.3, 0.5], (300, 3))
    b = a + [1.0, 0, 0]
    found = clusters(np.concatenate([a, b]), voxel=0.03)
    assert sorted(len(c) for c in found) == [300, 300]
    floor = np.column_stack([rng.uniform(-1, 1, (2000, 2)), np.zeros(2000)])
    planes = environment_planes(floor, np.concatenate([floor, a]), 0.01)
    assert len(planes) == 1 and abs(planes[0].normal[2]) > 0.999 and planes[0].normal[2] > 0


# --- end to end on tiny synthetic cases ---------------------------------------------------------

def _generate(name: str, root, frames: int = 10):
    from kinemaforge_opt.synth import generate_case
    from problems.catalogue import get_case

    # the catalogue's tiny cases have 4 time steps; the graph fits need at least 5 samples
    return generate_case(dataclasses.replace(get_case(name), frames=frames), root / name)


def test_no_motion_sequence_is_refused_plainly(tmp_path):
    seq = tmp_path / "still"
    depth = _plane_depth(np.array([0.0, 0.0, 1.0]), 1.5)
    frames = []
    for i in range(3):
        rgb, dp = f"rgb/cam0/{i:06d}.png", f"depth/cam0/{i:06d}.png"
        write_png(seq / rgb, np.zeros((CAM.height, CAM.width, 3), np.uint8))
        write_png(seq / dp, depth_to_png(depth, 1000.0))
        frames.append(Frame(i, float(i), "cam0", np.eye(4), rgb, dp))
    write_sequence_json(seq, {"cam0": CAM}, frames, 1000.0)
    with pytest.raises(DataError, match="no motion"):
        reconstruct_sequence(seq, tmp_path / "out", show_progress=False)


def test_unreadable_frame_is_named(tmp_path):
    paths = _generate("tiny_door_clean", tmp_path, frames=5)
    seq = load_sequence(paths.sequence)
    bad = seq.root / seq.frames[3].depth
    bad.write_bytes(b"not a png")
    from kinemaforge_opt.errors import InputFileError

    with pytest.raises(InputFileError, match=bad.name):
        reconstruct_sequence(paths.sequence, tmp_path / "out", show_progress=False)
    shutil.rmtree(paths.root)


def test_reconstruct_writes_the_contract(tmp_path):
    paths = _generate("tiny_door_clean", tmp_path)
    out = tmp_path / "out"
    rec = reconstruct_sequence(paths.sequence, out, show_progress=False)
    doc = json.loads((out / "reconstruction.json").read_text())
    assert doc["joints"] and all(j["type"] in ("revolute", "prismatic", "helical", "fixed") for j in doc["joints"])
    for j in doc["joints"]:
        assert len(j["axis_world"]) == 3 and len(j["origin_world"]) == 3
        assert j["limits"] is None if j["type"] == "fixed" else j["limits"][0] <= j["limits"][1]
    assert all(link["mass"] > 0 for link in doc["links"])
    assert (out / "model.urdf").is_file()
    assert all((out / "meshes" / f"{link['name']}.obj").is_file() for link in doc["links"])
    clouds = np.load(out / "clouds.npz")
    assert set(clouds.files) == {link["name"] for link in doc["links"]}
    assert rec.perception.tracks.has_orientation
