"""Ideal depth, RGB and per-pixel part labels by ray casting (open3d ``RaycastingScene``).

Cameras use OpenCV axes (x right, y down, z forward) and pixel centres at integer coordinates:
pixel (u, v) looks along K⁻¹ [u, v, 1].  Rays are built here with a unit z-component in the
camera frame, so the hit distance is the z-depth.
Labels: 0 = nothing hit, 1 = environment (floor and back wall), 2 + i = link i of the model
(in ``ArticulatedModel.link_names`` order).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import open3d as o3d
import trimesh

from ..spatial import normalize

LABEL_NONE, LABEL_ENVIRONMENT, LABEL_FIRST_LINK = 0, 1, 2


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics: image size [px], focal lengths and principal point [px]."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    @staticmethod
    def from_hfov(width: int, height: int, hfov_deg: float) -> "Intrinsics":
        """Square pixels, principal point at the image centre, horizontal field of view [deg]."""
        f = (width / 2) / np.tan(np.radians(hfov_deg) / 2)
        return Intrinsics(width, height, f, f, (width - 1) / 2, (height - 1) / 2)


def look_at(eye, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """(4, 4) T_world_camera of a camera at ``eye`` looking at ``target`` (OpenCV axes)."""
    eye, target = np.asarray(eye, dtype=float), np.asarray(target, dtype=float)
    z = normalize(target - eye)
    x = normalize(np.cross(z, np.asarray(up, dtype=float)))
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x, y, z])
    T[:3, 3] = eye
    return T


@dataclass(frozen=True, eq=False)
class RenderedView:
    """One ideal view.  depth: (H, W) z-depth [m], 0 = nothing hit.  labels: (H, W) uint8.
    rgb: (H, W, 3) in [0, 1].  cos_incidence: (H, W) |cos| between ray and surface normal."""

    depth: np.ndarray
    labels: np.ndarray
    rgb: np.ndarray
    cos_incidence: np.ndarray


class SceneRenderer:
    """Renders link meshes (in link frames) placed at given poses, plus a floor at z = 0 and a
    back wall, with Lambertian shading (a headlight and a light from above).

    meshes: link name -> trimesh in the link frame.  colors: link name -> RGB in [0, 1].
    link_names: the label order.  wall_y: y of the back wall [m] (None: no wall).
    """

    def __init__(self, meshes: dict[str, trimesh.Trimesh], colors: dict[str, tuple[float, float, float]],
                 link_names: tuple[str, ...], wall_y: float | None = None, floor_half_size: float = 6.0):
        self.link_names = tuple(link_names)
        self.meshes = [meshes[n] for n in self.link_names]
        self.albedo = np.array([[0, 0, 0], [0.62, 0.57, 0.48]] + [colors[n] for n in self.link_names], dtype=np.float32)
        s = floor_half_size
        env = [trimesh.creation.box(extents=[2 * s, 2 * s, 0.02], transform=trimesh.transformations.translation_matrix([0, 0, -0.01]))]
        if wall_y is not None:
            env.append(trimesh.creation.box(extents=[2 * s, 0.02, 2 * s], transform=trimesh.transformations.translation_matrix([0, wall_y + 0.01, s])))
        self.environment = trimesh.util.concatenate(env)

    def render(self, Ts_world_link: np.ndarray, intr: Intrinsics, T_world_camera: np.ndarray) -> RenderedView:
        """Render the links at ``Ts_world_link`` (L, 4, 4) from a camera at ``T_world_camera``."""
        scene = o3d.t.geometry.RaycastingScene()
        label_of = {}
        for label, mesh, T in [(LABEL_ENVIRONMENT, self.environment, np.eye(4))] + [
            (LABEL_FIRST_LINK + i, m, T) for i, (m, T) in enumerate(zip(self.meshes, Ts_world_link))
        ]:
            V = (mesh.vertices @ T[:3, :3].T + T[:3, 3]).astype(np.float32)
            gid = scene.add_triangles(o3d.core.Tensor(V), o3d.core.Tensor(mesh.faces.astype(np.uint32)))
            label_of[gid] = label
        R, p = T_world_camera[:3, :3].astype(np.float32), T_world_camera[:3, 3].astype(np.float32)
        c = camera_rays(intr).reshape(-1, 3)
        # (N, 3) world directions with unit camera z; written out because a (N, 3) @ (3, 3)
        # float32 matmul goes through a slow BLAS path here (about 60 ms at 640×480)
        dirs = c[:, :1] * R[:, 0] + c[:, 1:2] * R[:, 1] + R[:, 2]
        rays = np.empty((dirs.shape[0], 6), dtype=np.float32)
        rays[:, :3] = p
        rays[:, 3:] = dirs
        hit = scene.cast_rays(o3d.core.Tensor(rays), nthreads=1)
        t = hit["t_hit"].numpy()
        idx = np.flatnonzero(np.isfinite(t))  # pixels that hit something
        shape = (intr.height, intr.width)
        depth = np.zeros(t.size)
        depth[idx] = t[idx]
        lut = np.zeros(max(label_of) + 1, dtype=np.uint8)
        for gid, label in label_of.items():
            lut[gid] = label
        lab = lut[hit["geometry_ids"].numpy()[idx]]
        labels = np.zeros(t.size, dtype=np.uint8)
        labels[idx] = lab
        # shading and incidence on hit pixels only: (n, 3) float32 arrays
        n = hit["primitive_normals"].numpy()[idx]
        d = dirs[idx]
        nd = np.einsum("ij,ij->i", n, d) / np.sqrt(np.einsum("ij,ij->i", d, d))
        cos_inc = np.zeros(t.size, dtype=np.float32)
        cos_inc[idx] = np.abs(nd)
        albedo = self.albedo[lab]
        env = np.flatnonzero(lab == LABEL_ENVIRONMENT)
        pts = p + d[env] * t[idx[env], None]
        checker = np.sum(np.floor((pts + 0.125) / 0.25), axis=1) % 2  # 25 cm tiles on floor and wall
        albedo[env] *= (0.8 + 0.2 * checker)[:, None]
        light = 0.25 + 0.5 * np.abs(nd) + 0.25 * np.clip(-n[:, 2] * np.sign(nd), 0.0, 1.0)
        rgb = np.zeros((t.size, 3), dtype=np.float32)
        rgb[idx] = np.clip(albedo * light[:, None], 0.0, 1.0)
        return RenderedView(depth.reshape(shape), labels.reshape(shape), rgb.reshape(shape + (3,)), cos_inc.reshape(shape))


@functools.lru_cache(maxsize=16)
def camera_rays(intr: Intrinsics) -> np.ndarray:
    """(H, W, 3) float32 ray directions in the camera frame with unit z (hit distance = z-depth);
    read-only, cached per intrinsics."""
    u, v = np.meshgrid(np.arange(intr.width, dtype=float), np.arange(intr.height, dtype=float))
    rays = np.stack([(u - intr.cx) / intr.fx, (v - intr.cy) / intr.fy, np.ones_like(u)], axis=-1).astype(np.float32)
    rays.setflags(write=False)
    return rays
