"""Ideal depth, RGB and per-pixel part labels by ray casting (open3d ``RaycastingScene``).

Cameras use OpenCV axes (x right, y down, z forward) and pixel centres at integer coordinates:
pixel (u, v) looks along K⁻¹ [u, v, 1].  Rays are built here with a unit z-component in the
camera frame, so the hit distance is the z-depth.
Labels: 0 = nothing hit, 1 = environment (floor and back wall), 2 + i = link i of the model
(in ``ArticulatedModel.link_names`` order).

Speed: what never moves (the environment and the ``fixed_links``) is ray cast once per camera
pose and cached; each render casts only the pixels whose rays can reach a moving link (the
bounding rectangles of the links' projected vertices) against the moving links, and keeps the
nearer hit.  The result equals casting the whole scene at once.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import open3d as o3d
import trimesh

from ..errors import ModelError
from ..io.sequence import CameraInfo
from ..spatial import normalize

LABEL_NONE, LABEL_ENVIRONMENT, LABEL_FIRST_LINK = 0, 1, 2
CAMERA_CACHE_SIZE = 8  # static-scene layers kept (one per camera pose; about 10 MB each at 640×480)


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
    """One ideal view.  depth: (H, W) float32 z-depth [m], 0 = nothing hit.  labels: (H, W) uint8.
    rgb: (H, W, 3) float32 in [0, 1].  cos_incidence: (H, W) float32 |cos| between ray and surface
    normal."""

    depth: np.ndarray
    labels: np.ndarray
    rgb: np.ndarray
    cos_incidence: np.ndarray


@dataclass(frozen=True, eq=False)
class _Layer:
    """Per-pixel hits of N rays.  t: (N,) float32 z-depth [m], inf = no hit.  labels: (N,) uint8.
    rgb: (N, 3) float32.  cos: (N,) float32 |cos incidence| (0 where nothing was hit)."""

    t: np.ndarray
    labels: np.ndarray
    rgb: np.ndarray
    cos: np.ndarray


@dataclass(frozen=True, eq=False)
class _CameraRays:
    """The rays of one camera pose.  origin: (3,) float32 camera centre in the world [m].
    dirs: (N, 3) float32 world directions with unit camera z, N = H·W in row-major pixel order.
    static: the hits of the static scene (environment and fixed links)."""

    origin: np.ndarray
    dirs: np.ndarray
    static: _Layer


class SceneRenderer:
    """Renders link meshes (in link frames) placed at given poses, plus a floor at z = 0 and a
    back wall, with Lambertian shading (a headlight and a light from above).

    meshes: link name -> trimesh in the link frame.  colors: link name -> RGB in [0, 1].
    link_names: the label order.  wall_y: y of the back wall [m] (None: no wall).
    fixed_links: link name -> (4, 4) T_world_link of links that never move (such as the base of
    a fixed-base object); they are cast once per camera with the environment, and
    :meth:`render` must be given the same poses for them.
    """

    def __init__(self, meshes: dict[str, trimesh.Trimesh], colors: dict[str, tuple[float, float, float]],
                 link_names: tuple[str, ...], wall_y: float | None = None, floor_half_size: float = 6.0,
                 fixed_links: dict[str, np.ndarray] | None = None):
        self.link_names = tuple(link_names)
        self.meshes = [meshes[n] for n in self.link_names]
        self.albedo = np.array([[0, 0, 0], [0.62, 0.57, 0.48]] + [colors[n] for n in self.link_names], dtype=np.float32)
        s = floor_half_size
        env = [trimesh.creation.box(extents=[2 * s, 2 * s, 0.02], transform=trimesh.transformations.translation_matrix([0, 0, -0.01]))]
        if wall_y is not None:
            env.append(trimesh.creation.box(extents=[2 * s, 0.02, 2 * s], transform=trimesh.transformations.translation_matrix([0, wall_y + 0.01, s])))
        self.environment = trimesh.util.concatenate(env)
        self.fixed = {self.link_names.index(n): np.asarray(T, dtype=float) for n, T in (fixed_links or {}).items()}
        static = [(LABEL_ENVIRONMENT, _placed_vertices(self.environment, np.eye(4)), self.environment.faces)]
        static += [(LABEL_FIRST_LINK + i, _placed_vertices(self.meshes[i], T), self.meshes[i].faces) for i, T in self.fixed.items()]
        self._static_scene = _Scene(static)
        self._camera = functools.lru_cache(maxsize=CAMERA_CACHE_SIZE)(self._camera_rays)

    def render(self, Ts_world_link: np.ndarray, intr: CameraInfo, T_world_camera: np.ndarray) -> RenderedView:
        """Render the links at ``Ts_world_link`` (L, 4, 4) from a camera at ``T_world_camera``."""
        for i, T in self.fixed.items():
            if not np.allclose(Ts_world_link[i], T):
                raise ModelError(f"render: link {self.link_names[i]!r} was declared fixed but was given another pose")
        T_world_camera = np.ascontiguousarray(T_world_camera, dtype=float)
        cam = self._camera(intr, T_world_camera.tobytes())
        t, labels, rgb, cos = (a.copy() for a in (cam.static.t, cam.static.labels, cam.static.rgb, cam.static.cos))
        moving = [(LABEL_FIRST_LINK + i, _placed_vertices(m, T), m.faces)
                  for i, (m, T) in enumerate(zip(self.meshes, Ts_world_link)) if i not in self.fixed]
        if moving:
            idx = np.flatnonzero(_footprint([V for _, V, _ in moving], intr, T_world_camera))
            hits = self._shaded(_Scene(moving), cam.origin, cam.dirs[idx])
            nearer = hits.t < t[idx]
            at = idx[nearer]
            t[at], labels[at], rgb[at], cos[at] = hits.t[nearer], hits.labels[nearer], hits.rgb[nearer], hits.cos[nearer]
        shape = (intr.height, intr.width)
        depth = np.where(np.isfinite(t), t, np.float32(0.0))
        return RenderedView(depth.reshape(shape), labels.reshape(shape), rgb.reshape(shape + (3,)), cos.reshape(shape))

    def _camera_rays(self, intr: CameraInfo, T_world_camera_bytes: bytes) -> _CameraRays:
        """The rays of a camera pose (given as the bytes of its float64 (4, 4) T_world_camera, so
        that it can be a cache key) and their hits on the static scene."""
        T = np.frombuffer(T_world_camera_bytes, dtype=float).reshape(4, 4)
        R, p = T[:3, :3].astype(np.float32), T[:3, 3].astype(np.float32)
        c = camera_rays(intr).reshape(-1, 3)
        # written out because a (N, 3) @ (3, 3) float32 matmul goes through a slow BLAS path here
        # (about 60 ms at 640×480)
        dirs = c[:, :1] * R[:, 0] + c[:, 1:2] * R[:, 1] + R[:, 2]
        return _CameraRays(p, dirs, self._shaded(self._static_scene, p, dirs))

    def _shaded(self, scene: "_Scene", origin: np.ndarray, dirs: np.ndarray) -> _Layer:
        """Cast rays from ``origin`` (3,) along ``dirs`` (N, 3) and shade the hits."""
        t, labels, normals = scene.cast(origin, dirs)
        idx = np.flatnonzero(np.isfinite(t))  # rays that hit something
        rgb = np.zeros((t.size, 3), dtype=np.float32)
        cos = np.zeros(t.size, dtype=np.float32)
        rgb[idx], cos[idx] = self._shade(labels[idx], normals[idx], dirs[idx], t[idx], origin)
        return _Layer(t, labels, rgb, cos)

    def _shade(self, labels, normals, dirs, t, origin) -> tuple[np.ndarray, np.ndarray]:
        """Lambertian colour (n, 3) and |cos incidence| (n,) of n hits: labels (n,), primitive
        normals (n, 3), ray directions (n, 3), hit distances t (n,) [m], ray origin (3,) [m].
        Floor and wall get a 25 cm checkerboard."""
        nd = np.einsum("ij,ij->i", normals, dirs) / np.sqrt(np.einsum("ij,ij->i", dirs, dirs))
        albedo = self.albedo[labels]
        env = np.flatnonzero(labels == LABEL_ENVIRONMENT)
        pts = origin + dirs[env] * t[env, None]
        checker = np.sum(np.floor((pts + 0.125) / 0.25), axis=1) % 2
        albedo[env] *= (0.8 + 0.2 * checker)[:, None]
        light = 0.25 + 0.5 * np.abs(nd) + 0.25 * np.clip(-normals[:, 2] * np.sign(nd), 0.0, 1.0)
        return np.clip(albedo * light[:, None], 0.0, 1.0), np.abs(nd)


class _Scene:
    """A ray-casting scene of labelled triangle meshes.  parts: (label, (V, 3) float32 world
    vertices [m], (F, 3) faces) triples."""

    def __init__(self, parts):
        self.scene = o3d.t.geometry.RaycastingScene()
        label_of = {self.scene.add_triangles(o3d.core.Tensor(V), o3d.core.Tensor(np.asarray(F, dtype=np.uint32))): label
                    for label, V, F in parts}
        self.lut = np.zeros(max(label_of) + 1, dtype=np.uint8)
        for gid, label in label_of.items():
            self.lut[gid] = label
        self.cast(np.zeros(3, dtype=np.float32), np.ones((1, 3), dtype=np.float32))  # builds the BVH now, so that
        # later casts from several threads do not race to build it

    def cast(self, origin: np.ndarray, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Rays from ``origin`` (3,) along ``dirs`` (N, 3) -> hit distance t (N,) float32 in units
        of |dir| (inf = no hit), labels (N,) uint8 (0 = no hit), primitive normals (N, 3) float32."""
        rays = np.empty((dirs.shape[0], 6), dtype=np.float32)
        rays[:, :3] = origin
        rays[:, 3:] = dirs
        hit = self.scene.cast_rays(o3d.core.Tensor(rays), nthreads=0)
        t = hit["t_hit"].numpy()
        ids = hit["geometry_ids"].numpy()
        labels = np.zeros(t.size, dtype=np.uint8)
        ok = np.isfinite(t)
        labels[ok] = self.lut[ids[ok]]
        return t, labels, hit["primitive_normals"].numpy()


def _placed_vertices(mesh: trimesh.Trimesh, T_world_mesh: np.ndarray) -> np.ndarray:
    """(V, 3) float32 world vertices of ``mesh`` placed at ``T_world_mesh``."""
    return (mesh.vertices @ T_world_mesh[:3, :3].T + T_world_mesh[:3, 3]).astype(np.float32)


def _footprint(vertices_world: list[np.ndarray], intr: CameraInfo, T_world_camera: np.ndarray) -> np.ndarray:
    """(H, W) bool: the pixels whose rays can hit meshes with these (V, 3) world vertices — the
    union of the bounding rectangles of their projected vertices, 1 px wider (the whole image
    when a mesh reaches behind the camera)."""
    mask = np.zeros((intr.height, intr.width), dtype=bool)
    R, p = T_world_camera[:3, :3], T_world_camera[:3, 3]
    for V in vertices_world:
        c = (V - p) @ R  # camera coordinates
        if np.any(c[:, 2] <= 1e-6):
            mask[:] = True
            return mask
        u = intr.fx * c[:, 0] / c[:, 2] + intr.cx
        v = intr.fy * c[:, 1] / c[:, 2] + intr.cy
        u0, u1 = max(int(np.floor(u.min())) - 1, 0), min(int(np.ceil(u.max())) + 1, intr.width - 1)
        v0, v1 = max(int(np.floor(v.min())) - 1, 0), min(int(np.ceil(v.max())) + 1, intr.height - 1)
        mask[v0:v1 + 1, u0:u1 + 1] = True  # empty when the rectangle is off the image
    return mask


@functools.lru_cache(maxsize=16)
def camera_rays(intr: CameraInfo) -> np.ndarray:
    """(H, W, 3) float32 ray directions in the camera frame with unit z (hit distance = z-depth);
    read-only, cached per intrinsics."""
    u, v = np.meshgrid(np.arange(intr.width, dtype=float), np.arange(intr.height, dtype=float))
    rays = np.stack([(u - intr.cx) / intr.fx, (v - intr.cy) / intr.fy, np.ones_like(u)], axis=-1).astype(np.float32)
    rays.setflags(write=False)
    return rays
