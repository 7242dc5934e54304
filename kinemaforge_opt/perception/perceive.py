"""The perception stages on a loaded sequence: depth -> fused world clouds -> motion status ->
part proposals with SE(3) tracks -> background planes.  ``perceive(seq)`` returns a
:class:`Perception` whose ``tracks`` feed ``graph.infer_tree``."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from tqdm import tqdm

from ..errors import DataError
from ..io.sequence import Sequence
from ..io.tracks import PoseTracks
from .change import STATIC, motion_status
from .clouds import DepthNoise, TimeCloud, estimate_depth_noise, frame_cloud, fuse, voxel_size
from .segment import Plane, environment_planes
from .track import ICP_FINE_VOXELS, Proposal, Tracker, propose_and_track


@dataclass(frozen=True, eq=False)
class Perception:
    """Output of the perception stages.

    times: (T,) [s].  clouds: per time step the fused cloud.  status: per step (M_t,)
    STATIC/UNKNOWN/MOVING.  noise: the depth noise model.  voxel: voxel edge [m].
    proposals: tracked candidate parts.  tracks: their full-pose PoseTracks (one track per
    proposal, frame at the proposal centroid with world axes at its reference time).
    environment: background planes.  timing_s: seconds per stage."""

    times: np.ndarray
    clouds: list[TimeCloud]
    status: list[np.ndarray]
    noise: DepthNoise
    voxel: float
    proposals: list[Proposal]
    tracks: PoseTracks
    environment: list[Plane]
    timing_s: dict[str, float] = field(default_factory=dict)

    @property
    def inlier_distance(self) -> float:
        """Distance [m] within which a point lies on a surface: the ICP fine radius."""
        return ICP_FINE_VOXELS * self.voxel


def _tracks(proposals: list[Proposal], times: np.ndarray) -> PoseTracks:
    P = np.full((len(proposals), times.size, 3), np.nan)
    R = np.full((len(proposals), times.size, 3, 3), np.nan)
    for k, p in enumerate(proposals):
        c = p.points.mean(axis=0)
        P[k] = p.Ts_delta[:, :3, :3] @ c + p.Ts_delta[:, :3, 3]
        R[k] = p.Ts_delta[:, :3, :3]
    return PoseTracks(times, tuple(p.name for p in proposals), P, R)


def perceive(seq: Sequence, progress: tqdm | None = None) -> Perception:
    """Run the perception stages on a loaded sequence (see module doc of :mod:`perception`).

    Raises DataError when no part moves (no proposal survives)."""
    timing = {}

    def stage(name, t0):
        timing[name] = time.perf_counter() - t0
        if progress is not None:
            progress.update(1)
            progress.set_description(name)
        return time.perf_counter()

    t0 = time.perf_counter()
    depths = {f.index: seq.read_depth(f) for f in seq.frames}
    noise = estimate_depth_noise(list(depths.values()), seq.depth_scale)
    voxel = voxel_size(seq, [depths[f.index] for f in seq.frames])
    times = seq.times
    clouds = [fuse(t, [frame_cloud(seq, f, noise, depths[f.index]) for f in seq.frames_at(t)], voxel) for t in times]
    t0 = stage("clouds", t0)
    if times.size < 2:
        raise DataError(f"{seq.root}: the sequence has one time step (t = {times[0]} s); motion needs at least two")
    status = motion_status(clouds, seq.cameras, noise)
    t0 = stage("motion", t0)
    tracker = Tracker(clouds, status, seq.cameras, noise, voxel)
    proposals = propose_and_track(tracker)
    if not proposals:
        raise DataError(
            f"{seq.root}: no motion — no group of points moved between time steps beyond the depth "
            f"noise (σ ≈ {1e3 * float(noise.sigma(1.0)):.2g} mm at 1 m); "
            "there is no joint to infer"
        )
    static = np.concatenate([c.points[s == STATIC] for c, s in zip(clouds, status)])
    everything = np.concatenate([c.points for c in clouds])
    env = environment_planes(static, everything, ICP_FINE_VOXELS * voxel)
    stage("proposals+tracks", t0)
    return Perception(times, clouds, status, noise, voxel, proposals, _tracks(proposals, times), env, timing)
