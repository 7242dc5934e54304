"""Depth images -> world point clouds: back-projection, the depth-noise estimate, edge and
outlier filtering, multi-view fusion per time step and voxel downsampling.

Noise model: a stereo depth sensor's z-noise grows as σ_z = k·z² (disparity noise), so the
*inverse* depth 1/z has a constant noise σ_{1/z} = k.  On any planar surface 1/z is an affine
function of the pixel coordinates, so its second differences along image rows and columns are
pure noise (variance 6 k²); their robust spread (MAD) over all images gives k from the data
alone, without a sensor sheet.  Depth quantisation (1 / depth_scale) sets a floor.

Resolution: every image is first decimated to a pixel *stride* so that one view contributes
about one sample per voxel (the voxel edge is VOXEL_FOOTPRINTS full-resolution pixel
footprints, so the stride is VOXEL_FOOTPRINTS pixels); inverse depth stays affine on planes in
the decimated image, so the noise estimate and the edge test hold unchanged.  Points on moving
or undecided surfaces are fused at the voxel edge; the static background, which only feeds the
base link's mesh and the labels, is fused at a coarser voxel chosen so that one time step holds
at most STATIC_POINT_BUDGET static points (a cost bound, independent of the scene).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.spatial import cKDTree

from ..errors import DataError
from ..io.sequence import CameraInfo, Frame, Sequence
from ..parallel import thread_map

# A second difference of inverse depth further than this many σ from zero is a depth edge
# (a discontinuity or a crease), not noise: a 5σ two-sided test flags ~1e-6 of noise pixels.
EDGE_SIGMAS = 5.0
# Outlier removal of fused moving/undecided points: a point on a surface has about
# π·2² ≈ 12 neighbours within 2 voxels; one with fewer than 3 is isolated speckle.
OUTLIER_RADIUS_VOXELS = 2.0
OUTLIER_MIN_NEIGHBOURS = 3
# Voxel edge = this many times the median pixel footprint on the surface: removes the
# redundancy of overlapping views while keeping every surface a few voxels wide.
VOXEL_FOOTPRINTS = 2.0
# At most this many static points per fused time step (see module doc).
STATIC_POINT_BUDGET = 20000
# The noise estimate uses at most this many images (a few hundred thousand second differences
# pin k down to well under 1 %).
NOISE_IMAGES = 8


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
    column) indices in the full-resolution image.  points_world: (N, 3) [m].  depth: (h, w)
    z-depth [m] of the decimated image, NaN = no reading (kept for free-space tests).
    camera: the intrinsics of ``depth`` (the frame's camera decimated by ``stride``).
    status: (N,) STATIC/UNKNOWN/MOVING of each kept pixel (see :mod:`change`), or None.
    readings: (N,) how many readings of its pixel each point's depth is the mean of (a static
    camera's static pixels: :func:`~.perceive.static_depth`), or None: one each."""

    frame: Frame
    pixels: np.ndarray
    points_world: np.ndarray
    depth: np.ndarray
    camera: CameraInfo | None = None
    stride: int = 1
    status: np.ndarray | None = None
    readings: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class TimeCloud:
    """All views at one time, fused.  t: time [s].  views: the per-image clouds.
    points: (M, 3) voxel-downsampled, outlier-filtered world points [m].  sightlines: (M, 3) unit
    vectors from each point towards the cameras that saw it (the mean over the readings fused
    into it); a seen surface faces them (:func:`~kinemaforge_opt.nlp.visual.correspond`).
    variance_share: (M,) each point's depth variance as a share of one reading's, the mean over
    the points fused into it of 1/n (n: the readings each averages, ``FrameCloud.readings``);
    None: 1 (single readings)."""

    t: float
    views: tuple[FrameCloud, ...]
    points: np.ndarray
    sightlines: np.ndarray
    variance_share: np.ndarray | None = None

    @cached_property
    def tree(self) -> cKDTree:
        """KD-tree of ``points``, built on first use and kept: the tracker, the point labels and
        the mass test each search every step's cloud."""
        return cKDTree(self.points)


def camera_range(cloud: TimeCloud) -> np.ndarray:
    """(M,) distance [m] of each of ``cloud``'s points to the nearest camera of its step (≥ its
    depth: a noise band sized by it errs wide)."""
    nearest = np.full(len(cloud.points), np.inf)  # squared
    for v in cloud.views:
        np.minimum(nearest, ((cloud.points - v.frame.T_world_camera[:3, 3]) ** 2).sum(axis=1), out=nearest)
    return np.sqrt(nearest)


def decimated_camera(camera: CameraInfo, stride: int) -> CameraInfo:
    """Intrinsics of the image sampled at every ``stride``-th row and column (pixel (r, c) of the
    decimated image is pixel (stride·r, stride·c) of the original)."""
    if stride == 1:
        return camera
    return dataclasses.replace(
        camera, width=(camera.width + stride - 1) // stride, height=(camera.height + stride - 1) // stride,
        fx=camera.fx / stride, fy=camera.fy / stride, cx=camera.cx / stride, cy=camera.cy / stride)


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


def frame_cloud(seq: Sequence, frame: Frame, noise: DepthNoise, depth: np.ndarray | None = None,
                stride: int = 1) -> FrameCloud:
    """The world points of one frame's valid, non-edge pixels, sampled at every ``stride``-th
    row and column (``depth`` is the full-resolution image; read from disk when None)."""
    depth = seq.read_depth(frame) if depth is None else depth
    cam = decimated_camera(seq.cameras[frame.camera], stride)
    small = np.ascontiguousarray(depth[::stride, ::stride])
    keep = np.isfinite(small) & ~edge_mask(small, noise)
    pixels = np.argwhere(keep)
    rays = np.stack([(pixels[:, 1] - cam.cx) / cam.fx, (pixels[:, 0] - cam.cy) / cam.fy, np.ones(len(pixels))], axis=1)
    p_camera = rays * small[keep][:, None]
    T = frame.T_world_camera
    pts = p_camera @ T[:3, :3].T + T[:3, 3]
    return FrameCloud(frame, pixels * stride, pts, small, cam, stride)


def footprint(seq: Sequence, depths: list[np.ndarray]) -> float:
    """Median full-resolution pixel footprint z/f [m] over the images."""
    medians = thread_map(lambda d: np.nanmedian(d) if np.isfinite(d).any() else np.nan, depths)
    foot = [m / seq.cameras[f.camera].fx for f, m in zip(seq.frames, medians) if np.isfinite(m)]
    if not foot:
        raise DataError(f"{seq.root}: no depth image holds a valid reading")
    return float(np.median(foot))


def voxel_size(seq: Sequence, depths: list[np.ndarray]) -> float:
    """Voxel edge [m]: VOXEL_FOOTPRINTS × the median pixel footprint z/f over the images."""
    return VOXEL_FOOTPRINTS * footprint(seq, depths)


def pixel_stride(voxel: float, foot: float) -> int:
    """Pixel stride giving about one sample per voxel per view (module doc)."""
    return max(1, int(np.floor(voxel / foot + 1e-9)))


def downsample(points: np.ndarray, voxel: float, outliers: bool = False) -> np.ndarray:
    """(N, 3 + k) points [m] -> (M, 3 + k) centroids of the points in each occupied voxel of edge
    ``voxel`` [m], cells at integer multiples of the edge (what open3d's ``voxel_down_sample``
    does up to its grid offset; in numpy, several times faster on a busy host), in the order of
    each voxel's first input point; columns past the
    third are per-point attributes, averaged over each voxel like the positions;
    with ``outliers``, centroids with fewer than OUTLIER_MIN_NEIGHBOURS others within
    OUTLIER_RADIUS_VOXELS voxels are dropped (isolated speckle)."""
    if len(points) == 0:
        return np.zeros((0, points.shape[1]))
    k = np.floor(points[:, :3] / voxel).astype(np.int64)
    k -= k.min(axis=0)
    span = k.max(axis=0) + 1
    key = (k[:, 0] * span[1] + k[:, 1]) * span[2] + k[:, 2]
    _, first, inv, count = np.unique(key, return_index=True, return_inverse=True, return_counts=True)
    # voxels in the order of their first input point, not of their keys: the keys' order follows
    # the world axes, and later stages subsample by index (every k-th point, seeded subsets), so a
    # key order would make them pick other points when the same scene comes in a rotated world
    order = np.argsort(first)
    rank = np.empty_like(first)
    rank[order] = np.arange(first.size)
    inv, count = rank[inv], count[order]
    out = np.stack([np.bincount(inv, points[:, j], minlength=count.size) for j in range(points.shape[1])], axis=1) / count[:, None]
    if outliers and len(out) > OUTLIER_MIN_NEIGHBOURS:
        # a centroid is kept when its OUTLIER_MIN_NEIGHBOURS nearest others are all within the
        # radius (a k-nearest query with a distance bound: 3x cheaper than counting every
        # neighbour with query_ball_point, the same decision); one thread: fuse and seed_order
        # call this on thread_map's workers
        d = cKDTree(out[:, :3]).query(out[:, :3], k=[OUTLIER_MIN_NEIGHBOURS + 1],
                                      distance_upper_bound=OUTLIER_RADIUS_VOXELS * voxel)[0]
        out = out[np.isfinite(d[:, 0])]  # the nearest "neighbour" is the point itself
    return out


def static_voxel(n_static: int, voxel: float) -> float:
    """Coarse voxel [m] that brings ``n_static`` points fused at ``voxel`` within STATIC_POINT_BUDGET
    (areas scale with voxel²)."""
    return voxel * max(1.0, float(np.sqrt(n_static / STATIC_POINT_BUDGET)))


def fuse(t: float, views: list[FrameCloud], voxel: float, coarse: float | None = None) -> tuple[TimeCloud, np.ndarray]:
    """Fuse the views of one time step.  Returns the :class:`TimeCloud` and its (M,) int8 status.

    With per-pixel status in the views, points of each status are downsampled on their own
    (moving and undecided ones at ``voxel`` without isolated points, static ones at ``coarse``);
    without it, everything is fused at ``voxel`` and the status is UNKNOWN."""
    from .change import MOVING, STATIC, UNKNOWN

    def rows(v: FrameCloud, keep: np.ndarray | slice = slice(None)) -> np.ndarray:
        """(N, 7) positions, unit sightlines and depth variance shares (1/readings) of a view's
        kept points side by side, so that fusion averages them over each voxel."""
        x = v.points_world[keep]
        share = np.ones(len(x)) if v.readings is None else 1.0 / v.readings[keep]
        return np.hstack([x, _unit_rows(v.frame.T_world_camera[:3, 3] - x), share[:, None]])

    if any(v.status is None for v in views):
        fused = downsample(np.concatenate([rows(v) for v in views]) if views else np.zeros((0, 7)), voxel, outliers=True)
        return _time_cloud(t, views, fused), np.full(len(fused), UNKNOWN, dtype=np.int8)
    keeps = [slice(None)] * len(views)
    if coarse is not None and coarse >= 2 * voxel:
        # static pixels are sampled on the coarse grid first (each view then gives about one
        # static sample per coarse voxel, as the moving ones do per voxel)
        k = int(coarse / voxel)
        keeps = [(v.status != STATIC) | (((v.pixels[:, 0] // v.stride) % k == 0) & ((v.pixels[:, 1] // v.stride) % k == 0))
                 for v in views]
    pts = np.concatenate([rows(v, keep) for v, keep in zip(views, keeps)]) if views else np.zeros((0, 7))
    st = np.concatenate([v.status[keep] for v, keep in zip(views, keeps)]) if views else np.zeros(0, dtype=np.int8)
    parts, status = [], []
    for code, size, outl in ((MOVING, voxel, True), (UNKNOWN, voxel, True), (STATIC, coarse or voxel, False)):
        p = downsample(pts[st == code], size, outliers=outl)
        parts.append(p)
        status.append(np.full(len(p), code, dtype=np.int8))
    return _time_cloud(t, views, np.concatenate(parts)), np.concatenate(status)


def _unit_rows(v: np.ndarray) -> np.ndarray:
    """Rows of ``v`` (N, 3) scaled to unit length (zero rows stay zero)."""
    n = np.linalg.norm(v, axis=1, keepdims=True)
    return np.divide(v, n, out=np.zeros_like(v), where=n > 0)


def _time_cloud(t: float, views, fused: np.ndarray) -> TimeCloud:
    """The TimeCloud of fused (M, 7) positions, mean sightlines and mean variance shares."""
    return TimeCloud(t, tuple(views), fused[:, :3], _unit_rows(fused[:, 3:6]), fused[:, 6])
