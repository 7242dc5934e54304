"""SE(3) tracks of part proposals through the sequence (open3d ICP with verified candidates).

A proposal is a cluster of moving points at its reference time r.  Its motion ΔT(s) (world
frame, ΔT(r) = I, so the track stays anchored to the reference) is solved outward from r, one
time step at a time.  Frames far apart in time can hold large motions (a door swinging 70°
between two samples), so ICP is started from several candidate poses:

* the neighbouring solved pose, and its constant-velocity extrapolation;
* principal-axes alignments of the proposal onto every moving cluster at s (4 proper rotations).

Each candidate is refined by point-to-point ICP (coarse then fine radius; point-to-plane would
let a flat part slide in its own plane) against the non-static points at s, then *verified* by
the free-space tests of :mod:`change` against every depth image at s: the score is the share of
the proposal's points consistent with the images minus the share the images saw through.  A
candidate is acceptable when its points are mostly consistent.  Continuity first: the best
acceptable candidate started from the previous pose wins; the principal-axes candidates (which
also fit a symmetric part flipped) are used only when tracking from the previous pose is lost
(re-detection).  With no acceptable candidate the proposal is unobserved at s (NaN: occluded or
out of view), and the next step starts from the last solved pose.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d
from scipy.spatial import cKDTree

from ..io.sequence import CameraInfo
from .change import MOVING, STATIC, free_space_test, window_stack
from .clouds import DepthNoise, TimeCloud
from .segment import clusters

# ICP correspondence radii in voxels: coarse (captures the candidate's basin), then fine.
ICP_COARSE_VOXELS = 3.0
ICP_FINE_VOXELS = 1.5
ICP_ITERATIONS = 30
# A pose is accepted when at least this share of the proposal's tested points are consistent
# with the images (majority vote) ...
MIN_CONSISTENT_SHARE = 0.5
# ... and at most this share of them lie in space the cameras saw through.
MAX_VIOLATED_SHARE = 0.1


@dataclass(frozen=True, eq=False)
class Proposal:
    """A candidate rigid part.  name: track name.  ref: index of its reference time step.
    points: (N, 3) world points at the reference time [m].
    Ts_delta: (T, 4, 4) world-frame motion from the reference time (identity at ``ref``, NaN
    where unobserved): p_world(s) = Ts_delta[s] @ p_world(ref)."""

    name: str
    ref: int
    points: np.ndarray
    Ts_delta: np.ndarray

    def points_at(self, s: int) -> np.ndarray | None:
        """(N, 3) the proposal's points moved to time step s, or None if unobserved there."""
        T = self.Ts_delta[s]
        if not np.all(np.isfinite(T)):
            return None
        return self.points @ T[:3, :3].T + T[:3, 3]


def _pcd(points: np.ndarray, normals: np.ndarray | None = None) -> o3d.geometry.PointCloud:
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    if normals is not None:
        pcd.normals = o3d.utility.Vector3dVector(normals)
    return pcd


def _principal_frame(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centroid (3,) and (3, 3) principal axes (columns, right-handed) of (N, 3) points."""
    c = points.mean(axis=0)
    _, _, Vt = np.linalg.svd(points - c, full_matrices=False)
    E = Vt.T
    if np.linalg.det(E) < 0:
        E[:, 2] *= -1
    return c, E


def pca_alignments(source: np.ndarray, target: np.ndarray) -> list[np.ndarray]:
    """The 4 proper rigid transforms (4, 4) mapping the principal frame of (N, 3) ``source``
    onto that of (M, 3) ``target`` (axis signs are ambiguous)."""
    cs, Es = _principal_frame(source)
    ct, Et = _principal_frame(target)
    out = []
    for sx, sy in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
        D = np.diag([sx, sy, sx * sy])
        T = np.eye(4)
        T[:3, :3] = Et @ D @ Es.T
        T[:3, 3] = ct - T[:3, :3] @ cs
        out.append(T)
    return out


class Tracker:
    """Tracks proposals through fused time clouds (see module doc).

    clouds: the T time steps.  status: per step, (M_t,) STATIC/UNKNOWN/MOVING of its points.
    cameras, noise: for the free-space verification.  voxel: the cloud's voxel edge [m]."""

    def __init__(self, clouds: list[TimeCloud], status: list[np.ndarray], cameras: dict[str, CameraInfo],
                 noise: DepthNoise, voxel: float):
        self.clouds, self.status, self.cameras, self.noise, self.voxel = clouds, status, cameras, noise, voxel
        self.ranges = [[window_stack(v.depth) for v in c.views] for c in clouds]
        self.targets = []
        self.moving_clusters = []
        for c, s in zip(clouds, status):
            keep = s != STATIC
            self.targets.append(_pcd(c.points[keep], c.normals[keep]))
            moving = c.points[s == MOVING]
            self.moving_clusters.append([moving[i] for i in clusters(moving, voxel)])

    def verify(self, points: np.ndarray, s: int) -> tuple[float, float]:
        """(consistent share, violated share) of (N, 3) world points against the images at step
        s: the share of points some image confirms, and of points only seen through."""
        cons = np.zeros(len(points), dtype=int)
        viol = np.zeros(len(points), dtype=int)
        for view, window in zip(self.clouds[s].views, self.ranges[s]):
            v = free_space_test(points, self.cameras[view.frame.camera], view.frame.T_world_camera, window, self.noise)
            cons += v > 0
            viol += v < 0
        return float(np.mean(cons > 0)), float(np.mean((viol > 0) & (cons == 0)))

    def _icp(self, source: o3d.geometry.PointCloud, s: int, T0: np.ndarray) -> np.ndarray:
        target = self.targets[s]
        T = T0
        reg = o3d.pipelines.registration
        for radius in (ICP_COARSE_VOXELS * self.voxel, ICP_FINE_VOXELS * self.voxel):
            T = reg.registration_icp(source, target, radius, T, reg.TransformationEstimationPointToPoint(),
                                     reg.ICPConvergenceCriteria(max_iteration=ICP_ITERATIONS)).transformation
        return np.asarray(T)

    def solve_step(self, points: np.ndarray, s: int, guesses: list[np.ndarray]) -> np.ndarray | None:
        """Best verified (4, 4) world motion of (N, 3) reference points to step s, or None."""
        if len(self.targets[s].points) < 3:
            return None
        source = _pcd(points)
        pca = [T for cluster in self.moving_clusters[s] for T in pca_alignments(points, cluster)]
        for cands in (guesses, pca):
            best, best_score = None, -np.inf
            for T0 in cands:
                T = self._icp(source, s, T0)
                cons, viol = self.verify(points @ T[:3, :3].T + T[:3, 3], s)
                if cons - viol > best_score and cons >= MIN_CONSISTENT_SHARE and viol <= MAX_VIOLATED_SHARE:
                    best, best_score = T, cons - viol
            if best is not None:
                return best
        return None

    def track(self, name: str, ref: int, points: np.ndarray) -> Proposal:
        """Track (N, 3) world points of step ``ref`` through every step (module doc)."""
        n = len(self.clouds)
        Ts = np.full((n, 4, 4), np.nan)
        Ts[ref] = np.eye(4)
        for direction in (1, -1):
            solved = [np.eye(4)]
            s = ref + direction
            while 0 <= s < n:
                guesses = [solved[-1]]
                if len(solved) >= 2:
                    guesses.append(solved[-1] @ np.linalg.inv(solved[-2]) @ solved[-1])
                T = self.solve_step(points, s, guesses)
                if T is not None:
                    Ts[s] = T
                    solved.append(T)
                s += direction
        return Proposal(name, ref, points, Ts)


def propose_and_track(tracker: Tracker) -> list[Proposal]:
    """Proposals from the moving points of every time step (most moving points first): moving
    points not yet explained by a tracked proposal (within ICP_FINE_VOXELS voxels of its moved
    points) are clustered into new proposals, and each is tracked through the sequence."""
    order = np.argsort([-np.sum(s == MOVING) for s in tracker.status], kind="stable")
    proposals: list[Proposal] = []
    radius = ICP_FINE_VOXELS * tracker.voxel
    for r in order:
        moving = tracker.clouds[r].points[tracker.status[r] == MOVING]
        if len(moving) == 0:
            continue
        explained = np.zeros(len(moving), dtype=bool)
        for p in proposals:
            moved = p.points_at(r)
            if moved is not None:
                explained |= cKDTree(moved).query(moving, distance_upper_bound=radius)[0] < np.inf
        rest = moving[~explained]
        for idx in clusters(rest, tracker.voxel):
            proposals.append(tracker.track(f"p{len(proposals)}", int(r), rest[idx]))
    return proposals
