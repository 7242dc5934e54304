"""Ray-cast rendering against analytic geometry, and the sensor model's statistics."""

import numpy as np
import pytest
import trimesh

from kinemaforge_opt.errors import ModelError
from kinemaforge_opt.spatial import inverse
from kinemaforge_opt.io.sequence import CameraInfo
from kinemaforge_opt.synth.render import LABEL_ENVIRONMENT, LABEL_FIRST_LINK, SceneRenderer, look_at
from kinemaforge_opt.synth.sensor import CLEAN, D435, noisy_depth, noisy_rgb

INTR = CameraInfo.from_hfov("cam0", 160, 120, 60.0)


def box_renderer(wall_y=None):
    mesh = trimesh.creation.box(extents=[0.4, 0.2, 0.3])  # centred on its link frame
    return SceneRenderer({"box": mesh}, {"box": (0.8, 0.2, 0.2)}, ("box",), wall_y=wall_y)


def test_fronto_parallel_box_face_has_the_analytic_depth():
    r = box_renderer()
    T_world_box = np.eye(4)
    T_world_box[:3, 3] = [0.0, 0.0, 1.0]  # box face at y = -0.1
    T_world_camera = look_at([0.0, -2.0, 1.0], [0.0, 0.0, 1.0])
    view = r.render(T_world_box[None], INTR, T_world_camera)
    on_box = view.labels == LABEL_FIRST_LINK
    assert on_box.sum() > 500
    np.testing.assert_allclose(view.depth[on_box], 1.9, atol=1e-5)
    # the box's silhouette is where its corners project (pixel centres at integer coordinates)
    u = INTR.fx * np.array([-0.2, 0.2]) / 1.9 + INTR.cx
    v = INTR.fy * np.array([-0.15, 0.15]) / 1.9 + INTR.cy
    cols = np.nonzero(on_box.any(axis=0))[0]
    rows = np.nonzero(on_box.any(axis=1))[0]
    assert cols[0] == np.ceil(u[0]) and cols[-1] == np.floor(u[1])
    assert rows[0] == np.ceil(v[0]) and rows[-1] == np.floor(v[1])


def test_floor_depth_from_an_oblique_camera_matches_ray_plane_intersection():
    r = box_renderer()
    far = np.eye(4)
    far[:3, 3] = [0.0, 50.0, 5.0]  # the box out of view
    T_world_camera = look_at([0.3, -1.5, 1.2], [0.0, 0.5, 0.0])
    view = r.render(far[None], INTR, T_world_camera)
    floor = view.labels == LABEL_ENVIRONMENT
    assert floor.mean() > 0.9
    v, u = np.nonzero(floor)
    d_cam = np.stack([(u - INTR.cx) / INTR.fx, (v - INTR.cy) / INTR.fy, np.ones_like(u, dtype=float)], axis=1)
    d_world = d_cam @ T_world_camera[:3, :3].T
    z_expected = -T_world_camera[2, 3] / d_world[:, 2]  # unit z in the camera: hit distance = z-depth
    np.testing.assert_allclose(view.depth[floor], z_expected, rtol=1e-5)


def test_back_projected_link_pixels_lie_on_the_moved_box():
    r = box_renderer(wall_y=2.0)
    T_world_box = np.eye(4)
    c, s = np.cos(0.5), np.sin(0.5)
    T_world_box[:3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    T_world_box[:3, 3] = [0.1, 0.2, 0.5]
    T_world_camera = look_at([0.8, -1.2, 1.3], [0.1, 0.2, 0.5])
    view = r.render(T_world_box[None], INTR, T_world_camera)
    v, u = np.nonzero(view.labels == LABEL_FIRST_LINK)
    z = view.depth[v, u]
    p_cam = np.stack([(u - INTR.cx) / INTR.fx * z, (v - INTR.cy) / INTR.fy * z, z], axis=1)
    T_box_camera = inverse(T_world_box) @ T_world_camera
    p_box = p_cam @ T_box_camera[:3, :3].T + T_box_camera[:3, 3]
    half = np.array([0.2, 0.1, 0.15])
    outside = np.max(np.abs(p_box) - half, axis=1)
    assert np.all(outside < 1e-5)  # inside or on the box
    assert np.all(np.min(np.abs(np.abs(p_box) - half), axis=1) < 1e-5)  # on a face


def test_depth_noise_grows_with_z_squared_and_is_quantised():
    rng = np.random.default_rng(0)
    for z in (1.0, 2.5):
        ideal = np.full((200, 200), z)
        noisy = noisy_depth(ideal, np.ones_like(ideal), D435, rng)
        valid = noisy > 0
        assert valid.mean() == pytest.approx(1 - D435.random_dropout, abs=0.002)
        assert np.std(noisy[valid] - z) == pytest.approx(D435.depth_sigma_k * z**2, rel=0.1)
        np.testing.assert_allclose(noisy[valid] * 1000, np.round(noisy[valid] * 1000), atol=1e-6)


def test_dropouts_at_grazing_angles_edges_and_range():
    rng = np.random.default_rng(1)
    ideal = np.full((100, 100), 1.0)
    ideal[:, 50:] = 2.0  # a depth jump at column 50
    ideal[:5] = 0.1  # closer than the minimum range
    cos_inc = np.ones_like(ideal)
    cos_inc[60:] = np.cos(np.radians(89.0))
    noisy = noisy_depth(ideal, cos_inc, D435, rng)
    assert np.all(noisy[:5] == 0)
    assert (noisy[60:] == 0).mean() > 0.85
    edge = noisy[5:60, 49:51]
    assert (edge == 0).mean() == pytest.approx(D435.edge_dropout, abs=0.15)
    clean = noisy_depth(ideal, cos_inc, CLEAN, rng)
    np.testing.assert_array_equal(clean, ideal)


def test_rgb_noise_level():
    rng = np.random.default_rng(2)
    out = noisy_rgb(np.full((100, 100, 3), 0.5), D435, rng)
    assert out.dtype == np.uint8
    assert np.std(out / 255.0) == pytest.approx(D435.rgb_sigma, rel=0.15)


def test_fixed_links_cast_once_give_the_same_image_as_the_whole_scene():
    """The cached static layer plus the moving links' footprint equals one cast of everything,
    also when a moving link is partly out of view or reaches behind the camera."""
    base = trimesh.creation.box(extents=[0.6, 0.4, 0.8])
    door = trimesh.creation.box(extents=[0.5, 0.02, 0.7])
    meshes, colors = {"base": base, "door": door}, {"base": (0.5, 0.5, 0.5), "door": (0.2, 0.6, 0.3)}
    T_base = np.eye(4)
    T_base[:3, 3] = [0.0, 0.0, 0.4]
    whole = SceneRenderer(meshes, colors, ("base", "door"), wall_y=1.0)
    split = SceneRenderer(meshes, colors, ("base", "door"), wall_y=1.0, fixed_links={"base": T_base})
    T_world_camera = look_at([0.5, -2.0, 1.2], [0.0, 0.0, 0.4])
    for door_xyz in ([0.1, -0.3, 0.4], [0.9, -0.5, 0.6], [0.5, -2.0, 1.2]):  # in view, at the edge, around the camera
        T_door = np.eye(4)
        T_door[:3, 3] = door_xyz
        a = whole.render(np.stack([T_base, T_door]), INTR, T_world_camera)
        b = split.render(np.stack([T_base, T_door]), INTR, T_world_camera)
        for field in ("depth", "labels", "rgb", "cos_incidence"):
            np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
    with pytest.raises(ModelError, match="fixed"):
        split.render(np.stack([np.eye(4), T_door]), INTR, T_world_camera)
