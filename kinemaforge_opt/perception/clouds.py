"""Depth images -> world point clouds: back-projection, the depth-noise estimate, edge and
outlier filtering, multi-view fusion per time step and voxel downsampling (open3d).

Noise model: a stereo depth sensor's z-noise grows as σ_z = k·z² (disparity noise), so the
*inverse* depth 1/z has a constant noise σ_{1/z} = k.  On any planar surface 1/z is an affine
function of the pixel coordinates, so its second differences along image rows and columns are
pure noise (variance 6 k²); their robust spread (MAD) over all images gives k from the data
alone, without a sensor sheet.  Depth quantisation (1 / depth_scale) sets a floor.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d

from ..errors import DataError
from ..io.sequence import CameraInfo, Frame, Sequence

# A second difference of inverse depth further than this many σ from zero is a depth edge
# (a discontinuity or a crease), not noise: a 5σ two-sided test flags ~1e-6 of noise pixels.
EDGE_SIGMAS = 5.0
# Statistical outlier removal (open3d): neighbours compared and the distance cut-off in standard
# deviations of the mean-neighbour distance (the usual PCL/open3d setting).
OUTLIER_NEIGHBOURS = 16
OUTLIER_STD_RATIO = 3.0
# Voxel edge = this many times the median pixel footprint on the surface: removes the
# redundancy of overlapping views while keeping every surface a few voxels wide.
VOXEL_FOOTPRINTS = 2.0


@dataclass(frozen=True)
class DepthNoise:
    """Depth noise model σ_z(z) = sqrt((k z²)² + quantum²/12) [m].

    k: inverse-depth noise [1/m] estimated from the data; quantum: depth step [m]."""

    k: float
    quantum: float

    def sigma(self, z: np.ndarray) -> np.ndarray:
        """σ_z [m] at depth(s) ``z`` [m] (any shape)."""
        z = np.asarray(z, dtype=float)
        return np.sqrt((self.k * z**2) ** 2 + self.quantum**2 / 12.0)


@dataclass(frozen=True, eq=False)
class FrameCloud:
    """The kept pixels of one depth image.  frame: the source frame.  pixels: (N, 2) (row,
    column) indices.  points_world: (N, 3) [m].  depth: (H, W) z-depth [m], NaN = no reading
    (the raw image, kept for free-space tests)."""

    frame: Frame
    pixels: np.ndarray
    points_world: np.ndarray
    depth: np.ndarray


@dataclass(frozen=True, eq=False)
class TimeCloud:
    """All views at one time, fused.  t: time [s].  views: the per-image clouds.
    points: (M, 3) voxel-downsampled, outlier-filtered world points [m]; normals: (M, 3) unit."""

    t: float
    views: tuple[FrameCloud, ...]
    points: np.ndarray
    normals: np.ndarray


def pixel_rays(camera: CameraInfo) -> np.ndarray:
    """(H, W, 3) camera-frame rays K⁻¹[u, v, 1] (unit z-component) of every pixel centre."""
    v, u = np.mgrid[0 : camera.height, 0 : camera.width].astype(float)
    return np.stack([(u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy, np.ones_like(u)], axis=-1)


def backproject(depth: np.ndarray, camera: CameraInfo, T_world_camera: np.ndarray) -> np.ndarray:
    """(H, W) z-depth [m] -> (H, W, 3) world points [m] (NaN where depth is NaN)."""
    p_camera = pixel_rays(camera) * depth[..., None]
    return p_camera @ T_world_camera[:3, :3].T + T_world_camera[:3, 3]


def _second_differences(inv: np.ndarray) -> np.ndarray:
    """(H, W, 2) second differences of an image along rows and columns (NaN at borders/gaps)."""
    out = np.full(inv.shape + (2,), np.nan)
    out[1:-1, :, 0] = inv[:-2] - 2 * inv[1:-1] + inv[2:]
    out[:, 1:-1, 1] = inv[:, :-2] - 2 * inv[:, 1:-1] + inv[:, 2:]
    return out


def estimate_depth_noise(depths: list[np.ndarray], depth_scale: float) -> DepthNoise:
    """Fit :class:`DepthNoise` to (H, W) depth images [m] (NaN = no reading); see module doc."""
    d2 = np.concatenate([_second_differences(1.0 / d).ravel() for d in depths])
    d2 = d2[np.isfinite(d2)]
    if d2.size < 10:
        raise DataError("the depth images hold too few valid readings to estimate the sensor noise")
    k = 1.4826 * float(np.median(np.abs(d2))) / np.sqrt(6.0)
    return DepthNoise(k, 1.0 / depth_scale)


def edge_mask(depth: np.ndarray, noise: DepthNoise) -> np.ndarray:
    """(H, W) bool: pixels next to a depth discontinuity or crease (second difference of inverse
    depth beyond EDGE_SIGMAS σ along a row or column), where readings mix two surfaces."""
    d2 = _second_differences(1.0 / depth)
    sigma = np.sqrt(6.0) * np.sqrt(noise.k**2 + (noise.quantum / np.nan_to_num(depth, nan=1.0) ** 2) ** 2 / 12.0)
    bad = np.abs(d2) > EDGE_SIGMAS * sigma[..., None]
    edge = bad.any(axis=-1)
    # a flagged centre sample implicates its two neighbours too
    grown = edge.copy()
    grown[1:] |= bad[:-1, :, 0]
    grown[:-1] |= bad[1:, :, 0]
    grown[:, 1:] |= bad[:, :-1, 1]
    grown[:, :-1] |= bad[:, 1:, 1]
    return grown


def frame_cloud(seq: Sequence, frame: Frame, noise: DepthNoise, depth: np.ndarray | None = None) -> FrameCloud:
    """The world points of one frame's valid, non-edge pixels."""
    depth = seq.read_depth(frame) if depth is None else depth
    cam = seq.cameras[frame.camera]
    keep = np.isfinite(depth) & ~edge_mask(depth, noise)
    pts = backproject(depth, cam, frame.T_world_camera)
    pixels = np.argwhere(keep)
    return FrameCloud(frame, pixels, pts[keep], depth)


def voxel_size(seq: Sequence, depths: list[np.ndarray]) -> float:
    """Voxel edge [m]: VOXEL_FOOTPRINTS × the median pixel footprint z/f over the images."""
    foot = [np.nanmedian(d) / seq.cameras[f.camera].fx for f, d in zip(seq.frames, depths) if np.isfinite(d).any()]
    return VOXEL_FOOTPRINTS * float(np.median(foot))


def fuse(t: float, views: list[FrameCloud], voxel: float) -> TimeCloud:
    """Fuse the views of one time step: voxel downsampling, statistical outlier removal, normals."""
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.concatenate([v.points_world for v in views])))
    pcd = pcd.voxel_down_sample(voxel)
    if len(pcd.points) > OUTLIER_NEIGHBOURS:
        pcd, _ = pcd.remove_statistical_outlier(OUTLIER_NEIGHBOURS, OUTLIER_STD_RATIO)
    pcd.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=3 * voxel, max_nn=30))
    return TimeCloud(t, tuple(views), np.asarray(pcd.points), np.asarray(pcd.normals))
