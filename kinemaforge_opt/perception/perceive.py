"""The perception stages on a loaded sequence: depth -> fused world clouds -> motion status ->
background planes -> part proposals with SE(3) tracks -> per-point resegmentation of the proposals
(:mod:`resegment`).  ``perceive(seq)`` returns a :class:`Perception` whose ``tracks`` feed
``graph.infer_tree``."""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree
from threadpoolctl import threadpool_limits
from tqdm import tqdm

from ..errors import DataError
from ..graph.fit import fit_relation
from ..graph.motion import MIN_SAMPLES, noise_sigma, relative_motion
from ..io.sequence import Sequence
from ..io.tracks import PoseTracks
from ..parallel import thread_map
from ..spatial import rms_radius
from .change import MOVING, STATIC, TEST_SIGMAS, motion_status, pixel_status
from .clouds import (NOISE_IMAGES, VOXEL_FOOTPRINTS, DepthNoise, FrameCloud, TimeCloud, camera_range,
                     downsample, estimate_depth_noise, footprint, frame_cloud, fuse, pixel_stride, static_voxel)
from .resegment import resegment
from .segment import Plane, environment_planes
from .track import ICP_FINE_VOXELS, Proposal, Tracker, merge_fragments, observed_steps, propose_and_track


@dataclass(frozen=True, eq=False)
class Perception:
    """Output of the perception stages.

    times: (T,) [s].  clouds: per time step the fused cloud.  status: per step (M_t,)
    STATIC/UNKNOWN/MOVING (after tracking, every point on a tracked part is MOVING).  noise: the depth noise model.  voxel: voxel edge [m].
    proposals: tracked candidate parts.  tracks: their full-pose PoseTracks (one track per
    proposal, frame at the proposal centroid with world axes at its reference time).
    environment: background planes.  timing_s: wall seconds per stage; cpu_s: CPU seconds
    (this process, all threads) per stage.  plane_band: distance [m] within which a point may lie
    on an environment plane (:func:`environment_band`; None: the inlier distance)."""

    times: np.ndarray
    clouds: list[TimeCloud]
    status: list[np.ndarray]
    noise: DepthNoise
    voxel: float
    proposals: list[Proposal]
    tracks: PoseTracks
    environment: list[Plane]
    timing_s: dict[str, float] = field(default_factory=dict)
    cpu_s: dict[str, float] = field(default_factory=dict)
    plane_band: float | None = None

    @property
    def inlier_distance(self) -> float:
        """Distance [m] within which a point lies on a surface: the ICP fine radius."""
        return ICP_FINE_VOXELS * self.voxel

    @property
    def environment_band(self) -> float:
        """Distance [m] within which a point may lie on an environment plane."""
        return self.inlier_distance if self.plane_band is None else self.plane_band


PLANE_BAND_QUANTILE = 0.95
"""A moving camera's plane band covers the depth noise of this share of a step's readings."""


def environment_band(cloud: TimeCloud, noise: DepthNoise, inlier: float, averaged: bool) -> float:
    """Distance [m] within which a point of ``cloud`` may lie on an environment plane.

    Static cameras' static readings are temporal means (:func:`static_depth`), so a floor or wall
    lies within the ``inlier`` distance (the fine ICP radius) at any range.  A moving camera reads
    each point once: its σ_z at 2.5 m (1.9 cm for a D435-like sensor) exceeds that radius, and a
    floor seen that way puts 2.5–3 % of the scene more than the radius behind itself, where the
    one-side test of :func:`segment.environment_planes` allows 1 %.  Then the band is TEST_SIGMAS
    σ_z at the range (:func:`clouds.camera_range`) within which PLANE_BAND_QUANTILE
    of the step's points lie, and never less than ``inlier``."""
    if averaged or not len(cloud.points):
        return inlier
    return max(inlier, float(TEST_SIGMAS * noise.sigma(np.quantile(camera_range(cloud), PLANE_BAND_QUANTILE))))


def _tracks(proposals: list[Proposal], times: np.ndarray) -> PoseTracks:
    P = np.full((len(proposals), times.size, 3), np.nan)
    R = np.full((len(proposals), times.size, 3, 3), np.nan)
    for k, p in enumerate(proposals):
        c = p.points.mean(axis=0)
        P[k] = p.Ts_delta[:, :3, :3] @ c + p.Ts_delta[:, :3, 3]
        R[k] = p.Ts_delta[:, :3, :3]
    return PoseTracks(times, tuple(p.name for p in proposals), P, R)


def _jitter(p: Proposal) -> float:
    """Noise σ per coordinate [m] of a proposal's centroid track over its observed steps
    (graph.motion.noise_sigma: robust spread about a local quadratic)."""
    ok = np.isfinite(p.Ts_delta[:, 0, 0])
    c = p.points.mean(axis=0)
    path = p.Ts_delta[ok, :3, :3] @ c + p.Ts_delta[ok, :3, 3]
    return noise_sigma(path)


def _on_a_screw(p: Proposal, times: np.ndarray, limit: float) -> bool:
    """Whether one world screw (prismatic, revolute or helical: graph.fit) moves ``p``'s points as
    its track does at its observed steps (``times`` (T,) [s]) within ``limit`` [m] per coordinate:
    the fit's centroid residual and its rotation residual swept over the points' RMS radius, an
    RMS displacement of the points, over √3."""
    motion = relative_motion(_tracks([p], times), None, 0)
    radius = rms_radius(p.points)
    for kind in ("prismatic", "revolute", "helical"):
        h = fit_relation(kind, motion)
        if np.hypot(h.residual_rms, h.rotation_rms * radius) / np.sqrt(3.0) <= limit:
            return True
    return False


def _trackable(proposals: list[Proposal], times: np.ndarray, voxel: float) -> list[Proposal]:
    """The proposals whose tracks can relate to a joint: seen at no fewer steps than any joint fit
    needs (MIN_SAMPLES, or every one of the ``times`` (T,) [s] when there are fewer), and
    following a rigid part to within the fine ICP radius (ICP_FINE_VOXELS · ``voxel`` [m]; a
    track that jumps between surfaces follows no part): its jitter is within it, or, where the
    jitter is not, one world screw explains the track within it (:func:`_on_a_screw`).

    The jitter is the spread about a local quadratic over NOISE_WINDOW samples, which assumes the
    motion smooth at the sampling rate.  At 2 frames a second it is not: a fridge door resting
    for six samples and then swung 13° → 57° → 80° (protocol_refrigerator_1@s14,v4,f12)
    has a 35-mm jitter on a track that follows the door to a few millimetres, and the door was
    lost.  A track that jumps between surfaces is on no screw either."""
    need = min(MIN_SAMPLES, times.size)
    limit = ICP_FINE_VOXELS * voxel
    proposals = [p for p in proposals if observed_steps(p) >= need]
    return [p for p in proposals if _jitter(p) <= limit or _on_a_screw(p, times, limit)]


def static_cameras(seq: Sequence, times: np.ndarray) -> bool:
    """True when every camera has one frame per time step, all at one pose (the fast path of
    :func:`change.pixel_status` applies)."""
    for cam in seq.cameras:
        frames = [f for f in seq.frames if f.camera == cam]
        if len(frames) != times.size or len({f.t for f in frames}) != times.size:
            return False
        T0 = frames[0].T_world_camera
        if any(not np.allclose(f.T_world_camera, T0, atol=1e-9) for f in frames):
            return False
    return True


def static_depth(stack: np.ndarray, status: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(h, w) per-pixel mean [m] of the STATIC readings of a (T, h, w) depth stack [m] with its
    (T, h, w) status (NaN where a pixel has none), and (h, w) how many readings each mean holds.

    A static reading of a static camera sees the same surface point at every step where it is
    static, so its temporal mean has σ_z/√n noise: on a 3 m back wall (σ_z ≈ 3 cm at k = 0.003/m)
    the single readings are thicker than any plane band, their mean over 30 steps is not."""
    ok = (status == STATIC) & np.isfinite(stack)
    n = ok.sum(axis=0)
    total = np.where(ok, stack, 0.0).sum(axis=0, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, total / np.maximum(n, 1), np.nan), n


def _pixel_status_views(seq: Sequence, times: np.ndarray, views: list[list[FrameCloud]], noise: DepthNoise) -> list[list[FrameCloud]]:
    """The views with per-pixel status from :func:`change.pixel_status`, one static camera at a
    time (edge pixels count as no reading); the world points of static pixels are moved to their
    temporal mean depth (:func:`static_depth`: the background is denoised, so a floor or wall
    lies within the plane band of :mod:`segment` at any range)."""
    step_of = {t: i for i, t in enumerate(times)}
    out = [list(v) for v in views]
    wheres = []
    for cam in seq.cameras:
        where = [(i, k) for i, vs in enumerate(views) for k, v in enumerate(vs) if v.frame.camera == cam]
        wheres.append(sorted(where, key=lambda ik: step_of[views[ik[0]][ik[1]].frame.t]))
    for where, with_status in zip(wheres, thread_map(lambda w: _camera_status([views[i][k] for i, k in w], noise), wheres)):
        for (i, k), v in zip(where, with_status):
            out[i][k] = v
    return out


def _camera_status(views: list[FrameCloud], noise: DepthNoise) -> list[FrameCloud]:
    """One static camera's views (in time order) with their per-pixel status, static pixels moved
    to their temporal mean depth (see :func:`_pixel_status_views`)."""
    stack = []
    for v in views:
        d = np.full(v.depth.shape, np.nan, dtype=np.float32)
        r, c = v.pixels[:, 0] // v.stride, v.pixels[:, 1] // v.stride
        d[r, c] = v.depth[r, c]
        stack.append(d)
    stack = np.stack(stack)
    st = pixel_status(stack, noise)
    mean, count = static_depth(stack, st)
    out = []
    for v, s_img in zip(views, st):
        r, c = v.pixels[:, 0] // v.stride, v.pixels[:, 1] // v.stride
        status = s_img[r, c]
        pts = v.points_world.copy()
        still = status == STATIC
        readings = np.where(still, np.maximum(count[r, c], 1), 1)
        if still.any():
            K = v.camera  # the decimated intrinsics (frame_cloud sets them)
            z = mean[r[still], c[still]]
            rays = np.stack([(c[still] - K.cx) / K.fx, (r[still] - K.cy) / K.fy, np.ones(z.size)], axis=1)
            T = v.frame.T_world_camera
            pts[still] = (rays * z[:, None]) @ T[:3, :3].T + T[:3, 3]
        out.append(dataclasses.replace(v, status=status, points_world=pts, readings=readings))
    return out


def perceive(seq: Sequence, progress: tqdm | None = None) -> Perception:
    """Run the perception stages on a loaded sequence (see module doc of :mod:`perception`).

    Raises DataError when no part moves (no proposal survives).  BLAS runs on one thread: the
    products here are (N, 3) @ (3, 3), which threads only slow down (5× on a busy 2-core host)."""
    with threadpool_limits(limits=1, user_api="blas"):
        return _perceive(seq, progress)


def _with_parts_moving(points: np.ndarray, status: np.ndarray, proposals: list[Proposal], s: int,
                       radius: float) -> np.ndarray:
    """(M,) ``status`` of step s's (M, 3) ``points`` with those within ``radius`` [m] of a tracked
    part's moved points set MOVING."""
    on_part = np.zeros(len(points), dtype=bool)
    for p in proposals:
        moved = p.points_at(s)
        if moved is not None:
            # only points in the part's bounding box, grown by the radius, can be within it
            near = np.flatnonzero(np.all((points >= moved.min(axis=0) - radius)
                                         & (points <= moved.max(axis=0) + radius), axis=1))
            on_part[near] |= cKDTree(moved).query(points[near], distance_upper_bound=radius)[0] < np.inf
    return np.where(on_part, np.int8(MOVING), status)


def _perceive(seq: Sequence, progress: tqdm | None) -> Perception:
    timing, cpu = {}, {}
    c0 = [time.process_time()]

    def stage(name, t0, tick=True):
        timing[name] = time.perf_counter() - t0
        cpu[name] = time.process_time() - c0[0]
        c0[0] = time.process_time()
        if progress is not None and tick:  # three ticks, as the caller's bar expects
            progress.update(1)
            progress.set_description(name)
        return time.perf_counter()

    t0 = time.perf_counter()
    times = seq.times
    depths = dict(zip((f.index for f in seq.frames), thread_map(seq.read_depth, seq.frames)))
    t0 = stage("load", t0, tick=False)
    if times.size < 2:
        raise DataError(f"{seq.root}: the sequence has one time step (t = {times[0]} s); motion needs at least two")
    foot = footprint(seq, [depths[f.index] for f in seq.frames])
    voxel = VOXEL_FOOTPRINTS * foot
    stride = pixel_stride(voxel, foot)
    pick = np.unique(np.round(np.linspace(0, len(seq.frames) - 1, min(NOISE_IMAGES, len(seq.frames)))).astype(int))
    noise = estimate_depth_noise([depths[seq.frames[i].index][::stride, ::stride] for i in pick], seq.depth_scale)
    flat = thread_map(lambda f: frame_cloud(seq, f, noise, depths[f.index], stride), seq.frames)
    cloud_of = {f.index: c for f, c in zip(seq.frames, flat)}
    views = [[cloud_of[f.index] for f in seq.frames_at(t)] for t in times]
    del depths
    t0 = stage("clouds", t0)
    static = static_cameras(seq, times)
    if static:
        views = _pixel_status_views(seq, times, views, noise)
        first = np.concatenate([v.points_world[v.status == STATIC] for v in views[0]])
        coarse = static_voxel(len(downsample(first, voxel)), voxel)
        fused = thread_map(lambda tv: fuse(tv[0], tv[1], voxel, coarse), list(zip(times, views)))
        clouds = [c for c, _ in fused]
        status = [s for _, s in fused]
    else:  # moving cameras: free-space tests between time steps on the fused points
        clouds = [c for c, _ in thread_map(lambda tv: fuse(tv[0], tv[1], voxel), list(zip(times, views)))]
        status = motion_status(clouds, seq.cameras, noise)
    t0 = stage("motion", t0)
    radius = ICP_FINE_VOXELS * voxel
    mid = times.size // 2
    band = environment_band(clouds[mid], noise, radius, averaged=static)
    # each point's depth noise: a static camera's static reading is a mean (static_depth)
    share = clouds[mid].variance_share
    noise_band = TEST_SIGMAS * noise.sigma(camera_range(clouds[mid])) * np.sqrt(1.0 if share is None else share)
    env = environment_planes(clouds[mid].points[status[mid] == STATIC], clouds[mid].points, band,
                             noise_band=noise_band)
    t0 = stage("environment", t0, tick=False)
    tracker = Tracker(clouds, status, seq.cameras, noise, voxel, tuple(env), band)
    proposals = _trackable(propose_and_track(tracker), times, voxel)
    t0 = stage("proposals+tracks", t0)
    # points that another proposal's motion (or the base) explains better move there; a proposal
    # left as one part's fragment is then absorbed like any other
    split = resegment(tracker, proposals)
    if any(a is not b for a, b in zip(split, proposals)) or len(split) != len(proposals):
        proposals = _trackable(merge_fragments(tracker, split), times, voxel)
    if not proposals:
        raise DataError(
            f"{seq.root}: no motion — no group of points moved between time steps beyond the depth "
            f"noise (σ ≈ {1e3 * float(noise.sigma(1.0)):.2g} mm at 1 m); "
            "there is no joint to infer"
        )
    # points on a tracked part move with it, whatever their own test said
    status = thread_map(lambda s: _with_parts_moving(clouds[s].points, status[s], proposals, s, radius),
                        range(len(clouds)))
    stage("resegment", t0, tick=False)  # with the status of points on the parts
    return Perception(times, clouds, status, noise, voxel, proposals, _tracks(proposals, times), env, timing, cpu, band)
